"""The contract every perception mode fulfils: one estimate of the target per camera frame.

Estimates are in the world frame as the perception believes it (so with `pose_source="vio"`
they carry the pose drift); NaN marks what a mode could not estimate this frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from trade.geometry import Pose
from trade.types import ImuBatch
from trade_gym.ground_truth import GroundTruth

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PerceptionOutput:
    """bbox (4,) x, y, w, h [px]; world position (3,) [m] and velocity (3,) [m/s]; depths [m]."""

    bbox: FloatArray
    position_world_m: FloatArray
    velocity_world_mps: FloatArray
    target_depth_m: float
    target_depth_sigma_m: float
    ground_depth_m: float  # estimated ground depth along the ground-truth box centre's ray
    valid: bool  # the box is a fresh measurement this frame (not coasting)

    @classmethod
    def missing(cls) -> PerceptionOutput:
        nan3 = np.full(3, np.nan)
        return cls(np.full(4, np.nan), nan3, nan3.copy(), np.nan, np.nan, np.nan, False)


@dataclass(frozen=True)
class SensorFrame:
    """What the sensors deliver at one camera frame; `rgb` is None when nothing was rendered."""

    t_s: float
    rgb: npt.NDArray[np.uint8] | None
    T_world_cam: Pose  # from the pose source (exact or drifting)
    imu: ImuBatch


def finite_imu(imu: ImuBatch) -> ImuBatch:
    """The samples of `imu` whose time, specific force and rate are all finite (a faulty IMU's NaN/inf
    samples are dropped at the sensor boundary); `imu` itself when every sample is finite."""
    good = (np.isfinite(imu.t_s) & np.all(np.isfinite(imu.accel_mps2), axis=1)
            & np.all(np.isfinite(imu.gyro_radps), axis=1))
    if good.all():
        return imu
    return ImuBatch(imu.t_s[good], imu.accel_mps2[good], imu.gyro_radps[good])


class SensorFilter(Protocol):
    """Transforms what the sensors deliver before perception sees it (`TradeFollowEnv.set_sensor_filter`);
    `trade_gym.faults.SensorFaults` injects faults through it."""

    def filter_camera_pose(self, T_world_cam: Pose) -> Pose:
        """The pose the camera actually has this frame, given its mounted pose; rendering, ground truth and
        the pose source all use the result (e.g. a camera knocked sideways)."""
        ...

    def filter_sensors(self, sensors: SensorFrame, truth: GroundTruth) -> SensorFrame:
        """The frame perception receives (e.g. blank, dropped: rgb None, stale, corrupt IMU samples);
        `truth` is read-only context (where the target is)."""
        ...


class Perception(Protocol):
    """A perception mode. `truth` is consumed only by the oracle (and to initialise trackers)."""

    def reset(self, sensors: SensorFrame, init_box: FloatArray, truth: GroundTruth,
              rng: np.random.Generator) -> PerceptionOutput: ...

    def step(self, sensors: SensorFrame, truth: GroundTruth) -> PerceptionOutput: ...
