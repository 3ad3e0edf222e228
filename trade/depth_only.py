"""Depth-only target localisation (the paper's Table 2 baseline): single-image depth, aligned, read at the box.

The model's relative inverse depth is aligned to the ROI features' inverse depths (2-point RANSAC or plain least
squares) and the target depth is read straight from the scaled map at the box; no plane, no raycast.

The map shows the target's visible top, so the reading is short of its centre's depth by about half its height
(left uncorrected, as in the paper's baseline).

Cadence: the model runs on every 3rd frame (10 Hz at 30 fps, as the ground mask), a third of its cost with no
systematic loss in depth error (docs/perception.md); in between, the last aligned map is read at the current box
(at most 2 frames stale).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from trade.depth_alignment import AffineFit, AffineFitConfig, align_model_depth
from trade.geometry import CameraIntrinsics, Pose
from trade.ground_filter import DepthPredictor
from trade.roi_features import RoiFeatures
from trade.types import BBox

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DepthOnlyConfig:
    """Model cadence, the box window the depth is read from, and the alignment's RANSAC settings."""

    every_n_frames: int = 3  # run the model on every n-th frame; the last aligned map is read in between
    min_promoted_features: int = 8  # converged ROI depths needed to align the model's map
    box_window_fraction: float = 0.5  # depth = median over the box's central fraction (of width and height)
    min_depth_sigma_m: float = 0.25  # floor of the reported 1-sigma depth [m]
    alignment: AffineFitConfig = field(default_factory=AffineFitConfig)

    def __post_init__(self) -> None:
        if int(self.every_n_frames) != self.every_n_frames or self.every_n_frames < 1:
            raise ValueError(f"DepthOnlyConfig.every_n_frames must be an integer >= 1, got {self.every_n_frames!r}")
        if int(self.min_promoted_features) != self.min_promoted_features or self.min_promoted_features < 2:
            raise ValueError("DepthOnlyConfig.min_promoted_features must be an integer >= 2, "
                             f"got {self.min_promoted_features!r}")
        if not 0.0 < self.box_window_fraction <= 1.0:
            raise ValueError(f"DepthOnlyConfig.box_window_fraction must be in (0, 1], got {self.box_window_fraction!r}")
        if not (math.isfinite(self.min_depth_sigma_m) and self.min_depth_sigma_m > 0.0):
            raise ValueError(f"DepthOnlyConfig.min_depth_sigma_m must be finite and > 0, got {self.min_depth_sigma_m!r}")


@dataclass(frozen=True, eq=False)
class DepthOnlyEstimate:
    """depth_map_m: the latest aligned map (H, W) camera z [m], NaN where invalid (None before the first fit);
    depth_m / sigma_m: the target's depth read at the box this frame [m] (NaN without a box or a map);
    position_world_m: (3,) the box centre's ray at depth_m, world [m]; fit: this frame's alignment (None if the
    model did not run)."""

    depth_map_m: npt.NDArray[np.float32] | None
    depth_m: float
    sigma_m: float
    position_world_m: FloatArray
    fit: AffineFit | None
    model_ms: float
    align_ms: float


def box_window_depth(depth_map_m: npt.ArrayLike, box: BBox, fraction: float) -> float:
    """Median of the finite values of depth_map_m (H, W) [m] over the box's central `fraction` of width and
    height (at least the pixel under the box centre); NaN when none is finite."""
    d = np.asarray(depth_map_m)
    h, w = d.shape
    cu, cv = box.center
    half_u, half_v = 0.5 * fraction * box.w_px, 0.5 * fraction * box.h_px
    # pixel centres at integers: columns round(cu - half_u) .. round(cu + half_u), clipped to the image
    c0, c1 = max(0, int(round(cu - half_u))), min(w, int(round(cu + half_u)) + 1)
    r0, r1 = max(0, int(round(cv - half_v))), min(h, int(round(cv + half_v)) + 1)
    window = d[r0:r1, c0:c1]
    finite = window[np.isfinite(window)]
    return float(np.median(finite)) if finite.size else float("nan")


class DepthOnlyLocaliser:
    """Aligns the injected depth model's map to the ROI depths each due frame and reads the target's depth."""

    def __init__(self, config: DepthOnlyConfig, intrinsics: CameraIntrinsics, model: DepthPredictor,
                 rng: np.random.Generator, ransac: bool = True) -> None:
        self.config = config
        self.intrinsics = intrinsics
        self.model = model
        self.ransac = ransac
        self._rng = rng
        self.reset()

    def reset(self) -> None:
        self._frame = 0
        self._depth_map: npt.NDArray[np.float32] | None = None
        self._sigma_inv_m = float("nan")  # RMS residual of the map's alignment [1/m]

    def update(self, rgb: npt.NDArray[np.uint8], roi: RoiFeatures, box: BBox | None,
               T_world_cam: Pose) -> DepthOnlyEstimate:
        """rgb (H, W, 3) uint8; the model runs when due and enough ROI depths have converged (whether or not
        the target was found, so the map stays current); the depth is read at `box` when given."""
        cfg = self.config
        due = self._frame % cfg.every_n_frames == 0
        self._frame += 1
        fit, model_ms, align_ms = None, 0.0, 0.0
        promoted = roi.promoted
        if due and int(promoted.sum()) < cfg.min_promoted_features:
            self._depth_map = None  # too few converged depths to scale this frame's map
        elif due:
            start = time.perf_counter()
            model_inv = self.model.predict(rgb)
            model_ms = (time.perf_counter() - start) * 1e3
            start = time.perf_counter()
            aligned = align_model_depth(model_inv, roi.pixels[promoted], roi.depth_m[promoted], self._rng,
                                        cfg.alignment, self.ransac)
            align_ms = (time.perf_counter() - start) * 1e3
            fit = aligned.fit
            # a failed fit leaves no map: reading a map scaled for other frames would be a guess
            self._depth_map = aligned.depth_m if aligned.ok else None
            self._sigma_inv_m = aligned.fit.rms_inv_m
        depth = sigma = float("nan")
        position = np.full(3, np.nan)
        if box is not None and self._depth_map is not None:
            depth = box_window_depth(self._depth_map, box, cfg.box_window_fraction)
            if np.isfinite(depth):
                # z = 1 / rho: sigma_z = z^2 sigma_rho (first order), sigma_rho = the fit's RMS residual
                sigma = max(cfg.min_depth_sigma_m, depth * depth * self._sigma_inv_m)
                position = self._backproject(box.center, depth, T_world_cam)
        return DepthOnlyEstimate(self._depth_map, depth, sigma, position, fit, model_ms, align_ms)

    def _backproject(self, pixel: FloatArray, depth_m: float, T_world_cam: Pose) -> FloatArray:
        """World point (3,) [m] at camera z = depth_m on the ray of pixel (u, v): p = z [(u - cx) / fx, (v - cy) / fy, 1]."""
        K = self.intrinsics
        p_cam = depth_m * np.array([(pixel[0] - K.cx_px) / K.fx_px, (pixel[1] - K.cy_px) / K.fy_px, 1.0])
        return T_world_cam.apply(p_cam.reshape(1, 3))[0]
