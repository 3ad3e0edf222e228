"""action_mode="waypoint": the action is a position and heading offset from the drone in its heading frame when it
arrives, held by the quadrotor's position controller; bad modes and actions fail as in velocity mode."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from tests.trade_gym.env_checks import check_env_strict
from trade_gym.action import ACTION_DIM, WaypointScale, action_space, waypoint_setpoint
from trade_gym.config import CAMERA_RATE_HZ, EnvConfig
from trade_gym.env import TradeFollowEnv

SMALL = dict(scene="city", perception="oracle", camera_size=32, action_mode="waypoint")  # the city resets fastest
GOAL_RADIUS_M = 0.3
# Measured: 0 m overshoot along the step in env and quadrotor tests (tests/trade_gym/test_quadrotor.py)
OVERSHOOT_BOUND_M = 0.05
YAW_TOLERANCE_RAD = 0.02
HOLD_DRIFT_M = 0.05
SETTLE_S = 7.0  # a 7.5 m step comes within GOAL_RADIUS_M in 5.2 s (measured)
HOLD_S = 2.0


def _heading_offset(goal_m: np.ndarray, goal_yaw_rad: float, env: TradeFollowEnv) -> np.ndarray:
    """The action that points at the world goal from the drone's current pose (what a companion computer sends)."""
    state = env.quadrotor.read_state()
    c, s = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
    dx, dy, dz = goal_m - state.position_m
    yaw = math.remainder(goal_yaw_rad - state.yaw_rad, math.tau)
    return np.array([c * dx + s * dy, -s * dx + c * dy, dz, yaw]) / env.waypoint_scale.per_component()


def test_waypoint_setpoint_adds_the_offset_in_the_heading_frame():
    position, yaw = waypoint_setpoint((2.0, 1.0, -3.0, 0.5), (10.0, 20.0, 30.0), math.pi / 2)
    np.testing.assert_allclose(position, (9.0, 22.0, 27.0), atol=1e-12)  # forward is +y, left is -x at 90 deg
    assert yaw == pytest.approx(math.pi / 2 + 0.5)


def test_waypoint_env_has_the_same_action_space_and_its_own_scale():
    env = TradeFollowEnv(**SMALL, waypoint_scale={"max_offset_horizontal_m": 10.0})
    try:
        assert env.action_space == action_space()
        assert env.waypoint_scale == WaypointScale(max_offset_horizontal_m=10.0)
        assert env.waypoint_scale.per_component() == (10.0, 10.0, 5.0, math.pi / 2)
    finally:
        env.close()


def test_waypoint_action_reaches_the_commanded_offset_and_holds_it_without_overshoot():
    env = TradeFollowEnv(**SMALL)
    try:
        env.reset(seed=0)
        start = env.quadrotor.read_state()
        c, s = math.cos(start.yaw_rad), math.sin(start.yaw_rad)
        forward, left, up, turn = 6.0, -4.0, 2.0, 0.8  # [m], [rad] in the start's heading frame
        goal = start.position_m + np.array([c * forward - s * left, s * forward + c * left, up])
        goal_yaw = start.yaw_rad + turn
        first = np.array([forward, left, up, turn]) / env.waypoint_scale.per_component()
        np.testing.assert_allclose(first, _heading_offset(goal, goal_yaw, env), atol=1e-12)
        errors, yaws, along = [], [], []
        direction = (goal - start.position_m) / np.linalg.norm(goal - start.position_m)
        for _ in range(int((SETTLE_S + HOLD_S) * CAMERA_RATE_HZ)):
            env.step(_heading_offset(goal, goal_yaw, env).astype(np.float32))
            state = env.quadrotor.read_state()
            errors.append(np.linalg.norm(state.position_m - goal))
            along.append((state.position_m - start.position_m) @ direction)
            yaws.append(math.remainder(state.yaw_rad - goal_yaw, math.tau))
    finally:
        env.close()
    held = slice(int(SETTLE_S * CAMERA_RATE_HZ), None)
    assert np.max(np.array(errors)[held]) < GOAL_RADIUS_M
    assert np.max(along) <= np.linalg.norm(goal - start.position_m) + OVERSHOOT_BOUND_M
    assert np.max(np.abs(np.array(yaws)[held])) < YAW_TOLERANCE_RAD


def test_zero_waypoint_action_holds_position_and_heading():
    env = TradeFollowEnv(**SMALL)
    try:
        env.reset(seed=1)
        start = env.quadrotor.read_state()
        for _ in range(int(HOLD_S * CAMERA_RATE_HZ)):
            env.step(np.zeros(ACTION_DIM, np.float32))
        end = env.quadrotor.read_state()
    finally:
        env.close()
    assert np.linalg.norm(end.position_m - start.position_m) < HOLD_DRIFT_M
    assert abs(end.yaw_rad - start.yaw_rad) < YAW_TOLERANCE_RAD


def test_constant_forward_waypoint_action_flies_at_most_the_speed_limit():
    env = TradeFollowEnv(**SMALL)
    try:
        env.reset(seed=0)
        infos = [env.step(np.array([1.0, 0.0, 0.0, 0.0], np.float32))[4] for _ in range(3 * CAMERA_RATE_HZ)]
        limit = env.action_scale.horizontal_mps
    finally:
        env.close()
    positions = np.array([i["drone_position_m"] for i in infos])
    speed = np.linalg.norm(np.diff(positions[:, :2], axis=0), axis=1) * CAMERA_RATE_HZ
    assert speed[-1] == pytest.approx(limit, rel=0.05)  # a 20 m offset asks 10 m/s, clipped to 8


@pytest.mark.parametrize("mode", ["teleport", "Waypoint", "position", None])
def test_unknown_action_mode_raises_value_error_naming_it(mode):
    with pytest.raises(ValueError, match=f"action_mode must be one of .*got {mode!r}"):
        gym.make("TradeFollow-v0", action_mode=mode)


@pytest.mark.parametrize("bad", [{"max_offset_horizontal_m": 0.0}, {"max_offset_vertical_m": math.nan},
                                 {"max_yaw_offset_rad": 4.0}])
def test_bad_waypoint_scale_raises_value_error_naming_the_field(bad):
    (name,) = bad
    with pytest.raises(ValueError, match=f"WaypointScale.{name} must be"):
        EnvConfig(action_mode="waypoint", waypoint_scale=bad)


@pytest.mark.parametrize("bad", [np.zeros(5), np.zeros((1, 4)), None, "north", np.array([0, 0, 0, np.nan]),
                                 [0.0, np.inf, 0.0, 0.0]])
def test_waypoint_bad_action_raises_value_error_and_leaves_the_env_usable(bad):
    env = TradeFollowEnv(**SMALL)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError):
            env.step(bad)
        env.step(np.zeros(ACTION_DIM, np.float32))
    finally:
        env.close()


def test_waypoint_action_beyond_bounds_acts_as_the_clipped_action():
    envs = [TradeFollowEnv(**SMALL) for _ in range(2)]
    rng = np.random.default_rng(4)
    try:
        first = [e.reset(seed=11)[0] for e in envs]
        assert all(np.array_equal(first[0][k], first[1][k]) for k in first[0])
        for _ in range(15):
            wild = rng.uniform(-3.0, 3.0, ACTION_DIM) * rng.choice([1.0, 1e6], ACTION_DIM)
            obs_wild, reward_wild, *_, info_wild = envs[0].step(wild.astype(np.float32))
            obs_clip, reward_clip, *_, info_clip = envs[1].step(np.clip(wild, -1.0, 1.0).astype(np.float32))
            assert all(np.array_equal(obs_wild[k], obs_clip[k]) for k in obs_wild)
            assert reward_wild == reward_clip
            np.testing.assert_array_equal(info_wild["drone_position_m"], info_clip["drone_position_m"])
    finally:
        for e in envs:
            e.close()


def test_check_env_passes_in_waypoint_mode():
    env = gym.make("TradeFollow-v0", **SMALL)
    try:
        check_env_strict(env)
    finally:
        env.close()
