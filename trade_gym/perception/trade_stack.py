"""The TRADE stack (`perception="trade"`) and its baseline (`"dcf"`) as env perception modes.

Runs `trade.TradePipeline` on the rendered frames with the pose source's camera pose; the
ground-truth box is used only to initialise the tracker at reset (as the paper's protocol does).
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics
from trade.pipeline import Estimate, PipelineConfig, TradePipeline
from trade.depth_alignment import sample_map
from trade.raycast import raycast_plane
from trade.single_image_depth import SingleImageDepth
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.trajectory import TrajectoryModel, TrajectoryState
from trade.types import BBox
from trade_gym.config import EnvConfig
from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import FloatArray, PerceptionOutput, SensorFrame, finite_imu

TRAJECTORY_COLOUR_RGB = (255, 0, 255)  # magenta, as in the paper's figures
INLIER_COLOUR_RGB = (255, 255, 0)
FEATURE_DEPTH_RANGE_M = (5.0, 60.0)  # colour map range for ROI feature depths
POINT_RADIUS_PX = 1
INLIER_RADIUS_PX = 3
PLANE_INLIER_DRAW_M = 0.5  # the MSAC inlier threshold
# Frames the stack does not track (it coasts on the trajectory model instead, reporting no fresh box):
BLANK_MAX_RANGE = 8  # grey-level range (max - min, every pixel channel) at or below which a frame is blank
FROZEN_MIN_MOTION_M = 1e-3  # identical pixels although the camera moved this far [m] (or turned): frozen
FROZEN_MIN_TURN_RAD = 1e-3
# With trajectory guidance, a frame is not tracked while the trajectory model puts the target this far (as a
# fraction of the image side) outside the image, or behind the camera: no peak in it can be the target.
OUT_OF_VIEW_MARGIN_FRACTION = 0.25
# The stack's random generator is its own, seeded at reset by one draw in [0, STACK_SEED_HIGH) from the env's
# generator: its draws (RANSAC samples) never interleave with the IMU's and the pose source's, so a replay of the
# recorded sensors with the recorded seed gives the closed loop's estimates exactly.
STACK_SEED_HIGH = 2**63
# The env switches that make up the stack's settings (`pipeline_config`); `perception` picks trade or dcf.
STACK_SWITCHES = ("temporal_fusion", "ground_mask", "single_image_depth", "depth_only_ransac",
                  "trajectory_guidance", "snap_init_box")


def pipeline_config(config: EnvConfig) -> PipelineConfig:
    """The stack's configuration for an env configuration (its ablation switches)."""
    return PipelineConfig(
        tracker=GuidedTrackerConfig(trajectory_guidance=config.trajectory_guidance and config.perception == "trade",
                                    snap_init_box=config.snap_init_box),
        temporal_fusion=config.temporal_fusion,
        ground_mask=config.ground_mask,
        single_image_depth=config.single_image_depth,
        depth_only_ransac=config.depth_only_ransac,
    )


def unusable_frame(sensors: SensorFrame, tracked: SensorFrame) -> str | None:
    """Why the stack cannot track `sensors` after the last tracked frame `tracked`: "missing" (no image),
    "stale" (time did not advance: a duplicate), "blank" (grey-level range <= BLANK_MAX_RANGE), "frozen"
    (the same pixels although the camera moved); None when the frame is usable."""
    rgb = sensors.rgb
    if rgb is None:
        return "missing"
    if sensors.t_s <= tracked.t_s:
        return "stale"
    if int(rgb.max()) - int(rgb.min()) <= BLANK_MAX_RANGE:
        return "blank"
    if rgb is tracked.rgb or np.array_equal(rgb, tracked.rgb):
        moved = np.linalg.norm(sensors.T_world_cam.t - tracked.T_world_cam.t) > FROZEN_MIN_MOTION_M
        # rotation angle between the two camera poses: cos(a) = (trace(R1^T R2) - 1) / 2
        cos_turn = (np.trace(tracked.T_world_cam.R.T @ sensors.T_world_cam.R) - 1.0) / 2.0
        if moved or cos_turn < np.cos(FROZEN_MIN_TURN_RAD):
            return "frozen"
    return None


class TradePerception:
    """Adapter from the env's sensors to `TradePipeline` and back to `PerceptionOutput`."""

    def __init__(self, config: EnvConfig, intrinsics: CameraIntrinsics) -> None:
        self.pipeline_config = pipeline_config(config)
        self.intrinsics = intrinsics
        # The shipped single-image depth model, loaded (and its SHA-256 checked) once per env.
        needs_model = self.pipeline_config.ground_mask or self.pipeline_config.single_image_depth
        self.depth_model = SingleImageDepth() if needs_model else None
        self.pipeline: TradePipeline | None = None
        self.last: Estimate | None = None
        self._T_world_cam = None
        self._tracked_frame: SensorFrame | None = None  # the last frame the pipeline tracked
        self.rng_seed: int | None = None  # the seed of the stack's own generator this episode

    def reset(self, sensors: SensorFrame, init_box: FloatArray, truth: GroundTruth,
              rng: np.random.Generator) -> PerceptionOutput:
        """Start an episode; the stack's generator is seeded by one draw from `rng` (the env's)."""
        return self.reset_seeded(sensors, init_box, truth, int(rng.integers(STACK_SEED_HIGH)))

    def reset_seeded(self, sensors: SensorFrame, init_box: FloatArray, truth: GroundTruth,
                     rng_seed: int) -> PerceptionOutput:
        """Start an episode with the stack's generator seeded by `rng_seed` (a replay passes the recorded one)."""
        if sensors.rgb is None:
            raise RuntimeError("the trade perception needs rendered frames")
        if not np.all(np.isfinite(init_box)):
            raise RuntimeError("the target is not in view at reset; cannot initialise the tracker")
        self.rng_seed = int(rng_seed)
        self.pipeline = TradePipeline(self.pipeline_config, self.intrinsics, np.random.default_rng(self.rng_seed),
                                      self.depth_model)
        self.last = self.pipeline.initialise(sensors.rgb, BBox.from_array(init_box), sensors.T_world_cam,
                                             sensors.t_s)
        self._T_world_cam = sensors.T_world_cam
        self._tracked_frame = sensors
        return self._output(self.last, truth, sensors)

    def step(self, sensors: SensorFrame, truth: GroundTruth) -> PerceptionOutput:
        if unusable_frame(sensors, self._tracked_frame) is not None or self._predicted_out_of_view(sensors):
            return self._coast(sensors, truth)
        self.last = self.pipeline.step(sensors.rgb, sensors.T_world_cam, sensors.t_s, finite_imu(sensors.imu))
        self._T_world_cam = sensors.T_world_cam
        self._tracked_frame = sensors
        return self._output(self.last, truth, sensors)

    def _predicted_out_of_view(self, sensors: SensorFrame) -> bool:
        """Trajectory guidance on and the model's target position at this frame's time projects more than
        OUT_OF_VIEW_MARGIN_FRACTION of the image outside it, or lies behind the camera."""
        trajectory = self.pipeline.trajectory
        if not (self.pipeline_config.tracker.trajectory_guidance and trajectory.initialized):
            return False
        position = _predict_to(trajectory, sensors.t_s).position_m
        p_cam = sensors.T_world_cam.inverse().apply(position.reshape(1, 3))
        if p_cam[0, 2] <= 0.0:
            return True
        u, v = self.intrinsics.project(p_cam)[0]
        w, h = self.intrinsics.width_px, self.intrinsics.height_px
        mu, mv = OUT_OF_VIEW_MARGIN_FRACTION * w, OUT_OF_VIEW_MARGIN_FRACTION * h
        return not (-mu <= u <= w - 1 + mu and -mv <= v <= h - 1 + mv)

    def _coast(self, sensors: SensorFrame, truth: GroundTruth) -> PerceptionOutput:
        """No usable image: the trajectory model predicts the target to this frame's time; no box."""
        position = velocity = np.full(3, np.nan)
        depth = float("nan")
        trajectory = self.pipeline.trajectory
        if trajectory.initialized:
            state = _predict_to(trajectory, sensors.t_s)
            position, velocity = state.position_m, state.velocity_mps
            # the predicted position's camera-frame z
            depth = float(sensors.T_world_cam.inverse().apply(position.reshape(1, 3))[0, 2])
        return PerceptionOutput(np.full(4, np.nan), position, velocity, depth, float("nan"),
                                self._ground_depth(self.last, truth, sensors), valid=False)

    def _output(self, est: Estimate, truth: GroundTruth, sensors: SensorFrame) -> PerceptionOutput:
        bbox = est.box.as_array() if est.box is not None else np.full(4, np.nan)
        return PerceptionOutput(
            bbox=bbox,
            position_world_m=est.position_world_m,
            velocity_world_mps=est.velocity_world_mps,
            target_depth_m=est.depth_m,
            target_depth_sigma_m=est.depth_sigma_m,
            ground_depth_m=self._ground_depth(est, truth, sensors),
            valid=est.tracked and est.box is not None,
        )

    def _ground_depth(self, est: Estimate, truth: GroundTruth, sensors: SensorFrame) -> float:
        """Depth of the estimated ground plane along the ground-truth box centre's ray (the paper's
        Table 1 quantity: plane quality independent of tracking errors)."""
        return self.ground_depth_at(est, sensors, truth.target_bbox)

    def ground_depth_at(self, est: Estimate, sensors: SensorFrame, box: FloatArray) -> float:
        """Depth [m] of `est`'s ground plane along the ray of the centre of `box` (x, y, w, h [px]) from the pose
        of `sensors`; NaN without a box or a plane. Depth-only mode: the aligned depth map read at that pixel
        (which shows the target's top, so it is short by about its height)."""
        if not np.all(np.isfinite(box)):
            return float("nan")
        centre = box[:2] + box[2:] / 2.0
        if est.depth_map_m is not None:
            return float(sample_map(est.depth_map_m, centre.reshape(1, 2))[0])
        if est.plane is None:
            return float("nan")
        hit = raycast_plane(self.intrinsics, sensors.T_world_cam, centre, est.plane, 0.0)
        return hit.depth_m if hit.valid else float("nan")

    @property
    def overlay(self) -> TradeOverlay | None:
        if self.last is None or self._T_world_cam is None:
            return None
        return TradeOverlay(self.last, self.intrinsics, self._T_world_cam)


def _predict_to(trajectory: TrajectoryModel, t_s: float) -> TrajectoryState:
    """The model's state advanced to t_s [s]; the current state when t_s is not later (a stale frame)."""
    state = trajectory.state
    return trajectory.predict(t_s) if t_s > state.t_s else state


class TradeOverlay:
    """Draws what the paper's figures show: predicted trajectory (magenta), ROI features coloured
    by depth, plane inliers circled."""

    def __init__(self, est: Estimate, intrinsics: CameraIntrinsics, T_world_cam) -> None:
        self.est, self.K, self.T_world_cam = est, intrinsics, T_world_cam

    def draw(self, image: npt.NDArray[np.uint8]) -> None:
        est = self.est
        if est.roi is not None and len(est.roi.pixels):
            self._draw_features(image)
        if len(est.trajectory_preview_world_m):
            uv = self.K.project(self.T_world_cam.inverse().apply(est.trajectory_preview_world_m))
            uv = uv[np.all(np.isfinite(uv), axis=1)]
            if len(uv) >= 2:
                cv2.polylines(image, [np.round(uv).astype(np.int32)], False, TRAJECTORY_COLOUR_RGB, 1)

    def _draw_features(self, image: npt.NDArray[np.uint8]) -> None:
        roi, plane = self.est.roi, self.est.plane
        lo, hi = FEATURE_DEPTH_RANGE_M
        depth = np.nan_to_num(roi.depth_m, nan=hi)
        level = np.clip((depth - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
        colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)[:, ::-1]
        inlier = np.zeros(len(roi.pixels), bool)
        if plane is not None:
            finite = np.all(np.isfinite(roi.points_world), axis=1) & roi.promoted
            inlier[finite] = np.abs(plane.signed_distance(roi.points_world[finite])) <= PLANE_INLIER_DRAW_M
        for (u, v), colour, is_inlier in zip(np.round(roi.pixels).astype(int), colours, inlier):
            cv2.circle(image, (int(u), int(v)), POINT_RADIUS_PX, tuple(int(c) for c in colour), -1)
            if is_inlier:
                cv2.circle(image, (int(u), int(v)), INLIER_RADIUS_PX, INLIER_COLOUR_RGB, 1)

