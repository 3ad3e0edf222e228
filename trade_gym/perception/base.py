"""The contract every perception mode fulfils: one estimate of the target per camera frame, from the sensors only.

Estimates are in the world frame as the perception believes it (so with `pose_source="vio"`
they carry the pose drift); NaN marks what a mode could not estimate this frame. Perception never sees ground
truth through this contract (the oracle gets its own at construction); the env scores estimates
(`trade_gym.scoring`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from trade.geometry import Pose
from trade.planes import Plane
from trade.types import ImuBatch

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GroundEstimate:
    """What a perception mode believes the ground is, so the env can score it along any pixel's ray: `plane` in
    the world frame as perception believes it (seen from the frame's pose-source pose), or `depth_map_m` (H, W)
    camera-frame z [m] (depth-only mode), or, for the oracle, `true_depth_factor`: its noise model's ground is the
    true ground with every depth times this factor. None / NaN where the mode has none this frame."""

    plane: Plane | None = None
    depth_map_m: npt.NDArray[np.float32] | None = None
    true_depth_factor: float = float("nan")


@dataclass(frozen=True)
class PerceptionOutput:
    """bbox (4,) x, y, w, h [px]; world position (3,) [m] and velocity (3,) [m/s]; target depth [m] (camera-frame
    z of the target) and its 1-sigma; the estimated ground."""

    bbox: FloatArray
    position_world_m: FloatArray
    velocity_world_mps: FloatArray
    target_depth_m: float
    target_depth_sigma_m: float
    ground: GroundEstimate
    valid: bool  # the box is a fresh measurement this frame (not coasting)

    @classmethod
    def missing(cls) -> PerceptionOutput:
        nan3 = np.full(3, np.nan)
        return cls(np.full(4, np.nan), nan3, nan3.copy(), np.nan, np.nan, GroundEstimate(), False)


@dataclass(frozen=True)
class SensorFrame:
    """What the sensors deliver at one camera frame; `rgb` is None when nothing was rendered."""

    t_s: float
    rgb: npt.NDArray[np.uint8] | None
    T_world_cam: Pose  # from the pose source (exact or drifting)
    imu: ImuBatch
    # (3,) the drone's velocity from the pose source, in its (drifting) world frame [m/s]; None where unknown
    # (a recorded sequence without it)
    velocity_world_mps: FloatArray | None = None


def finite_imu(imu: ImuBatch) -> ImuBatch:
    """The samples of `imu` whose time, specific force and rate are all finite (a faulty IMU's NaN/inf
    samples are dropped at the sensor boundary); `imu` itself when every sample is finite."""
    good = (np.isfinite(imu.t_s) & np.all(np.isfinite(imu.accel_mps2), axis=1)
            & np.all(np.isfinite(imu.gyro_radps), axis=1))
    if good.all():
        return imu
    return ImuBatch(imu.t_s[good], imu.accel_mps2[good], imu.gyro_radps[good])


class Perception(Protocol):
    """A perception mode: sensors in, one estimate out per frame. `reset` starts an episode from the initial box
    (x, y, w, h) [px] (the paper's protocol: the ground-truth box, perturbed) and the env's generator."""

    def reset(self, sensors: SensorFrame, init_box: FloatArray, rng: np.random.Generator) -> PerceptionOutput: ...

    def step(self, sensors: SensorFrame) -> PerceptionOutput: ...
