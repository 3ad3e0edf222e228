"""Oracle perception: ground truth passed through a noise model, with no image processing.

The target is measured in the true camera frame and mapped to the world with the pose
source's estimate, so VIO drift reaches the oracle's estimates the way it reaches TRADE's. The oracle is the
one mode that reads ground truth: through the providers the env gives it at construction, never through
`reset`/`step`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from trade.geometry import Pose
from trade.validation import require
from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import FloatArray, GroundEstimate, PerceptionOutput, SensorFrame

MIN_BOX_SIDE_PX = 1.0
N_NORMAL_DRAWS = 11
N_CORRELATED = 10  # box (4), position (3), velocity (3) follow the Gauss-Markov process; ground stays white
# The fitted first-fix delay [s] (trade_gym.agents.train trains with it). OracleConfig's default stays 0: the
# estimate's NaN depth in info before the first fix defeats gymnasium's check_env (NaN != NaN).
FITTED_FIRST_FIX_DELAY_S = 2.6
GROUND_DRAW = 10  # the draw for the ground's depth factor


@dataclass(frozen=True)
class OracleConfig:
    """Noise model: Gaussian box jitter [px], position noise as a fraction of depth, velocity
    noise [m/s], a per-frame dropout probability (the estimate then coasts), the correlation time of
    the box, position and velocity noise [s] (first-order Gauss-Markov; 0 = white) and the delay after
    reset before the first 3D position and velocity exist [s] (TRADE needs its ROI depths first).

    The defaults are the one source of the env's `oracle_*` arguments: fitted to full TRADE's closed-loop errors
    on training worlds (benchmarks/fit_oracle_noise.py: median over scenes; benchmarks/results/
    oracle_noise_fit.json), except first_fix_delay_s (see FITTED_FIRST_FIX_DELAY_S)."""

    box_sigma_px: float = 1.725
    depth_sigma_frac: float = 0.0136
    velocity_sigma_mps: float = 0.446
    dropout_prob: float = 0.0
    noise_correlation_s: float = 0.564
    first_fix_delay_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("box_sigma_px", "depth_sigma_frac", "velocity_sigma_mps", "noise_correlation_s",
                     "first_fix_delay_s"):
            value = getattr(self, name)
            require(0.0 <= value < math.inf, f"OracleConfig.{name}", value, "finite and >= 0")
        require(0.0 <= self.dropout_prob <= 1.0, "OracleConfig.dropout_prob", self.dropout_prob, "in [0, 1]")


class OraclePerception:
    """Ground truth plus noise; needs no rendered image. `ground_truth` and `T_world_cam_true` return the current
    frame's ground truth and true camera pose (the env's, read at each reset and step)."""

    def __init__(self, config: OracleConfig, ground_truth: Callable[[], GroundTruth],
                 T_world_cam_true: Callable[[], Pose]) -> None:
        self.config = config
        self._truth = ground_truth
        self._true_pose = T_world_cam_true
        self._rng = np.random.default_rng(0)
        self._last = PerceptionOutput.missing()
        self._noise: np.ndarray | None = None  # (N_CORRELATED,) unit-variance Gauss-Markov state
        self._t_reset_s = 0.0
        self._t_last_s = 0.0

    def reset(self, sensors: SensorFrame, init_box: FloatArray, rng: np.random.Generator) -> PerceptionOutput:
        self._rng = rng
        self._last = PerceptionOutput.missing()
        self._noise = None
        self._t_reset_s = self._t_last_s = sensors.t_s
        return self.step(sensors)

    def _unit_noise(self, draws: np.ndarray, dt: float) -> np.ndarray:
        """n_k = rho n_{k-1} + sqrt(1 - rho^2) w_k with rho = exp(-dt / tau), w_k ~ N(0, 1): stationary unit
        variance, correlation time tau; white (n_k = w_k) for tau = 0 or at the first frame."""
        tau = self.config.noise_correlation_s
        if self._noise is None or tau <= 0.0:
            self._noise = draws.copy()
        else:
            rho = math.exp(-max(dt, 0.0) / tau)
            self._noise = rho * self._noise + math.sqrt(1.0 - rho * rho) * draws
        return self._noise

    def step(self, sensors: SensorFrame) -> PerceptionOutput:
        cfg, truth = self.config, self._truth()
        # Draw every noise term each frame so the random stream does not depend on visibility.
        draws = self._rng.standard_normal(N_NORMAL_DRAWS)  # one call: box (4), position (3), velocity (3), ground
        dt_s = sensors.t_s - self._t_last_s
        self._t_last_s = sensors.t_s
        noise = self._unit_noise(draws[:N_CORRELATED], dt_s)
        box_noise = noise[0:4] * cfg.box_sigma_px
        pos_noise = noise[4:7]
        vel_noise = noise[7:10] * cfg.velocity_sigma_mps
        ground_noise = float(draws[GROUND_DRAW])
        dropped = self._rng.random() < cfg.dropout_prob
        if dropped or not all(math.isfinite(v) for v in truth.target_bbox.tolist()):
            self._last = _coast(self._last, dt_s)
            return self._last
        bbox = truth.target_bbox + box_noise
        bbox[2:] = np.maximum(bbox[2:], MIN_BOX_SIDE_PX)
        T_cam_world_true = self._true_pose().inverse()
        target_cam = T_cam_world_true.apply(truth.target_position_m.reshape(1, 3))[0]
        depth_sigma = cfg.depth_sigma_frac * max(target_cam[2], 0.0)
        target_cam = target_cam + pos_noise * depth_sigma
        position = sensors.T_world_cam.apply(target_cam.reshape(1, 3))[0]
        # Velocity rotates with the estimated orientation error, as a measured vector would.
        R_err = sensors.T_world_cam.R @ T_cam_world_true.R
        velocity = R_err @ truth.target_velocity_mps + vel_noise
        ground = GroundEstimate(true_depth_factor=1.0 + cfg.depth_sigma_frac * ground_noise)  # z = z_true (1 + s n)
        if sensors.t_s - self._t_reset_s < cfg.first_fix_delay_s:
            # No 3D fix yet: a box, but no position, velocity or depth (as TRADE before its ROI depths exist).
            position, velocity = np.full(3, np.nan), np.full(3, np.nan)
            target_cam = np.full(3, np.nan)
            depth_sigma = float("nan")
        self._last = PerceptionOutput(
            bbox=bbox,
            position_world_m=position,
            velocity_world_mps=velocity,
            target_depth_m=float(target_cam[2]),
            target_depth_sigma_m=float(depth_sigma),
            ground=ground,
            valid=True,
        )
        return self._last


def _coast(last: PerceptionOutput, dt_s: float) -> PerceptionOutput:
    """No fresh box: the world estimate moves on at its last velocity, p_k = p_{k-1} + v_{k-1} dt
    (as TRADE's trajectory model predicts while the tracker is lost)."""
    return PerceptionOutput(
        bbox=np.full(4, np.nan),
        position_world_m=last.position_world_m + last.velocity_world_mps * dt_s,
        velocity_world_mps=last.velocity_world_mps,
        target_depth_m=np.nan,
        target_depth_sigma_m=np.nan,
        ground=GroundEstimate(),
        valid=False,
    )

