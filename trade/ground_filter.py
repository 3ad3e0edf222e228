"""Which ROI feature tracks lie on the ground plane: single-image depth, affine alignment, segmentation.

Every `every_n_frames` frames the depth model runs, its map is aligned to the ROI features' metric
depths (affine RANSAC in inverse depth), the ground is segmented around the box, and each live track
is labelled ground or not (in the mask, and a converged track's depth must agree with the scaled map);
labels persist with the track until the next model run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from trade.depth_alignment import AffineFitConfig, AlignedDepth, FitStatus, align_model_depth, sample_map
from trade.geometry import CameraIntrinsics, Pose
from trade.ground_segmentation import GroundMask, GroundSegmentationConfig, points_in_mask, segment_ground
from trade.roi_features import RoiFeatures
from trade.types import BBox

BoolArray = npt.NDArray[np.bool_]

# The shipped depth model's training views had mount pitches U(60, 90) deg from a level drone (its model card,
# assets/models/depth_small.md; ViewConfig of scripts/make_depth_dataset.py): the top of a 110 deg image stayed >= 5
# deg below the horizon. A camera pitched lower sees the horizon and sky, and the model's map is no depth map there:
# at 45 deg (desert training world 10000, 256 px) its inverse depth fell from the sky at the top of the image to the
# foreground at its bottom (correlation -0.99 with the true inverse depth around the target), and once aligned its
# ground tiles tilted ~51 deg, so the segmentation found no level seed and no track was ever labelled ground.
SHIPPED_MODEL_MIN_PITCH_DEG = 60.0


class DepthPredictor(Protocol):
    """Relative inverse depth of an RGB image: (H, W, 3) uint8 -> (H, W) float32."""

    def predict(self, rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]: ...


@dataclass(frozen=True)
class GroundFilterConfig:
    """Cadence of the depth model and the configs of alignment and segmentation."""

    every_n_frames: int = 3  # run the model on every n-th frame (10 Hz at a 30 Hz camera)
    # The mask needs a camera pitched at least this far below the horizon [deg] (the model's training views,
    # `trade.camera_pitch.ground_mask_usable`); below it the pipeline runs without the mask.
    min_camera_pitch_deg: float = SHIPPED_MODEL_MIN_PITCH_DEG
    min_promoted_features: int = 8  # converged ROI depths needed to align the model's map
    object_height_smoothing: float = 0.3  # weight of a new height estimate in the running mean
    depth_agreement_sigmas: float = 3.0  # a converged track is ground only if its depth agrees with the map
    alignment: AffineFitConfig = field(default_factory=AffineFitConfig)
    segmentation: GroundSegmentationConfig = field(default_factory=GroundSegmentationConfig)

    def __post_init__(self) -> None:
        if int(self.every_n_frames) != self.every_n_frames or self.every_n_frames < 1:
            raise ValueError(f"GroundFilterConfig.every_n_frames must be an integer >= 1, got {self.every_n_frames!r}")
        if int(self.min_promoted_features) != self.min_promoted_features or self.min_promoted_features < 2:
            raise ValueError("GroundFilterConfig.min_promoted_features must be an integer >= 2, "
                             f"got {self.min_promoted_features!r}")
        if not (np.isfinite(self.min_camera_pitch_deg) and 0.0 <= self.min_camera_pitch_deg <= 90.0):
            raise ValueError("GroundFilterConfig.min_camera_pitch_deg must be in [0, 90], "
                             f"got {self.min_camera_pitch_deg!r}")
        if not (np.isfinite(self.depth_agreement_sigmas) and self.depth_agreement_sigmas > 0.0):
            raise ValueError("GroundFilterConfig.depth_agreement_sigmas must be finite and > 0, "
                             f"got {self.depth_agreement_sigmas!r}")
        if not 0.0 < self.object_height_smoothing <= 1.0:
            raise ValueError("GroundFilterConfig.object_height_smoothing must be in (0, 1], "
                             f"got {self.object_height_smoothing!r}")


@dataclass(frozen=True, eq=False)
class GroundLabels:
    """ground: (N,) per ROI track, True on the ground; None before the first successful mask.
    mask: the latest ground mask (or None); ran_model: the model ran this frame."""

    ground: BoolArray | None
    object_height_m: float | None
    mask: GroundMask | None
    ran_model: bool
    model_ms: float
    segmentation_ms: float
    # The model's latest map was rejected (non-finite, negative or constant): every track counts as ground
    # (the plane fit then runs on all tracks, as without the mask) until a valid map gives a mask.
    model_rejected: bool = False


class GroundFilter:
    """Labels ROI tracks as ground using a single-image depth model (injected)."""

    def __init__(self, config: GroundFilterConfig, intrinsics: CameraIntrinsics, model: DepthPredictor,
                 rng: np.random.Generator) -> None:
        self.config = config
        self.intrinsics = intrinsics
        self.model = model
        self._rng = rng
        self.reset()

    def reset(self) -> None:
        self._frame = 0
        self._labels: dict[int, bool] = {}
        self._object_height_m: float | None = None
        self._mask: GroundMask | None = None
        self._model_rejected = False

    def update(self, rgb: npt.NDArray[np.uint8], roi: RoiFeatures, box: BBox, T_world_cam: Pose) -> GroundLabels:
        """Run the model when due (and enough ROI depths have converged), then label the tracks."""
        due = self._frame % self.config.every_n_frames == 0
        self._frame += 1
        model_ms = seg_ms = 0.0
        ran = False
        if due and int(roi.promoted.sum()) >= self.config.min_promoted_features:
            start = time.perf_counter()
            model_inv = self.model.predict(rgb)
            model_ms = (time.perf_counter() - start) * 1e3
            start = time.perf_counter()
            self._segment(model_inv, roi, box, T_world_cam)
            seg_ms = (time.perf_counter() - start) * 1e3
            ran = True
        return GroundLabels(self._ground_of(roi), self._object_height_m, self._mask, ran, model_ms, seg_ms,
                            self._model_rejected)

    def _segment(self, model_inv: npt.NDArray[np.float32], roi: RoiFeatures, box: BBox, T_world_cam: Pose) -> None:
        promoted = roi.promoted
        aligned = align_model_depth(model_inv, roi.pixels[promoted], roi.depth_m[promoted], self._rng,
                                    self.config.alignment)
        if aligned.fit.status is FitStatus.INVALID_MODEL_OUTPUT:
            self._model_rejected = True  # fall back to all tracks until a valid map
            return
        if not aligned.ok:
            return  # no consistent fit: keep the previous labels
        mask = segment_ground(aligned.depth_m, self.intrinsics, T_world_cam, box, roi.roi, self.config.segmentation)
        if mask.plane is None:
            return
        self._mask = mask
        self._model_rejected = False
        ground = points_in_mask(roi.pixels, mask.mask) & self._depth_agrees(roi, aligned)
        self._labels = {int(t): bool(g) for t, g in zip(roi.track_ids, ground)}
        seg = self.config.segmentation
        height = float(mask.object_height_m)
        if np.isfinite(height):
            # the measured height above the mask plane, kept within the segmentation's plausible range
            height = min(max(height, seg.min_object_height_m), seg.max_object_height_m)
            a = self.config.object_height_smoothing
            self._object_height_m = height if self._object_height_m is None else (1 - a) * self._object_height_m + a * height

    def _depth_agrees(self, roi: RoiFeatures, aligned: AlignedDepth) -> BoolArray:
        """(N,) True unless a converged track's depth contradicts the scaled map at its pixel:
        |z_track - z_map| >= k sqrt(sigma_track^2 + sigma_map^2), sigma_map = z_map^2 rms (first order of
        z = 1 / rho, rms: the alignment's inverse-depth residual). City runs had converged tracks at 1-4 m
        on a street 32 m below (most likely born on the oncoming car, then slid onto the street): the mask
        alone calls them ground and the plane fit chose them."""
        agrees = ~roi.promoted
        promoted = np.flatnonzero(roi.promoted)
        z_map = sample_map(aligned.depth_m, roi.pixels[promoted])
        sigma_map = z_map * z_map * aligned.fit.rms_inv_m
        gap = np.abs(roi.depth_m[promoted] - z_map)
        agrees[promoted] = gap < self.config.depth_agreement_sigmas * np.hypot(roi.sigma_m[promoted], sigma_map)
        return agrees

    @property
    def mask(self) -> GroundMask | None:
        """The latest ground mask (None before the first one)."""
        return self._mask

    @property
    def model_rejected(self) -> bool:
        """The model's latest map was rejected: every track counts as ground until a valid map."""
        return self._model_rejected

    def labels(self, roi: RoiFeatures) -> BoolArray | None:
        """(N,) the persisted labels of `roi`'s live tracks without running the model (frames without a
        box); None before the first mask."""
        return self._ground_of(roi)

    def _ground_of(self, roi: RoiFeatures) -> BoolArray | None:
        """Labels of the live tracks; tracks born since the last mask are not ground yet; all ground while
        the model's output is rejected."""
        if self._model_rejected:
            return np.ones(len(roi.track_ids), dtype=bool)
        if self._mask is None:
            return None
        return np.array([self._labels.get(int(t), False) for t in roi.track_ids], dtype=bool)
