"""Simulated MEMS IMU: resamples the physics ground truth at the IMU rate and adds noise.

Owns the noise model (white noise + bias random walk, MPU-9250 densities) and the sample clock.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from trade.types import ImuBatch
from trade.validation import require

FloatArray = npt.NDArray[np.float64]

_CLOCK_TOLERANCE_S = 1e-9  # a sample due at t counts as reached when truth time >= t - tolerance
_N_AXES = 6  # accel (3) then gyro (3)
_WEIGHT_CACHE_SIZE = 256  # interpolation patterns kept (the env cycles through a few)
# Times closer than this share cached interpolation weights. 1 ns: the float drift of the accumulated physics
# time (~1e-12 s after minutes) no longer makes new keys, so the cache holds the few real patterns (4, not one
# more every ~25 frames, ~50 B/step of heap growth until the 256-entry clear).
_WEIGHT_KEY_RESOLUTION_S = 1e-9
_N_NOISE_COLUMNS = 2 * _N_AXES  # accel white (3), gyro white (3), accel bias steps (3), gyro bias steps (3)


@dataclass(frozen=True)
class ImuConfig:
    """IMU rate and noise densities (continuous-time, per sqrt(Hz)).

    Defaults: MPU-9250 datasheet white noise (accel 300 ug/sqrt(Hz) = 2.94e-3 m/s^2/sqrt(Hz), gyro
    0.01 deg/s/sqrt(Hz) = 1.75e-4 rad/s/sqrt(Hz)); bias random walks of a consumer MEMS IMU as in the
    VINS-Mono defaults (accel 4e-5 m/s^3/sqrt(Hz), gyro 2e-6 rad/s^2/sqrt(Hz)); initial biases of a
    calibrated unit. Discrete model per sample: white sigma = density * sqrt(rate_hz); bias step sigma =
    random_walk * sqrt(1 / rate_hz). `noise=False` switches noise and bias off: the IMU then
    delivers the interpolated truth (still at rate_hz).
    """

    rate_hz: float = 200.0
    accel_noise_density_mps2_per_rthz: float = 2.94e-3
    gyro_noise_density_radps_per_rthz: float = 1.75e-4
    accel_bias_random_walk_mps3_per_rthz: float = 4.0e-5
    gyro_bias_random_walk_radps2_per_rthz: float = 2.0e-6
    accel_initial_bias_sigma_mps2: float = 0.02
    gyro_initial_bias_sigma_radps: float = 1.0e-3
    noise: bool = True  # noise and bias on (EnvConfig.imu_noise)

    def __post_init__(self) -> None:
        require(0.0 < self.rate_hz < math.inf, "ImuConfig.rate_hz", self.rate_hz, "finite and > 0")
        non_negative = (
            "accel_noise_density_mps2_per_rthz", "gyro_noise_density_radps_per_rthz",
            "accel_bias_random_walk_mps3_per_rthz", "gyro_bias_random_walk_radps2_per_rthz",
            "accel_initial_bias_sigma_mps2", "gyro_initial_bias_sigma_radps",
        )
        for name in non_negative:
            value = getattr(self, name)
            require(0.0 <= value < math.inf, f"ImuConfig.{name}", value, "finite and >= 0")

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def white_sigma(self) -> FloatArray:
        """(6,) per-sample white noise sigma [accel m/s^2 x3, gyro rad/s x3] = density * sqrt(rate)."""
        root = math.sqrt(self.rate_hz)
        return np.repeat([self.accel_noise_density_mps2_per_rthz * root,
                          self.gyro_noise_density_radps_per_rthz * root], 3)

    @property
    def bias_step_sigma(self) -> FloatArray:
        """(6,) per-sample bias random-walk step sigma = random_walk * sqrt(1 / rate)."""
        root = math.sqrt(1.0 / self.rate_hz)
        return np.repeat([self.accel_bias_random_walk_mps3_per_rthz * root,
                          self.gyro_bias_random_walk_radps2_per_rthz * root], 3)


class Imu:
    """Samples at t0 + k / rate_hz (k >= 1) from truth given after every physics step.

    `add_truth` only stores; `read` interpolates, adds noise and returns every sample whose
    timestamp is at or before the latest truth time and after the previous read.
    """

    def __init__(self, config: ImuConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.reset(0.0, rng)

    def reset(self, t0_s: float, rng: np.random.Generator) -> None:
        """Restart the sample clock at `t0_s` [s], draw initial biases from `rng`, drop stored truth."""
        cfg = self.config
        self._rng = rng
        self._sigmas = np.concatenate([cfg.white_sigma, cfg.bias_step_sigma])  # (12,) per draw column
        self._t0_s = float(t0_s)
        self._next_k = 1
        self._truth: list[tuple[float, float, float, float, float, float, float]] = []
        self._weight_cache: dict[tuple, FloatArray] = {}
        sigma0 = np.repeat([cfg.accel_initial_bias_sigma_mps2, cfg.gyro_initial_bias_sigma_radps], 3)
        self._bias = sigma0 * rng.standard_normal(_N_AXES) if cfg.noise else np.zeros(_N_AXES)

    def prime_at_rest(self, R_world_body: FloatArray, gravity_mps2: float, frame_rate_hz: float,
                      rng: np.random.Generator) -> None:
        """Run the IMU before the episode starts (`reset` with `rng`): the first `read` carries the samples of one
        frame period at `frame_rate_hz` (rounded up to whole IMU periods) taken at rest in attitude `R_world_body`
        (3, 3), so it holds a real, seeded reading (gravity on the body axes plus noise and bias) instead of zeros."""
        rate_hz = self.config.rate_hz
        lead_s = math.ceil(rate_hz / frame_rate_hz) / rate_hz
        self.reset(-lead_s, rng)
        rest_force_body = R_world_body.T @ np.array([0.0, 0.0, gravity_mps2])
        still = np.zeros(3)
        self.add_truth(-lead_s, rest_force_body, still)
        self.add_truth(0.0, rest_force_body, still)

    @property
    def accel_bias_mps2(self) -> FloatArray:
        """(3,) current accelerometer bias [m/s^2] (after the last delivered sample)."""
        return self._bias[:3].copy()

    @property
    def gyro_bias_radps(self) -> FloatArray:
        """(3,) current gyro bias [rad/s] (after the last delivered sample)."""
        return self._bias[3:].copy()

    def add_truth(self, t_s: float, specific_force_body: Sequence[float] | FloatArray,
                  gyro_body: Sequence[float] | FloatArray) -> None:
        """Store truth at `t_s` [s]: specific force (3,) body [m/s^2], angular rate (3,) body [rad/s]."""
        f, w = specific_force_body, gyro_body
        self._truth.append((float(t_s), float(f[0]), float(f[1]), float(f[2]),
                            float(w[0]), float(w[1]), float(w[2])))

    def add_truth_rows(self, rows: FloatArray) -> None:
        """Store truth rows (N, 7): time [s], specific force (3,) body [m/s^2], angular rate (3,) body [rad/s]."""
        self._truth.extend(map(tuple, rows.tolist()))

    def read(self) -> ImuBatch:
        """Samples due since the previous read: t_s (N,), accel (N, 3) [m/s^2], gyro (N, 3) [rad/s]."""
        truth = self._truth
        if not truth:
            return ImuBatch.empty()
        cfg = self.config
        self._truth = [truth[-1]]  # keep the latest as the anchor for the next interpolation
        # last sample index due: k_end = floor((t_last - t0) rate + tolerance)
        k_end = math.floor((truth[-1][0] - self._t0_s + _CLOCK_TOLERANCE_S) * cfg.rate_hz)
        if k_end < self._next_k:
            return ImuBatch.empty()
        times = [self._t0_s + k * cfg.period_s for k in range(self._next_k, k_end + 1)]
        self._next_k = k_end + 1
        truth_values = np.array(truth)[:, 1:]  # (M, 6)
        values = self._weights([row[0] for row in truth], times) @ truth_values
        if cfg.noise:
            values += self._noise(len(times))
        return ImuBatch(t_s=np.array(times), accel_mps2=values[:, :3], gyro_radps=values[:, 3:])

    def _weights(self, t_truth: list[float], t_query: list[float]) -> FloatArray:
        """(N, M) interpolation weights for truth at t_truth (M,) and samples at t_query (N,) [s].

        Cached by the times relative to the first sample, rounded to `_WEIGHT_KEY_RESOLUTION_S`: the
        pattern of physics, IMU and frame times repeats every few frames, so nearly every read is a
        cache hit (a hit reuses weights of times within that resolution, far below any effect)."""
        t_ref = t_query[0]
        key = (tuple(round((t - t_ref) / _WEIGHT_KEY_RESOLUTION_S) for t in t_truth),
               tuple(round((t - t_ref) / _WEIGHT_KEY_RESOLUTION_S) for t in t_query))
        W = self._weight_cache.get(key)
        if W is None:
            if len(self._weight_cache) >= _WEIGHT_CACHE_SIZE:
                self._weight_cache.clear()
            W = self._weight_cache[key] = _interpolation_weights(np.array(t_truth), np.array(t_query))
        return W

    def _noise(self, n: int) -> FloatArray:
        """(n, 6) noise: bias_k = bias_{k-1} + sigma_b * N(0, 1); sample = bias_k + sigma_w * N(0, 1).

        With the draws scaled, the bias walk is a cumulative sum, written as L @ steps with L the
        (n, n) lower-triangular ones (cheaper than np.cumsum for a handful of samples)."""
        draws = self._rng.standard_normal((n, _N_NOISE_COLUMNS)) * self._sigmas  # white (6), bias steps (6)
        walk = _lower_ones(n) @ draws[:, _N_AXES:]  # (n, 6) bias change since the last read
        noise = draws[:, :_N_AXES] + walk + self._bias
        self._bias = self._bias + walk[-1]
        return noise


def _interpolation_weights(t_truth: FloatArray, t_query: FloatArray) -> FloatArray:
    """(N, M) weights W so that W @ values (M, D) linearly interpolates values given at sorted times
    t_truth (M,) to t_query (N,), held flat outside."""
    M = len(t_truth)
    W = np.zeros((len(t_query), M))
    if M == 1:
        W[:, 0] = 1.0
        return W
    # fractional index s(t) by np.interp; x = (1 - w) x_i + w x_{i+1}, i = floor(s), w = s - i
    s = np.interp(t_query, t_truth, np.arange(M, dtype=np.float64))
    i = np.minimum(s.astype(np.intp), M - 2)
    w = s - i
    rows = np.arange(len(t_query))
    W[rows, i] = 1.0 - w
    W[rows, i + 1] += w
    return W


@functools.lru_cache(maxsize=_WEIGHT_CACHE_SIZE)
def _lower_ones(n: int) -> FloatArray:
    """(n, n) lower-triangular ones: L @ x is the cumulative sum of x's rows."""
    L = np.tril(np.ones((n, n)))
    L.setflags(write=False)
    return L
