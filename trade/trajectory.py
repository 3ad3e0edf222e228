"""Trajectory model of the tracked target: a damped constant-acceleration Kalman filter (filterpy).

Owns the world-frame state x = [p, v, a] (9,), its prediction to any time, position updates and look-ahead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from filterpy.kalman import KalmanFilter

FloatArray = npt.NDArray[np.float64]

DIM_X = 9  # state: position p [m], velocity v [m/s], acceleration a [m/s^2], each (3,) in world
DIM_Z = 3  # measurement: position [m] in world
_I3 = np.eye(3)
_SUBSTEP_ROUNDING = 1e-9  # relative slack so float noise in t_s does not add a sub-step


@dataclass(frozen=True)
class TrajectoryConfig:
    """Noise and damping of the model; damping factors are the fraction kept after 1 s without updates."""

    jerk_psd_m2ps5: float = 4.0  # spectral density of the white jerk driving a [m^2/s^5]
    measurement_sigma_m: float = 0.5  # default 1-sigma of a position measurement [m]
    velocity_damping_per_s: float = 0.8  # d_v per second, in (0, 1]; 1 = constant-acceleration model
    accel_damping_per_s: float = 0.3  # d_a per second, in (0, 1]
    initial_position_sigma_m: float = 1.0
    initial_velocity_sigma_mps: float = 5.0
    initial_accel_sigma_mps2: float = 2.0
    max_step_s: float = 0.05  # longer predictions are split into equal sub-steps no longer than this

    def __post_init__(self) -> None:
        positive = (
            "jerk_psd_m2ps5",
            "measurement_sigma_m",
            "initial_position_sigma_m",
            "initial_velocity_sigma_mps",
            "initial_accel_sigma_mps2",
            "max_step_s",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"TrajectoryConfig.{name} must be finite and > 0, got {value!r}")
        for name in ("velocity_damping_per_s", "accel_damping_per_s"):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise ValueError(f"TrajectoryConfig.{name} must be in (0, 1], got {value!r}")


@dataclass(frozen=True)
class TrajectoryState:
    """Filter state at time t_s; covariance is (9, 9) over [p, v, a]."""

    position_m: FloatArray  # (3,) world [m]
    velocity_mps: FloatArray  # (3,) world [m/s]
    acceleration_mps2: FloatArray  # (3,) world [m/s^2]
    covariance: FloatArray  # (9, 9)
    t_s: float


def transition_matrix(dt_s: float, config: TrajectoryConfig) -> FloatArray:
    """(9, 9) F for one step of dt_s: p' = p + v dt + a dt^2/2; v' = d_v (v + a dt); a' = d_a a.

    d = damping_per_s ** dt_s, so damping compounds per second whatever the step size.
    """
    d_v = config.velocity_damping_per_s**dt_s
    d_a = config.accel_damping_per_s**dt_s
    F = np.zeros((DIM_X, DIM_X))
    F[0:3, 0:3] = _I3
    F[0:3, 3:6] = dt_s * _I3
    F[0:3, 6:9] = 0.5 * dt_s**2 * _I3
    F[3:6, 3:6] = d_v * _I3
    F[3:6, 6:9] = d_v * dt_s * _I3
    F[6:9, 6:9] = d_a * _I3
    return F


def process_noise(dt_s: float, config: TrajectoryConfig) -> FloatArray:
    """(9, 9) Q of continuous white jerk with density q, per axis (undamped approximation):

    Q_axis = q [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2], [dt^3/6, dt^2/2, dt]].
    """
    dt = dt_s
    block = config.jerk_psd_m2ps5 * np.array(
        [
            [dt**5 / 20.0, dt**4 / 8.0, dt**3 / 6.0],
            [dt**4 / 8.0, dt**3 / 3.0, dt**2 / 2.0],
            [dt**3 / 6.0, dt**2 / 2.0, dt],
        ]
    )
    return np.kron(block, _I3).astype(np.float64, copy=False)  # state ordered [p(3), v(3), a(3)]: block (i, j) multiplies I3


def measurement_matrix() -> FloatArray:
    """(3, 9) H = [I 0 0]: the filter observes position only."""
    H = np.zeros((DIM_Z, DIM_X))
    H[:, 0:3] = _I3
    return H


def initial_covariance(config: TrajectoryConfig) -> FloatArray:
    """(9, 9) diagonal P0 from the configured initial sigmas."""
    sigmas = [config.initial_position_sigma_m, config.initial_velocity_sigma_mps, config.initial_accel_sigma_mps2]
    return np.diag(np.repeat(np.square(sigmas), 3))


def _substeps(dt_s: float, max_step_s: float) -> tuple[int, float]:
    """Split dt_s into n equal steps of h <= max_step_s; (0, 0.0) for dt_s == 0."""
    n = math.ceil(dt_s / max_step_s - _SUBSTEP_ROUNDING) if dt_s > 0 else 0
    return n, (dt_s / n if n else 0.0)


class TrajectoryModel:
    """Damped constant-acceleration Kalman filter on the target's world position (filterpy)."""

    def __init__(self, config: TrajectoryConfig | None = None) -> None:
        self.config = config if config is not None else TrajectoryConfig()
        self._kf = KalmanFilter(dim_x=DIM_X, dim_z=DIM_Z)
        self._H = measurement_matrix()
        self._kf.H = self._H
        self._t_s: float | None = None

    @property
    def initialized(self) -> bool:
        return self._t_s is not None

    @property
    def state(self) -> TrajectoryState:
        t_s = self._require_initialized()
        x = self._kf.x[:, 0]
        return TrajectoryState(x[0:3].copy(), x[3:6].copy(), x[6:9].copy(), self._kf.P.copy(), t_s)

    def reset(self, position_m: npt.ArrayLike, t_s: float) -> TrajectoryState:
        """Start at position_m (3,) world [m], at rest, at time t_s [s]."""
        p = np.asarray(position_m, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(p)) and math.isfinite(t_s)):
            raise ValueError(f"reset needs a finite position and time, got position_m={p!r}, t_s={t_s!r}")
        self._kf.x = np.zeros((DIM_X, 1))
        self._kf.x[0:3, 0] = p
        self._kf.P = initial_covariance(self.config)
        self._t_s = float(t_s)
        return self.state

    def predict(self, t_s: float) -> TrajectoryState:
        """Advance the state to time t_s [s] (>= current time); x = F x, P = F P F^T + Q per sub-step."""
        t0_s = self._require_initialized()
        dt_s = float(t_s) - t0_s
        if not (math.isfinite(dt_s) and dt_s >= 0.0):
            raise ValueError(f"predict needs t_s >= the state time {t0_s}, got t_s={t_s!r}")
        n, h = _substeps(dt_s, self.config.max_step_s)
        if n:
            F, Q = transition_matrix(h, self.config), process_noise(h, self.config)
            for _ in range(n):
                self._kf.predict(F=F, Q=Q)
        self._t_s = float(t_s)
        return self.state

    def update(self, position_m: npt.ArrayLike, sigma_m: float | npt.ArrayLike | None = None) -> bool:
        """Fuse a world position (3,) [m] with 1-sigma sigma_m (scalar or (3,); None = config default).

        R = diag(sigma^2); y = z - H x; K = P H^T (H P H^T + R)^-1; x += K y; P = (I - K H) P (Joseph form).
        Returns False, leaving the state untouched, when the position or the sigma is not finite.
        """
        self._require_initialized()
        z = np.asarray(position_m, dtype=np.float64).reshape(DIM_Z)
        sigma_in = self.config.measurement_sigma_m if sigma_m is None else sigma_m
        sigma = np.broadcast_to(np.asarray(sigma_in, dtype=np.float64), (DIM_Z,))
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(sigma))):
            return False
        if np.any(sigma <= 0.0):
            raise ValueError(f"update needs sigma_m > 0, got {sigma_in!r}")
        self._kf.update(z.reshape(DIM_Z, 1), R=np.diag(sigma**2), H=self._H)
        return True

    def predict_ahead(self, horizon_s: float, n: int) -> FloatArray:
        """(n, 3) predicted world positions [m] at t + horizon_s * k / n, k = 1..n; the state is unchanged."""
        self._require_initialized()
        if not (math.isfinite(horizon_s) and horizon_s > 0 and n >= 1):
            raise ValueError(f"predict_ahead needs horizon_s > 0 and n >= 1, got {horizon_s!r}, {n!r}")
        m, h = _substeps(horizon_s / n, self.config.max_step_s)
        # F^m advances one output interval horizon_s / n
        F_interval = np.linalg.matrix_power(transition_matrix(h, self.config), m)
        out = np.empty((n, 3))
        x = self._kf.x[:, 0].copy()
        for k in range(n):
            x = F_interval @ x
            out[k] = x[0:3]
        return out

    def _require_initialized(self) -> float:
        """The state time [s]; RuntimeError before the first reset."""
        if self._t_s is None:
            raise RuntimeError("TrajectoryModel used before reset(position_m, t_s)")
        return self._t_s
