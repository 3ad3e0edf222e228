"""The followers trade-bench can fly, by name: scripted, learned (when shipped), and hover and
random as floors. Each run gets a fresh policy; the random one is seeded from the run's seed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trade_gym.agents import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_ACTION_SCALE, ActionScale
from trade_gym.policy import Policy

POLICY_NAMES = ("scripted", "learned", "hover", "random")
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


def make_policy(name: str, seed: int, camera_pitch_deg: float,
                action_scale: ActionScale = DEFAULT_ACTION_SCALE) -> Policy:
    """A fresh policy for one run; `camera_pitch_deg` and `action_scale` must be the env's."""
    if name == "scripted":
        return ScriptedFollower(ScriptedFollowerConfig(camera_pitch_deg=camera_pitch_deg,
                                                       max_speed_horizontal_mps=action_scale.horizontal_mps,
                                                       max_speed_vertical_mps=action_scale.vertical_mps))
    if name == "hover":
        return HoverPolicy()
    if name == "random":
        return RandomPolicy(np.random.default_rng((seed, RANDOM_POLICY_STREAM)))
    if name == "learned":
        from trade_gym.agents.learned import LearnedFollower

        return LearnedFollower()
    raise ValueError(f"policy must be one of {POLICY_NAMES}, got {name!r}")
