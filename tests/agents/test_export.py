"""SB3 -> ONNX export: onnxruntime reproduces SB3's deterministic actions on the same observations."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC

from trade_gym.agents.export import export_onnx, max_export_error, sb3_actions
from trade_gym.action import ACTION_DIM
from trade_gym.agents.learned import LearnedFollower
from trade_gym.agents.obs_flatten import N_FEATURES, feature_space, flatten_observation
from trade_gym.env import TradeFollowEnv

MATCH_TOLERANCE = 1e-5
# Random weights large enough that some PPO actions hit the clip; SAC's tanh saturates sooner.
WEIGHT_STD = {PPO: 0.5, SAC: 0.1}


class FeatureEnv(gym.Env):
    """Spaces only: the policy's flat features in, a 3-D (forward, left, up) action out."""

    observation_space = feature_space()
    action_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(N_FEATURES, np.float32), {}

    def step(self, action):
        return np.zeros(N_FEATURES, np.float32), 0.0, True, False, {}


def random_model(algo, seed: int, **kwargs):
    model = algo("MlpPolicy", FeatureEnv(), seed=seed, device="cpu", policy_kwargs={"net_arch": [64, 64]}, **kwargs)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in model.policy.parameters():
            parameter.copy_(torch.randn(parameter.shape, generator=generator) * WEIGHT_STD[algo])
    return model


@pytest.fixture(scope="module")
def env_observations() -> list[dict[str, np.ndarray]]:
    n_steps = 20
    env = TradeFollowEnv(scene="city", perception="oracle", oracle_first_fix_delay_s=0.0)
    try:
        obs, _ = env.reset(seed=3)
        observations = [obs]
        for k in range(n_steps):
            obs, *_ = env.step(np.array([0.3, np.sin(k / 5.0), 0.0, 0.0], np.float32))
            observations.append(obs)
    finally:
        env.close()
    return observations


@pytest.mark.parametrize("algo, kwargs", [(PPO, {}), (PPO, {"use_sde": True}), (SAC, {})])
def test_export_onnx_actions_match_sb3_within_tolerance_on_env_observations(algo, kwargs, env_observations,
                                                                             tmp_path):
    model = random_model(algo, seed=1, **kwargs)
    path = tmp_path / "policy.onnx"
    digest = export_onnx(model, path)
    # the exported policy's own actions: no soft start, no acceleration limit
    follower = LearnedFollower(path, digest, soft_start_s=0.0, max_accel_unfixed_mps2=math.inf)
    observations = env_observations
    batch = {key: np.stack([o[key] for o in observations]) for key in observations[0]}
    features, _ = flatten_observation(batch)
    expected = sb3_actions(model, features)
    actions, _ = follower.predict(batch)
    assert actions.shape == (len(observations), ACTION_DIM)
    np.testing.assert_allclose(actions, expected, rtol=0.0, atol=MATCH_TOLERANCE)
    assert np.all(actions[:, 3] == 0.0)  # yaw rate held at zero
    assert np.all(np.abs(actions) <= 1.0)
    assert np.ptp(actions[:, :3]) > 0.1  # the observations really drive different actions


def test_export_onnx_matches_sb3_on_random_features_including_saturated_actions(tmp_path):
    model = random_model(PPO, seed=2)
    path = tmp_path / "policy.onnx"
    export_onnx(model, path)
    assert max_export_error(model, path, np.random.default_rng(0)) <= MATCH_TOLERANCE
    features = np.random.default_rng(1).normal(0.0, 2.0, (256, N_FEATURES)).astype(np.float32)
    saturated = np.abs(sb3_actions(model, features)[:, :3]) == 1.0
    assert saturated.any() and not saturated.all()


def test_export_onnx_same_model_twice_gives_identical_file(tmp_path):
    model = random_model(PPO, seed=4)
    assert export_onnx(model, tmp_path / "a.onnx") == export_onnx(model, tmp_path / "b.onnx")


def test_export_onnx_wrong_observation_space_raises_value_error(tmp_path):
    model = PPO("MlpPolicy", "Pendulum-v1", seed=0, device="cpu")
    with pytest.raises(ValueError, match="features"):
        export_onnx(model, tmp_path / "policy.onnx")
