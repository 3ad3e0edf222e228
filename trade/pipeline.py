"""The TRADE pipeline: trajectory-guided correlation tracking and robust 3D localisation per frame.

initialise(frame, box, pose) once, then step(frame, pose, imu) per frame; each call returns a
frozen `Estimate`. Every stage is a component with its own config; ablations are switches here.
With `single_image_depth` the depth-only mode (paper Table 2) replaces plane fit, fusion and raycast.
Frames the guards refuse (`trade.frame_guard`: missing, stale, blank, frozen, target predicted out of view)
are not tracked: the pipeline coasts on its trajectory model, on recorded data as in the env.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from trade.camera_pitch import NADIR_PITCH_DEG, check_pitch, ground_mask_usable, roi_config_for_pitch
from trade.depth_only import DepthOnlyConfig, DepthOnlyLocaliser
from trade.frame_guard import (
    MISSING, OUT_OF_VIEW, FrameGuardConfig, TrackedFrame, predicted_out_of_view, unusable_frame,
)
from trade.geometry import CameraIntrinsics, Pose, RotationWarp
from trade.ground_filter import DepthPredictor, GroundFilter, GroundFilterConfig
from trade.planes import MultiRansacConfig, Plane, multi_ransac
from trade.raycast import RaycastConfig, depth_uncertainty, raycast_plane
from trade.roi_features import RoiConfig, RoiFeatures, RoiFeatureTracker
from trade.temporal_fusion import TemporalFusionConfig, TemporalPlaneFusion
from trade.tracking.dcf import DcfTracker
from trade.tracking.guided import GuidedTracker
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.trajectory import TrajectoryConfig, TrajectoryModel, TrajectoryState
from trade.types import BBox, ImuBatch, PixelPrediction

FloatArray = npt.NDArray[np.float64]

# The paper's rule: planes whose normals are < 15 deg apart are one solution and the flattest
# wins, so a roof parallel to the ground competes with it (the ground mask must remove it).
PAPER_RANSAC = MultiRansacConfig(parallel_min_separation_m=math.inf, flatness_tolerance_deg=0.0)


def _gray(image_rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """(H, W) uint8 grey levels of an (H, W, 3) uint8 RGB image (cvtColor keeps the depth; its stubs do not say)."""
    return cast(npt.NDArray[np.uint8], cv2.cvtColor(image_rgb, cv2.COLOR_RGB2GRAY))


@dataclass(frozen=True)
class PipelineConfig:
    """Paper defaults; every ablation of the paper is a switch (trajectory guidance is the tracker's:
    `tracker.trajectory_guidance`)."""

    tracker: GuidedTrackerConfig = field(default_factory=GuidedTrackerConfig)
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    roi: RoiConfig = field(default_factory=RoiConfig)
    ransac: MultiRansacConfig = PAPER_RANSAC
    fusion: TemporalFusionConfig = field(default_factory=lambda: TemporalFusionConfig(ransac=PAPER_RANSAC))
    raycast: RaycastConfig = field(default_factory=RaycastConfig)
    ground_filter: GroundFilterConfig = field(default_factory=GroundFilterConfig)
    depth_only: DepthOnlyConfig = field(default_factory=DepthOnlyConfig)
    guard: FrameGuardConfig = field(default_factory=FrameGuardConfig)  # which frames are not tracked
    temporal_fusion: bool = True
    ground_mask: bool = False  # plane fit only on tracks the single-image-depth ground mask keeps
    # Depth-only mode of the paper's Table 2: the target depth read from the aligned single-image depth map
    # at the box (no plane fit, fusion or raycast; temporal_fusion is unused, ground_mask must be off).
    single_image_depth: bool = False
    depth_only_ransac: bool = True  # depth-only alignment by 2-point RANSAC; False: plain least squares
    object_height_m: float = 1.5  # prior object height; the plane is lifted by half of it
    # Refuse a plane fix at which the box's longer side spans less than object_height_m: a ground vehicle is at
    # least as long as it is tall. A roof a few metres under the camera, taken for the ground, fails it.
    size_gate: bool = True
    # A plane the size gate refuses is not the ground the target stands on: forget it (and the fused points that
    # made it), so the next frames' points refit the ground instead of being gated out as off the roof's plane.
    size_gate_drops_plane: bool = True
    # Lift by the ground mask's object height estimate instead of the prior; off, as it raised the desert's
    # target-depth error (docs/perception.md).
    object_height_from_mask: bool = False
    min_plane_points: int = 10  # promoted ROI points a frame needs for its own plane fit
    # With ground_mask on, the points left have passed the mask and the depth-agreement test, so fewer make a
    # plane: this replaces min_plane_points and fusion.min_points (at 10 a city frame at 32 m rarely has a plane).
    min_masked_plane_points: int = 6
    trajectory_preview_s: float = 1.0  # horizon of the predicted trajectory kept for drawing
    trajectory_preview_points: int = 10
    # The camera's mount pitch below the body's forward axis [deg] (90: nadir, the paper's offline setting; 45: its
    # real flight). The settings it changes follow from it by the rules of `trade.camera_pitch`: the ROI promotion
    # threshold is a height error, and below ground_filter.min_camera_pitch_deg the ground mask is not used.
    camera_pitch_deg: float = NADIR_PITCH_DEG

    def __post_init__(self) -> None:
        check_pitch("PipelineConfig.camera_pitch_deg", self.camera_pitch_deg)
        if self.single_image_depth and self.ground_mask:
            raise ValueError("single_image_depth (depth-only, no plane) and ground_mask (selects plane points) "
                             f"exclude each other; got single_image_depth={self.single_image_depth!r}, "
                             f"ground_mask={self.ground_mask!r}")
        if not (math.isfinite(self.object_height_m) and self.object_height_m >= 0):
            raise ValueError(f"PipelineConfig.object_height_m must be finite and >= 0, got {self.object_height_m!r}")
        for name in ("min_plane_points", "min_masked_plane_points"):
            value = getattr(self, name)
            if int(value) != value or not 3 <= value <= self.fusion.buffer_size:
                raise ValueError(f"PipelineConfig.{name} must be an integer in [3, fusion.buffer_size], got {value!r}")


@dataclass(frozen=True)
class StageTimings:
    """Wall time of each stage in one step [ms]."""

    tracker_ms: float = 0.0
    roi_ms: float = 0.0
    plane_ms: float = 0.0
    fusion_ms: float = 0.0
    raycast_ms: float = 0.0
    trajectory_ms: float = 0.0
    ground_mask_ms: float = 0.0  # single-image depth, alignment and segmentation (when they ran)
    depth_only_ms: float = 0.0  # depth-only mode: single-image depth and alignment (when they ran)

    @property
    def total_ms(self) -> float:
        return (self.tracker_ms + self.roi_ms + self.plane_ms + self.fusion_ms + self.raycast_ms
                + self.trajectory_ms + self.ground_mask_ms + self.depth_only_ms)


@dataclass(frozen=True, eq=False)
class Estimate:
    """One frame's output. box: tracked box (None when lost); position/velocity: world [m], [m/s]
    from the trajectory model (NaN before it starts); depth: camera-frame z of the target [m]; plane and
    depth_map_m: the ground the stack holds (on a coasting frame, the last tracked frame's)."""

    t_s: float
    box: BBox | None
    tracked: bool  # a fresh box this frame (the peak passed the score test)
    peak_score: float
    ambiguous: bool
    predicted_px: FloatArray  # (2,) trajectory prediction projected into this frame; NaN if none
    position_world_m: FloatArray
    velocity_world_mps: FloatArray
    depth_m: float
    depth_sigma_m: float
    plane: Plane | None
    n_plane_points: int
    roi: RoiFeatures | None
    trajectory_preview_world_m: FloatArray  # (K, 3) predicted positions ahead
    timings: StageTimings
    depth_map_m: npt.NDArray[np.float32] | None = None  # depth-only mode: aligned map (H, W) camera z [m]
    coast_reason: str | None = None  # why the frame was not tracked (`trade.frame_guard.COAST_REASONS`); None: it was


@dataclass(frozen=True, eq=False)
class _Fix:
    """One frame's 3D fix of the target before the trajectory update (NaN where none)."""

    position_world_m: FloatArray  # (3,) world [m]
    depth_m: float
    sigma_m: float
    plane: Plane | None
    n_plane_points: int
    depth_map_m: npt.NDArray[np.float32] | None
    timings: StageTimings


class TradePipeline:
    """Tracking with trajectory estimates plus robust 3D localisation (paper sections 3-4)."""

    def __init__(self, config: PipelineConfig, intrinsics: CameraIntrinsics, rng: np.random.Generator,
                 depth_model: DepthPredictor | None = None) -> None:
        for switch in ("ground_mask", "single_image_depth"):
            if getattr(config, switch) and depth_model is None:
                raise ValueError(f"{switch}=True needs a single-image depth model (depth_model=None given)")
        self.config = config
        self.intrinsics = intrinsics
        self._rng = rng
        self.tracking = GuidedTracker(config.tracker)
        self.trajectory = TrajectoryModel(config.trajectory)
        self.roi = RoiFeatureTracker(roi_config_for_pitch(config.roi, config.camera_pitch_deg), intrinsics)
        # the mask only where the depth model knows the view (`ground_mask_usable`); else the plane takes all tracks
        self.masked = config.ground_mask and ground_mask_usable(config.camera_pitch_deg,
                                                                config.ground_filter.min_camera_pitch_deg)
        self._min_plane_points = config.min_masked_plane_points if self.masked else config.min_plane_points
        fusion = replace(config.fusion, min_points=self._min_plane_points) if self.masked else config.fusion
        self.fusion = TemporalPlaneFusion(fusion, rng)
        self.ground = (GroundFilter(config.ground_filter, intrinsics, depth_model, rng)
                       if self.masked and depth_model is not None else None)
        self.depth_only = (DepthOnlyLocaliser(config.depth_only, intrinsics, depth_model, rng,
                                              config.depth_only_ransac)
                           if config.single_image_depth and depth_model is not None else None)
        self._object_height_m = config.object_height_m
        self._tracked: TrackedFrame | None = None  # the last tracked frame (None before initialise)
        self._last: Estimate | None = None  # its estimate

    @property
    def tracker(self) -> DcfTracker:
        """The correlation filter (its committed box)."""
        return self.tracking.dcf

    @property
    def ground_mask(self) -> npt.NDArray[np.bool_] | None:
        """(H, W) the latest ground mask, True on the ground (None without the mask or before its first run)."""
        mask = self.ground.mask if self.ground is not None else None
        return None if mask is None else mask.mask

    def initialise(self, image_rgb: npt.NDArray[np.uint8], box: BBox, T_world_cam: Pose, t_s: float) -> Estimate:
        """Start tracking `box` (x, y, w, h) [px] in `image_rgb` (H, W, 3) uint8 at time t_s."""
        self._check_image(image_rgb)
        box = self.tracking.init(image_rgb, box)
        self.trajectory = TrajectoryModel(self.config.trajectory)
        self.roi.reset()
        self.fusion.reset()
        if self.ground is not None:
            self.ground.reset()
        if self.depth_only is not None:
            self.depth_only.reset()
        self._object_height_m = self.config.object_height_m
        start = time.perf_counter()
        roi = self.roi.step(_gray(image_rgb), box, T_world_cam)
        roi_ms = (time.perf_counter() - start) * 1e3
        est = self._localise(image_rgb, t_s, box, True, 1.0, False, np.full(2, np.nan), roi, T_world_cam,
                             StageTimings(roi_ms=roi_ms))
        return self._remember(est, image_rgb, T_world_cam)

    def step(self, image_rgb: npt.NDArray[np.uint8] | None, T_world_cam: Pose, t_s: float,
             imu: ImuBatch | None = None) -> Estimate:
        """Track and localise in the next frame (`image_rgb` None: no image arrived). A frame the guards refuse
        (`trade.frame_guard`) is not tracked: the estimate coasts (`coast_reason` says why) and the tracker, ROI
        tracks and plane fit are left as they were. `T_world_cam` comes from the pose estimator (VIO); `imu` is
        accepted for pose estimators that fuse it and is not used by the stack itself. ValueError for an image
        that is not (H, W, 3) uint8 or a non-finite time."""
        previous, last = self._tracked, self._last
        if previous is None or last is None:
            raise RuntimeError("TradePipeline.step() before initialise()")
        if image_rgb is not None:
            self._check_image(image_rgb)
        if not math.isfinite(t_s):
            raise ValueError(f"frame time must be finite, got t_s={t_s!r}")
        if image_rgb is None:  # the guards' first reason (`unusable_frame`)
            return self._coast(t_s, T_world_cam, MISSING, last)
        reason = self._coast_reason(image_rgb, T_world_cam, t_s, previous)
        if reason is not None:
            return self._coast(t_s, T_world_cam, reason, last)
        start = time.perf_counter()
        prediction = self._predict_pixel(t_s, T_world_cam)
        predicted_px = prediction.centre_px
        rotation = RotationWarp.between(self.intrinsics, previous.T_world_cam, T_world_cam)
        frame = self.tracking.step(image_rgb, prediction, rotation)
        box, choice, tracked = frame.box, frame.choice, frame.tracked
        tracker_ms = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        roi = self.roi.step(_gray(image_rgb), box, T_world_cam)
        roi_ms = (time.perf_counter() - start) * 1e3
        est = self._localise(image_rgb, t_s, box if tracked else None, tracked, choice.score, choice.ambiguous,
                             predicted_px, roi, T_world_cam, StageTimings(tracker_ms=tracker_ms, roi_ms=roi_ms))
        return self._remember(est, image_rgb, T_world_cam)

    # ------------------------------------------------------------------ guards
    def _remember(self, est: Estimate, image_rgb: npt.NDArray[np.uint8], T_world_cam: Pose) -> Estimate:
        """Keep the tracked frame (the guards compare the next frames with it) and its estimate."""
        self._tracked = TrackedFrame(est.t_s, image_rgb, T_world_cam)
        self._last = est
        return est

    def _predict_to(self, t_s: float) -> TrajectoryState:
        """The trajectory model's state advanced to t_s [s]; the current state when t_s is not later."""
        state = self.trajectory.state
        return self.trajectory.predict(t_s) if t_s > state.t_s else state

    def _coast_reason(self, image_rgb: npt.NDArray[np.uint8], T_world_cam: Pose, t_s: float,
                      previous: TrackedFrame) -> str | None:
        """Why this frame is not tracked after the `previous` tracked one (a `trade.frame_guard` reason), None when
        it is tracked. With trajectory guidance a usable frame is still refused while the model puts the target out
        of view."""
        reason = unusable_frame(image_rgb, T_world_cam, t_s, previous, self.config.guard)
        if reason is None and self.config.tracker.trajectory_guidance and self.trajectory.initialized:
            position = self._predict_to(t_s).position_m
            if predicted_out_of_view(position, T_world_cam, self.intrinsics,
                                     self.config.guard.out_of_view_margin_fraction):
                return OUT_OF_VIEW
        return reason

    def _coast(self, t_s: float, T_world_cam: Pose, reason: str, last: Estimate) -> Estimate:
        """A frame not tracked: the trajectory model predicts the target to t_s (NaN before its first fix), the
        depth is that position's camera-frame z, no box; the ground is the `last` tracked frame's estimate's."""
        position, velocity = np.full(3, np.nan), np.full(3, np.nan)
        depth = float("nan")
        if self.trajectory.initialized:
            state = self._predict_to(t_s)
            position, velocity = state.position_m, state.velocity_mps
            depth = float(T_world_cam.inverse().apply(position.reshape(1, 3))[0, 2])
        return Estimate(t_s=t_s, box=None, tracked=False, peak_score=float("nan"), ambiguous=False,
                        predicted_px=np.full(2, np.nan), position_world_m=position, velocity_world_mps=velocity,
                        depth_m=depth, depth_sigma_m=float("nan"), plane=last.plane,
                        n_plane_points=last.n_plane_points, roi=None, trajectory_preview_world_m=np.zeros((0, 3)),
                        timings=StageTimings(), depth_map_m=last.depth_map_m, coast_reason=reason)

    # ------------------------------------------------------------------ stages
    def _predict_pixel(self, t_s: float, T_world_cam: Pose) -> PixelPrediction:
        """Advance the trajectory model to t_s and project its position and position covariance."""
        if not self.trajectory.initialized:
            return PixelPrediction.none()
        state = self.trajectory.predict(t_s)
        T_cam_world = T_world_cam.inverse()
        position_cam_m = T_cam_world.apply(state.position_m)[0]
        covariance_cam_m2 = T_cam_world.R @ state.covariance[:3, :3] @ T_cam_world.R.T
        return PixelPrediction(self.intrinsics.project(position_cam_m)[0],
                               self.intrinsics.project_covariance(position_cam_m, covariance_cam_m2),
                               float(position_cam_m[2]), math.sqrt(covariance_cam_m2[2, 2]))

    def _ground_points(self, image_rgb: npt.NDArray[np.uint8], box: BBox | None, roi: RoiFeatures,
                       T_world_cam: Pose) -> tuple[FloatArray, float]:
        """Promoted ROI points for the plane fit (only those on the ground mask when it is on) and
        the ground filter's time [ms]."""
        keep = roi.promoted.copy()
        ground_ms = 0.0
        if self.ground is not None:
            if box is not None:
                labels = self.ground.update(image_rgb, roi, box, T_world_cam)
                ground_ms = labels.model_ms + labels.segmentation_ms
                ground = labels.ground
                if labels.object_height_m is not None and self.config.object_height_from_mask:
                    self._object_height_m = labels.object_height_m
            else:  # target lost this frame: no segmentation, the tracks keep their last labels
                ground = self.ground.labels(roi)
            # only tracks the mask labelled ground; none before the first mask (roof points would win and
            # temporal fusion would then gate the true ground out)
            keep &= ground if ground is not None else False
        points = roi.points_world[keep]
        return points[np.all(np.isfinite(points), axis=1)], ground_ms

    def _locate_on_plane(self, image_rgb: npt.NDArray[np.uint8], box: BBox | None, roi: RoiFeatures,
                         T_world_cam: Pose, timings: StageTimings) -> _Fix:
        """Plane fit (frame, then fused), raycast of the box centre onto the lifted plane."""
        cfg = self.config
        points, ground_ms = self._ground_points(image_rgb, box, roi, T_world_cam)
        start = time.perf_counter()
        query_xy = T_world_cam.t[:2]
        frame_fit = multi_ransac(points, cfg.ransac, self._rng, query_xy) if len(points) >= self._min_plane_points \
            else None
        plane_ms = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        plane, solutions = (frame_fit.selected, frame_fit.solutions) if frame_fit is not None else (None, ())
        if cfg.temporal_fusion:
            inliers = points[frame_fit.inlier_mask] if frame_fit is not None else np.zeros((0, 3))
            fused = self.fusion.update(inliers, query_xy)
            if fused.plane is not None:
                plane, solutions = fused.plane, fused.solutions
        fusion_ms = (time.perf_counter() - start) * 1e3
        start = time.perf_counter()
        position = np.full(3, np.nan)
        depth = sigma = float("nan")
        if box is not None and plane is not None:
            height = self._object_height_m
            hit = raycast_plane(self.intrinsics, T_world_cam, box.center, plane, height, cfg.raycast)
            if hit.valid and self._plausible_size(box, hit.depth_m, height):
                spread = depth_uncertainty(self.intrinsics, T_world_cam, box.center, solutions or (plane,),
                                           height, cfg.raycast)
                position, depth = hit.point_world, hit.depth_m
                sigma = spread.sigma_m if spread.valid else cfg.raycast.min_depth_sigma_m
            elif hit.valid and cfg.size_gate_drops_plane:
                self.fusion.reset()
                plane, solutions = None, ()
        raycast_ms = (time.perf_counter() - start) * 1e3
        timings = replace(timings, plane_ms=plane_ms, fusion_ms=fusion_ms, raycast_ms=raycast_ms,
                          ground_mask_ms=ground_ms)
        return _Fix(position, depth, sigma, plane, int(len(points)), None, timings)

    def _plausible_size(self, box: BBox, depth_m: float, object_height_m: float) -> bool:
        """Whether the box's longer side spans at least the object's height at `depth_m` (a ground vehicle is at
        least as long as it is tall), when `PipelineConfig.size_gate` is on."""
        if not self.config.size_gate:
            return True
        K = self.intrinsics
        return max(box.w_px / K.fx_px, box.h_px / K.fy_px) * depth_m >= object_height_m

    def _locate_depth_only(self, depth_only: DepthOnlyLocaliser, image_rgb: npt.NDArray[np.uint8], box: BBox | None,
                           roi: RoiFeatures, T_world_cam: Pose, timings: StageTimings) -> _Fix:
        """Depth-only mode: the target's depth read from the aligned single-image depth map at the box."""
        est = depth_only.update(image_rgb, roi, box, T_world_cam)
        timings = replace(timings, depth_only_ms=est.model_ms + est.align_ms)
        return _Fix(est.position_world_m, est.depth_m, est.sigma_m, None, 0, est.depth_map_m, timings)

    def _localise(self, image_rgb: npt.NDArray[np.uint8], t_s: float, box: BBox | None, tracked: bool,
                  score: float, ambiguous: bool, predicted_px: FloatArray, roi: RoiFeatures, T_world_cam: Pose,
                  timings: StageTimings) -> Estimate:
        cfg = self.config
        if self.depth_only is not None:
            fix = self._locate_depth_only(self.depth_only, image_rgb, box, roi, T_world_cam, timings)
        else:
            fix = self._locate_on_plane(image_rgb, box, roi, T_world_cam, timings)
        depth = fix.depth_m
        start = time.perf_counter()
        state = self._update_trajectory(t_s, fix.position_world_m, fix.sigma_m)
        preview = (self.trajectory.predict_ahead(cfg.trajectory_preview_s, cfg.trajectory_preview_points)
                   if self.trajectory.initialized else np.zeros((0, 3)))
        trajectory_ms = (time.perf_counter() - start) * 1e3
        if state is not None and not np.isfinite(depth):
            # Coasting: report the depth of the trajectory model's position.
            depth = float(T_world_cam.inverse().apply(state[0].reshape(1, 3))[0, 2])
        return Estimate(
            t_s=t_s,
            box=box,
            tracked=tracked,
            peak_score=float(score),
            ambiguous=bool(ambiguous),
            predicted_px=predicted_px,
            position_world_m=np.full(3, np.nan) if state is None else state[0],
            velocity_world_mps=np.full(3, np.nan) if state is None else state[1],
            depth_m=depth,
            depth_sigma_m=fix.sigma_m,
            plane=fix.plane,
            n_plane_points=fix.n_plane_points,
            roi=roi,
            trajectory_preview_world_m=preview,
            timings=replace(fix.timings, trajectory_ms=trajectory_ms),
            depth_map_m=fix.depth_map_m,
        )

    def _update_trajectory(self, t_s: float, position: FloatArray, sigma_m: float) -> tuple[FloatArray, FloatArray] | None:
        """Kalman update from the raycast 3D position (residuals only); None before the first fix."""
        if not self.trajectory.initialized:
            if not np.all(np.isfinite(position)):
                return None
            self.trajectory.reset(position, t_s)
        elif np.all(np.isfinite(position)):
            # predict() already advanced the model to t_s in _predict_pixel (or initialise).
            self.trajectory.update(position, sigma_m)
        state = self.trajectory.state
        return state.position_m.copy(), state.velocity_mps.copy()

    def _check_image(self, image_rgb: npt.NDArray[np.uint8]) -> None:
        K = self.intrinsics
        expected = (K.height_px, K.width_px, 3)
        if image_rgb.shape != expected or image_rgb.dtype != np.uint8:
            raise ValueError(f"image must be uint8 of shape {expected}, got {image_rgb.dtype} {image_rgb.shape}")
