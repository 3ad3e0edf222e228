"""The training env of learned followers: TradeFollow-v0 (its own reward) with the scene and world seed drawn
per episode, and the 3-D action that holds the yaw rate at zero.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from trade_gym.action import ACTION_NAMES, action_space
from trade_gym.bench.splits import TRAINING
from trade_gym.env import TradeFollowEnv

# forward, left, up: the env's action without its last component, the yaw rate, held at 0 (rotating the image hurts
# the tracker)
TRAIN_ACTION_DIM = ACTION_NAMES.index("yaw_rate")


class SceneRandomizedEnv(gym.Env):
    """TradeFollow-v0 with the scene and the world seed (from the training split) drawn per episode from this
    env's generator; the reward is the env's own.

    One inner env per scene (built on first use); `reset(seed=s)` reseeds the draws."""

    metadata = {"render_modes": []}

    def __init__(self, scenes: tuple[str, ...], **env_kwargs: Any) -> None:
        self.scenes = tuple(scenes)
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
        obs, info = self._env(self.scene).reset(seed=world_seed, options=options)
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
