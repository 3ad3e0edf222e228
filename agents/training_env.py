"""The training env of learned followers: TradeFollow-v0 with the scene and world seed drawn per episode,
the training reward (see `agents.train.TrainConfig`) and the 3-D action that holds the yaw rate at zero.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from trade_gym.bench.splits import TRAINING
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.scenes import get_scene

MIN_START_HEIGHT_M = 1.0  # floor of the reset height used to normalise the height-hold term
TRAIN_ACTION_DIM = 3  # forward, left, up; the yaw rate is held at 0 (rotating the image hurts the tracker)


class SceneRandomizedEnv(gym.Env):
    """TradeFollow-v0 with the scene and the world seed (from the training split) drawn per episode from this
    env's generator.

    One inner env per scene (built on first use); `reset(seed=s)` reseeds the draws. Adds the
    training-only term `- distance_weight * horizontal distance / follow height` to the reward and, unless
    `keep_shape_terms`, replaces the env's centering and altitude terms by `- height_weight * |h - h0| / h0`
    (h: height above the target, h0: its value at reset); see `TrainConfig`. The added terms are in
    `info["reward_shaping_*"]`, so the `reward_*` terms still sum to the reward."""

    metadata = {"render_modes": []}

    def __init__(self, scenes: tuple[str, ...], distance_weight: float, height_weight: float = 0.0,
                 keep_shape_terms: bool = True, **env_kwargs: Any) -> None:
        self.scenes = tuple(scenes)
        self.distance_weight, self.height_weight = distance_weight, height_weight
        self.keep_shape_terms = keep_shape_terms
        self._start_height_m = 1.0
        self.env_kwargs = env_kwargs
        self._follow_height_m = {s: get_scene(s).follow_altitude_agl_m for s in self.scenes}
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
        self._start_height_m = max(_height_above_target(info), MIN_START_HEIGHT_M)
        return obs, {**info, "scene": self.scene, "world_seed": world_seed}

    def step(self, action):
        obs, reward, terminated, truncated, info = self._envs[self.scene].step(action)
        # r_train = r_env - w_d d_horizontal / h_follow (+ the replaced terms below)
        distance_over_height = info["horizontal_distance_m"] / self._follow_height_m[self.scene]
        info["reward_shaping_distance"] = -self.distance_weight * distance_over_height
        if self.keep_shape_terms:
            info["reward_shaping_replaced"] = 0.0
        else:
            # - r_centering - r_altitude - w_h min(|h - h0| / h0, 1)
            hold = min(abs(_height_above_target(info) - self._start_height_m) / self._start_height_m, 1.0)
            info["reward_shaping_replaced"] = (-info["reward_centering"] - info["reward_altitude"]
                                               - self.height_weight * hold)
        reward = reward + info["reward_shaping_distance"] + info["reward_shaping_replaced"]
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


def _height_above_target(info: dict) -> float:
    return float(info["drone_position_m"][2] - info["target_position_m"][2])


class ZeroYawAction(gym.ActionWrapper):
    """The policy sets (forward, left, up) in [-1, 1]; the env receives them with a zero yaw rate."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (TRAIN_ACTION_DIM,), np.float32)

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.append(np.asarray(action, np.float32), np.float32(0.0))
