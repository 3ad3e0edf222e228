"""The one episode loop of TradeFollow-v0: fly a policy for an episode and collect its per-step infos.

The benchmark runner, its video, the benchmarks and the tests fly through `fly_episode`; what they add (record
frames, time, instrument) comes in as hooks on the reset and on every step, or as a wrapper around the env.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from trade_gym.env import TradeFollowEnv
from trade_gym.policy import Policy

# hook(env, observation, info) after the reset (the reset's info) or after a step; `env` is the env flown
FrameHook = Callable[[gym.Env, dict[str, np.ndarray], dict[str, Any]], None]


def run_episode(policy: Policy, seed: int, max_steps: int | None = None, **env_kwargs: Any) -> list[dict]:
    """Fly `policy` for one episode (or `max_steps`) in a new env and return the info of every step."""
    env = TradeFollowEnv(**env_kwargs)
    try:
        return fly_episode(env, policy, seed, max_steps)
    finally:
        env.close()


def fly_episode(env: gym.Env, policy: Policy, seed: int, max_steps: int | None = None, *,
                on_reset: FrameHook | None = None, on_step: FrameHook | None = None) -> list[dict]:
    """Reset `env` with `seed`, fly `policy` until the episode ends (or `max_steps` steps); the info of every step.

    `on_reset(env, obs, info)` runs after the reset, `on_step(env, obs, info)` after every step. The caller owns
    `env`, which may be wrapped (recording, faults, timing) or instrumented (e.g. its perception wrapped)."""
    infos: list[dict] = []
    obs, info = env.reset(seed=seed)
    if on_reset is not None:
        on_reset(env, obs, info)
    first = True
    while max_steps is None or len(infos) < max_steps:
        action, _ = policy.predict(obs, episode_start=np.array([first]))
        first = False
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if on_step is not None:
            on_step(env, obs, info)
        if terminated or truncated:
            break
    return infos
