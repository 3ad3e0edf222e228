"""The observation a follower policy sees: the same keys and shapes in every perception mode.

Vectors are expressed in the drone's heading frame (yaw only: x forward, y left, z up), so a
policy is invariant to the world's yaw; a missing estimate shows as zeros with `track_valid` 0.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from trade.geometry import rotation_z
from trade.types import ImuBatch
from trade_gym.perception.base import FloatArray, PerceptionOutput

POSITION_BOUND_M = 1000.0
VELOCITY_BOUND_MPS = 100.0
IMU_ACCEL_BOUND_MPS2 = 160.0  # MPU-9250 full scale 16 g
IMU_GYRO_BOUND_RADPS = 35.0  # MPU-9250 full scale 2000 deg/s
TIME_BOUND_S = 3600.0


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
        }
    )


def build_observation(
    estimate: PerceptionOutput,
    drone_position_est_m: FloatArray,
    drone_yaw_est_rad: float,
    drone_velocity_world_mps: FloatArray,
    imu: ImuBatch,
    time_lost_s: float,
    image_size_px: int,
) -> dict[str, np.ndarray]:
    """Map an estimate and the drone's own state to the observation dict (float32, clipped)."""
    R_heading_world = rotation_z(drone_yaw_est_rad).T
    rel = estimate.position_world_m - drone_position_est_m
    rel_h = R_heading_world @ rel if np.all(np.isfinite(rel)) else np.zeros(3)
    vel = estimate.velocity_world_mps
    vel_h = R_heading_world @ vel if np.all(np.isfinite(vel)) else np.zeros(3)
    bbox = estimate.bbox
    if np.all(np.isfinite(bbox)):
        centre = bbox[:2] + bbox[2:] / 2.0
        bbox_norm = np.concatenate([centre, bbox[2:]]) / image_size_px
    else:
        bbox_norm = np.zeros(4)
    depth = estimate.target_depth_m if np.isfinite(estimate.target_depth_m) else 0.0
    if len(imu.t_s):
        imu_mean = np.concatenate([imu.accel_mps2.mean(axis=0), imu.gyro_radps.mean(axis=0)])
        imu_mean = np.where(np.isfinite(imu_mean), imu_mean, 0.0)
    else:
        imu_mean = np.zeros(6)
    obs = {
        "target_pos_rel_m": np.clip(rel_h, -POSITION_BOUND_M, POSITION_BOUND_M),
        "target_vel_mps": np.clip(vel_h, -VELOCITY_BOUND_MPS, VELOCITY_BOUND_MPS),
        "drone_vel_mps": np.clip(R_heading_world @ drone_velocity_world_mps, -VELOCITY_BOUND_MPS,
                                 VELOCITY_BOUND_MPS),
        "bbox_norm": np.clip(bbox_norm, 0.0, 1.0),
        "target_depth_m": np.clip([depth], 0.0, POSITION_BOUND_M),
        "track_valid": np.array([1.0 if estimate.valid else 0.0]),
        "time_lost_s": np.array([min(time_lost_s, TIME_BOUND_S)]),
        "imu": np.concatenate([
            np.clip(imu_mean[:3], -IMU_ACCEL_BOUND_MPS2, IMU_ACCEL_BOUND_MPS2),
            np.clip(imu_mean[3:], -IMU_GYRO_BOUND_RADPS, IMU_GYRO_BOUND_RADPS),
        ]),
    }
    return {k: v.astype(np.float32) for k, v in obs.items()}
