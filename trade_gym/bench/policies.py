"""The followers trade-bench can fly, by name: scripted, learned (when shipped), waypoint (the paper's real-flight
follower, on position setpoints), and hover and random as floors. Each run gets a fresh policy; the random one is
seeded from the run's seed. A follower that needs an env setting gets it from `policy_env_kwargs`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trade_gym.agents import ScriptedFollower, ScriptedFollowerConfig, WaypointFollower, WaypointFollowerConfig
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_ACTION_SCALE, ActionScale
from trade_gym.config import EnvConfig
from trade_gym.policy import Policy

POLICY_NAMES = ("scripted", "learned", "waypoint", "hover", "random")
# The action mode each follower flies (its actions mean nothing in the other); hover and random fly either.
POLICY_ACTION_MODES = {"scripted": "velocity", "learned": "velocity", "waypoint": "waypoint"}
# The env seeds its generator with the run seed alone; the random policy draws from a separate
# stream, SeedSequence((seed, RANDOM_POLICY_STREAM)), so its actions do not replay the env's draws.
RANDOM_POLICY_STREAM = 1


class HoverPolicy:
    """Zero action: the drone holds its position while the target drives away."""

    def predict(self, observation: dict[str, np.ndarray], state: Any = None,
                episode_start: np.ndarray | None = None, deterministic: bool = True) -> tuple[np.ndarray, Any]:
        return np.zeros(ACTION_DIM, np.float32), state


class RandomPolicy:
    """Uniform actions in [-1, 1]^4 from its own generator (seeded by the run)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def predict(self, observation: dict[str, np.ndarray], state: Any = None,
                episode_start: np.ndarray | None = None, deterministic: bool = True) -> tuple[np.ndarray, Any]:
        return self.rng.uniform(ACTION_LOW, ACTION_HIGH, ACTION_DIM).astype(np.float32), state


def learned_unavailable_reason() -> str | None:
    """None when `trade_gym.agents.learned.LearnedFollower()` loads its default model, else why it does not."""
    try:
        from trade_gym.agents.learned import LearnedFollower
    except ImportError as exc:
        return f"trade_gym.agents.learned is not importable ({exc})"
    try:
        LearnedFollower()
    except Exception as exc:  # noqa: BLE001 - any loader failure means "not available here"
        return f"the learned follower's default model does not load ({type(exc).__name__}: {exc})"
    return None


def available_policies() -> tuple[str, ...]:
    """Policy names usable on this installation ("learned" only when its model loads)."""
    return tuple(n for n in POLICY_NAMES if n != "learned" or learned_unavailable_reason() is None)


def policy_env_kwargs(name: str) -> dict[str, Any]:
    """The env keyword arguments policy `name` needs beyond the defaults: action_mode="waypoint" for the waypoint
    follower (a run's spec adds them, `trade_gym.bench.suites.RunSpec.env_kwargs`); {} for the others."""
    mode = POLICY_ACTION_MODES.get(name, EnvConfig.action_mode)
    return {} if mode == EnvConfig.action_mode else {"action_mode": mode}


def make_policy(name: str, seed: int, camera_pitch_deg: float, action_scale: ActionScale = DEFAULT_ACTION_SCALE,
                env_config: EnvConfig | None = None) -> Policy:
    """A fresh policy for one run; `camera_pitch_deg` and `action_scale` must be the env's, and `env_config` its config
    (None: the defaults with that pitch and the policy's `policy_env_kwargs`). ValueError when the env's action mode
    is not the one the policy flies."""
    config = env_config or EnvConfig(camera_pitch_deg=camera_pitch_deg, **policy_env_kwargs(name))
    mode = POLICY_ACTION_MODES.get(name, config.action_mode)
    if config.action_mode != mode:
        raise ValueError(f"policy {name!r} flies action_mode={mode!r}, the env has action_mode={config.action_mode!r}")
    if name == "waypoint":
        return WaypointFollower(WaypointFollowerConfig.of(config))
    if name == "scripted":
        return ScriptedFollower(ScriptedFollowerConfig.of(config, action_scale))
    if name == "hover":
        return HoverPolicy()
    if name == "random":
        return RandomPolicy(np.random.default_rng((seed, RANDOM_POLICY_STREAM)))
    if name == "learned":
        from trade_gym.agents.learned import LearnedFollower

        return LearnedFollower(base_config=ScriptedFollowerConfig.of(config, action_scale))
    raise ValueError(f"policy must be one of {POLICY_NAMES}, got {name!r}")
