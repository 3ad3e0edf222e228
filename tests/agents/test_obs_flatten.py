"""The flat feature vector: layout, scaling, batching and the wrapper used in training."""

from __future__ import annotations

import numpy as np
import pytest

from trade_gym.agents.obs_flatten import FEATURE_CLIP, FEATURE_LAYOUT, N_FEATURES, FlatObservation, flatten_observation
from trade_gym.env import TradeFollowEnv
from trade_gym.observation import observation_space


def sample_observation(seed: int) -> dict[str, np.ndarray]:
    space = observation_space()
    space.seed(seed)
    obs = space.sample()
    obs["target_pos_rel_m"] = np.array([3.0, -2.0, -16.0], np.float32)
    return obs


def test_flatten_single_observation_follows_layout_offsets_and_scales():
    obs = sample_observation(0)
    features, batched = flatten_observation(obs)
    assert not batched and features.shape == (1, N_FEATURES) and features.dtype == np.float32
    start = 0
    for key, size, offset, scale in FEATURE_LAYOUT:
        expected = np.clip((obs[key] - offset) / scale, -FEATURE_CLIP, FEATURE_CLIP)
        np.testing.assert_allclose(features[0, start:start + size], expected, rtol=1e-6)
        start += size
    assert features[0, -1] == 1.0  # a 3D position is known


def test_flatten_batch_equals_stacked_singles():
    observations = [sample_observation(seed) for seed in range(5)]
    batch = {key: np.stack([o[key] for o in observations]) for key in observations[0]}
    features, batched = flatten_observation(batch)
    assert batched and features.shape == (5, N_FEATURES)
    singles = np.concatenate([flatten_observation(o)[0] for o in observations])
    np.testing.assert_array_equal(features, singles)


def test_flatten_zero_relative_position_marks_position_unknown():
    obs = sample_observation(1)
    obs["target_pos_rel_m"] = np.zeros(3, np.float32)
    assert flatten_observation(obs)[0][0, -1] == 0.0


def test_flatten_extreme_values_are_clipped():
    obs = sample_observation(2)
    obs["target_pos_rel_m"] = np.array([1000.0, -1000.0, 0.5], np.float32)
    features = flatten_observation(obs)[0][0]
    assert features[0] == FEATURE_CLIP and features[1] == -FEATURE_CLIP


def test_flatten_missing_key_raises_key_error_naming_it():
    obs = sample_observation(3)
    del obs["imu"]
    with pytest.raises(KeyError, match="imu"):
        flatten_observation(obs)


def test_flat_observation_wrapper_matches_function_on_env_observations():
    raw_env = TradeFollowEnv(scene="city", perception="oracle", episode_duration_s=1.0)
    wrapped = FlatObservation(TradeFollowEnv(scene="city", perception="oracle", episode_duration_s=1.0))
    try:
        raw, _ = raw_env.reset(seed=0)
        flat, _ = wrapped.reset(seed=0)
        for step in range(4):
            assert wrapped.observation_space.contains(flat)
            np.testing.assert_array_equal(flat, flatten_observation(raw)[0][0])
            action = np.array([0.2, -0.1, 0.0, 0.0], np.float32)
            raw, *_ = raw_env.step(action)
            flat, *_ = wrapped.step(action)
    finally:
        raw_env.close()
        wrapped.close()


def test_flatten_ignores_the_estimate_age_the_policy_was_trained_without():
    obs = sample_observation(0)
    aged = dict(obs, estimate_age_s=np.array([0.4], np.float32))
    fresh = dict(obs, estimate_age_s=np.array([0.0], np.float32))
    assert "estimate_age_s" in observation_space().spaces
    assert not any(key == "estimate_age_s" for key, _, _, _ in FEATURE_LAYOUT)
    np.testing.assert_array_equal(flatten_observation(aged)[0], flatten_observation(fresh)[0])
