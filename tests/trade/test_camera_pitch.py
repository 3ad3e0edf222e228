"""Spec of the settings that follow from the camera's mount pitch (trade/camera_pitch.py), on synthetic geometry:
a textured ground plane z = 0 rendered exactly (a homography) for a camera pitched below the horizon."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from trade.camera_pitch import ground_mask_usable, roi_config_for_pitch
from trade.geometry import CameraIntrinsics, Pose
from trade.ground_filter import SHIPPED_MODEL_MIN_PITCH_DEG
from trade.pipeline import PipelineConfig, TradePipeline
from trade.planes import MultiRansacConfig
from trade.roi_features import RoiConfig, RoiFeatureTracker, roi_tile_edges, tile_index
from trade.types import BBox

SIZE_PX = 256
FOV_DEG = 60.0
HEIGHT_M = 10.0  # camera height above the ground plane z = 0
PITCH_DEG = 45.0  # the paper's real flight
TEXTURE_PX = 1024
TEXTURE_FOCAL_PX = 300.0  # the texture is a nadir view of the ground from TEXTURE_HEIGHT_M over (TEXTURE_X_M, 0)
TEXTURE_HEIGHT_M = 20.0
TEXTURE_X_M = 14.0
N_WORLD = np.array([0.0, 0.0, 1.0])
INLIER_THRESHOLD_M = MultiRansacConfig().inlier_threshold_m


def _pitched(pitch_deg: float) -> np.ndarray:
    """R_world_cam of a level camera looking along world +x, pitch_deg below the horizon (image right = world -y)."""
    s, c = math.sin(math.radians(pitch_deg)), math.cos(math.radians(pitch_deg))
    return np.column_stack([[0.0, -1.0, 0.0], [-s, 0.0, -c], [c, 0.0, -s]])


def _texture(rng: np.random.Generator) -> np.ndarray:
    noise = cv2.GaussianBlur(rng.random((TEXTURE_PX, TEXTURE_PX)), (0, 0), 1.5)
    return cv2.normalize(noise, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _render(texture: np.ndarray, K: CameraIntrinsics, T_world_cam: Pose) -> np.ndarray:
    """The ground plane z = 0 seen from T_world_cam: warp by H = K (R + t n^T / d) K_tex^-1 (plane n . X = d)."""
    K_tex = np.array([[TEXTURE_FOCAL_PX, 0, TEXTURE_PX / 2], [0, TEXTURE_FOCAL_PX, TEXTURE_PX / 2], [0, 0, 1]])
    T_world_tex = Pose(_pitched(90.0), np.array([TEXTURE_X_M, 0.0, TEXTURE_HEIGHT_M]))
    T_cam_tex = T_world_cam.inverse().compose(T_world_tex)
    n_tex, d_tex = T_world_tex.R.T @ N_WORLD, -N_WORLD @ T_world_tex.t
    H = K.K @ (T_cam_tex.R + np.outer(T_cam_tex.t, n_tex) / d_tex) @ np.linalg.inv(K_tex)
    return cv2.warpPerspective(texture, H, (K.width_px, K.height_px), flags=cv2.INTER_LINEAR)


def _fly(config: RoiConfig, n_frames: int, step_m: float, box_step_px: float = 0.0):
    """The ROI tracker over n_frames of a camera pitched PITCH_DEG flying forward step_m per frame, the target's box
    (24 px, at the image centre) moving box_step_px per frame up the image (a target driving away faster)."""
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    texture = _texture(np.random.default_rng(3))
    tracker = RoiFeatureTracker(config, K)
    for k in range(n_frames):
        pose = Pose(_pitched(PITCH_DEG), np.array([k * step_m, 0.0, HEIGHT_M]))
        box = BBox.from_center(SIZE_PX / 2, SIZE_PX / 2 - k * box_step_px, 24.0, 24.0)
        out = tracker.step(_render(texture, K, pose), box, pose)
    return out, box


@pytest.mark.parametrize("roi", [RoiConfig(), RoiConfig(roi_margin_factor=1.0, promote_sigma_m=0.3)])
def test_nadir_camera_keeps_every_roi_setting(roi) -> None:
    assert roi_config_for_pitch(roi, 90.0) == roi


def test_pitched_camera_promotion_threshold_is_a_height_error_and_keeps_tracks_wider() -> None:
    roi = roi_config_for_pitch(RoiConfig(), PITCH_DEG)
    s = math.sin(math.radians(PITCH_DEG))
    assert roi.promote_sigma_m * s == pytest.approx(RoiConfig().promote_sigma_m)  # sigma_z sin(pitch): height
    assert roi.promote_relative_sigma == RoiConfig().promote_relative_sigma
    assert roi.keep_margin_scale * s == pytest.approx(1.0)
    assert roi.roi_margin_factor == RoiConfig().roi_margin_factor  # seeding stays the paper's


def test_pitched_camera_promotes_tracks_by_height_error_within_the_plane_inlier_band() -> None:
    """After 12 frames of 3 cm the depth rule has promoted fewer than a frame's plane fit needs; the height rule
    promotes enough, and each promoted point lies within the plane fit's inlier band of the true ground."""
    by_depth, _ = _fly(RoiConfig(), 12, 0.03)
    by_height, _ = _fly(roi_config_for_pitch(RoiConfig(), PITCH_DEG), 12, 0.03)
    min_points = PipelineConfig().min_plane_points
    assert by_depth.promoted.sum() < min_points <= by_height.promoted.sum()
    assert np.all(np.abs(by_height.points_world[by_height.promoted, 2]) < INLIER_THRESHOLD_M)


def test_tracks_sliding_out_of_the_roi_are_kept_within_the_wider_margins_and_gain_parallax() -> None:
    """The box drives up the image faster than the ground flows (a target pulling away from a slow drone): the
    paper's ROI drops tracks as it slides off them; kept over 1/sin(pitch) wider margins, more tracks converge."""
    config = roi_config_for_pitch(RoiConfig(), PITCH_DEG)
    paper, _ = _fly(replace(config, keep_margin_scale=1.0), 40, 0.03, box_step_px=1.0)
    wider, box = _fly(config, 40, 0.03, box_step_px=1.0)
    assert np.all(paper.tile >= 0)
    beyond = wider.tile < 0
    assert beyond.any()  # kept beyond the ROI ...
    kept_zone = roi_tile_edges(box, config.roi_margin_factor * config.keep_margin_scale)
    assert np.all(tile_index(wider.pixels, *kept_zone) >= 0)  # ... within the wider margins
    assert np.all(np.bincount(wider.tile[~beyond], minlength=9) <= config.max_features_per_tile)
    assert wider.promoted.sum() > paper.promoted.sum()
    assert np.all(np.abs(wider.points_world[wider.promoted, 2]) < INLIER_THRESHOLD_M)


class _NoDepth:
    """A depth model the tests below must not call."""

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        raise AssertionError("the depth model ran")


@pytest.mark.parametrize("pitch_deg, masked", [(90.0, True), (SHIPPED_MODEL_MIN_PITCH_DEG, True), (45.0, False)])
def test_ground_mask_runs_only_on_views_the_depth_model_was_trained_on(pitch_deg, masked) -> None:
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    config = PipelineConfig(ground_mask=True, camera_pitch_deg=pitch_deg)
    pipeline = TradePipeline(config, K, np.random.default_rng(0), _NoDepth())
    assert ground_mask_usable(pitch_deg, SHIPPED_MODEL_MIN_PITCH_DEG) is masked
    assert pipeline.masked is masked and (pipeline.ground is not None) is masked
    # without the mask the plane fit needs the unmasked number of points, as the light stack's
    assert pipeline.fusion.config.min_points == (config.min_masked_plane_points if masked else config.fusion.min_points)


@pytest.mark.parametrize("pitch_deg", [0.0, -10.0, 90.5, float("nan")])
def test_pipeline_config_pitch_out_of_range_names_the_field(pitch_deg) -> None:
    with pytest.raises(ValueError, match="camera_pitch_deg"):
        PipelineConfig(camera_pitch_deg=pitch_deg)
