"""Closed loop: the scripted follower keeps the target in view in every scene (oracle perception)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from trade_gym.agents import ScriptedFollower
from trade_gym.agents.scripted import ScriptedFollowerConfig
from trade_gym.action import ActionScale
from trade_gym.config import CAMERA_RATE_HZ, EnvConfig
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
    step_mps = config.servo_max_accel_mps2 / CAMERA_RATE_HZ
    np.testing.assert_allclose(np.array(speeds) * config.max_speed_horizontal_mps,
                               step_mps * np.arange(1, 11), rtol=1e-5)


def test_image_servo_integral_grows_with_a_constant_offset_and_restarts_with_the_episode():
    config = ScriptedFollowerConfig(servo_max_accel_mps2=math.inf)
    policy = ScriptedFollower(config)
    obs = _unfixed((0.6, 0.5))  # 0.2 half-images right: 0.2 tan(fov / 2) per metre of height
    left = [float(policy.predict(obs, episode_start=np.array([k == 0]))[0][1]) for k in range(30)]
    error = -0.2 * math.tan(math.radians(config.camera_fov_deg) / 2.0)
    assert left[0] == pytest.approx((config.servo_gain_mps + config.servo_integral_gain_mps_per_s / CAMERA_RATE_HZ)
                                    * error / config.max_speed_horizontal_mps, rel=1e-5)
    assert np.all(np.diff(left) < 0)  # ever faster to the right while the box stays off-centre
    again = float(policy.predict(obs, episode_start=np.array([True]))[0][1])
    assert again == pytest.approx(left[0], rel=1e-6)


def test_image_servo_takes_the_drones_tilt_out():
    """The IMU says the drone has pitched 20 deg nose-down; the box sits where a point right below it then appears
    (well up in the image): no horizontal command, where a servo that took the camera as level would fly on."""
    config = ScriptedFollowerConfig(servo_max_accel_mps2=math.inf, servo_integral_gain_mps_per_s=0.0)
    policy = ScriptedFollower(config)
    rate = np.zeros(6, np.float32)
    rate[4] = math.radians(20.0) * CAMERA_RATE_HZ  # about body y (left): nose down, over one frame
    slope = math.tan(math.radians(config.camera_fov_deg) / 2.0)
    up = math.tan(math.radians(20.0)) / slope  # a point below, 20 deg behind the tilted optical axis, in half-images
    obs = {**_unfixed((0.5, 0.5 - up / 2.0)), "imu": rate}
    action = policy.predict(obs, episode_start=np.array([True]))[0]
    np.testing.assert_allclose(action[:2], 0.0, atol=1e-6)
    level = ScriptedFollower(config).predict(_unfixed((0.5, 0.5 - up / 2.0)))[0]
    assert level[0] > 0.5  # read as level: the point is 0.36 heights ahead, 4.6 m/s forward


def _fixed(vel_mps: tuple[float, float]) -> dict[str, np.ndarray]:
    """A 3D estimate with the target right below at 16 m, at `vel_mps` (forward, left)."""
    return {"target_pos_rel_m": np.array([0.0, 0.0, -16.0], np.float32),
            "target_vel_mps": np.array([*vel_mps, 0.0], np.float32),
            "bbox_norm": np.array([0.5, 0.5, 0.05, 0.1], np.float32)}


def test_first_3d_estimate_feeds_forward_the_servos_integral_then_hands_over():
    """Servo after a box that stays off-centre, then 3D estimates right below with the trajectory model's first
    velocity (zero): the 3D law feeds forward the servo's integral (its estimate of the target's velocity) at the
    first estimate instead of braking, and the estimate's own velocity after handover_s."""
    config = ScriptedFollowerConfig()
    policy = ScriptedFollower(config)
    for k in range(20):
        policy.predict(_unfixed((0.5, 0.3)), episode_start=np.array([k == 0]))  # box ahead
    integral_mps = policy._episodes.servo[0, 0]
    assert integral_mps > 0.5
    frames = int(config.handover_s * CAMERA_RATE_HZ)
    handed = [policy.predict(_fixed((0.0, 0.0)))[0] for _ in range(frames + 1)]
    assert handed[0][0] == pytest.approx(integral_mps / config.max_speed_horizontal_mps, rel=1e-6)
    assert np.all(np.diff([a[0] for a in handed]) < 0)  # blends down to the 3D law's
    assert handed[-1][0] == pytest.approx(0.0, abs=1e-7)


def test_a_3d_estimate_on_the_first_frame_has_nothing_to_hand_over():
    """Oracle perception: a 3D estimate from the episode's first frame flies the 3D law at once."""
    config = ScriptedFollowerConfig()
    moving = _fixed((2.0, 0.5))
    action = ScriptedFollower(config).predict(moving, episode_start=np.array([True]))[0]
    at_once = ScriptedFollower(replace(config, handover_s=0.0)).predict(moving)[0]
    np.testing.assert_array_equal(action, at_once)
    assert action[0] == pytest.approx(2.0 / config.max_speed_horizontal_mps, rel=1e-6)


def test_config_of_an_env_takes_its_camera_and_action_scale():
    env_config = EnvConfig(camera_pitch_deg=45.0, camera_fov_deg=90.0)
    scale = ActionScale(horizontal_mps=6.0, vertical_mps=2.0, yaw_rate_radps=1.0)
    config = ScriptedFollowerConfig.of(env_config, scale)
    assert (config.camera_pitch_deg, config.camera_fov_deg) == (45.0, 90.0)
    assert (config.max_speed_horizontal_mps, config.max_speed_vertical_mps) == (6.0, 2.0)


@pytest.mark.parametrize("kwargs, field", [({"servo_max_accel_mps2": 0.0}, "servo_max_accel_mps2"),
                                           ({"servo_integral_gain_mps_per_s": -1.0}, "servo_integral_gain"),
                                           ({"servo_gain_mps": math.nan}, "servo_gain_mps"),
                                           ({"handover_s": -0.5}, "handover_s"),
                                           ({"handover_s": math.inf}, "handover_s"),
                                           ({"camera_fov_deg": 200.0}, "camera_fov_deg")])
def test_bad_follower_setting_raises_naming_it(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ScriptedFollowerConfig(**kwargs)


def _below(height_m: float) -> dict[str, np.ndarray]:
    """A 3D estimate with the target right below at `height_m`, standing still."""
    return {**_fixed((0.0, 0.0)), "target_pos_rel_m": np.array([0.0, 0.0, -height_m], np.float32)}


def test_the_height_to_hold_follows_the_estimate_through_the_hand_over_then_is_kept():
    """After a servo, a first estimate 4x too close (8 m) corrected to 32 m within the hand-over: no descent towards
    8 m; the height at the hand-over's end is held (a later estimate higher up brings the drone down to it)."""
    config = ScriptedFollowerConfig()
    policy = ScriptedFollower(config)
    for k in range(10):
        policy.predict(_unfixed((0.5, 0.3)), episode_start=np.array([k == 0]))
    frames = round(config.handover_s * CAMERA_RATE_HZ)
    ups = [policy.predict(_below(8.0 if k < 10 else 32.0))[0][2] for k in range(frames + 1)]
    np.testing.assert_array_equal(ups, 0.0)  # the held height is the estimate's: no vertical command
    up = policy.predict(_below(33.0))[0][2]  # after the hand-over: 33 m against the 32 m held
    assert up == pytest.approx(-config.height_gain_per_s * 1.0 / config.max_speed_vertical_mps, rel=1e-5)


def _coasting(height_m: float) -> dict[str, np.ndarray]:
    """An estimate right below at `height_m` without a valid track (the trajectory model coasting)."""
    return {**_below(height_m), "track_valid": np.array([0.0], np.float32)}


def test_the_height_is_held_where_it_is_while_the_track_is_lost():
    """A coasting estimate that sinks (its vertical velocity is unmeasured) gives no vertical command, nor does it
    move the height to hold during the hand-over; with the track back the held height is flown again."""
    config = ScriptedFollowerConfig()
    policy = ScriptedFollower(config)
    for k in range(10):
        policy.predict(_unfixed((0.5, 0.3)), episode_start=np.array([k == 0]))
    policy.predict({**_below(32.0), "track_valid": np.array([1.0], np.float32)})  # the first estimate: 32 m
    frames = round(config.handover_s * CAMERA_RATE_HZ)
    ups = [policy.predict(_coasting(32.0 - 0.05 * k))[0][2] for k in range(1, frames + 5)]  # past the hand-over
    np.testing.assert_array_equal(ups, 0.0)
    up = policy.predict({**_below(30.0), "track_valid": np.array([1.0], np.float32)})[0][2]  # 2 m below 32 m held
    assert up == pytest.approx(config.height_gain_per_s * 2.0 / config.max_speed_vertical_mps, rel=1e-5)
