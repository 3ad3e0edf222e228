"""Run one episode of TradeFollow-v0 under a policy and collect its per-step info records."""

from __future__ import annotations

from typing import Any

import numpy as np

from trade_gym.policy import Policy
from trade_gym.env import TradeFollowEnv


def run_episode(policy: Policy, seed: int, max_steps: int | None = None, **env_kwargs: Any) -> list[dict]:
    """Fly `policy` for one episode (or `max_steps`) in a new env and return the info of every step."""
    env = TradeFollowEnv(**env_kwargs)
    try:
        return fly_episode(env, policy, seed, max_steps)
    finally:
        env.close()


def fly_episode(env: TradeFollowEnv, policy: Policy, seed: int, max_steps: int | None = None) -> list[dict]:
    """Reset `env` with `seed`, fly `policy` until the episode ends (or `max_steps`); the info of every step.
    The caller owns `env` (and may have instrumented it, e.g. wrapped its perception)."""
    infos: list[dict] = []
    obs, _ = env.reset(seed=seed)
    first = True
    while max_steps is None or len(infos) < max_steps:
        action, _ = policy.predict(obs, episode_start=np.array([first]))
        first = False
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if terminated or truncated:
            break
    return infos
