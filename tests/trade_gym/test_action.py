"""The action's size, bounds and scale come from `trade_gym.action` alone: the env maps [-1, 1] to the quadrotor's
setpoint limits, and the followers (scripted, learned, the training env, the benchmark's floors) read the same.
"""

from __future__ import annotations

import numpy as np

from trade_gym.agents import ScriptedFollowerConfig
from trade_gym.agents.training_env import TRAIN_ACTION_DIM, ZeroYawAction
from trade_gym.action import ACTION_DIM, ACTION_NAMES, DEFAULT_ACTION_SCALE, ActionScale, action_space
from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.bench.policies import RandomPolicy, make_policy
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.quadrotor import QuadrotorConfig

SMALL = dict(scene="city", perception="oracle", camera_size=32)
FLIGHT_FRAMES = 90  # 3 s: the velocity loop (time constant 0.5 s) has settled
SPEED_TOLERANCE_MPS = 0.2
SLOW_QUADROTOR = {"max_speed_horizontal_mps": 4.0, "max_speed_vertical_mps": 1.0, "max_yaw_rate_radps": 0.5}


def test_default_env_action_is_the_published_space_and_scale():
    env = TradeFollowEnv(**SMALL)
    try:
        assert env.action_space == action_space() and env.action_space.shape == (ACTION_DIM,) == (len(ACTION_NAMES),)
        assert env.action_scale == DEFAULT_ACTION_SCALE == ActionScale.of(QuadrotorConfig())
    finally:
        env.close()


def test_full_action_flies_at_the_quadrotor_limits_given_as_a_mapping():
    env = TradeFollowEnv(**SMALL, quadrotor=SLOW_QUADROTOR)
    try:
        assert env.action_scale == ActionScale(4.0, 1.0, 0.5)
        env.reset(seed=0)
        positions = [env.step(np.array([1.0, 0.0, 0.0, 0.0], np.float32))[4]["drone_position_m"]
                     for _ in range(FLIGHT_FRAMES)]
    finally:
        env.close()
    speed = np.linalg.norm(np.diff(np.array(positions)[:, :2], axis=0), axis=1) * CAMERA_RATE_HZ
    assert np.max(speed) <= SLOW_QUADROTOR["max_speed_horizontal_mps"] + SPEED_TOLERANCE_MPS
    assert speed[-1] > SLOW_QUADROTOR["max_speed_horizontal_mps"] - SPEED_TOLERANCE_MPS


def test_scripted_follower_defaults_to_the_published_scale_and_the_bench_passes_the_envs():
    config = ScriptedFollowerConfig()
    assert (config.max_speed_horizontal_mps, config.max_speed_vertical_mps) == (
        DEFAULT_ACTION_SCALE.horizontal_mps, DEFAULT_ACTION_SCALE.vertical_mps)
    slow = ActionScale.of(QuadrotorConfig(**SLOW_QUADROTOR))
    policy = make_policy("scripted", 0, 90.0, slow)
    assert (policy.config.max_speed_horizontal_mps, policy.config.max_speed_vertical_mps) == (4.0, 1.0)


def test_training_action_is_the_env_action_without_the_yaw_rate():
    env = ZeroYawAction(TradeFollowEnv(**SMALL))
    try:
        assert env.action_space == action_space(TRAIN_ACTION_DIM) and TRAIN_ACTION_DIM == ACTION_DIM - 1
        np.testing.assert_array_equal(env.action(np.ones(TRAIN_ACTION_DIM, np.float32)), [1.0, 1.0, 1.0, 0.0])
    finally:
        env.close()


def test_random_floor_draws_actions_inside_the_published_space():
    policy = RandomPolicy(np.random.default_rng(0))
    actions = [policy.predict({})[0] for _ in range(50)]
    assert all(action_space().contains(a) for a in actions)
