"""The training env of learned followers: TradeFollow-v0 (its own reward) with the scene, the world seed and the
scenario (target motion, decoy tier, appearance) drawn per episode, and the 3-D action that holds the yaw rate at
zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from trade.validation import require
from trade_gym.action import ACTION_NAMES, action_space
from trade_gym.bench.splits import TRAINING
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.appearance import APPEARANCE_MODES
from trade_gym.sim.scenes import DECOY_TIERS
from trade_gym.sim.target_motion import TARGET_MOTIONS

# forward, left, up: the env's action without its last component, the yaw rate, held at 0 (rotating the image hurts
# the tracker)
TRAIN_ACTION_DIM = ACTION_NAMES.index("yaw_rate")


@dataclass(frozen=True)
class ScenarioDraws:
    """The scenario settings drawn uniformly per training episode (the env's reset options); a single choice is
    used without a draw."""

    target_motions: tuple[str, ...] = ("cruise",)
    decoy_tiers: tuple[str, ...] = ("ambiguous",)
    appearances: tuple[str, ...] = ("fixed",)

    def __post_init__(self) -> None:
        for name, allowed in (("target_motions", TARGET_MOTIONS), ("decoy_tiers", DECOY_TIERS),
                              ("appearances", APPEARANCE_MODES)):
            value = getattr(self, name)
            require(bool(value) and all(v in allowed for v in value), name, value, f"a non-empty subset of {allowed}")

    def draw(self, rng: np.random.Generator) -> dict[str, str]:
        """The reset options of one episode."""
        return {option: _pick(choices, rng) for option, choices in (
            ("target_motion", self.target_motions), ("decoys", self.decoy_tiers), ("appearance", self.appearances))}


def _pick(choices: tuple[str, ...], rng: np.random.Generator) -> str:
    return choices[0] if len(choices) == 1 else choices[int(rng.integers(len(choices)))]


class SceneRandomizedEnv(gym.Env):
    """TradeFollow-v0 with the scene, the world seed (from the training split) and the scenario (`ScenarioDraws`)
    drawn per episode from this env's generator; the reward is the env's own.

    One inner env per scene (built on first use); `reset(seed=s)` reseeds the draws."""

    metadata = {"render_modes": []}

    def __init__(self, scenes: tuple[str, ...], scenarios: ScenarioDraws = ScenarioDraws(), **env_kwargs: Any) -> None:
        self.scenes = tuple(scenes)
        self.scenarios = scenarios
        self.env_kwargs = env_kwargs
        self._envs: dict[str, TradeFollowEnv] = {}
        probe = self._env(self.scenes[0])
        self.observation_space, self.action_space = probe.observation_space, probe.action_space
        self.scene = self.scenes[0]

    def _env(self, scene: str) -> TradeFollowEnv:
        if scene not in self._envs:
            self._envs[scene] = TradeFollowEnv(scene=scene, **self.env_kwargs)
        return self._envs[scene]

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.scene = self.scenes[int(self.np_random.integers(len(self.scenes)))]
        world_seed = int(self.np_random.integers(TRAINING.first, TRAINING.last + 1))  # training worlds only
        episode = self.scenarios.draw(self.np_random) | (options or {})
        obs, info = self._env(self.scene).reset(seed=world_seed, options=episode)
        return obs, {**info, "scene": self.scene, "world_seed": world_seed}

    def step(self, action):
        obs, reward, terminated, truncated, info = self._envs[self.scene].step(action)
        info["scene"] = self.scene  # for the learning curve's per-scene rows
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


class ZeroYawAction(gym.ActionWrapper):
    """The policy sets (forward, left, up) in [-1, 1]; the env receives them with a zero yaw rate."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.action_space = action_space(TRAIN_ACTION_DIM)

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.append(np.asarray(action, np.float32), np.float32(0.0))
