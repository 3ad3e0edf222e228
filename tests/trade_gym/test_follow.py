"""Closed loop: the scripted follower keeps the target in view in every scene (oracle perception)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym.agents import ScriptedFollower
from trade_gym.agents.scripted import ScriptedFollowerConfig
from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.rollout import run_episode

MIN_VISIBLE_FRACTION = 0.95


def fly_episode(scene: str, seed: int, **kwargs) -> list[dict]:
    return run_episode(ScriptedFollower(), seed, scene=scene, **kwargs)


@pytest.mark.parametrize("scene", ["desert", "city", "mountain"])
def test_scripted_follower_keeps_target_in_view_full_episode(scene):
    infos = fly_episode(scene, seed=0, perception="oracle", camera_size=64)
    assert len(infos) == 900  # the full 30 s, neither crashed nor lost
    assert not any(i["crashed"] for i in infos)
    visible = np.mean([i["target_visible"] for i in infos])
    assert visible >= MIN_VISIBLE_FRACTION, f"{scene}: target visible in {visible:.3f} of frames"


def test_scripted_follower_batch_and_single_agree():
    policy_a, policy_b = ScriptedFollower(), ScriptedFollower()
    obs = {
        "target_pos_rel_m": np.array([3.0, -2.0, -16.0], np.float32),
        "target_vel_mps": np.array([2.0, 0.5, 0.0], np.float32),
        "bbox_norm": np.array([0.6, 0.4, 0.05, 0.1], np.float32),
    }
    single, _ = policy_a.predict(obs, episode_start=np.array([True]))
    batch, _ = policy_b.predict({k: v[None] for k, v in obs.items()}, episode_start=np.array([True]))
    assert single.shape == (4,) and batch.shape == (1, 4)
    np.testing.assert_array_equal(single, batch[0])
    assert single[0] > 0 and single[1] < 0  # moves towards the target: forward and right


def test_scripted_follower_without_3d_estimate_servos_towards_the_box():
    policy = ScriptedFollower()
    obs = {
        "target_pos_rel_m": np.zeros(3, np.float32),
        "target_vel_mps": np.zeros(3, np.float32),
        "bbox_norm": np.array([0.8, 0.3, 0.05, 0.1], np.float32),  # right of and above the centre
    }
    action, _ = policy.predict(obs, episode_start=np.array([True]))
    assert action[0] > 0 and action[1] < 0  # forward (image up) and right (image right)
    assert action[2] == 0 and action[3] == 0


def _unfixed(bbox_centre: tuple[float, float]) -> dict[str, np.ndarray]:
    return {"target_pos_rel_m": np.zeros(3, np.float32), "target_vel_mps": np.zeros(3, np.float32),
            "bbox_norm": np.array([*bbox_centre, 0.05, 0.1], np.float32)}


def test_image_servo_setpoint_changes_at_most_the_acceleration_limit_per_frame():
    config = ScriptedFollowerConfig()
    policy = ScriptedFollower(config)
    obs = _unfixed((1.0, 0.5))  # the box at the image's right edge: full-speed right wanted
    speeds = [float(np.linalg.norm(policy.predict(obs, episode_start=np.array([k == 0]))[0][:2])) for k in range(10)]
    step_mps = config.image_max_accel_mps2 / CAMERA_RATE_HZ
    np.testing.assert_allclose(np.array(speeds) * config.max_speed_horizontal_mps,
                               step_mps * np.arange(1, 11), rtol=1e-5)


def test_image_servo_integral_grows_with_a_constant_offset_and_restarts_with_the_episode():
    config = ScriptedFollowerConfig(image_max_accel_mps2=math.inf)
    policy = ScriptedFollower(config)
    obs = _unfixed((0.6, 0.5))  # 0.2 half-images right
    left = [float(policy.predict(obs, episode_start=np.array([k == 0]))[0][1]) for k in range(30)]
    proportional = -config.image_gain_mps * 0.2 / config.max_speed_horizontal_mps
    assert left[0] == pytest.approx(proportional - config.image_integral_gain_mps_per_s * 0.2 / CAMERA_RATE_HZ
                                    / config.max_speed_horizontal_mps, rel=1e-5)
    assert np.all(np.diff(left) < 0)  # ever faster to the right while the box stays off-centre
    again = float(policy.predict(obs, episode_start=np.array([True]))[0][1])
    assert again == pytest.approx(left[0], rel=1e-6)


@pytest.mark.parametrize("kwargs, field", [({"image_max_accel_mps2": 0.0}, "image_max_accel_mps2"),
                                           ({"image_integral_gain_mps_per_s": -1.0}, "image_integral_gain")])
def test_bad_image_servo_setting_raises_naming_it(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ScriptedFollowerConfig(**kwargs)
