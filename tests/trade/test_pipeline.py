"""The whole TRADE pipeline on a synthetic planar sequence, and trade/'s import isolation."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import cv2
import numpy as np
import pytest

from tests.trade.planar_scene import (
    R_WORLD_CAM_DOWN, TARGET_SIDE_M, TEXTURE_M_PER_PX, TEXTURE_SIDE_PX, PlanarScene, occlude,
)
from trade.geometry import Pose
from trade.pipeline import PipelineConfig, TradePipeline
from trade.tracking import GuidedTrackerConfig
from trade.types import BBox, iou

ALTITUDE_M = 15.0
FPS = 30.0
PITCH_DEG = 30.0  # depth-only sequence: a pitched view, so the ground is not parallel to the image
CAMERA_VELOCITY_MPS = np.array([2.0, 0.0, 0.0])
TARGET_START_M = np.array([1.0, -1.0])
TARGET_VELOCITY_MPS = np.array([2.2, 0.4])


def _frame(scene: PlanarScene, k: int):
    """Frame k of the planar sequence (camera at ALTITUDE_M and the target both driving): t [s], image, camera
    pose, the target's box and its (x, y) on the ground [m]."""
    t = k / FPS
    cam = np.array([0.0, 0.0, ALTITUDE_M]) + CAMERA_VELOCITY_MPS * t
    tgt = TARGET_START_M + TARGET_VELOCITY_MPS * t
    return t, scene.render(cam, tgt), scene.camera_pose(cam), scene.target_box(cam, tgt), tgt


def _run(config: PipelineConfig, n_frames: int = 90, seed: int = 0):
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=seed)
    pipeline = TradePipeline(config, scene.intrinsics, np.random.default_rng(seed))
    records = []
    for k in range(n_frames):
        t, image, pose, box_gt, tgt = _frame(scene, k)
        est = (pipeline.initialise(image, BBox.from_array(box_gt), pose, t) if k == 0
               else pipeline.step(image, pose, t))
        records.append((est, box_gt, np.array([tgt[0], tgt[1], 0.0]), t))
    return records


def test_import_trade_keeps_simulator_env_and_torch_out():
    """Also when the stack locates the shipped depth model (it finds trade_gym.assets without importing it)."""
    code = ("import sys, trade, trade.pipeline, trade.single_image_depth; "
            "bad = [m for m in ('pybullet', 'gymnasium', 'torch', 'trade_gym') if m in sys.modules]; "
            "print(','.join(bad)); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, f"trade imported: {result.stdout.strip()} {result.stderr[-500:]}"


def test_pipeline_tracks_and_localises_target_on_planar_scene():
    records = _run(PipelineConfig(object_height_m=0.0))
    ious = [iou(est.box.as_array(), gt) if est.box is not None else 0.0 for est, gt, _, _ in records]
    assert np.mean(np.array(ious) >= 0.5) >= 0.9
    late = records[45:]
    depth_err = [abs(est.plane.offset_m) for est, _, _, _ in late if est.plane is not None]
    assert len(depth_err) == len(late)  # a plane every late frame
    assert np.median(depth_err) < 0.3  # the plane z = 0 recovered within 0.3 m at 20 m altitude
    pos_err = [np.linalg.norm(est.position_world_m[:2] - truth[:2]) for est, _, truth, _ in late]
    assert np.median(pos_err) < 0.5
    vel = records[-1][0].velocity_world_mps
    assert np.linalg.norm(vel[:2] - TARGET_VELOCITY_MPS) < 0.6


def test_pipeline_tracks_through_trajectory_prediction_15px_off():
    """A wrong 3D estimate (e.g. a roof taken for the ground) puts the trajectory prediction off the
    target; the tracker keeps the target through the constant-image-velocity window."""
    class OffsetPrediction(TradePipeline):
        def _predict_pixel(self, t_s, T_world_cam):
            prediction = super()._predict_pixel(t_s, T_world_cam)
            return replace(prediction, centre_px=prediction.centre_px + np.array([15.0, -10.0]))

    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=3)
    pipeline = OffsetPrediction(PipelineConfig(object_height_m=0.0), scene.intrinsics, np.random.default_rng(3))
    ious = []
    for k in range(90):
        t, image, pose, gt, _ = _frame(scene, k)
        est = pipeline.initialise(image, BBox.from_array(gt), pose, t) if k == 0 else pipeline.step(image, pose, t)
        ious.append(iou(est.box.as_array(), gt) if est.box is not None else 0.0)
    assert np.mean(np.array(ious) >= 0.5) >= 0.9


def test_pipeline_reports_stage_timings_and_finite_outputs():
    records = _run(PipelineConfig(object_height_m=0.0), n_frames=45)
    for est, _, _, _ in records[30:]:  # ROI depths converge after ~25 frames
        assert est.timings.total_ms > 0.0
        assert np.all(np.isfinite(est.position_world_m)) and np.isfinite(est.depth_m)
        assert est.depth_sigma_m > 0.0


def test_pipeline_coasts_on_time_going_backwards_and_rejects_bad_images():
    scene = PlanarScene.make(size_px=64)
    pipeline = TradePipeline(PipelineConfig(), scene.intrinsics, np.random.default_rng(0))
    cam = np.array([0.0, 0.0, ALTITUDE_M])
    image = scene.render(cam, np.zeros(2))
    pipeline.initialise(image, BBox.from_array(scene.target_box(cam, np.zeros(2))), scene.camera_pose(cam), 1.0)
    past = pipeline.step(image, scene.camera_pose(cam), 0.5)  # a stale frame: not tracked (test_frame_guard)
    assert past.coast_reason == "stale" and past.box is None and not past.tracked
    with pytest.raises(ValueError, match="uint8"):
        pipeline.step(image.astype(np.float32), scene.camera_pose(cam), 2.0)


def test_pipeline_config_depth_only_with_ground_mask_is_refused():
    with pytest.raises(ValueError, match="single_image_depth"):
        PipelineConfig(single_image_depth=True, ground_mask=True)


def test_pipeline_depth_only_without_depth_model_is_refused():
    scene = PlanarScene.make(size_px=64)
    with pytest.raises(ValueError, match="depth model"):
        TradePipeline(PipelineConfig(single_image_depth=True), scene.intrinsics, np.random.default_rng(0))


class _ExactInverseDepth:
    """Stub single-image depth model: an affine map (0.3 + 25 / z) of the true depth the test sets per frame."""

    depth_m: np.ndarray

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        return (0.3 + 25.0 / self.depth_m).astype(np.float32)


def _pitched_pose(cam_xyz: np.ndarray) -> Pose:
    """R_WORLD_CAM_DOWN tilted by PITCH_DEG about the camera x axis: the optical axis leans towards +x."""
    p = np.radians(PITCH_DEG)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(p), -np.sin(p)], [0.0, np.sin(p), np.cos(p)]])
    return Pose(R_WORLD_CAM_DOWN @ tilt, np.asarray(cam_xyz, dtype=np.float64))


def _render_pitched(scene: PlanarScene, pose: Pose, target_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RGB (plane homography of the scene's texture with the target pasted) and the true depth (H, W) [m]."""
    ground = scene.texture_with_target(target_xy)
    K = scene.intrinsics
    x0 = -TEXTURE_SIDE_PX / 2 * TEXTURE_M_PER_PX
    # texture (a, b, 1) -> world (x0 + a s, x0 + b s, 0) - t -> camera R^T (.) -> pixels K (.)
    M = np.array([[TEXTURE_M_PER_PX, 0.0, x0 - pose.t[0]], [0.0, TEXTURE_M_PER_PX, x0 - pose.t[1]],
                  [0.0, 0.0, -pose.t[2]]])
    image = cv2.warpPerspective(ground, K.K @ pose.R.T @ M, (K.width_px, K.height_px), flags=cv2.INTER_LINEAR)
    v, u = np.mgrid[0:K.height_px, 0:K.width_px]
    rays_world = K.rays(np.c_[u.ravel(), v.ravel()].astype(np.float64)) @ pose.R.T
    return image, (-pose.t[2] / rays_world[:, 2]).reshape(K.height_px, K.width_px)


def test_pipeline_depth_only_reads_target_depth_from_aligned_map_on_pitched_sequence():
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    model = _ExactInverseDepth()
    pipeline = TradePipeline(PipelineConfig(single_image_depth=True, object_height_m=0.0), scene.intrinsics,
                             np.random.default_rng(0), model)
    errors, model_ran = [], []
    for k in range(60):
        t = k / FPS
        pose = _pitched_pose(np.array([-8.0, 0.0, ALTITUDE_M]) + np.array([2.0, 0.0, 0.0]) * t)
        target = np.array([1.0, -1.0, 0.0]) + np.array([2.2, 0.4, 0.0]) * t
        image, model.depth_m = _render_pitched(scene, pose, target[:2])
        if k == 0:
            uv = scene.intrinsics.project(pose.inverse().apply(target.reshape(1, 3)))[0]
            half = TARGET_SIDE_M / 2 * scene.intrinsics.fx_px / float(pose.inverse().apply(target.reshape(1, 3))[0, 2])
            est = pipeline.initialise(image, BBox.from_center(uv[0], uv[1], 2 * half, 2 * half), pose, t)
        else:
            est = pipeline.step(image, pose, t)
        assert est.plane is None and est.n_plane_points == 0  # no plane in the depth-only mode
        if est.depth_map_m is not None and est.tracked:
            model_ran.append(est.timings.depth_only_ms > 0.0)
            true_depth = float(pose.inverse().apply(target.reshape(1, 3))[0, 2])
            errors.append(abs(est.depth_m - true_depth) / true_depth)
    assert len(errors) >= 20  # the map exists once the ROI depths converge
    assert 0.2 < np.mean(model_ran) < 0.5  # the model runs on every 3rd frame; its map is read in between
    assert np.median(errors) < 0.03


def test_pipeline_ground_mask_target_never_found_fits_no_plane():
    # Before the first mask, a frame without a box used to feed every converged ROI point to the plane fit
    # (city seed 3: the roof won and temporal fusion then gated the street out). The labels must hold.
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    model = _ExactInverseDepth()
    model.depth_m = np.full((128, 128), ALTITUDE_M)
    never_tracked = GuidedTrackerConfig(min_peak_score=2.0, reacquire_min_peak_score=2.0)  # scores <= 1
    config = PipelineConfig(ground_mask=True, tracker=never_tracked)
    pipeline = TradePipeline(config, scene.intrinsics, np.random.default_rng(0), model)
    for k in range(45):
        t = k / FPS
        cam = np.array([0.0, 0.0, ALTITUDE_M]) + np.array([2.0, 0.0, 0.0]) * t
        image = scene.render(cam, np.array([1.0, -1.0]))
        est = (pipeline.initialise(image, BBox.from_array(scene.target_box(cam, np.array([1.0, -1.0]))),
                                   scene.camera_pose(cam), t) if k == 0 else pipeline.step(image, scene.camera_pose(cam), t))
        if k > 0:
            assert est.box is None and est.n_plane_points == 0 and est.plane is None
    assert est.roi is not None and int(est.roi.promoted.sum()) >= 10  # there were points to (wrongly) use


def test_pipeline_ground_mask_without_depth_model_is_refused():
    scene = PlanarScene.make(size_px=64)
    with pytest.raises(ValueError, match="depth model"):
        TradePipeline(PipelineConfig(ground_mask=True), scene.intrinsics, np.random.default_rng(0))


OCCLUDE_AT_FRAME = 45
OCCLUDED_FRAMES = 40


def _turning_target_xy(k: int) -> np.ndarray:
    """Along +x at 2.2 m/s, then back at the same speed from the moment it is occluded."""
    t, t_turn = k / FPS, OCCLUDE_AT_FRAME / FPS
    return np.array([-3.0 + 2.2 * min(t, t_turn) - 2.2 * max(0.0, t - t_turn), -1.0])


def _occluded_turn(config: PipelineConfig) -> list[tuple[bool, bool, float, np.ndarray, np.ndarray]]:
    """(occluded, tracked, IoU, predicted px, true centre px) per frame of a sequence in which the target
    turns back while a grey patch hides it, so the coasting prediction ends up ahead of it."""
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    pipeline = TradePipeline(config, scene.intrinsics, np.random.default_rng(0))
    records = []
    for k in range(OCCLUDE_AT_FRAME + OCCLUDED_FRAMES + 10):
        cam = np.array([0.0, 0.0, ALTITUDE_M]) + np.array([1.0, 0.0, 0.0]) * k / FPS
        tgt = _turning_target_xy(k)
        image, pose, gt = scene.render(cam, tgt), scene.camera_pose(cam), scene.target_box(cam, tgt)
        occluded = OCCLUDE_AT_FRAME <= k < OCCLUDE_AT_FRAME + OCCLUDED_FRAMES
        centre = gt[:2] + gt[2:] / 2
        if occluded:
            occlude(image, gt)
        est = pipeline.initialise(image, BBox.from_array(gt), pose, k / FPS) if k == 0 else pipeline.step(image, pose, k / FPS)
        records.append((occluded, est.tracked, iou(est.box.as_array(), gt) if est.box is not None else 0.0,
                        est.predicted_px, centre))
    return records


def test_pipeline_redetects_target_away_from_the_coasting_prediction_after_occlusion():
    """After 40 occluded frames the prediction is > half a search window off the target; the grid of
    windows around it finds the target on the first frame it is back, the prediction's window alone never."""
    records = _occluded_turn(PipelineConfig(object_height_m=0.0))
    back = OCCLUDE_AT_FRAME + OCCLUDED_FRAMES
    _, _, _, predicted, centre = records[back]
    assert np.linalg.norm(predicted - centre) > 20.0  # the box is ~17 px, its search window ~34 px
    assert not any(tracked for occluded, tracked, _, _, _ in records if occluded)  # nothing else taken meanwhile
    assert all(tracked and overlap >= 0.5 for _, tracked, overlap, _, _ in records[back:])
    single_window = _occluded_turn(PipelineConfig(object_height_m=0.0, tracker=GuidedTrackerConfig(reacquire_rings=0)))
    assert not any(tracked for _, tracked, _, _, _ in single_window[back:])


def test_pipeline_snaps_an_initial_box_drawn_off_the_target_to_it():
    """A box drawn 4 px right and 3 px up of a ~17 px target (the paper's protocol perturbs it within 5 px)
    is snapped to the target's colour blob before the tracker learns its template; unsnapped it stays off."""
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    cam, tgt = np.array([0.0, 0.0, ALTITUDE_M]), np.array([1.0, -1.0])
    image, pose, gt = scene.render(cam, tgt), scene.camera_pose(cam), scene.target_box(cam, tgt)
    drawn = BBox.from_array(gt + np.array([4.0, -3.0, 0.0, 0.0]))
    snapped = TradePipeline(PipelineConfig(tracker=GuidedTrackerConfig(snap_init_box=True)), scene.intrinsics,
                            np.random.default_rng(0))
    assert iou(snapped.initialise(image, drawn, pose, 0.0).box.as_array(), gt) >= 0.85
    assert iou(snapped.tracker.box.as_array(), gt) >= 0.85
    kept = TradePipeline(PipelineConfig(), scene.intrinsics, np.random.default_rng(0))  # off by default
    assert kept.initialise(image, drawn, pose, 0.0).box == drawn


def test_pipeline_keeps_the_initial_box_where_no_plausible_blob_is():
    """On plain ground (no target under the box) the snap finds no blob it accepts: the box keeps its size,
    moved at most the search's reach (half its shorter side) by the colour-separation search."""
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    cam = np.array([0.0, 0.0, ALTITUDE_M])
    image = scene.render(cam, np.array([40.0, 40.0]))  # the target outside the view
    drawn = BBox(50.0, 50.0, 17.0, 17.0)
    pipeline = TradePipeline(PipelineConfig(tracker=GuidedTrackerConfig(snap_init_box=True)), scene.intrinsics,
                             np.random.default_rng(0))
    kept = pipeline.initialise(image, drawn, scene.camera_pose(cam), 0.0).box
    reach_px = np.floor(GuidedTrackerConfig().snap_search_fraction * 17.0)
    assert (kept.w_px, kept.h_px) == (drawn.w_px, drawn.h_px)
    assert max(abs(kept.x_px - drawn.x_px), abs(kept.y_px - drawn.y_px)) <= reach_px
    unsearched_config = GuidedTrackerConfig(snap_init_box=True, snap_search_fraction=0.0)
    unsearched = TradePipeline(PipelineConfig(tracker=unsearched_config), scene.intrinsics, np.random.default_rng(0))
    assert unsearched.initialise(image, drawn, scene.camera_pose(cam), 0.0).box == drawn


ROOF_BELOW_CAMERA_M = 1.0


@pytest.mark.parametrize("size_gate", [True, False])
def test_pipeline_refuses_a_fix_on_a_roof_the_target_could_not_stand_on(size_gate: bool) -> None:
    """A roof taken for the ground: every plane point lies 1 m under the camera. At that depth the 4 m target's
    box would span 0.3 m, less than the 1.5 m object height, so the size gate refuses every fix and drops the plane
    (`size_gate_drops_plane`); without it the target is put on the roof. On the true ground the gate lets the
    fixes through."""
    config = PipelineConfig(size_gate=size_gate)
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    pipelines = {"roof": _RoofPoints(config, scene.intrinsics, np.random.default_rng(0)),
                 "ground": TradePipeline(config, scene.intrinsics, np.random.default_rng(0))}
    fixes = {name: [] for name in pipelines}
    for k in range(60):
        t, image, pose, gt, _ = _frame(scene, k)
        for name, pipeline in pipelines.items():
            est = pipeline.initialise(image, BBox.from_array(gt), pose, t) if k == 0 else pipeline.step(image, pose, t)
            if est.tracked:
                fixes[name].append((est.depth_m, est.plane is not None))
    ground = np.array([depth for depth, has_plane in fixes["ground"] if has_plane])
    assert len(ground) >= 20 and np.all(np.abs(ground - ALTITUDE_M) < 1.5)  # a plane on most late frames
    roof = np.array(fixes["roof"])
    if size_gate:
        assert np.all(np.isnan(roof[:, 0])) and not np.any(roof[:, 1]), roof  # no fix, and no roof plane held
    else:
        on_plane = roof[roof[:, 1] > 0, 0]
        assert len(on_plane) >= 20 and np.all(on_plane < ROOF_BELOW_CAMERA_M), roof


class _RoofPoints(TradePipeline):
    """Every plane point lifted onto a roof ROOF_BELOW_CAMERA_M under the camera while `on_roof` is set."""

    on_roof = True

    def _ground_points(self, image_rgb, box, roi, T_world_cam):
        points, ground_ms = super()._ground_points(image_rgb, box, roi, T_world_cam)
        lift = ALTITUDE_M - ROOF_BELOW_CAMERA_M if self.on_roof else 0.0
        return points + [0.0, 0.0, lift], ground_ms


@pytest.mark.parametrize("drops", [True, False])
def test_pipeline_that_drops_a_roof_plane_fixes_on_the_ground_as_soon_as_its_points_come(drops: bool) -> None:
    """Roof points for 30 frames, then the true ground's: with the refused roof plane dropped, the first ground
    frames make the plane and the fixes are at the true depth within a few frames; kept, the fused roof plane
    gates the ground points out for the fusion's max_gated_frames (here longer than the run)."""
    roof_frames, n_frames = 30, 60
    fusion = replace(PipelineConfig().fusion, outvoted_reinit=False, max_gated_frames=n_frames)
    config = PipelineConfig(size_gate_drops_plane=drops, fusion=fusion)
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
    pipeline = _RoofPoints(config, scene.intrinsics, np.random.default_rng(0))
    depths = []
    for k in range(n_frames):
        pipeline.on_roof = k < roof_frames
        t, image, pose, gt, _ = _frame(scene, k)
        est = pipeline.initialise(image, BBox.from_array(gt), pose, t) if k == 0 else pipeline.step(image, pose, t)
        depths.append(est.depth_m if est.tracked and est.plane is not None else np.nan)
    after = np.array(depths[roof_frames + 5:])
    if drops:
        assert np.all(np.abs(after - ALTITUDE_M) < 1.5), after
    else:
        assert not np.any(np.abs(after - ALTITUDE_M) < 1.5), after
