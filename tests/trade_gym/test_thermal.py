"""camera_modality="thermal" in the env: a hot target on the night ground, one grey image through the stack, seeded on
a stream of its own (everything else as with "rgb"), flat-field freezes, false colour only in render(), bad values."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.sim.scenes import SCENES
from trade_gym.sim.thermal_camera import DEFAULT_TIME_OF_DAY_H
from tests.trade_gym.env_checks import assert_same_truth_and_observations, check_env_strict

FRAMES = dict(perception="oracle", render_oracle_frames=True, camera_size=64)
THERMAL = dict(FRAMES, camera_modality="thermal")
ACTION = np.array([0.3, -0.2, 0.1, 0.4], dtype=np.float32)
NIGHT_H = 2.0


def _episode(seed: int, steps: int = 3, **kwargs):
    """(reset info, [camera image per frame], [info per frame], [obs per frame]) of one open-loop episode."""
    env = gym.make("TradeFollow-v0", **kwargs)
    try:
        obs, info = env.reset(seed=seed)
        images, infos, observations = [env.unwrapped.camera_frame.rgb], [info], [obs]
        for _ in range(steps):
            obs, _, _, _, info = env.step(ACTION)
            images.append(env.unwrapped.camera_frame.rgb)
            infos.append(info)
            observations.append(obs)
        return infos[0], images, infos, observations
    finally:
        env.close()


@pytest.mark.parametrize("scene", SCENES)
def test_at_night_the_target_is_hotter_than_the_ground_and_the_agc_spans_8_bits(scene):
    kwargs = THERMAL | {"camera_size": 128}  # the mountain's tank is a few pixels at 64 px
    env = gym.make("TradeFollow-v0", scene=scene, time_of_day_h=NIGHT_H, world_seed=3, **kwargs)
    try:
        env.reset(seed=1)
        base = env.unwrapped
        frame, world = base.camera_frame, base.world
        radiance = base._look.thermal.last_radiance_k
        target = frame.seg == world.target.body_id
        ground = np.isin(frame.seg, world.body_ids_by_role["terrain"])
        assert target.sum() > 20 and ground.sum() > 0.1 * ground.size
        # as a whole (a truck's cargo box or a tank's hull alone is about as warm as the ground at night)
        assert np.mean(radiance[target]) > np.median(radiance[ground]) + 3.0  # [K]
        assert np.percentile(radiance[target], 90) > np.percentile(radiance[ground], 99)  # the engine stands out
        grey = frame.rgb[:, :, 0]
        assert np.percentile(grey[target], 90) > np.percentile(grey[ground], 95)  # and shows brightest
        assert grey.min() == 0 and grey.max() == 255  # the automatic gain control uses the whole 8 bits
    finally:
        env.close()


def test_perception_and_camera_frame_get_one_grey_image_in_three_equal_channels():
    info, images, _, _ = _episode(2, steps=1, **THERMAL)
    for image in images:
        assert image.shape == (64, 64, 3) and image.dtype == np.uint8
        assert np.array_equal(image[:, :, 0], image[:, :, 1]) and np.array_equal(image[:, :, 0], image[:, :, 2])
    assert info["thermal"]["time_of_day_h"] == DEFAULT_TIME_OF_DAY_H
    env = gym.make("TradeFollow-v0", **THERMAL)  # the full stack runs on it unchanged
    try:
        env.reset(seed=2)
        delivered = env.unwrapped.delivered_sensors.rgb
        assert delivered is not None and np.array_equal(delivered, env.unwrapped.camera_frame.rgb)
    finally:
        env.close()


def test_render_shows_the_thermal_image_in_false_colour():
    env = gym.make("TradeFollow-v0", render_mode="rgb_array", **THERMAL)
    try:
        env.reset(seed=0)
        shown, grey = env.render(), env.unwrapped.camera_frame.rgb
        assert shown.shape == grey.shape and not np.array_equal(shown[:, :, 0], shown[:, :, 2])
        hot, cold = np.unravel_index(np.argmax(grey[:, :, 0]), grey.shape[:2]), np.unravel_index(
            np.argmin(grey[:, :, 0]), grey.shape[:2])
        assert shown[hot].astype(int).sum() > shown[cold].astype(int).sum()  # hot shows brighter
    finally:
        env.close()


def test_two_resets_with_one_seed_give_identical_thermal_frames():
    _, first, _, _ = _episode(4, **THERMAL)
    _, again, _, _ = _episode(4, **THERMAL)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], first[1])  # fresh sensor noise (and motion) per frame
    env = gym.make("TradeFollow-v0", **THERMAL)
    try:  # other seeds first: seed 4 still gives the same frame
        for seed in (5, 6):
            env.reset(seed=seed)
        env.reset(seed=4)
        np.testing.assert_array_equal(env.unwrapped.camera_frame.rgb, first[0])
    finally:
        env.close()


def test_ground_truth_and_every_other_draw_are_the_same_as_with_rgb():
    _, rgb_images, rgb_infos, rgb_obs = _episode(11, pose_source="vio", **FRAMES)
    _, thermal_images, thermal_infos, thermal_obs = _episode(11, pose_source="vio", **THERMAL)
    assert_same_truth_and_observations(rgb_infos, thermal_infos, rgb_obs, thermal_obs)
    assert not np.array_equal(rgb_images[0], thermal_images[0])


def test_randomized_appearance_draws_the_thermal_look_per_seed_and_keeps_a_given_time_of_day():
    draws = [_episode(seed, steps=0, appearance="randomized", world_seed=3, **THERMAL)[0]["thermal"]
             for seed in (5, 6)]
    assert draws[0]["time_of_day_h"] != draws[1]["time_of_day_h"]
    assert draws[0]["air_mean_k"] != draws[1]["air_mean_k"] and draws[0]["emissivity"] != draws[1]["emissivity"]
    given = _episode(5, steps=0, appearance="randomized", world_seed=3, time_of_day_h=21.5, **THERMAL)[0]["thermal"]
    assert given["time_of_day_h"] == 21.5 and given["air_mean_k"] == draws[0]["air_mean_k"]


def test_flat_field_correction_freezes_the_image_for_the_configured_time():
    duration_s = 0.2
    ffc = {"ffc_freeze": True, "ffc_interval_s": 1.0, "ffc_duration_s": duration_s}
    info, images, _, _ = _episode(3, steps=45, thermal=ffc, **THERMAL)
    held = [np.array_equal(a, b) for a, b in zip(images, images[1:])]  # the drone moves: live frames differ
    runs = [len(run) for run in "".join("1" if h else "0" for h in held).split("0") if run]
    assert len(runs) >= 1 and all(abs(frames / 30.0 - duration_s) <= 1.0 / 30.0 for frames in runs)
    assert 0.0 <= info["thermal"]["first_ffc_s"] < 1.0


def test_check_env_passes_with_the_thermal_camera():
    env = gym.make("TradeFollow-v0", camera_modality="thermal", camera_size=64)
    try:
        check_env_strict(env)
    finally:
        env.close()


@pytest.mark.parametrize("kwargs, message", [
    ({"camera_modality": "infrared"}, r"camera_modality must be one of .*got 'infrared'"),
    ({"camera_modality": None}, r"camera_modality must be one of .*got None"),
    ({"camera_modality": "thermal", "time_of_day_h": 24.5}, r"time_of_day_h must be in \[0.0, 24.0\], got 24.5"),
    ({"camera_modality": "thermal", "time_of_day_h": -1.0}, r"time_of_day_h must be in \[0.0, 24.0\], got -1.0"),
    ({"camera_modality": "thermal", "time_of_day_h": "noon"}, r"time_of_day_h must be a finite number, got 'noon'"),
    ({"time_of_day_h": 13.0}, r"time_of_day_h .*needs camera_modality='thermal'.*13.0"),
    ({"camera_modality": "thermal", "thermal": {"netd_mk": -5.0}}, r"ThermalConfig.netd_mk must be >= 0, got -5.0"),
])
def test_bad_thermal_arguments_raise_value_error_naming_the_value(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("TradeFollow-v0", **kwargs)
