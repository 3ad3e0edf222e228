"""Determinism: the same seed gives the same bytes, across env instances, reuse, processes and vector envs.

Fast tests use short runs; the 200-step versions of the issue's criteria are marked slow (`make test-slow`).
test_env.py already checks 200 oracle steps with frames; here the TRADE stack is in the loop.
"""

from __future__ import annotations

import functools
import hashlib
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AsyncVectorEnv, SyncVectorEnv

from trade_gym.agents import ScriptedFollower
from trade_gym.env import TradeFollowEnv

ENV_ID = "trade_gym:TradeFollow-v0"  # the module prefix imports trade_gym in spawned workers
TRADE = dict(perception="trade", camera_size=64)
ORACLE = dict(perception="oracle", camera_size=64)
FAST = dict(scene="city")  # fast tests use the scene that builds quickest; slow ones the default desert
FAST_STEPS = 20
REPO_ROOT = Path(__file__).resolve().parents[2]
FULL_STEPS = 200
REUSE_EPISODES = 100
REUSE_EPISODE_STEPS = 3
N_PROCESSES = 3
N_SEEDS = 10


def _update(h: hashlib._Hash, value) -> None:
    """Feed a step's value (dict, tuple, array, number, bool, None) into the hash, keys sorted."""
    if isinstance(value, dict):
        for key in sorted(value):
            h.update(key.encode())
            _update(h, value[key])
    elif value is None:  # a missing depth in info
        h.update(b"None")
    elif isinstance(value, (tuple, list)):
        h.update(b"(%d" % len(value))
        for v in value:
            _update(h, v)
    else:
        arr = np.asarray(value)
        if arr.dtype == object:
            for v in arr.reshape(-1):
                _update(h, v)
        else:
            h.update(arr.dtype.str.encode() + str(arr.shape).encode() + arr.tobytes())


def single_digest(seed: int, steps: int, render: bool = False, env: TradeFollowEnv | None = None,
                  **kwargs) -> str:
    """SHA-256 over a reset and `steps` steps flown by the scripted follower: observations, rewards, flags,
    infos (and rendered frames)."""
    own = env is None
    env = env or TradeFollowEnv(render_mode="rgb_array" if render else None, **kwargs)
    h = hashlib.sha256()
    try:
        policy = ScriptedFollower()
        obs, info = env.reset(seed=seed)
        _update(h, (obs, info))
        for k in range(steps):
            action, _ = policy.predict(obs, episode_start=np.array([k == 0]))
            out = env.step(action)
            _update(h, out)
            if render:
                _update(h, env.render())
            obs = out[0]
            if out[2] or out[3]:
                break
    finally:
        if own:
            env.close()
    return h.hexdigest()


def vector_digest(kind: str, steps: int, n_envs: int = 2, **kwargs) -> str:
    """SHA-256 of a vector env's reset(seed=0) and `steps` batched steps of the scripted follower."""
    make = functools.partial(gym.make, ENV_ID, **kwargs)
    envs = SyncVectorEnv([make] * n_envs) if kind == "sync" else AsyncVectorEnv([make] * n_envs, context=kind)
    h = hashlib.sha256()
    try:
        policy = ScriptedFollower()
        obs, info = envs.reset(seed=0)
        _update(h, (obs, info))
        starts = np.ones(n_envs, bool)
        for _ in range(steps):
            actions, _ = policy.predict(obs, episode_start=starts)
            obs, reward, terminated, truncated, info = envs.step(actions)
            _update(h, (obs, reward, terminated, truncated, info))
            starts = terminated | truncated
    finally:
        envs.close()
    return h.hexdigest()


def _digest_in_subprocess(seed: int, steps: int, kwargs: dict) -> str:
    code = ("from tests.trade_gym.test_determinism import single_digest; "
            f"print(single_digest({seed}, {steps}, **{kwargs!r}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


# ------------------------------------------------------------------------------------------- fast
def test_two_trade_envs_same_seed_identical_bytes_with_frames_20_steps():
    runs = [single_digest(0, FAST_STEPS, render=True, **TRADE, **FAST) for _ in range(2)]
    assert runs[0] == runs[1]


def test_digest_sees_a_one_step_difference():
    assert single_digest(0, 5, **ORACLE, **FAST) != single_digest(0, 6, **ORACLE, **FAST)


def test_seeds_0_to_9_give_10_distinct_initial_observations_oracle():
    env = TradeFollowEnv(**ORACLE, **FAST)
    try:
        firsts = {b"".join(v.tobytes() for _, v in sorted(env.reset(seed=s)[0].items())) for s in range(N_SEEDS)}
    finally:
        env.close()
    assert len(firsts) == N_SEEDS


def test_subprocess_digest_equals_in_process_digest_oracle():
    kwargs = {**ORACLE, **FAST}
    assert _digest_in_subprocess(4, FAST_STEPS, kwargs) == single_digest(4, FAST_STEPS, **kwargs)


def test_async_fork_vector_env_digest_equals_sync_oracle():
    assert vector_digest("fork", FAST_STEPS, **ORACLE, **FAST) == vector_digest("sync", FAST_STEPS, **ORACLE, **FAST)


# ------------------------------------------------------------------------------------------- slow
@pytest.mark.slow
def test_two_trade_envs_same_seed_identical_bytes_with_frames_200_steps():
    assert single_digest(0, FULL_STEPS, render=True, **TRADE) == single_digest(0, FULL_STEPS, render=True, **TRADE)


@pytest.mark.slow
def test_trade_env_after_100_episodes_of_reuse_matches_a_fresh_env():
    env = TradeFollowEnv(render_mode="rgb_array", **TRADE)
    try:
        for episode in range(REUSE_EPISODES):
            single_digest(100 + episode, REUSE_EPISODE_STEPS, env=env)
        reused = single_digest(0, FULL_STEPS, render=True, env=env)
    finally:
        env.close()
    assert reused == single_digest(0, FULL_STEPS, render=True, **TRADE)


@pytest.mark.slow
def test_trade_digest_of_200_steps_is_the_same_in_3_processes():
    digests = {_digest_in_subprocess(0, FULL_STEPS, TRADE) for _ in range(N_PROCESSES)}
    assert digests == {single_digest(0, FULL_STEPS, **TRADE)}


@pytest.mark.slow
def test_trade_vector_env_digest_async_fork_and_spawn_equal_sync_200_steps():
    sync = vector_digest("sync", FULL_STEPS, **TRADE)
    assert vector_digest("fork", FULL_STEPS, **TRADE) == sync
    assert vector_digest("spawn", FULL_STEPS, **TRADE) == sync


@pytest.mark.slow
def test_seeds_0_to_9_give_10_distinct_initial_observations_trade():
    env = TradeFollowEnv(**TRADE)
    try:
        firsts = {b"".join(v.tobytes() for _, v in sorted(env.reset(seed=s)[0].items())) for s in range(N_SEEDS)}
    finally:
        env.close()
    assert len(firsts) == N_SEEDS


def test_reset_observation_carries_the_hover_imu_reading_seeded():
    """The IMU ran before the episode: the first observation holds gravity on body z plus seeded noise."""
    env = TradeFollowEnv(**ORACLE, **FAST)
    try:
        first = env.reset(seed=3)[0]["imu"]
        again = env.reset(seed=3)[0]["imu"]
        other = env.reset(seed=4)[0]["imu"]
    finally:
        env.close()
    accel, gyro = first[:3], first[3:]
    assert abs(accel[2] - 9.81) < 0.2 and np.all(np.abs(accel[:2]) < 0.2)
    assert np.all(np.abs(gyro) < 0.02)
    assert np.array_equal(first, again) and not np.array_equal(first, other)
