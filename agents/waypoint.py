"""The paper's real-flight follower: waypoints that keep altitude and yaw and centre the target, for action_mode="waypoint".

TRADE's Voxl 2 flight sent PX4 waypoints from the Kalman filter's 3D location of the target: the drone's altitude and
yaw, plus a horizontal offset that keeps the object centred in the camera's view. It sees only the observation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from trade.camera_pitch import NADIR_PITCH_DEG
from trade.validation import is_finite_number, is_positive_number, require
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_WAYPOINT_SCALE
from trade_gym.agents.image_servo import MIN_RAY_DESCENT
from trade_gym.agents.scripted import target_inputs
from trade_gym.config import CAMERA_FOV_RANGE_DEG, CAMERA_PITCH_RANGE_DEG, CAMERA_RATE_HZ, EnvConfig
from trade_gym.sim.quadrotor import QuadrotorConfig

WAYPOINT_MODE = "waypoint"  # the env's action_mode this follower flies


@dataclass(frozen=True)
class WaypointFollowerConfig:
    """Camera pitch [deg], the target's lead time [s], the box servo's offset [m] and the env's waypoint scale [m].

    `lead_time_s`: the waypoint is the filter's location of the target predicted this far ahead (p + v t, both from
    the observation). The position controller flies k_p times the offset, so a waypoint on the target's current
    location trails a target driving at v by v / k_p (6 m at the desert's 3 m/s); predicting 1 / k_p ahead cancels
    that lag. 0 sends the current filtered location, as the paper states it.
    `image_offset_m`: before the first 3D estimate, the waypoint per half-image offset of the box centre (image up is
    forward, image right is right): 12 m flies the box towards the centre at up to 6 m/s at the default gain, as the
    scripted follower's image servo does, and gives TRADE's triangulation its baseline. 20 m gave TRADE its first fix
    sooner (desert frame 44 instead of 71) but lost the DCF baseline's target (tracked fraction on development worlds
    0-1, mountain and city, 128 px, 300 frames: 0.12, 0.15, 0.01, 0.00 against 1.00, 0.69, 0.39, 0.08 at 12 m).
    That is the downward camera's servo. A pitched camera's image is not linear in ground distance: at 45 deg a target
    twice the standoff away sits a quarter of a half-image above the centre, where the linear servo asked for 3 m and
    the drone fell behind a 3 m/s target (real-flight-tuning, desert 10212: 16 -> 30 m in 6 s). There the box's ray
    is followed to flat ground from the servo height image_offset_m / tan(fov / 2), the height at which that ground
    point mapping equals the linear servo for a downward camera (`_servo_image`).
    `handover_s`: from a track's first 3D estimate the offset blends linearly from the image servo's to the 3D one
    over this time (with a box to servo on; without one the 3D offset alone). The two differ at the hand-over: the
    filter's first velocities are unconverged (desert 10216 by day: 13.7 m/s for a 3 m/s target two updates after
    the first fix), and a step to the led waypoint saturated it, the drone pitched into it and the camera swung the
    target out of the tracker's window; a step to the unled one braked a drone the servo had flying forward (10217).
    2 s is 1 / k_p, the position loop's time constant (`lead_time_s`'s); 0 switches at once.
    `frame_dt_s`: the env's frame period [s], the time between two `predict` calls of one episode.
    """

    camera_pitch_deg: float = EnvConfig.camera_pitch_deg  # must match the env's
    camera_fov_deg: float = EnvConfig.camera_fov_deg  # must match the env's
    lead_time_s: float = 1.0 / QuadrotorConfig.position_gain_horizontal_per_s
    image_offset_m: float = 12.0
    # the env's waypoint scale (`env.waypoint_scale`) [m per unit action]
    max_offset_horizontal_m: float = DEFAULT_WAYPOINT_SCALE.max_offset_horizontal_m
    handover_s: float = 1.0 / QuadrotorConfig.position_gain_horizontal_per_s
    frame_dt_s: float = 1.0 / CAMERA_RATE_HZ

    def __post_init__(self) -> None:
        c = "WaypointFollowerConfig"
        for name in ("image_offset_m", "max_offset_horizontal_m", "frame_dt_s"):
            require(is_positive_number(getattr(self, name)), f"{c}.{name}", getattr(self, name), "a finite number > 0")
        for name in ("lead_time_s", "handover_s"):
            require(is_finite_number(getattr(self, name)) and getattr(self, name) >= 0.0, f"{c}.{name}",
                    getattr(self, name), "a finite number >= 0 [s]")
        low, high = CAMERA_FOV_RANGE_DEG
        require(is_finite_number(self.camera_fov_deg) and low <= self.camera_fov_deg <= high,
                f"{c}.camera_fov_deg", self.camera_fov_deg, f"in [{low}, {high}] (the env's range)")
        low, high = CAMERA_PITCH_RANGE_DEG
        require(is_finite_number(self.camera_pitch_deg) and low <= self.camera_pitch_deg <= high,
                f"{c}.camera_pitch_deg", self.camera_pitch_deg, f"in [{low}, {high}] (the env's range)")

    @classmethod
    def of(cls, config: EnvConfig) -> WaypointFollowerConfig:
        """The follower's settings for an env built with `config`: its camera pitch and field of view, waypoint scale
        and position gain. ValueError unless the env flies waypoints (`action_mode="waypoint"`)."""
        if config.action_mode != WAYPOINT_MODE:
            raise ValueError(f"WaypointFollower sends position setpoints and needs an env with "
                             f"action_mode={WAYPOINT_MODE!r}, got action_mode={config.action_mode!r}")
        time_constant_s = 1.0 / config.quadrotor.position_gain_horizontal_per_s
        return cls(camera_pitch_deg=config.camera_pitch_deg, camera_fov_deg=config.camera_fov_deg,
                   lead_time_s=time_constant_s, max_offset_horizontal_m=config.waypoint_scale.max_offset_horizontal_m,
                   handover_s=time_constant_s, frame_dt_s=config.frame_dt_s)


class WaypointFollower:
    """`predict(obs) -> (action, state)` for `gym.make("TradeFollow-v0", action_mode="waypoint")`; one observation or
    a batch (leading axis). The action is (forward, left, 0, 0) over the waypoint scale: the altitude and the yaw stay
    where they are, the horizontal offset puts the drone where the camera's optical axis meets the target.

    With a 3D estimate (`target_pos_rel_m` not zero) the offset is rel + lead_time v - (h / tan(pitch), 0), h = -rel_z
    the height above the target. Before one, it servos the box towards the image centre (`image_offset_m`); with no
    box either, it holds position (a zero action). From the servo to the 3D offset it hands over in `handover_s`,
    per env of a batch: `episode_start` True (and every env on the first call, after `reset()` or when the batch size
    changes) starts an episode without a 3D estimate. On a velocity-mode env these actions would be read as
    velocities: build it with `WaypointFollower.for_env(env)`, which refuses one.
    """

    def __init__(self, config: WaypointFollowerConfig | None = None) -> None:
        self.config = config or WaypointFollowerConfig()
        self._weight_3d: np.ndarray | None = None  # (N,) per env the 3D offset's weight in [0, 1] (`handover_s`)

    @classmethod
    def for_env(cls, env: gym.Env) -> WaypointFollower:
        """A follower set up for `env` (a TradeFollow-v0, wrapped or not); ValueError unless it flies waypoints."""
        config = getattr(env.unwrapped, "config", None)
        if not isinstance(config, EnvConfig):
            raise ValueError(f"WaypointFollower.for_env needs a TradeFollow-v0 env, got {env!r}")
        return cls(WaypointFollowerConfig.of(config))

    def reset(self) -> None:
        """Forget the hand-overs: the next call starts new episodes."""
        self._weight_3d = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        rel, vel, bbox, batched = target_inputs(observation)
        weights = self._handover_weights(np.any(rel != 0.0, axis=1), episode_start)
        offsets = np.stack([self._offset(r, v, b, w) for r, v, b, w in zip(rel, vel, bbox, weights)])
        action = np.zeros((len(rel), ACTION_DIM), np.float32)  # up and yaw stay 0: keep altitude and yaw
        action[:, :2] = self._scaled(offsets)
        return (action if batched else action[0]), state

    def _handover_weights(self, known: np.ndarray, episode_start: np.ndarray | None) -> np.ndarray:
        """(N,) the 3D offset's weight this frame per env: 0 without a 3D estimate, else one frame of `handover_s`
        more than on the last frame, at most 1 (1 at once for `handover_s` 0)."""
        weights = self._weight_3d
        if weights is None or len(weights) != len(known):
            weights = np.zeros(len(known))
        elif episode_start is not None:
            weights = np.where(np.asarray(episode_start, dtype=bool).reshape(-1), 0.0, weights)
        cfg = self.config
        step = 1.0 if cfg.handover_s == 0.0 else cfg.frame_dt_s / cfg.handover_s
        self._weight_3d = np.where(known, np.minimum(weights + step, 1.0), 0.0)
        return self._weight_3d

    def _offset(self, rel: np.ndarray, vel: np.ndarray, bbox_norm: np.ndarray, weight_3d: float) -> np.ndarray:
        """(forward, left) [m]: the 3D offset with `weight_3d`, the box servo's with the rest (the 3D one alone
        without a box; the servo's alone without a 3D estimate)."""
        if weight_3d == 0.0:
            return self._servo_image(bbox_norm)
        centred = self._centre_on_target(rel, vel)
        if weight_3d == 1.0 or not np.any(bbox_norm):
            return centred
        return weight_3d * centred + (1.0 - weight_3d) * self._servo_image(bbox_norm)

    def _centre_on_target(self, rel: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """(forward, left) [m]: to where the optical axis meets the target predicted `lead_time_s` ahead."""
        cfg = self.config
        height_m = max(-rel[2], 0.0)
        ahead_m = height_m / math.tan(math.radians(cfg.camera_pitch_deg))
        return rel[:2] + cfg.lead_time_s * vel[:2] - np.array([ahead_m, 0.0])

    def _servo_image(self, bbox_norm: np.ndarray) -> np.ndarray:
        """(forward, left) [m] towards the box centre (none without a box: hold position). A downward camera: the
        offset is `image_offset_m` per half-image. A pitched one (pitch p): the box centre's ray (X, Y) = (right,
        down) tan(fov / 2) in the camera, in the level heading frame (c - s Y, -X, -(c Y + s)) with (c, s) = (cos p,
        sin p), meets flat ground h = image_offset_m / tan(fov / 2) below at h (c - s Y, -X) / (c Y + s); the offset
        is that point less the optical axis's, (h c / s, 0). At p = 90 deg this is the downward camera's offset; a ray
        at or above the horizon asks for the farthest offset forward the action allows (`_scaled` clips it)."""
        if not np.any(bbox_norm):
            return np.zeros(2)
        cfg = self.config
        right, down = 2.0 * (bbox_norm[:2] - 0.5)  # half-image units
        if cfg.camera_pitch_deg >= NADIR_PITCH_DEG:
            return -cfg.image_offset_m * np.array([down, right])
        slope = math.tan(math.radians(cfg.camera_fov_deg) / 2.0)
        x, y, height_m = right * slope, down * slope, cfg.image_offset_m / slope
        pitch = math.radians(cfg.camera_pitch_deg)
        c, s = math.cos(pitch), math.sin(pitch)
        descent = max(c * y + s, MIN_RAY_DESCENT)
        return height_m * np.array([(c - s * y) / descent - c / s, -x / descent])

    def _scaled(self, offsets: np.ndarray) -> np.ndarray:
        """(N, 2) offsets [m] as actions: over the waypoint scale, the horizontal norm clipped to 1 (direction kept)."""
        unit = offsets / self.config.max_offset_horizontal_m
        norm = np.linalg.norm(unit, axis=1, keepdims=True)
        unit = unit / np.maximum(norm, ACTION_HIGH)
        return np.clip(unit, ACTION_LOW, ACTION_HIGH)
