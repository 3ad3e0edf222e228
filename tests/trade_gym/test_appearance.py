"""Appearance randomisation: seeded per reset on its own stream, "fixed" exactly as before, ground truth untouched."""

from __future__ import annotations

import hashlib
import json
import math

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade.geometry import CameraIntrinsics
from trade_gym.sim import appearance as ap
from trade_gym.sim.camera import DEFAULT_LIGHTING, CameraFrame
from trade_gym.sim.camera_effects import MOTION_BLUR_MAX_FRACTION, CameraEffects, CameraLook, line_kernel
from trade_gym.sim.scenes import SCENES, get_scene
from trade_gym.sim.texture_variants import ground_variant, palette_variant
from trade_gym.sim.vehicles import PALETTE_CELL_PX, PALETTE_RGB
from tests.trade_gym.env_checks import assert_same_truth_and_observations, check_env_strict

FRAMES = dict(perception="oracle", render_oracle_frames=True, camera_size=64)
ACTION = np.array([0.3, -0.2, 0.1, 0.4], dtype=np.float32)
STEPS = 3
# sha256 over (rgb, depth_m, vehicle labels) bytes of the reset frame and STEPS frames after ACTION, FRAMES
# settings, reset seed 7, labels from seg: 1 target, 2 + i decoy i, 0 anything else (the static bodies' own ids
# are the world's business: the terrain is built as tiles). Made on 0372246 by this file's `_episode` and
# `_frames_hash` without the `appearance` argument; on that commit the same loop hashing (rgb, depth_m, seg) gave
# the hashes made on 592a6cc, before the appearance option existed, so "fixed" still renders as then.
HASHES_BEFORE_APPEARANCE = {
    "desert": "fa169c1c6cc57f2cbefa113ec278947dfb14128ba095291552ab43f465ae4780",
    "city": "d014e264f5626aff84aba6b56b23dcd27681f4cd8fa2c9dd54fd5c12824d9c14",
    "mountain": "8e14a225b6a4dbc2b68951fe1cdd355fda3067ed8f1b35c6535b3bbc7d076ce2",
}


def _episode(seed: int, steps: int = STEPS, **kwargs):
    """(reset info, [frame per step], [info per step], [obs per step]) of one open-loop episode."""
    env = gym.make("TradeFollow-v0", **{**FRAMES, **kwargs})
    try:
        obs, info = env.reset(seed=seed)
        frames, infos, observations = [_labelled(env)], [info], [obs]
        for _ in range(steps):
            obs, _, _, _, info = env.step(ACTION)
            frames.append(_labelled(env))
            infos.append(info)
            observations.append(obs)
        return infos[0], frames, infos, observations
    finally:
        env.close()


def _labelled(env) -> CameraFrame:
    """The env's camera frame with seg turned into vehicle labels: 1 target, 2 + i decoy i, 0 anything else."""
    frame, world = env.unwrapped.camera_frame, env.unwrapped.world
    labels = np.zeros_like(frame.seg)
    for label, vehicle in enumerate((world.target, *world.decoys), start=1):
        labels[frame.seg == vehicle.body_id] = label
    return CameraFrame(frame.rgb, frame.depth_m, labels, frame.T_world_cam, frame.intrinsics)


def _frames_hash(frames: list[CameraFrame]) -> str:
    h = hashlib.sha256()
    for f in frames:
        for buffer in (f.rgb, f.depth_m, f.seg):
            h.update(buffer.tobytes())
    return h.hexdigest()


def _info_bytes(reset_info: dict) -> bytes:
    return json.dumps(reset_info["appearance"], sort_keys=True).encode()


@pytest.mark.parametrize("scene", SCENES)
def test_fixed_renders_every_frame_as_before_the_option_existed(scene):
    for kwargs in ({}, {"appearance": "fixed"}):
        info, frames, _, _ = _episode(7, scene=scene, **kwargs)
        assert _frames_hash(frames) == HASHES_BEFORE_APPEARANCE[scene]
        assert info["appearance"] == {"mode": "fixed"}


def test_same_reset_seed_gives_the_same_appearance_and_images_whatever_came_before():
    first, frames, _, _ = _episode(5, appearance="randomized")
    again, frames_again, _, _ = _episode(5, appearance="randomized")
    assert first["appearance"]["mode"] == "randomized"
    assert _info_bytes(first) == _info_bytes(again)
    assert [f.rgb.tobytes() for f in frames] == [f.rgb.tobytes() for f in frames_again]
    env = gym.make("TradeFollow-v0", appearance="randomized", **FRAMES)
    try:  # other draws first (other texture variants loaded into the client and cached): seed 5 still looks the same
        for seed in (6, 8, 9):
            env.reset(seed=seed)
        _, info = env.reset(seed=5)
        assert _info_bytes(info) == _info_bytes(first)
        assert env.unwrapped.camera_frame.rgb.tobytes() == frames[0].rgb.tobytes()
    finally:
        env.close()


def test_different_seeds_draw_different_appearances_and_images():
    a, frames_a, _, _ = _episode(5, steps=0, appearance="randomized", world_seed=3)
    b, frames_b, _, _ = _episode(6, steps=0, appearance="randomized", world_seed=3)  # same world, other look
    assert _info_bytes(a) != _info_bytes(b)
    assert not np.array_equal(frames_a[0].rgb, frames_b[0].rgb)
    np.testing.assert_array_equal(frames_a[0].seg, frames_b[0].seg)


def test_each_frame_draws_fresh_sensor_noise_from_a_seeded_stream():
    frame = _flat_frame(100.0, 10.0)
    first, second = _effects(read_noise_dn=2.0), _effects(read_noise_dn=2.0)  # both seeded 0
    a = [first.apply(frame, np.zeros(3), np.zeros(3)).rgb for _ in range(2)]
    b = [second.apply(frame, np.zeros(3), np.zeros(3)).rgb for _ in range(2)]
    assert not np.array_equal(a[0], a[1])  # fresh noise each frame
    assert all(np.array_equal(x, y) for x, y in zip(a, b))  # the same sequence from the same seed
    assert 1.0 < float(np.std(a[0].astype(float))) < 3.0  # about the drawn 2 DN (JPEG at 100 keeps most of it)


@pytest.mark.parametrize("kwargs", [{}, {"decoys": "parked", "pose_source": "vio"}], ids=["default", "parked-vio"])
def test_ground_truth_and_every_other_draw_are_the_same_under_randomized_appearance(kwargs):
    _, fixed_frames, fixed_infos, fixed_obs = _episode(11, **kwargs)
    _, rand_frames, rand_infos, rand_obs = _episode(11, appearance="randomized", **kwargs)
    for f, r in zip(fixed_frames, rand_frames, strict=True):
        np.testing.assert_array_equal(f.depth_m, r.depth_m)
        np.testing.assert_array_equal(f.seg, r.seg)
        assert not np.array_equal(f.rgb, r.rgb)
    assert_same_truth_and_observations(fixed_infos, rand_infos, fixed_obs, rand_obs)


def test_check_env_passes_with_randomized_appearance():
    env = gym.make("TradeFollow-v0", appearance="randomized", camera_size=64)
    try:
        check_env_strict(env)
    finally:
        env.close()


@pytest.mark.parametrize("bad", ["random", "Fixed", None, 1])
def test_bad_appearance_raises_value_error_naming_it(bad):
    with pytest.raises(ValueError, match=rf"appearance must be one of .*got {bad!r}"):
        gym.make("TradeFollow-v0", appearance=bad, **FRAMES)


def test_target_and_decoys_share_one_drawn_paint():
    env = gym.make("TradeFollow-v0", appearance="randomized", **FRAMES)
    try:
        _, info = env.reset(seed=4)
        world = env.unwrapped.world
        colours = {p.getVisualShapeData(v.body_id, physicsClientId=world.client_id)[0][7]
                   for v in (world.target, *world.decoys)}
        assert len(world.decoys) > 0
        assert colours == {(*info["appearance"]["vehicle_tint_rgb"], 1.0)}
    finally:
        env.close()


def test_draws_stay_in_their_named_ranges():
    spec = get_scene("city")
    for seed in range(200):
        a = ap.draw_appearance(np.random.default_rng(seed), spec)
        elevation_deg = math.degrees(math.asin(a.lighting.direction_world[2]))
        assert ap.SUN_ELEVATION_RANGE_DEG[0] <= elevation_deg <= ap.SUN_ELEVATION_RANGE_DEG[1]
        assert math.isclose(np.linalg.norm(a.lighting.direction_world), 1.0)
        assert ap.LIGHT_AMBIENT_RANGE[0] <= a.lighting.ambient <= ap.LIGHT_AMBIENT_RANGE[1]
        assert max(a.ground_tint_rgb) == 1.0 and min(a.ground_tint_rgb) >= ap.GROUND_TINT_RANGE[0]
        assert a.ground_contrast in ap.GROUND_CONTRASTS and a.ground_detail in ap.GROUND_DETAILS
        assert all(ap.VEHICLE_TINT_RANGE[0] <= c <= ap.VEHICLE_TINT_RANGE[1] for c in a.vehicle_tint_rgb)
        nadir = math.exp(-a.camera.haze_extinction_per_m * spec.follow_altitude_agl_m)
        assert ap.HAZE_NADIR_TRANSMISSION_RANGE[0] <= nadir <= ap.HAZE_NADIR_TRANSMISSION_RANGE[1]
        assert ap.EXPOSURE_RANGE_S[0] <= a.camera.exposure_s <= ap.EXPOSURE_RANGE_S[1]
        assert ap.JPEG_QUALITY_RANGE[0] <= a.camera.jpeg_quality <= ap.JPEG_QUALITY_RANGE[1]
        assert json.loads(json.dumps(a.as_info())) == a.as_info()  # plain values only


def test_appearance_stream_leaves_the_env_generator_untouched():
    rng = np.random.default_rng(21)
    state = rng.bit_generator.state
    assert ap.appearance_stream(rng, "fixed") is None
    a, b = ap.appearance_stream(rng, "randomized"), ap.appearance_stream(rng, "randomized")
    assert rng.bit_generator.state == state and rng.bit_generator.seed_seq.n_children_spawned == 0
    assert a.integers(0, 2**62) == b.integers(0, 2**62)
    rng.random()
    assert ap.appearance_stream(rng, "randomized").integers(0, 2**62) != ap.appearance_stream(
        np.random.default_rng(21), "randomized").integers(0, 2**62)  # unseeded resets: the state moved, so the draw


def test_default_lighting_is_what_pybullet_lights_with_when_given_none():
    env = gym.make("TradeFollow-v0", **FRAMES)
    try:
        env.reset(seed=2)
        u = env.unwrapped
        np.testing.assert_array_equal(u.camera.render(u.true_camera_pose, DEFAULT_LIGHTING).rgb, u.camera_frame.rgb)
    finally:
        env.close()


def test_identity_texture_variants_are_the_shipped_textures():
    rgb = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    np.testing.assert_array_equal(ground_variant(rgb, 0, 1, 1.0), rgb)
    palette = np.repeat(np.repeat(np.array([PALETTE_RGB], np.uint8), PALETTE_CELL_PX, 1), PALETTE_CELL_PX, 0)
    np.testing.assert_array_equal(palette_variant(palette, (0,), 0.0), palette)
    turned = palette_variant(palette, (0,), 120.0)
    assert turned[0, 0, 1] > turned[0, 0, 0]  # red car body turned green
    np.testing.assert_array_equal(turned[:, PALETTE_CELL_PX:], palette[:, PALETTE_CELL_PX:])  # other cells as shipped


def _flat_frame(intensity_dn: float, depth_m: float, size: int = 64) -> CameraFrame:
    return CameraFrame(np.full((size, size, 3), intensity_dn, np.uint8), np.full((size, size), depth_m, np.float32),
                       np.zeros((size, size), np.int32), None, CameraIntrinsics.from_fov(size, size, 110.0))


def _effects(**changes) -> CameraEffects:
    look = dict(haze_extinction_per_m=0.0, haze_rgb=(200.0, 200.0, 200.0), exposure_s=0.01, gain_ev=0.0,
                read_noise_dn=0.0, shot_noise_dn=0.0, vignetting=0.0, jpeg_quality=100) | changes
    return CameraEffects(CameraLook(**look), CameraIntrinsics.from_fov(64, 64, 110.0), np.random.default_rng(0))


def test_haze_blends_toward_the_haze_colour_by_distance_along_the_ray():
    beta = 0.01
    near, far = (_effects(haze_extinction_per_m=beta).apply(_flat_frame(100.0, d), np.zeros(3), np.zeros(3))
                 for d in (10.0, 100.0))
    centre = near.rgb[32, 32, 0], far.rgb[32, 32, 0]
    # I = haze + (I0 - haze) exp(-beta d); the centre ray is 1.006 z long at 64 px
    for got, d in zip(centre, (10.0, 100.0)):
        assert abs(got - (200.0 + (100.0 - 200.0) * math.exp(-beta * d * 1.006))) <= 1.0
    assert far.rgb[0, 0, 0] > far.rgb[32, 32, 0]  # a corner ray is longer: more haze
    np.testing.assert_array_equal(far.depth_m, _flat_frame(100.0, 100.0).depth_m)  # depth untouched


def test_gain_and_vignetting_scale_the_image_darker_at_the_corners():
    out = _effects(gain_ev=1.0, vignetting=0.3).apply(_flat_frame(60.0, 10.0), np.zeros(3), np.zeros(3)).rgb
    assert abs(int(out[32, 32, 0]) - 120) <= 1  # +1 EV doubles
    assert abs(int(out[0, 0, 0]) - 120 * 0.7) <= 2  # the corner loses the vignetting share


def test_motion_blur_smears_along_the_image_motion_of_the_drone():
    effects = _effects(exposure_s=0.01)
    depth = np.full((64, 64), 20.0, np.float32)
    fx = effects.intrinsics.fx_px
    # flying +x (camera frame) at 10 m/s over ground 20 m below: the scene moves -x at fx v / Z [px/s]
    np.testing.assert_allclose(effects.blur_px(depth, np.array([10.0, 0.0, 0.0]), np.zeros(3)),
                               (-fx * 10.0 / 20.0 * 0.01, 0.0))
    kernel = line_kernel(5.0, np.array([1.0, 0.0]))
    assert math.isclose(kernel.sum(), 1.0, rel_tol=1e-6) and kernel.shape == (7, 7)
    np.testing.assert_array_equal(kernel[:3], 0.0)  # all on the middle row
    stripes = np.zeros((64, 64, 3), np.uint8)
    stripes[:, ::8] = 255
    frame = CameraFrame(stripes, depth, np.zeros((64, 64), np.int32), None, effects.intrinsics)
    rotating = np.array([0.0, 8.0, 0.0])  # 8 rad/s about the camera's y axis: a horizontal smear, bounded
    blurred = effects.apply(frame, np.zeros(3), rotating).rgb.astype(float)[:, :, 0]
    reach = math.ceil(MOTION_BLUR_MAX_FRACTION * 64 / 2.0)  # the smear's half length, bounded
    row = blurred[32]
    assert row[8] < 250 and row[9] > 5  # a stripe's light spreads sideways...
    np.testing.assert_allclose(row[8 + reach + 1:16 - reach], 0.0, atol=1.0)  # ...no farther than the bound
    np.testing.assert_allclose(blurred.std(axis=0), 0.0, atol=1.0)  # nothing smeared vertically
