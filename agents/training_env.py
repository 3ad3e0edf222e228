"""The training env of learned followers: TradeFollow-v0 (its own reward) with the scene, the world seed and the
scenario (target motion, decoy tier, appearance) drawn per episode (`EpisodeDraws`, a wrapper of any TradeFollow-v0,
as rl-zoo3's `env_wrapper` composes it), the 3-D action that holds the yaw rate at zero, and the residual action
(`ResidualAction`: the policy's action added to the scripted follower's).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding

from trade.validation import require
from trade_gym.action import action_space
from trade_gym.agents.residual import POLICY_AXES, Residual
from trade_gym.agents.scripted import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.bench.splits import TRAINING
from trade_gym.config import SCENE_NAMES
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.appearance import APPEARANCE_MODES
from trade_gym.sim.scenes import DECOY_TIERS
from trade_gym.sim.target_motion import TARGET_MOTIONS

# forward, left, up: the env's action without its last component, the yaw rate, held at 0 (rotating the image hurts
# the tracker)
TRAIN_ACTION_DIM = len(POLICY_AXES)


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


def draw_episode(rng: np.random.Generator, scenes: tuple[str, ...],
                 scenarios: ScenarioDraws) -> tuple[int, dict[str, str]]:
    """One training episode: (world seed from the training split, reset options with the scene and the scenario)."""
    scene = scenes[int(rng.integers(len(scenes)))]
    world_seed = int(rng.integers(TRAINING.first, TRAINING.last + 1))  # training worlds only
    return world_seed, {"scene": scene} | scenarios.draw(rng)


class EpisodeDraws(gym.Wrapper):
    """A TradeFollow env reset per episode on a drawn scene, training-split world seed and scenario
    (`draw_episode`): `reset(seed=world_seed, options={"scene": ..., <scenario>})`, the caller's options on top.

    The draws come from a generator of the wrapper's own, which `reset(seed=s)` reseeds (as SB3 seeds each worker's
    first reset). It wraps the env `gym.make("TradeFollow-v0", ...)` made, whatever wraps that (rl-zoo3's Monitor):
    its kwargs are `TrainConfig`'s fields of the same names (lists welcome, as YAML gives them)."""

    def __init__(self, env: gym.Env, scenes: Sequence[str] = SCENE_NAMES,
                 target_motions: Sequence[str] = ScenarioDraws.target_motions,
                 decoy_tiers: Sequence[str] = ScenarioDraws.decoy_tiers,
                 appearances: Sequence[str] = ScenarioDraws.appearances) -> None:
        super().__init__(env)
        self.scenes = _checked_scenes(scenes)
        self.scenarios = ScenarioDraws(tuple(target_motions), tuple(decoy_tiers), tuple(appearances))
        self._draws: np.random.Generator | None = None
        self.scene = self.scenes[0]  # the current episode's

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None or self._draws is None:
            self._draws, _ = seeding.np_random(seed)  # as gym.Env.reset seeds its np_random
        world_seed, episode = draw_episode(self._draws, self.scenes, self.scenarios)
        episode |= options or {}
        self.scene = episode["scene"]
        obs, info = self.env.reset(seed=world_seed, options=episode)
        return obs, {**info, "scene": self.scene, "world_seed": world_seed}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["scene"] = self.scene  # for the learning curve's per-scene rows
        return obs, reward, terminated, truncated, info


def _checked_scenes(scenes: Sequence[str]) -> tuple[str, ...]:
    require(bool(scenes) and all(s in SCENE_NAMES for s in scenes), "scenes", scenes,
            f"a non-empty subset of {SCENE_NAMES}")
    return tuple(scenes)


class SceneRandomizedEnv(EpisodeDraws):
    """TradeFollow-v0 built with `env_kwargs`, its scene, world seed (from the training split) and scenario
    (`ScenarioDraws`) drawn per episode (`EpisodeDraws`); the reward is the env's own.

    One env for every scene: each reset builds the episode's world, so the episodes are those of one env per scene."""

    def __init__(self, scenes: Sequence[str], scenarios: ScenarioDraws = ScenarioDraws(), **env_kwargs: Any) -> None:
        scenes = _checked_scenes(scenes)
        super().__init__(TradeFollowEnv(scene=scenes[0], **env_kwargs), scenes, scenarios.target_motions,
                         scenarios.decoy_tiers, scenarios.appearances)


class ZeroYawAction(gym.ActionWrapper):
    """The policy sets (forward, left, up) in [-1, 1]; the env receives them with a zero yaw rate."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.action_space = action_space(TRAIN_ACTION_DIM)

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.append(np.asarray(action, np.float32), np.float32(0.0))


class ResidualAction(gym.Wrapper):
    """A TradeFollow env whose action is the residual: the env receives `Residual(scale, axes).combine(scripted,
    action)`, the scripted follower (with the env's camera and action scale) acting on the last observation,
    restarted with each episode, as `LearnedFollower` flies a residual policy (`trade_gym.agents.residual`)."""

    def __init__(self, env: gym.Env, scale: float, axes: Sequence[str] = POLICY_AXES) -> None:
        super().__init__(env)
        self.residual = Residual(scale, tuple(axes))
        unwrapped = env.unwrapped
        if not isinstance(unwrapped, TradeFollowEnv):
            raise TypeError(f"ResidualAction wraps a TradeFollow env, got {type(unwrapped).__name__}")
        self.base = ScriptedFollower(ScriptedFollowerConfig.of(unwrapped.config, unwrapped.action_scale))
        self._obs: dict[str, np.ndarray] | None = None
        self._start = True

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._obs, self._start = obs, True
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("step() called before reset()")
        base, _ = self.base.predict(self._obs, episode_start=np.array([self._start]))
        self._start = False
        obs, reward, terminated, truncated, info = self.env.step(self.residual.combine(base, action))
        self._obs = obs
        return obs, reward, terminated, truncated, info
