"""Frame guards of the TRADE pipeline: the frames it does not track (it coasts on the trajectory model instead).

Owns `FrameGuardConfig`, `unusable_frame` (missing, stale, blank or frozen image) and `predicted_out_of_view`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics, Pose
from trade.validation import check_non_negative, is_int_at_least, require

FloatArray = npt.NDArray[np.float64]

# Why a frame was not tracked (`Estimate.coast_reason`).
MISSING, STALE, BLANK, FROZEN, OUT_OF_VIEW = "missing", "stale", "blank", "frozen", "out_of_view"
COAST_REASONS = (MISSING, STALE, BLANK, FROZEN, OUT_OF_VIEW)
UINT8_MAX = 255


@dataclass(frozen=True)
class FrameGuardConfig:
    """A frame is blank when its grey-level range (max - min over every pixel and channel) is at most
    `blank_max_range`; frozen when its pixels equal the last tracked frame's although the camera moved more than
    `frozen_min_motion_m` [m] or turned more than `frozen_min_turn_rad` [rad]. With trajectory guidance a frame is
    not tracked while the trajectory model puts the target more than `out_of_view_margin_fraction` of the image
    side outside the image, or behind the camera: no peak in it can be the target."""

    blank_max_range: int = 8
    frozen_min_motion_m: float = 1e-3
    frozen_min_turn_rad: float = 1e-3
    out_of_view_margin_fraction: float = 0.25

    def __post_init__(self) -> None:
        value = self.blank_max_range
        require(is_int_at_least(value, 0) and value < UINT8_MAX, "FrameGuardConfig.blank_max_range", value,
                f"an integer in [0, {UINT8_MAX})")
        for name in ("frozen_min_motion_m", "frozen_min_turn_rad", "out_of_view_margin_fraction"):
            check_non_negative(f"FrameGuardConfig.{name}", getattr(self, name))


@dataclass(frozen=True, eq=False)
class TrackedFrame:
    """The last frame the pipeline tracked: its time [s], image (H, W, 3) uint8 and camera pose."""

    t_s: float
    image_rgb: npt.NDArray[np.uint8]
    T_world_cam: Pose


def unusable_frame(image_rgb: npt.NDArray[np.uint8] | None, T_world_cam: Pose, t_s: float,
                   tracked: TrackedFrame, config: FrameGuardConfig) -> str | None:
    """Why the pipeline cannot track this frame after the last tracked frame `tracked`: MISSING (no image), STALE
    (time did not advance: a duplicate or an old frame), BLANK (grey-level range <= config.blank_max_range),
    FROZEN (the same pixels although the camera moved or turned); None when the frame is usable."""
    if image_rgb is None:
        return MISSING
    if t_s <= tracked.t_s:
        return STALE
    if int(image_rgb.max()) - int(image_rgb.min()) <= config.blank_max_range:
        return BLANK
    if image_rgb is tracked.image_rgb or np.array_equal(image_rgb, tracked.image_rgb):
        moved = np.linalg.norm(T_world_cam.t - tracked.T_world_cam.t) > config.frozen_min_motion_m
        # rotation angle between the two camera poses: cos(a) = (trace(R1^T R2) - 1) / 2
        cos_turn = (np.trace(tracked.T_world_cam.R.T @ T_world_cam.R) - 1.0) / 2.0
        if moved or cos_turn < np.cos(config.frozen_min_turn_rad):
            return FROZEN
    return None


def predicted_out_of_view(position_world_m: FloatArray, T_world_cam: Pose, intrinsics: CameraIntrinsics,
                          margin_fraction: float) -> bool:
    """Whether the point `position_world_m` (3,) [m] lies behind the camera or projects more than
    `margin_fraction` of the image side outside the image (pixel centres 0 .. W - 1, 0 .. H - 1)."""
    p_cam = T_world_cam.inverse().apply(position_world_m.reshape(1, 3))
    if p_cam[0, 2] <= 0.0:
        return True
    u, v = intrinsics.project(p_cam)[0]
    w, h = intrinsics.width_px, intrinsics.height_px
    mu, mv = margin_fraction * w, margin_fraction * h
    return not (-mu <= u <= w - 1 + mu and -mv <= v <= h - 1 + mv)
