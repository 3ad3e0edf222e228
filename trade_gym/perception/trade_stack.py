"""The TRADE stack (`perception="trade"`) and its baseline (`"dcf"`) as env perception modes.

Runs `trade.TradePipeline` (with its frame guards) on the delivered frames with the pose source's camera
pose. It sees the sensors only: the initial box at reset (the paper's protocol: the ground-truth box, perturbed)
is all it is told; the env scores its estimates (`trade_gym.scoring`).
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics, Pose
from trade.ground_filter import DepthPredictor
from trade.pipeline import Estimate, PipelineConfig, TradePipeline
from trade.roi_features import RoiFeatures
from trade.single_image_depth import SingleImageDepth
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.types import BBox
from trade_gym.config import EnvConfig
from trade_gym.perception.base import FloatArray, GroundEstimate, PerceptionOutput, SensorFrame, finite_imu

TRAJECTORY_COLOUR_RGB = (255, 0, 255)  # magenta, as in the paper's figures
INLIER_COLOUR_RGB = (255, 255, 0)
GROUND_TINT_RGB = np.array((0.0, 255.0, 255.0), np.float32)  # cyan over the ground mask
GROUND_TINT_WEIGHT = 0.3
FEATURE_DEPTH_RANGE_M = (5.0, 60.0)  # colour map range for ROI feature depths
POINT_RADIUS_PX = 1
INLIER_RADIUS_PX = 3
PLANE_INLIER_DRAW_M = 0.5  # the MSAC inlier threshold
# The stack's random generator is its own, seeded at reset by one draw in [0, STACK_SEED_HIGH) from the env's
# generator: its draws (RANSAC samples) never interleave with the IMU's and the pose source's, so a replay of the
# recorded sensors with the recorded seed gives the closed loop's estimates exactly.
STACK_SEED_HIGH = 2**63
# The env switches that make up the stack's settings (`pipeline_config`); `perception` picks trade or dcf.
STACK_SWITCHES = ("temporal_fusion", "ground_mask", "single_image_depth", "depth_only_ransac",
                  "trajectory_guidance", "snap_init_box")


def pipeline_config(config: EnvConfig) -> PipelineConfig:
    """The stack's configuration for an env configuration (its ablation switches and its camera's mount pitch)."""
    return PipelineConfig(
        tracker=GuidedTrackerConfig(trajectory_guidance=config.trajectory_guidance and config.perception == "trade",
                                    snap_init_box=config.snap_init_box),
        temporal_fusion=config.temporal_fusion,
        ground_mask=config.ground_mask,
        single_image_depth=config.single_image_depth,
        depth_only_ransac=config.depth_only_ransac,
        camera_pitch_deg=config.camera_pitch_deg,  # the settings that follow from the viewing geometry
    )


class TradePerception:
    """Adapter from the env's sensors to `TradePipeline` and back to `PerceptionOutput`."""

    def __init__(self, config: EnvConfig, intrinsics: CameraIntrinsics) -> None:
        self.pipeline_config = pipeline_config(config)
        self.intrinsics = intrinsics
        # The shipped single-image depth model, loaded (and its SHA-256 checked) once per env.
        needs_model = self.pipeline_config.ground_mask or self.pipeline_config.single_image_depth
        # (a `SensorFaults` wrapper may swap in a faulty one)
        self.depth_model: DepthPredictor | None = SingleImageDepth() if needs_model else None
        self.pipeline: TradePipeline | None = None
        self.last: Estimate | None = None  # the pipeline's estimate at the last tracked frame
        self._T_world_cam: Pose | None = None  # that frame's camera pose (the overlay draws from it)
        self.rng_seed: int | None = None  # the seed of the stack's own generator this episode

    def reset(self, sensors: SensorFrame, init_box: FloatArray, rng: np.random.Generator) -> PerceptionOutput:
        """Start an episode; the stack's generator is seeded by one draw from `rng` (the env's)."""
        return self.reset_seeded(sensors, init_box, int(rng.integers(STACK_SEED_HIGH)))

    def reset_seeded(self, sensors: SensorFrame, init_box: FloatArray, rng_seed: int) -> PerceptionOutput:
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
        return _output(self.last)

    def step(self, sensors: SensorFrame) -> PerceptionOutput:
        """The pipeline's estimate of this frame; a frame its guards refuse coasts (no fresh box)."""
        if self.pipeline is None:
            raise RuntimeError("TradePerception.step() before reset()")
        est = self.pipeline.step(sensors.rgb, sensors.T_world_cam, sensors.t_s, finite_imu(sensors.imu))
        if est.coast_reason is None:
            self.last, self._T_world_cam = est, sensors.T_world_cam
        return _output(est)

    @property
    def overlay(self) -> TradeOverlay | None:
        if self.last is None or self._T_world_cam is None or self.pipeline is None:  # set together by reset
            return None
        return TradeOverlay(self.last, self.intrinsics, self._T_world_cam, self.pipeline.ground_mask)


def _output(est: Estimate) -> PerceptionOutput:
    """The env's view of a pipeline estimate: box (NaN: none), trajectory state, depth, the ground it holds."""
    return PerceptionOutput(
        bbox=est.box.as_array() if est.box is not None else np.full(4, np.nan),
        position_world_m=est.position_world_m,
        velocity_world_mps=est.velocity_world_mps,
        target_depth_m=est.depth_m,
        target_depth_sigma_m=est.depth_sigma_m,
        ground=GroundEstimate(plane=est.plane, depth_map_m=est.depth_map_m),
        valid=est.tracked and est.box is not None,
    )


class TradeOverlay:
    """Draws what the paper's figures show: predicted trajectory (magenta), ROI features coloured
    by depth, plane inliers circled; and the latest ground mask (cyan tint) when the mask is on."""

    def __init__(self, est: Estimate, intrinsics: CameraIntrinsics, T_world_cam,
                 ground_mask: npt.NDArray[np.bool_] | None = None) -> None:
        self.est, self.K, self.T_world_cam, self.ground_mask = est, intrinsics, T_world_cam, ground_mask

    def draw(self, image: npt.NDArray[np.uint8]) -> None:
        est = self.est
        if self.ground_mask is not None and self.ground_mask.shape == image.shape[:2]:
            tinted = image[self.ground_mask].astype(np.float32)
            image[self.ground_mask] = (tinted + GROUND_TINT_WEIGHT * (GROUND_TINT_RGB - tinted)).astype(np.uint8)
        if est.roi is not None and len(est.roi.pixels):
            self._draw_features(image, est.roi)
        if len(est.trajectory_preview_world_m):
            uv = self.K.project(self.T_world_cam.inverse().apply(est.trajectory_preview_world_m))
            uv = uv[np.all(np.isfinite(uv), axis=1)]
            if len(uv) >= 2:
                cv2.polylines(image, [np.round(uv).astype(np.int32)], False, TRAJECTORY_COLOUR_RGB, 1)

    def _draw_features(self, image: npt.NDArray[np.uint8], roi: RoiFeatures) -> None:
        plane = self.est.plane
        lo, hi = FEATURE_DEPTH_RANGE_M
        depth = np.nan_to_num(roi.depth_m, nan=hi)
        level = np.clip((depth - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
        colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)[:, ::-1]
        inlier = np.zeros(len(roi.pixels), np.bool_)
        if plane is not None:
            finite = np.all(np.isfinite(roi.points_world), axis=1) & roi.promoted
            inlier[finite] = np.abs(plane.signed_distance(roi.points_world[finite])) <= PLANE_INLIER_DRAW_M
        for (u, v), colour, is_inlier in zip(np.round(roi.pixels).astype(int), colours, inlier):
            cv2.circle(image, (int(u), int(v)), POINT_RADIUS_PX, tuple(int(c) for c in colour), -1)
            if is_inlier:
                cv2.circle(image, (int(u), int(v)), INLIER_RADIUS_PX, INLIER_COLOUR_RGB, 1)

