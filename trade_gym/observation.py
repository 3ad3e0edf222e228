"""The observation a follower policy sees: the same keys and shapes in every perception mode.

Vectors are expressed in the drone's heading frame (yaw only: x forward, y left, z up), so a
policy is invariant to the world's yaw; a missing estimate shows as zeros with `track_valid` 0.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from gymnasium import spaces

from trade.types import ImuBatch
from trade_gym.perception.base import FloatArray, PerceptionOutput, finite_imu

POSITION_BOUND_M = 1000.0
VELOCITY_BOUND_MPS = 100.0
IMU_ACCEL_BOUND_MPS2 = 160.0  # MPU-9250 full scale 16 g
IMU_GYRO_BOUND_RADPS = 35.0  # MPU-9250 full scale 2000 deg/s
TIME_BOUND_S = 3600.0


# (key, start, end) of each observation entry in the flat buffer `build_observation` fills, in the
# order of `OBSERVATION_SIZES`.
OBSERVATION_SIZES = (("target_pos_rel_m", 3), ("target_vel_mps", 3), ("drone_vel_mps", 3), ("bbox_norm", 4),
                     ("target_depth_m", 1), ("track_valid", 1), ("time_lost_s", 1), ("imu", 6),
                     ("estimate_age_s", 1))
_ends = np.cumsum([n for _, n in OBSERVATION_SIZES]).tolist()
_LAYOUT = tuple((key, end - n, end) for (key, n), end in zip(OBSERVATION_SIZES, _ends))
_IMU_ENTRIES = dict(OBSERVATION_SIZES)["imu"]  # specific force (3) then rate (3)
IMU_GYRO_COLUMNS = slice(3, 6)  # the rate's entries in "imu" [rad/s], body x forward, y left, z up


def observation_space() -> spaces.Dict:
    """Dict space; see the table in `TradeFollowEnv`'s docstring."""
    def box(bound: float, n: int, low: float | None = None) -> spaces.Box:
        lo = -bound if low is None else low
        return spaces.Box(lo, bound, (n,), np.float32)

    return spaces.Dict(
        {
            "target_pos_rel_m": box(POSITION_BOUND_M, 3),
            "target_vel_mps": box(VELOCITY_BOUND_MPS, 3),
            "drone_vel_mps": box(VELOCITY_BOUND_MPS, 3),
            "bbox_norm": box(1.0, 4, low=0.0),
            "target_depth_m": box(POSITION_BOUND_M, 1, low=0.0),
            "track_valid": box(1.0, 1, low=0.0),
            "time_lost_s": box(TIME_BOUND_S, 1, low=0.0),
            "imu": spaces.Box(
                np.array([-IMU_ACCEL_BOUND_MPS2] * 3 + [-IMU_GYRO_BOUND_RADPS] * 3, np.float32),
                np.array([IMU_ACCEL_BOUND_MPS2] * 3 + [IMU_GYRO_BOUND_RADPS] * 3, np.float32),
                dtype=np.float32,
            ),
            "estimate_age_s": box(TIME_BOUND_S, 1, low=0.0),
        }
    )


def build_observation(
    estimate: PerceptionOutput,
    drone_position_est_m: FloatArray,
    drone_yaw_est_rad: float,
    drone_velocity_world_mps: FloatArray | None,
    imu: ImuBatch,
    time_lost_s: float,
    estimate_age_s: float,
    image_size_px: int,
) -> dict[str, np.ndarray]:
    """Map an estimate and the drone's own state to the observation dict (float32, clipped); `estimate_age_s`
    is the estimate's age [s] (`trade_gym.latency`); a drone velocity of None (unknown: a sensor frame without it,
    `SensorFrame.velocity_world_mps`) is observed as zeros, as a non-finite one is.

    Written with scalar math: this runs every env step and numpy's per-call overhead on
    3-vectors would dominate it."""
    c, s = math.cos(drone_yaw_est_rad), math.sin(drone_yaw_est_rad)
    rel = estimate.position_world_m - drone_position_est_m
    depth = estimate.target_depth_m if math.isfinite(estimate.target_depth_m) else 0.0
    values = [
        *_heading(rel, c, s, POSITION_BOUND_M),
        *_heading(estimate.velocity_world_mps, c, s, VELOCITY_BOUND_MPS),
        *_heading(drone_velocity_world_mps, c, s, VELOCITY_BOUND_MPS),
        *_bbox_norm(estimate.bbox, image_size_px),
        min(max(depth, 0.0), POSITION_BOUND_M),
        1.0 if estimate.valid else 0.0,
        min(time_lost_s, TIME_BOUND_S),
        *_imu_values(imu),
        min(max(estimate_age_s, 0.0), TIME_BOUND_S),
    ]
    # One float32 buffer per step (fresh each call), handed out as per-key views: one array
    # construction instead of nine.
    flat = np.array(values, np.float32)
    return {key: flat[lo:hi] for key, lo, hi in _LAYOUT}


def _heading(v: FloatArray | None, c: float, s: float, bound: float) -> list[float]:
    """R_heading_world v = Rz(yaw)^T v for v (3,) world, c, s = cos, sin of the yaw, clipped to +-bound;
    zeros when v is None or not finite (unknown)."""
    if v is None:
        return [0.0, 0.0, 0.0]
    x, y, z = v.tolist()
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return [0.0, 0.0, 0.0]
    return [_clip(c * x + s * y, bound), _clip(-s * x + c * y, bound), _clip(z, bound)]


def _bbox_norm(bbox: FloatArray, image_size_px: int) -> list[float]:
    """(x, y, w, h) [px] -> (centre x, centre y, w, h) / image size, in [0, 1]; zeros when not finite."""
    x, y, w, h = bbox.tolist()
    if not all(math.isfinite(v) for v in (x, y, w, h)):
        return [0.0, 0.0, 0.0, 0.0]
    return [min(max(v / image_size_px, 0.0), 1.0) for v in (x + w / 2.0, y + h / 2.0, w, h)]


def _imu_values(imu: ImuBatch) -> list[float]:
    """The frame's mean specific force [m/s^2] and rate [rad/s], clipped to the sensor's full scale;
    zeros when the frame has no finite sample."""
    imu_mean = _imu_mean(imu)
    if imu_mean is None:
        return [0.0] * _IMU_ENTRIES
    mean = imu_mean.tolist()
    return [_clip(v, IMU_ACCEL_BOUND_MPS2) for v in mean[:3]] + [_clip(v, IMU_GYRO_BOUND_RADPS) for v in mean[3:]]


def _imu_mean(imu: ImuBatch) -> FloatArray | None:
    """(6,) mean specific force and rate over the frame's finite samples (a faulty IMU's NaN/inf samples
    are dropped); None when the frame has no finite sample."""
    n = len(imu.t_s)
    if not n:
        return None
    # ufunc reductions: ndarray.mean's Python-level wrapper costs more than the sums on (N <= 7, 3) arrays
    mean = np.concatenate([_sum_rows(imu.accel_mps2), _sum_rows(imu.gyro_radps)]) / n
    if math.isfinite(float(mean.sum())):
        return mean
    imu = finite_imu(imu)  # rare: only when a sample is corrupt
    n = len(imu.t_s)
    if not n:
        return None
    return np.concatenate([_sum_rows(imu.accel_mps2), _sum_rows(imu.gyro_radps)]) / n


_sum_rows = functools.partial(np.add.reduce, axis=0)


def _clip(value: float, bound: float) -> float:
    return min(max(value, -bound), bound)
