"""The paper's scripted follower: hold height and yaw, move horizontally to keep the target centred.

It sees only the observation: the filtered target position and velocity relative to the
drone (heading frame). The height held is the height above the target at episode start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from trade.validation import require
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_ACTION_SCALE
from trade_gym.config import CAMERA_PITCH_RANGE_DEG, CAMERA_RATE_HZ, EnvConfig



@dataclass(frozen=True)
class ScriptedFollowerConfig:
    """Gains [1/s], feed-forward fraction, camera pitch [deg] and the env's action scale."""

    position_gain_per_s: float = 0.8
    # Before a 3D estimate exists the follower servos the box to the image centre (`_servo_image`): a PI law,
    # speed = -(image_gain_mps e + image_integral_gain_mps_per_s integral(e dt)), e the box centre's offset in
    # half-image units, whose setpoint changes by at most image_max_accel_mps2 per second. Set on training worlds
    # 10200-10204 (breadth-tuning): a proportional law at 6 m/s lagged a starting stop-and-go or evasive target out of
    # the following band before the first 3D fix; at 18 m/s without the limit its sudden tilts lost the DCF
    # baseline's target (benchmarks/results/breadth_tuning_image_gain.json); the integral removes the lag at a
    # constant target speed, so the proportional gain and the acceleration stay low enough for the DCF.
    image_gain_mps: float = 10.0
    image_integral_gain_mps_per_s: float = 4.0
    image_max_accel_mps2: float = 4.0
    height_gain_per_s: float = 0.6
    velocity_feedforward: float = 1.0
    camera_pitch_deg: float = EnvConfig.camera_pitch_deg  # must match the env's
    # the env's action scale (`env.action_scale`) [m/s per unit action]
    max_speed_horizontal_mps: float = DEFAULT_ACTION_SCALE.horizontal_mps
    max_speed_vertical_mps: float = DEFAULT_ACTION_SCALE.vertical_mps

    def __post_init__(self) -> None:
        for name in ("position_gain_per_s", "height_gain_per_s", "image_gain_mps", "max_speed_horizontal_mps",
                     "max_speed_vertical_mps", "image_max_accel_mps2"):
            value = getattr(self, name)
            require(value == math.inf and name == "image_max_accel_mps2" or np.isfinite(value) and value > 0,
                    f"ScriptedFollowerConfig.{name}", value, "> 0")
        require(np.isfinite(self.image_integral_gain_mps_per_s) and self.image_integral_gain_mps_per_s >= 0,
                "ScriptedFollowerConfig.image_integral_gain_mps_per_s", self.image_integral_gain_mps_per_s, ">= 0")
        low, high = CAMERA_PITCH_RANGE_DEG
        require(low <= self.camera_pitch_deg <= high, "ScriptedFollowerConfig.camera_pitch_deg", self.camera_pitch_deg,
                f"in [{low}, {high}] (the env's range)")


def target_inputs(observation: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The observation's target entries a scripted follower reads, as float64 batches: (N, 3) relative position
    [m], (N, 3) velocity [m/s], (N, 4) normalised box, and whether the observation was a batch."""
    rel = np.asarray(observation["target_pos_rel_m"], dtype=np.float64)
    batched = rel.ndim == 2
    vel = np.asarray(observation["target_vel_mps"], dtype=np.float64).reshape(-1, 3)
    bbox = np.asarray(observation["bbox_norm"], dtype=np.float64).reshape(-1, 4)
    return rel.reshape(-1, 3), vel, bbox, batched


class ScriptedFollower:
    """`predict(obs) -> (action, state)`; works on one observation or a batch (leading axis)."""

    def __init__(self, config: ScriptedFollowerConfig | None = None) -> None:
        self.config = config or ScriptedFollowerConfig()
        self._hold_height_m: np.ndarray | None = None
        self._servo_state: np.ndarray | None = None  # (n, 4): the image servo's integral (2) and last setpoint (2)

    def reset(self) -> None:
        self._hold_height_m = None
        self._servo_state = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        rel, vel, bbox, batched = target_inputs(observation)
        valid_ever = np.any(rel != 0.0, axis=1)
        height = -rel[:, 2]  # drone height above the target [m]
        n = len(rel)
        if self._hold_height_m is None or self._servo_state is None or len(self._hold_height_m) != n:
            self._hold_height_m = np.full(n, np.nan)
            self._servo_state = np.zeros((n, 4))
        if episode_start is not None:
            starts = np.asarray(episode_start, bool).reshape(-1)
            self._hold_height_m = np.where(starts, np.nan, self._hold_height_m)
            self._servo_state[starts] = 0.0
        # The first valid estimate of an episode fixes the height to hold.
        unset = np.isnan(self._hold_height_m) & valid_ever
        self._hold_height_m = np.where(unset, height, self._hold_height_m)
        action = np.stack([
            self._act(rel[i], vel[i], self._hold_height_m[i]) if valid_ever[i]
            else self._servo_image(bbox[i], self._servo_state[i])
            for i in range(len(rel))
        ]).astype(np.float32)
        return (action if batched else action[0]), state

    def _servo_image(self, bbox_norm: np.ndarray, state: np.ndarray) -> np.ndarray:
        """No 3D estimate yet (e.g. before the ROI depths converge): centre the box in the image with the PI law of
        `ScriptedFollowerConfig`; `state` (the integral and last setpoint [m/s], forward and left) is updated in
        place. Image right is the drone's right, image up its forward direction; this motion also gives the feature
        triangulation its baseline. Without a box the setpoint decays towards hover at the acceleration limit."""
        cfg = self.config
        dt = 1.0 / CAMERA_RATE_HZ
        integral, last = state[:2], state[2:]
        if np.any(bbox_norm):
            offset = 2.0 * (bbox_norm[:2] - 0.5)  # (right, down) in half-image units
            error = -np.array([offset[1], offset[0]])  # (forward, left) towards the box
            integral += cfg.image_integral_gain_mps_per_s * error * dt
            np.clip(integral, -cfg.max_speed_horizontal_mps, cfg.max_speed_horizontal_mps, out=integral)  # anti-windup
            wanted = cfg.image_gain_mps * error + integral
        else:
            wanted = np.zeros(2)
        step = wanted - last
        max_step = cfg.image_max_accel_mps2 * dt
        norm = float(np.linalg.norm(step))
        if norm > max_step:
            step *= max_step / norm
        last += step
        v_forward, v_left = last
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
