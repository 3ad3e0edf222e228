"""Behaviour-cloning warm start: demonstrations carry the scripted labels, and the clone fits them."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv

from trade_gym.agents.obs_flatten import N_FEATURES
from trade_gym.agents.scripted import ScriptedFollower
from trade_gym.agents.train import TrainConfig, make_training_env
from trade_gym.agents.warm_start import (
    WarmStartConfig,
    actor_parameters,
    clone_into_policy,
    collect_demonstrations,
    discounted_returns,
)

DEMO = WarmStartConfig(demo_steps=240, action_noise_std=0.3, epochs=200, batch_size=64, learning_rate=3e-3)
# 2 s episodes, so the first 3D fix must come sooner than the fitted delay (2.6 s) for the flag to rise in each
CONFIG = TrainConfig(n_envs=1, scenes=("city",), episode_duration_s=2.0, warm_start=None, critic_warmup_steps=0,
                     env_kwargs=(("perception", "oracle"), ("oracle_first_fix_delay_s", 1.0)))
MAX_CLONE_MSE = 2e-3  # the scripted follower is smooth in its inputs; an MLP fits it closely
GAMMA = 0.9  # short horizon (44 steps to 1 %), so 2 s episodes leave usable returns
MIN_CRITIC_EXPLAINED_VARIANCE = 0.5


@pytest.fixture(scope="module")
def demonstrations():
    vec_env = DummyVecEnv([make_training_env(CONFIG, 0, flat=False)])
    vec_env.seed(3)
    try:
        return collect_demonstrations(vec_env, DEMO, np.random.default_rng(0), GAMMA)
    finally:
        vec_env.close()


def test_collect_demonstrations_returns_features_clean_labels_and_returns(demonstrations):
    demos = demonstrations
    assert demos.features.shape == (DEMO.demo_steps, N_FEATURES) and demos.labels.shape == (DEMO.demo_steps, 3)
    assert demos.returns.shape == demos.return_valid.shape == (DEMO.demo_steps,)
    assert np.all(np.abs(demos.labels) <= 1.0) and np.ptp(demos.labels[:, 0]) > 0.05
    # several 2 s episodes (60 steps each): the position-known flag resets to 0 at each start
    assert np.sum(np.diff(demos.features[:, -1]) < 0) >= 2
    assert 0 < demos.return_valid.sum() < DEMO.demo_steps  # the tails before truncations are not usable


def test_discounted_returns_follow_recursion_and_mark_cut_returns_invalid():
    rewards = np.ones((6, 2))
    dones = np.zeros((6, 2), bool)
    truncated = np.zeros((6, 2), bool)
    dones[2, 0] = True  # env 0 terminates at t = 2: complete returns up to there
    dones[3, 1] = truncated[3, 1] = True  # env 1 is truncated at t = 3
    returns, valid = discounted_returns(rewards, dones, truncated, gamma=0.5)  # horizon: 0.5^7 < 1 %
    np.testing.assert_allclose(returns[:3, 0], [1.75, 1.5, 1.0])
    np.testing.assert_allclose(returns[:4, 1], [1.875, 1.75, 1.5, 1.0])
    assert valid[:3, 0].all() and not valid[3:, 0].any()  # after the termination the collection ends
    assert not valid[:, 1].any()


def test_clone_into_policy_fits_actor_to_labels_and_critic_to_returns(demonstrations):
    env = DummyVecEnv([make_training_env(CONFIG, 0)])
    try:
        model = PPO("MlpPolicy", env, seed=0, device="cpu", gamma=GAMMA, policy_kwargs={"net_arch": [64, 64]})
        labels = demonstrations.labels
        baseline = float(np.mean((labels - labels.mean(axis=0)) ** 2))
        fit = clone_into_policy(model.policy, demonstrations, DEMO, seed=0)
        assert fit["clone_mse"] < MAX_CLONE_MSE < baseline
        assert fit["critic_explained_variance"] > MIN_CRITIC_EXPLAINED_VARIANCE
        assert any(p is model.policy.log_std for p in actor_parameters(model.policy))
    finally:
        env.close()


def test_scripted_labels_equal_the_scripted_follower_on_the_same_observations():
    vec_env = DummyVecEnv([make_training_env(CONFIG, 0, flat=False)])
    vec_env.seed(5)
    try:
        obs = vec_env.reset()
        expected, _ = ScriptedFollower().predict(obs, episode_start=np.ones(1, bool))
        vec_env.seed(5)
        demos = collect_demonstrations(vec_env, WarmStartConfig(demo_steps=1), np.random.default_rng(0), GAMMA)
        np.testing.assert_array_equal(demos.labels, expected[:, :3])
    finally:
        vec_env.close()


def test_warm_start_config_bad_value_raises_value_error_naming_field():
    with pytest.raises(ValueError, match="demo_steps"):
        WarmStartConfig(demo_steps=0)
    with pytest.raises(ValueError, match="action_noise_std"):
        WarmStartConfig(action_noise_std=-0.1)
