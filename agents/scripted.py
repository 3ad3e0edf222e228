"""The paper's scripted follower: hold height and yaw, move horizontally to keep the target centred.

It sees only the observation: the filtered target position and velocity relative to the
drone (heading frame). The height held is the height above the target at episode start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from trade.validation import require
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_ACTION_SCALE
from trade_gym.config import CAMERA_PITCH_RANGE_DEG, EnvConfig



@dataclass(frozen=True)
class ScriptedFollowerConfig:
    """Gains [1/s], feed-forward fraction, camera pitch [deg] and the env's action scale."""

    position_gain_per_s: float = 0.8
    image_gain_mps: float = 6.0  # before a 3D estimate exists: speed per half-image offset of the box
    height_gain_per_s: float = 0.6
    velocity_feedforward: float = 1.0
    camera_pitch_deg: float = EnvConfig.camera_pitch_deg  # must match the env's
    # the env's action scale (`env.action_scale`) [m/s per unit action]
    max_speed_horizontal_mps: float = DEFAULT_ACTION_SCALE.horizontal_mps
    max_speed_vertical_mps: float = DEFAULT_ACTION_SCALE.vertical_mps

    def __post_init__(self) -> None:
        for name in ("position_gain_per_s", "height_gain_per_s", "image_gain_mps", "max_speed_horizontal_mps",
                     "max_speed_vertical_mps"):
            value = getattr(self, name)
            require(np.isfinite(value) and value > 0, f"ScriptedFollowerConfig.{name}", value, "> 0")
        low, high = CAMERA_PITCH_RANGE_DEG
        require(low <= self.camera_pitch_deg <= high, "ScriptedFollowerConfig.camera_pitch_deg", self.camera_pitch_deg,
                f"in [{low}, {high}] (the env's range)")


class ScriptedFollower:
    """`predict(obs) -> (action, state)`; works on one observation or a batch (leading axis)."""

    def __init__(self, config: ScriptedFollowerConfig | None = None) -> None:
        self.config = config or ScriptedFollowerConfig()
        self._hold_height_m: np.ndarray | None = None

    def reset(self) -> None:
        self._hold_height_m = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        rel = np.asarray(observation["target_pos_rel_m"], dtype=np.float64)
        batched = rel.ndim == 2
        rel = rel.reshape(-1, 3)
        vel = np.asarray(observation["target_vel_mps"], dtype=np.float64).reshape(-1, 3)
        bbox = np.asarray(observation["bbox_norm"], dtype=np.float64).reshape(-1, 4)
        valid_ever = np.any(rel != 0.0, axis=1)
        height = -rel[:, 2]  # drone height above the target [m]
        n = len(rel)
        if self._hold_height_m is None or len(self._hold_height_m) != n:
            self._hold_height_m = np.full(n, np.nan)
        if episode_start is not None:
            starts = np.asarray(episode_start, bool).reshape(-1)
            self._hold_height_m = np.where(starts, np.nan, self._hold_height_m)
        # The first valid estimate of an episode fixes the height to hold.
        unset = np.isnan(self._hold_height_m) & valid_ever
        self._hold_height_m = np.where(unset, height, self._hold_height_m)
        action = np.stack([
            self._act(rel[i], vel[i], self._hold_height_m[i]) if valid_ever[i] else self._servo_image(bbox[i])
            for i in range(len(rel))
        ]).astype(np.float32)
        return (action if batched else action[0]), state

    def _servo_image(self, bbox_norm: np.ndarray) -> np.ndarray:
        """No 3D estimate yet (e.g. before the ROI depths converge): centre the box in the image.
        Image right is the drone's right, image up its forward direction; this motion also gives
        the feature triangulation its baseline."""
        cfg = self.config
        if not np.any(bbox_norm):
            return np.zeros(ACTION_DIM)
        offset = 2.0 * (bbox_norm[:2] - 0.5)  # (right, down) in half-image units
        v_forward, v_left = -cfg.image_gain_mps * offset[1], -cfg.image_gain_mps * offset[0]
        return np.array([
            np.clip(v_forward / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            np.clip(v_left / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            0.0,
            0.0,
        ])

    def _act(self, rel: np.ndarray, vel: np.ndarray, hold_height_m: float) -> np.ndarray:
        cfg = self.config
        if not np.isfinite(hold_height_m):
            return np.zeros(ACTION_DIM)
        # Desired horizontal offset: the target sits on the optical axis at the held height.
        ahead_m = hold_height_m / np.tan(np.radians(cfg.camera_pitch_deg))
        error_xy = rel[:2] - np.array([ahead_m, 0.0])
        v_xy = cfg.velocity_feedforward * vel[:2] + cfg.position_gain_per_s * error_xy
        v_z = cfg.height_gain_per_s * (hold_height_m - (-rel[2]))
        return np.array([
            np.clip(v_xy[0] / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            np.clip(v_xy[1] / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            np.clip(v_z / cfg.max_speed_vertical_mps, ACTION_LOW, ACTION_HIGH),
            0.0,
        ])
