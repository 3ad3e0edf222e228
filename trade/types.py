"""Small frozen records passed between the stages of the perception stack.

Boxes are (x, y, w, h) in pixels with (x, y) the top-left corner; IMU in body frame, SI.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class BBox:
    """Axis-aligned image box: top-left (x_px, y_px), size (w_px, h_px)."""

    x_px: float
    y_px: float
    w_px: float
    h_px: float

    def __post_init__(self) -> None:
        vals = (self.x_px, self.y_px, self.w_px, self.h_px)
        if not all(np.isfinite(vals)) or self.w_px <= 0 or self.h_px <= 0:
            raise ValueError(f"BBox needs finite values and positive size, got {vals!r}")

    @classmethod
    def from_array(cls, xywh: npt.ArrayLike) -> BBox:
        x, y, w, h = (float(v) for v in np.asarray(xywh, dtype=np.float64).reshape(4))
        return cls(x, y, w, h)

    @classmethod
    def from_center(cls, cx_px: float, cy_px: float, w_px: float, h_px: float) -> BBox:
        return cls(cx_px - w_px / 2.0, cy_px - h_px / 2.0, w_px, h_px)

    @property
    def center(self) -> FloatArray:
        """(2,) centre [px]."""
        return np.array([self.x_px + self.w_px / 2.0, self.y_px + self.h_px / 2.0])

    def as_array(self) -> FloatArray:
        return np.array([self.x_px, self.y_px, self.w_px, self.h_px])


def iou(a: Sequence[float], b: Sequence[float]) -> float:
    """IoU of two (x, y, w, h) boxes; 0.0 when either is missing (NaN or inf) or empty.

    Scalar code without generators or builtin min/max calls: the env scores the estimate against the
    target and every decoy in view each step."""
    ax, ay, aw, ah = map(float, a)
    bx, by, bw, bh = map(float, b)
    if not math.isfinite(ax + ay + aw + ah + bx + by + bw + bh):  # any NaN or inf makes the sum non-finite
        return 0.0
    a_right, b_right, a_bottom, b_bottom = ax + aw, bx + bw, ay + ah, by + bh
    ix = (a_right if a_right < b_right else b_right) - (ax if ax > bx else bx)
    iy = (a_bottom if a_bottom < b_bottom else b_bottom) - (ay if ay > by else by)
    if ix <= 0.0 or iy <= 0.0:
        return 0.0
    inter = ix * iy
    union = aw * ah + bw * bh - inter
    return inter / union if union > 0 else 0.0


@dataclass(frozen=True, eq=False)
class PixelPrediction:
    """Where the trajectory model puts the target in the image: centre_px (2,), its first-order
    covariance_px2 (2, 2) [px^2], its camera-frame depth_m [m] and that depth's 1-sigma depth_sigma_m [m];
    all NaN when there is no prediction."""

    centre_px: FloatArray
    covariance_px2: FloatArray
    depth_m: float
    depth_sigma_m: float

    @classmethod
    def none(cls) -> PixelPrediction:
        return cls(np.full(2, np.nan), np.full((2, 2), np.nan), math.nan, math.nan)

    @property
    def valid(self) -> bool:
        return bool(np.all(np.isfinite(self.centre_px)) and np.all(np.isfinite(self.covariance_px2)))


@dataclass(frozen=True)
class ImuBatch:
    """IMU samples delivered with one camera frame.

    t_s: (N,) timestamps [s]; accel_mps2: (N, 3) specific force in body frame [m/s^2]
    (reads +9.81 on body z when hovering); gyro_radps: (N, 3) angular rate in body frame.
    """

    t_s: FloatArray
    accel_mps2: FloatArray
    gyro_radps: FloatArray

    @classmethod
    def empty(cls) -> ImuBatch:
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))

