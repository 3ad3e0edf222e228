"""Lifecycle: close, use after close, pickling, and errors raised inside vector-env workers.

Complements test_env.py (close twice after a reset, step after close).
"""

from __future__ import annotations

import contextlib
import copy
import pickle

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest
from gymnasium.vector import AsyncVectorEnv, SyncVectorEnv

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.env import TradeFollowEnv

SMALL = dict(scene="city", perception="oracle", camera_size=64)  # the city resets fastest
STEPS = 10


def _connected(client: int) -> bool:
    return p.getConnectionInfo(physicsClientId=client)["isConnected"] == 1


def _run(env, n: int, seed: int | None) -> list[bytes]:
    """Observations of a reset (with `seed`) and n zero-action steps, as bytes."""
    obs, _ = env.reset(seed=seed)
    out = [b"".join(np.asarray(obs[k]).tobytes() for k in sorted(obs))]
    for _ in range(n):
        obs, *_ = env.step(np.zeros(4, np.float32))
        out.append(b"".join(np.asarray(obs[k]).tobytes() for k in sorted(obs)))
    return out


def test_close_before_reset_and_twice_through_make_is_safe():
    env = gym.make("TradeFollow-v0", **SMALL)
    client = env.unwrapped._client
    env.close()
    env.close()
    assert not _connected(client)


@pytest.mark.parametrize("call", ["reset", "step"])
def test_use_after_close_raises_runtime_error_naming_close(call):
    env = TradeFollowEnv(**SMALL)
    env.reset(seed=0)
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.reset(seed=0) if call == "reset" else env.step(np.zeros(4, np.float32))


def test_step_before_reset_raises_runtime_error_naming_reset():
    env = TradeFollowEnv(**SMALL)
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(4, np.float32))
    finally:
        env.close()


@pytest.mark.parametrize("clone", [lambda e: pickle.loads(pickle.dumps(e)), copy.deepcopy], ids=["pickle", "deepcopy"])
def test_pickled_env_gets_own_client_and_runs_like_a_fresh_env(clone):
    original, fresh = TradeFollowEnv(**SMALL), TradeFollowEnv(**SMALL)
    try:
        original.reset(seed=3)
        original.step(np.zeros(4, np.float32))
        copied = clone(original)
        try:
            assert copied._client not in (original._client, fresh._client) and _connected(copied._client)
            assert copied.config == original.config
            with pytest.raises(RuntimeError, match="reset"):
                copied.step(np.zeros(4, np.float32))  # the episode is not copied
            assert _run(copied, STEPS, seed=5) == _run(fresh, STEPS, seed=5)
        finally:
            copied.close()
        assert _connected(original._client)  # closing the copy leaves the original's client alone
    finally:
        original.close()
        fresh.close()


def test_pickled_env_continues_the_random_stream_of_the_original():
    env = TradeFollowEnv(**SMALL)
    try:
        env.reset(seed=8)
        copied = pickle.loads(pickle.dumps(env))
        try:
            # reset() without a seed draws the next episode from the same generator state in both
            assert _run(copied, 3, seed=None) == _run(env, 3, seed=None)
        finally:
            copied.close()
    finally:
        env.close()


def test_pickling_mid_episode_leaves_the_original_episode_unchanged():
    envs = [TradeFollowEnv(**SMALL) for _ in range(2)]
    try:
        for e in envs:
            e.reset(seed=2)
        copied = pickle.loads(pickle.dumps(envs[0]))
        copied.reset(seed=9)
        copied.step(np.ones(4, np.float32))
        copied.close()
        for _ in range(STEPS):
            a = envs[0].step(np.full(4, 0.3, np.float32))[0]
            b = envs[1].step(np.full(4, 0.3, np.float32))[0]
            assert all(np.array_equal(a[k], b[k]) for k in a)
    finally:
        for e in envs:
            e.close()


def _make_small():
    return gym.make("TradeFollow-v0", **SMALL)


@pytest.mark.parametrize("vector", ["sync", "async"])
def test_vector_env_worker_bad_action_reaches_parent_as_value_error(vector):
    envs = SyncVectorEnv([_make_small] * 2) if vector == "sync" else AsyncVectorEnv([_make_small] * 2,
                                                                                        context="fork")
    try:
        envs.reset(seed=0)
        actions = np.zeros((2, 4), np.float32)
        actions[1, 2] = np.nan
        with pytest.warns(UserWarning) if vector == "async" else contextlib.nullcontext():
            with pytest.raises(ValueError, match="finite"):
                envs.step(actions)
    finally:
        envs.close()


def test_async_vector_env_worker_bad_config_reaches_parent_as_value_error():
    with pytest.raises(ValueError, match="camera_size"):
        AsyncVectorEnv([lambda: gym.make("TradeFollow-v0", camera_size=-1)] * 2, context="fork")


def test_pickled_make_env_with_wrappers_resets_and_steps_on_its_own_client():
    env = gym.make("TradeFollow-v0", **SMALL)
    try:
        env.reset(seed=1)
        copied = pickle.loads(pickle.dumps(env))
        try:
            assert copied.unwrapped._client != env.unwrapped._client
            assert _run(copied, 3, seed=1) == _run(env, 3, seed=1)
        finally:
            copied.close()
    finally:
        env.close()
