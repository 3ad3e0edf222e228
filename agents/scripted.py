"""The paper's scripted follower: hold height and yaw, move horizontally to keep the target centred.

It sees only the observation: the filtered target position and velocity relative to the
drone (heading frame). The height held is the height above the target at the end of the hand-over from the image
servo (`ScriptedFollowerConfig.handover_s` after the episode's first 3D estimate; at that estimate when no servo ran).
While the track is not valid (`track_valid` 0: the estimate coasts on the trajectory model) the drone holds the height
it is at: a coasting estimate's vertical velocity is not measured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from trade.validation import is_finite_number, is_positive_number, require
from trade_gym.action import ACTION_DIM, ACTION_HIGH, ACTION_LOW, DEFAULT_ACTION_SCALE, ActionScale
from trade_gym.agents.image_servo import attitude_after, box_ground_offset
from trade_gym.config import CAMERA_FOV_RANGE_DEG, CAMERA_PITCH_RANGE_DEG, CAMERA_RATE_HZ, EnvConfig
from trade_gym.observation import IMU_GYRO_COLUMNS


@dataclass(frozen=True)
class ScriptedFollowerConfig:
    """Gains, feed-forward fraction, the hand-over time [s], the camera's pitch and field of view [deg] and the env's
    action scale; `ScriptedFollowerConfig.of(env_config, action_scale)` reads the env's."""

    position_gain_per_s: float = 0.8
    # Before a 3D estimate exists the follower servos the box to the image centre (`_servo_image`): a PI law,
    # speed = servo_gain_mps e + servo_integral_gain_mps_per_s integral(e dt), e the (forward, left) offset per metre
    # of height on level ground from the optical axis to the box centre's ray, the drone's tilt taken out
    # (`trade_gym.agents.image_servo`); its setpoint changes by at most servo_max_accel_mps2 per second (inf: the
    # drone's own acceleration limit alone). Set on training worlds 10200-10204 (breadth-tuning,
    # benchmarks/results/breadth_tuning_image_servo_tilt.json): 12.6 and 8.4 are 18 and 12 per half-image of the 110
    # deg camera (tan 55 deg = 1.43 units), which caught a stop-and-go target starting at twice the scene's speed
    # before it left the desert's band; without the limit the step from hover tilted the camera in one frame and the
    # DCF baseline lost its city target at once, at 12 m/s^2 it did not.
    servo_gain_mps: float = 12.6
    servo_integral_gain_mps_per_s: float = 8.4
    servo_max_accel_mps2: float = 12.0
    # From the first 3D estimate the 3D law's velocity feed-forward blends linearly from the servo's integral (its
    # estimate of the target's velocity) to the estimate's velocity over handover_s (0: at once): the trajectory
    # model's first velocity is zero, and with it the 3D law braked a drone the servo had flying after the target.
    # Through the hand-over the height to hold follows the estimate: a first estimate 4x too close (city training
    # world 10200, evasive, under a residual of this follower) had the drone descend from 34 m to 9 m above the
    # target and out of the following band.
    handover_s: float = 1.0
    height_gain_per_s: float = 0.6
    velocity_feedforward: float = 1.0
    camera_pitch_deg: float = EnvConfig.camera_pitch_deg  # must match the env's
    camera_fov_deg: float = EnvConfig.camera_fov_deg  # must match the env's
    # the env's action scale (`env.action_scale`) [m/s per unit action]
    max_speed_horizontal_mps: float = DEFAULT_ACTION_SCALE.horizontal_mps
    max_speed_vertical_mps: float = DEFAULT_ACTION_SCALE.vertical_mps

    def __post_init__(self) -> None:
        c = "ScriptedFollowerConfig"
        for name in ("position_gain_per_s", "height_gain_per_s", "servo_gain_mps", "max_speed_horizontal_mps",
                     "max_speed_vertical_mps"):
            require(is_positive_number(getattr(self, name)), f"{c}.{name}", getattr(self, name), "a finite number > 0")
        for name in ("servo_integral_gain_mps_per_s", "handover_s"):
            require(is_finite_number(getattr(self, name)) and getattr(self, name) >= 0.0, f"{c}.{name}",
                    getattr(self, name), "a finite number >= 0")
        require(self.servo_max_accel_mps2 == math.inf or is_positive_number(self.servo_max_accel_mps2),
                f"{c}.servo_max_accel_mps2", self.servo_max_accel_mps2, "> 0 (inf: no limit)")
        low, high = CAMERA_PITCH_RANGE_DEG
        require(low <= self.camera_pitch_deg <= high, f"{c}.camera_pitch_deg", self.camera_pitch_deg,
                f"in [{low}, {high}] (the env's range)")
        low, high = CAMERA_FOV_RANGE_DEG
        require(is_finite_number(self.camera_fov_deg) and low <= self.camera_fov_deg <= high, f"{c}.camera_fov_deg",
                self.camera_fov_deg, f"in [{low}, {high}] (the env's range)")

    @classmethod
    def of(cls, config: EnvConfig, action_scale: ActionScale) -> ScriptedFollowerConfig:
        """The defaults with the camera and action scale of an env built with `config` (`env.action_scale`)."""
        return cls(camera_pitch_deg=config.camera_pitch_deg, camera_fov_deg=config.camera_fov_deg,
                   max_speed_horizontal_mps=action_scale.horizontal_mps,
                   max_speed_vertical_mps=action_scale.vertical_mps)


def target_inputs(observation: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The observation's target entries a scripted follower reads, as float64 batches: (N, 3) relative position
    [m], (N, 3) velocity [m/s], (N, 4) normalised box, and whether the observation was a batch."""
    rel = np.asarray(observation["target_pos_rel_m"], dtype=np.float64)
    batched = rel.ndim == 2
    vel = np.asarray(observation["target_vel_mps"], dtype=np.float64).reshape(-1, 3)
    bbox = np.asarray(observation["bbox_norm"], dtype=np.float64).reshape(-1, 4)
    return rel.reshape(-1, 3), vel, bbox, batched


def body_rates(observation: dict[str, np.ndarray], n: int) -> np.ndarray:
    """(n, 3) the IMU's mean angular rate over the frame [rad/s] (body x forward, y left, z up); zeros for an
    observation without "imu" (a hand-built one: the drone is then taken as level)."""
    if "imu" not in observation:
        return np.zeros((n, 3))
    return np.asarray(observation["imu"], dtype=np.float64).reshape(n, -1)[:, IMU_GYRO_COLUMNS]


def track_valid(observation: dict[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) whether each observation's track is valid (`track_valid` 1); all True for an observation without
    "track_valid" (a hand-built one: its estimate is then taken as measured)."""
    if "track_valid" not in observation:
        return np.ones(n, dtype=bool)
    return np.asarray(observation["track_valid"]).reshape(n) != 0.0  # the observation's {0, 1}


HANDED_OVER_FRAMES = 2 ** 62  # `_Episodes.fixed_frames` of an episode with no servo to hand over from


@dataclass
class _Episodes:
    """The per-env state of a batch's episodes (n envs), updated in place."""

    hold_height_m: np.ndarray  # (n,): the height above the target to hold [m]; NaN before the first 3D estimate
    servo: np.ndarray  # (n, 4): the image servo's integral (2) and last setpoint (2) [m/s], forward and left
    attitude: np.ndarray  # (n, 3, 3): R_heading_body from the gyro since the episode start
    # (n,): frames since the episode's first 3D estimate; -1 before it; HANDED_OVER_FRAMES when no servo ran before it
    fixed_frames: np.ndarray

    @classmethod
    def fresh(cls, n: int) -> _Episodes:
        return cls(np.full(n, np.nan), np.zeros((n, 4)), np.tile(np.eye(3), (n, 1, 1)), np.full(n, -1))

    def restart(self, starts: np.ndarray) -> None:
        """Start new episodes for the envs `starts` (n,) marks: level, without a height, a servo state or an estimate."""
        self.hold_height_m[starts] = np.nan
        self.servo[starts] = 0.0
        self.attitude[starts] = np.eye(3)
        self.fixed_frames[starts] = -1


class ScriptedFollower:
    """`predict(obs) -> (action, state)`; works on one observation or a batch (leading axis). Per env of a batch,
    `episode_start` True (and every env on the first call, after `reset()` or when the batch size changes) starts an
    episode: level, without a height to hold, a servo state or a 3D estimate."""

    def __init__(self, config: ScriptedFollowerConfig | None = None) -> None:
        self.config = config or ScriptedFollowerConfig()
        self._handover_frames = round(self.config.handover_s * CAMERA_RATE_HZ)
        self._episodes: _Episodes | None = None

    def reset(self) -> None:
        self._episodes = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        rel, vel, bbox, batched = target_inputs(observation)
        n = len(rel)
        if self._episodes is None or len(self._episodes.hold_height_m) != n:
            self._episodes = _Episodes.fresh(n)
        elif episode_start is not None:
            self._episodes.restart(np.asarray(episode_start, bool).reshape(-1))
        ep = self._episodes
        estimated = np.any(rel != 0.0, axis=1)  # a 3D estimate: from the episode's first one on
        rates = body_rates(observation, n)
        tracked = track_valid(observation, n)
        actions = []
        for i in range(n):
            ep.attitude[i] = attitude_after(ep.attitude[i], rates[i], 1.0 / CAMERA_RATE_HZ)
            if not estimated[i]:
                actions.append(self._servo_image(bbox[i], ep.attitude[i], ep.servo[i]))
                continue
            if ep.fixed_frames[i] < 0:  # the episode's first 3D estimate
                # an estimate from the first frame on (e.g. oracle perception) has no servo to hand over from
                ep.fixed_frames[i] = 0 if np.any(ep.servo[i]) else HANDED_OVER_FRAMES
                ep.hold_height_m[i] = -rel[i, 2]
            else:
                ep.fixed_frames[i] += 1
                if ep.fixed_frames[i] <= self._handover_frames and tracked[i]:
                    # the height to hold follows the estimate through the hand-over, then it is kept: the first
                    # ROI depths after a fast servo can be off several times for a few frames
                    ep.hold_height_m[i] = -rel[i, 2]
            feedforward = self._feedforward(vel[i], ep.servo[i], int(ep.fixed_frames[i]))
            actions.append(self._act(rel[i], feedforward, ep.hold_height_m[i], bool(tracked[i])))
        action = np.stack(actions).astype(np.float32)
        return (action if batched else action[0]), state

    def _feedforward(self, vel: np.ndarray, servo: np.ndarray, fixed_frames: int) -> np.ndarray:
        """The target velocity the 3D law feeds forward `fixed_frames` after the episode's first 3D estimate: the
        estimate's `vel`, blended from the servo's integral (`servo`'s first two) over
        `ScriptedFollowerConfig.handover_s`."""
        cfg = self.config
        weight = 1.0 if cfg.handover_s == 0.0 else min(1.0, fixed_frames / (cfg.handover_s * CAMERA_RATE_HZ))
        if weight >= 1.0:
            return vel
        blended = vel.copy()
        blended[:2] = weight * vel[:2] + (1.0 - weight) * servo[:2]
        return blended

    def _servo_image(self, bbox_norm: np.ndarray, R_heading_body: np.ndarray, state: np.ndarray) -> np.ndarray:
        """No 3D estimate yet (e.g. before the ROI depths converge): fly towards where the box's ray meets level
        ground, with the PI law of `ScriptedFollowerConfig`; `state` (the integral and last setpoint [m/s], forward
        and left) is updated in place. This motion also gives the feature triangulation its baseline. Without a box
        the setpoint decays towards hover at the acceleration limit."""
        cfg = self.config
        dt = 1.0 / CAMERA_RATE_HZ
        integral, last = state[:2], state[2:]
        if np.any(bbox_norm):
            error = box_ground_offset(bbox_norm, R_heading_body, cfg.camera_pitch_deg, cfg.camera_fov_deg)
            integral += cfg.servo_integral_gain_mps_per_s * error * dt
            np.clip(integral, -cfg.max_speed_horizontal_mps, cfg.max_speed_horizontal_mps, out=integral)  # anti-windup
            wanted = cfg.servo_gain_mps * error + integral
        else:
            wanted = np.zeros(2)
        step = wanted - last
        max_step = cfg.servo_max_accel_mps2 * dt
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

    def _act(self, rel: np.ndarray, vel: np.ndarray, hold_height_m: float, tracked: bool) -> np.ndarray:
        """The 3D law: horizontally, the target on the optical axis at the held height; vertically, the held height
        above the target while the track is valid, and the height the drone is at while it is not (a coasting
        estimate's vertical velocity is the trajectory model's, unmeasured: on city training world 10203 one sank at
        1.3-1.6 m/s for a car on a flat street and the drone followed it down into a building)."""
        cfg = self.config
        if not np.isfinite(hold_height_m):
            return np.zeros(ACTION_DIM)
        # Desired horizontal offset: the target sits on the optical axis at the held height.
        ahead_m = hold_height_m / np.tan(np.radians(cfg.camera_pitch_deg))
        error_xy = rel[:2] - np.array([ahead_m, 0.0])
        v_xy = cfg.velocity_feedforward * vel[:2] + cfg.position_gain_per_s * error_xy
        v_z = cfg.height_gain_per_s * (hold_height_m - (-rel[2])) if tracked else 0.0
        return np.array([
            np.clip(v_xy[0] / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            np.clip(v_xy[1] / cfg.max_speed_horizontal_mps, ACTION_LOW, ACTION_HIGH),
            np.clip(v_z / cfg.max_speed_vertical_mps, ACTION_LOW, ACTION_HIGH),
            0.0,
        ])
