"""Camera pose given to perception: exact ground truth ("gt") or a VIO-like drifting estimate ("vio").

Owns the drift model: random walks in position and yaw whose increments scale with the distance flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from trade.geometry import FloatArray, Pose, rotation_z
from trade.validation import is_finite_number, require

POSE_SOURCE_NAMES = ("gt", "vio")


@dataclass(frozen=True)
class VioConfig:
    """Drift of a visual-inertial odometry pose, in its four unobservable directions.

    Position (world x, y, z) and yaw errors are random walks driven by the distance flown: over a
    distance d each axis gains N(0, sigma^2 d). Defaults give ~1 m (1 % of distance) per axis and
    ~1.1 deg of yaw after 100 m, typical of filter-based VIO such as xVIO on long, high flights
    (the paper reports VIO poses noticeably worse than ground truth). Roll and pitch stay exact
    because gravity makes them observable.
    """

    position_drift_sigma_m_per_sqrt_m: float = 0.1
    yaw_drift_sigma_rad_per_sqrt_m: float = 0.002
    # Velocity is observable to a VIO (visual flow against inertial), so its error stays bounded: a first-order
    # Gauss-Markov error per axis of this steady-state sigma and correlation time, zero at reset (the filter
    # starts at rest), in the drifted frame (rotated by the yaw drift like the pose).
    velocity_error_sigma_mps: float = 0.05
    velocity_error_correlation_s: float = 2.0

    def __post_init__(self) -> None:
        require(is_finite_number(self.velocity_error_correlation_s) and self.velocity_error_correlation_s > 0,
                "VioConfig.velocity_error_correlation_s", self.velocity_error_correlation_s, "a finite number > 0")
        for name in ("position_drift_sigma_m_per_sqrt_m", "yaw_drift_sigma_rad_per_sqrt_m",
                     "velocity_error_sigma_mps"):
            value = getattr(self, name)
            require(is_finite_number(value) and value >= 0, f"VioConfig.{name}", value, "a finite number >= 0")


class PoseSource(Protocol):
    """Anything that turns the true camera pose into the pose perception sees."""

    def reset(self, rng: np.random.Generator) -> None: ...

    def estimate(self, T_world_cam_true: Pose, distance_flown_m: float) -> Pose: ...

    def velocity(self, velocity_world_true_mps: FloatArray, t_s: float) -> FloatArray: ...


class GroundTruthPoseSource:
    """Returns the true camera pose and velocity unchanged."""

    def reset(self, rng: np.random.Generator) -> None:
        """Nothing to reset; accepts the generator for a common interface."""

    def estimate(self, T_world_cam_true: Pose, distance_flown_m: float) -> Pose:
        return T_world_cam_true

    def velocity(self, velocity_world_true_mps: FloatArray, t_s: float) -> FloatArray:
        return velocity_world_true_mps


class VioPoseSource:
    """Drifting pose: p_est = p + dp, R_est = Rz(dpsi) R, with dp, dpsi random walks in distance flown;
    velocity v_est = Rz(dpsi) v + e, e a Gauss-Markov error in time.

    `distance_flown_m` is the odometer since reset (monotone); each call advances the walks by the
    distance dd flown since the previous call: dp += sigma_p sqrt(dd) N(0, I3),
    dpsi += sigma_psi sqrt(dd) N(0, 1). Each `velocity` call at a later time t advances e over
    dt: e = a e + sigma_v sqrt(1 - a^2) N(0, I3), a = exp(-dt / tau_v).
    """

    def __init__(self, config: VioConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.reset(rng)

    def reset(self, rng: np.random.Generator) -> None:
        self._rng = rng
        self._position_error_m = np.zeros(3)
        self._yaw_error_rad = 0.0
        self._last_distance_m = 0.0
        self._velocity_error_mps = np.zeros(3)
        self._last_velocity_t_s: float | None = None
        # A child stream (spawning leaves `rng`'s own draws as they were), so the velocity error does not move
        # the pose drift or any other draw of the env's generator.
        self._velocity_rng = rng.spawn(1)[0]

    @property
    def position_error_m(self) -> np.ndarray:
        """(3,) current world position drift [m]."""
        return self._position_error_m.copy()

    @property
    def yaw_error_rad(self) -> float:
        """Current yaw drift [rad]."""
        return self._yaw_error_rad

    def estimate(self, T_world_cam_true: Pose, distance_flown_m: float) -> Pose:
        """Drifted T_world_cam; `distance_flown_m` is the total distance flown since reset [m]."""
        distance = float(distance_flown_m)
        if not math.isfinite(distance) or distance < self._last_distance_m:
            raise ValueError(
                f"distance_flown_m must be finite and non-decreasing, got {distance!r} "
                f"after {self._last_distance_m!r}"
            )
        step = distance - self._last_distance_m
        self._last_distance_m = distance
        if step > 0.0:
            cfg, root = self.config, math.sqrt(step)
            draws = self._rng.standard_normal(4)
            position_step = cfg.position_drift_sigma_m_per_sqrt_m * root * draws[:3]
            self._position_error_m = self._position_error_m + position_step
            self._yaw_error_rad += cfg.yaw_drift_sigma_rad_per_sqrt_m * root * float(draws[3])
        T = T_world_cam_true
        return Pose(rotation_z(self._yaw_error_rad) @ T.R, T.t + self._position_error_m)


    def velocity(self, velocity_world_true_mps: FloatArray, t_s: float) -> FloatArray:
        """(3,) velocity in the drifted frame [m/s] at time `t_s` (non-decreasing across calls) [s]."""
        last = self._last_velocity_t_s
        if not math.isfinite(t_s) or (last is not None and t_s < last):
            raise ValueError(f"t_s must be finite and non-decreasing, got {t_s!r} after {last!r}")
        if last is not None and t_s > last:
            cfg = self.config
            a = math.exp(-(t_s - last) / cfg.velocity_error_correlation_s)
            noise = cfg.velocity_error_sigma_mps * math.sqrt(1.0 - a * a) * self._velocity_rng.standard_normal(3)
            self._velocity_error_mps = a * self._velocity_error_mps + noise
        self._last_velocity_t_s = float(t_s)
        return rotation_z(self._yaw_error_rad) @ np.asarray(velocity_world_true_mps, float) + self._velocity_error_mps


def make_pose_source(name: str, rng: np.random.Generator, vio_config: VioConfig | None = None) -> PoseSource:
    """Pose source by name ("gt" or "vio"), reset with `rng`; ValueError for any other name."""
    if name == "gt":
        source: PoseSource = GroundTruthPoseSource()
        source.reset(rng)
        return source
    if name == "vio":
        return VioPoseSource(vio_config if vio_config is not None else VioConfig(), rng)
    raise ValueError(f"unknown pose_source {name!r}; valid: {', '.join(POSE_SOURCE_NAMES)}")
