"""Shared test check: Gymnasium's `check_env` with every warning raised as an error."""

from __future__ import annotations

import warnings

import gymnasium as gym
from gymnasium.utils.env_checker import check_env


def check_env_strict(env: gym.Env, **kwargs) -> None:
    """`check_env(env.unwrapped, **kwargs)` with warnings as errors (a warning is a failed check)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, **kwargs)
