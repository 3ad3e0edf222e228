"""The paper's real-flight follower: waypoints that keep altitude and yaw and centre the target (action_mode="waypoint")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym.agents import WaypointFollower, WaypointFollowerConfig
from trade_gym.config import EnvConfig
from trade_gym.env import TradeFollowEnv
from trade_gym.rollout import fly_episode
from trade.camera_pitch import mount_rotation

MIN_VISIBLE_FRACTION = 0.95
EPISODE_STEPS = 900  # the full 30 s


def _obs(rel=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), bbox=(0.0, 0.0, 0.0, 0.0)) -> dict[str, np.ndarray]:
    return {"target_pos_rel_m": np.array(rel, np.float32), "target_vel_mps": np.array(vel, np.float32),
            "bbox_norm": np.array(bbox, np.float32)}


@pytest.mark.parametrize("scene", ["desert", "mountain"])
def test_waypoint_follower_keeps_the_target_in_view_a_full_episode_without_crashing(scene):
    env = TradeFollowEnv(scene=scene, perception="oracle", camera_size=64, action_mode="waypoint")
    try:
        infos = fly_episode(env, WaypointFollower.for_env(env), seed=0)
    finally:
        env.close()
    assert len(infos) == EPISODE_STEPS  # neither crashed nor lost
    assert not any(i["crashed"] for i in infos)
    visible = np.mean([i["target_visible"] for i in infos])
    assert visible >= MIN_VISIBLE_FRACTION, f"{scene}: target visible in {visible:.3f} of frames"


def test_for_env_refuses_a_velocity_mode_env_naming_the_mode():
    env = TradeFollowEnv(scene="city", perception="oracle", camera_size=32)
    try:
        with pytest.raises(ValueError, match="needs an env with action_mode='waypoint', got action_mode='velocity'"):
            WaypointFollower.for_env(env)
    finally:
        env.close()


def test_config_of_an_env_takes_its_pitch_scale_and_position_gain():
    config = EnvConfig(action_mode="waypoint", camera_pitch_deg=45.0, waypoint_scale={"max_offset_horizontal_m": 10.0},
                       quadrotor={"position_gain_horizontal_per_s": 0.25})
    follower = WaypointFollowerConfig.of(config)
    assert (follower.camera_pitch_deg, follower.max_offset_horizontal_m, follower.lead_time_s) == (45.0, 10.0, 4.0)
    assert (follower.handover_s, follower.frame_dt_s) == (4.0, config.frame_dt_s)
    assert WaypointFollowerConfig.of(EnvConfig(action_mode="waypoint")) == WaypointFollowerConfig()


def test_target_under_the_optical_axis_and_standing_still_gives_a_zero_action():
    straight_down = WaypointFollower()  # pitch 90 deg: the axis meets the ground below the drone
    action, _ = straight_down.predict(_obs(rel=(0.0, 0.0, -16.0)))
    np.testing.assert_allclose(action, np.zeros(4), atol=1e-6)  # 16 m / tan(90 deg) is 1e-15 m, not 0
    pitched = WaypointFollower(WaypointFollowerConfig(camera_pitch_deg=45.0))  # the axis meets it 16 m ahead
    action, _ = pitched.predict(_obs(rel=(16.0, 0.0, -16.0)))
    np.testing.assert_allclose(action, np.zeros(4), atol=1e-6)


def test_offset_is_the_target_predicted_lead_time_ahead_minus_the_axis_offset_with_altitude_and_yaw_kept():
    config = WaypointFollowerConfig(camera_pitch_deg=45.0, lead_time_s=2.0, max_offset_horizontal_m=20.0)
    action, _ = WaypointFollower(config).predict(_obs(rel=(20.0, -3.0, -10.0), vel=(1.5, 0.5, 0.2)))
    forward_m, left_m = 20.0 + 2.0 * 1.5 - 10.0, -3.0 + 2.0 * 0.5
    np.testing.assert_allclose(action, [forward_m / 20.0, left_m / 20.0, 0.0, 0.0], rtol=1e-6)


def test_far_target_clips_the_horizontal_offset_keeping_its_direction():
    action, _ = WaypointFollower().predict(_obs(rel=(300.0, -400.0, -16.0)))
    assert math.hypot(action[0], action[1]) == pytest.approx(1.0)
    assert action[0] / action[1] == pytest.approx(300.0 / -400.0)


def test_before_a_3d_estimate_it_servos_towards_the_box_and_without_one_holds_position():
    follower = WaypointFollower()
    action, _ = follower.predict(_obs(bbox=(0.8, 0.3, 0.05, 0.1)))  # right of and above the centre
    assert action[0] > 0 and action[1] < 0 and action[2] == 0 and action[3] == 0  # forward and right
    np.testing.assert_allclose(action[:2] * follower.config.max_offset_horizontal_m,
                               [follower.config.image_offset_m * 0.4, -follower.config.image_offset_m * 0.6], rtol=1e-6)
    action, _ = follower.predict(_obs())
    np.testing.assert_array_equal(action, np.zeros(4, np.float32))


@pytest.mark.parametrize("down", [-0.6, -0.25, 0.3])
def test_a_pitched_cameras_servo_flies_to_where_the_box_ray_meets_the_ground_from_the_servo_height(down):
    """At 45 deg, from the camera's own mount (`mount_rotation`): the box centre's ray meets flat ground h below, h
    the servo height image_offset_m / tan(fov / 2); the offset is that point less the optical axis's."""
    config = WaypointFollowerConfig(camera_pitch_deg=45.0, max_offset_horizontal_m=1000.0)
    slope = math.tan(math.radians(config.camera_fov_deg) / 2.0)
    height_m, right = config.image_offset_m / slope, 0.2
    ray_body = mount_rotation(45.0) @ np.array([right * slope, down * slope, 1.0])  # x forward, y left, z up
    axis_body = mount_rotation(45.0) @ np.array([0.0, 0.0, 1.0])
    ground = lambda ray: ray[:2] * height_m / -ray[2]  # noqa: E731
    expected = ground(ray_body) - ground(axis_body)
    bbox = (0.5 + right / 2.0, 0.5 + down / 2.0, 0.05, 0.1)
    action, _ = WaypointFollower(config).predict(_obs(bbox=bbox))
    np.testing.assert_allclose(action[:2] * config.max_offset_horizontal_m, expected, rtol=1e-5, atol=1e-5)
    centred, _ = WaypointFollower(config).predict(_obs(bbox=(0.5, 0.5, 0.05, 0.1)))
    np.testing.assert_allclose(centred, np.zeros(4), atol=1e-6)


def test_a_pitched_cameras_servo_asks_for_the_farthest_forward_offset_for_a_ray_above_the_horizon():
    config = WaypointFollowerConfig(camera_pitch_deg=30.0, camera_fov_deg=110.0)  # the top rows look 25 deg up
    action, _ = WaypointFollower(config).predict(_obs(bbox=(0.5, 0.02, 0.05, 0.05)))
    np.testing.assert_allclose(action, [1.0, 0.0, 0.0, 0.0], atol=1e-6)


def test_batch_and_single_observations_agree():
    observations = [_obs(rel=(3.0, -2.0, -16.0), vel=(2.0, 0.5, 0.0)), _obs(bbox=(0.6, 0.4, 0.05, 0.1)), _obs()]
    follower = WaypointFollower()
    batch, _ = follower.predict({k: np.stack([o[k] for o in observations]) for k in observations[0]})
    assert batch.shape == (3, 4) and batch.dtype == np.float32
    for row, observation in zip(batch, observations):
        np.testing.assert_array_equal(row, follower.predict(observation)[0])


HANDOVER = WaypointFollowerConfig(handover_s=0.5, frame_dt_s=0.1, lead_time_s=0.0, max_offset_horizontal_m=100.0)
BOX = (0.8, 0.3, 0.05, 0.1)  # right of and above the centre
REL = (5.0, 2.0, -16.0)  # the downward camera's 3D offset is (5, 2) m


def _offsets(follower: WaypointFollower, *observations: dict[str, np.ndarray], start: bool = False) -> list[np.ndarray]:
    """The (forward, left) offsets [m] the follower asks for on consecutive frames (the first one starting an
    episode when `start`)."""
    return [follower.predict(o, episode_start=np.array([start and k == 0]))[0][:2] * 100.0
            for k, o in enumerate(observations)]


def test_the_hand_over_blends_the_servo_offset_into_the_3d_one_over_handover_s():
    """A box, then a 3D estimate with it: the offset moves from the servo's to the 3D one in handover_s / frame_dt_s
    = 5 frames; losing the 3D estimate, or a new episode, hands over again."""
    follower = WaypointFollower(HANDOVER)
    servo, *blended = _offsets(follower, _obs(bbox=BOX), *[_obs(rel=REL, bbox=BOX)] * 6)
    np.testing.assert_allclose(servo, [HANDOVER.image_offset_m * 0.4, -HANDOVER.image_offset_m * 0.6], rtol=1e-6)
    for k, offset in enumerate(blended, start=1):
        weight = min(k / 5, 1.0)
        np.testing.assert_allclose(offset, weight * np.array(REL[:2]) + (1 - weight) * servo, rtol=1e-5, atol=1e-5)
    lost, again = _offsets(follower, _obs(bbox=BOX), _obs(rel=REL, bbox=BOX))
    np.testing.assert_allclose([lost, again], [servo, 0.2 * np.array(REL[:2]) + 0.8 * servo], rtol=1e-5)
    (restarted,) = _offsets(follower, _obs(rel=REL, bbox=BOX), start=True)
    np.testing.assert_allclose(restarted, again, rtol=1e-5)


def test_the_hand_over_takes_the_3d_offset_alone_without_a_box_and_at_once_with_handover_s_0():
    follower = WaypointFollower(HANDOVER)
    np.testing.assert_allclose(_offsets(follower, _obs(rel=REL))[0], REL[:2], rtol=1e-6)
    at_once = WaypointFollower(WaypointFollowerConfig(handover_s=0.0, lead_time_s=0.0, max_offset_horizontal_m=100.0))
    np.testing.assert_allclose(_offsets(at_once, _obs(bbox=BOX), _obs(rel=REL, bbox=BOX))[1], REL[:2], rtol=1e-6)


def test_the_hand_over_is_per_env_in_a_batch():
    """Two envs three frames into a hand-over; the first starts a new episode: its weight restarts, the other's
    goes on."""
    follower, pair = WaypointFollower(HANDOVER), {k: np.stack([v, v]) for k, v in _obs(rel=REL, bbox=BOX).items()}
    for _ in range(3):
        follower.predict(pair, episode_start=np.array([False, False]))
    action, _ = follower.predict(pair, episode_start=np.array([True, False]))
    single = WaypointFollower(HANDOVER)
    first, _ = single.predict(_obs(rel=REL, bbox=BOX))
    np.testing.assert_allclose(action[0], first, rtol=1e-6)
    for _ in range(3):
        fourth, _ = single.predict(_obs(rel=REL, bbox=BOX))
    np.testing.assert_allclose(action[1], fourth, rtol=1e-6)


@pytest.mark.parametrize("bad", [{"lead_time_s": -1.0}, {"image_offset_m": 0.0}, {"camera_pitch_deg": 10.0},
                                 {"max_offset_horizontal_m": math.nan}, {"camera_fov_deg": 200.0},
                                 {"handover_s": -0.5}, {"frame_dt_s": 0.0}])
def test_bad_follower_setting_raises_naming_it(bad):
    (name,) = bad
    with pytest.raises(ValueError, match=f"WaypointFollowerConfig.{name} must be"):
        WaypointFollowerConfig(**bad)
