"""The pipeline's frame guards (`trade.frame_guard`): a missing, stale, blank or frozen frame, or a target the
trajectory model puts out of view, is not tracked; the pipeline coasts on its trajectory model and tracks again
on the next good frame. On the synthetic planar sequence of test_pipeline, without any simulator."""

from __future__ import annotations

import numpy as np
import pytest

from tests.trade.planar_scene import PlanarScene
from trade.frame_guard import (
    BLANK, FROZEN, MISSING, OUT_OF_VIEW, STALE, FrameGuardConfig, TrackedFrame, predicted_out_of_view,
    unusable_frame,
)
from trade.geometry import CameraIntrinsics, Pose
from trade.pipeline import PipelineConfig, TradePipeline
from trade.tracking import GuidedTrackerConfig
from trade.types import BBox, iou

ALTITUDE_M = 15.0
FPS = 30.0
CAMERA_VELOCITY_MPS = np.array([2.0, 0.0, 0.0])
TARGET_START_M = np.array([1.0, -1.0])
TARGET_VELOCITY_MPS = np.array([2.2, 0.4])
WARM_UP_FRAMES = 45  # the trajectory model has its first fix by then (ROI depths converge after ~25 frames)
TRACKED_IOU = 0.5
FAR_M = 200.0  # a camera this far sideways cannot see the target
GUARD = FrameGuardConfig()


def _frame(scene: PlanarScene, k: int, camera_offset_m: np.ndarray | None = None):
    """Frame k of the planar sequence: image, camera pose (moved by `camera_offset_m` [m] from where the image was
    taken), time [s], true box."""
    t = k / FPS
    cam = np.array([0.0, 0.0, ALTITUDE_M]) + CAMERA_VELOCITY_MPS * t
    tgt = TARGET_START_M + TARGET_VELOCITY_MPS * t
    offset = np.zeros(3) if camera_offset_m is None else camera_offset_m
    return scene.render(cam, tgt), scene.camera_pose(cam + offset), t, scene.target_box(cam, tgt)


def _warmed_up(guidance: bool = True, seed: int = 0) -> tuple[PlanarScene, TradePipeline]:
    """A pipeline that has tracked WARM_UP_FRAMES frames, its trajectory model started."""
    scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=seed)
    config = PipelineConfig(object_height_m=0.0, tracker=GuidedTrackerConfig(trajectory_guidance=guidance))
    pipeline = TradePipeline(config, scene.intrinsics, np.random.default_rng(seed))
    for k in range(WARM_UP_FRAMES):
        image, pose, t, box = _frame(scene, k)
        est = pipeline.initialise(image, BBox.from_array(box), pose, t) if k == 0 else pipeline.step(image, pose, t)
    assert est.coast_reason is None and est.tracked and pipeline.trajectory.initialized
    return scene, pipeline


def _assert_coasts(est, reason: str, pipeline: TradePipeline, t_s: float) -> None:
    """No box, not tracked, the trajectory model's position at t_s, the last plane kept."""
    assert est.coast_reason == reason
    assert est.box is None and not est.tracked and np.isnan(est.depth_sigma_m)
    assert np.all(np.isfinite(est.position_world_m)) and np.isfinite(est.depth_m)
    assert np.array_equal(est.position_world_m, pipeline.trajectory.state.position_m)
    assert pipeline.trajectory.state.t_s == t_s
    assert est.plane is not None


def _assert_tracks_next_frame(scene: PlanarScene, pipeline: TradePipeline, k: int) -> None:
    image, pose, t, box = _frame(scene, k)
    est = pipeline.step(image, pose, t)
    assert est.coast_reason is None and est.tracked and iou(est.box.as_array(), box) >= TRACKED_IOU


def test_unusable_frame_names_missing_stale_blank_and_frozen_frames():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    tracked = TrackedFrame(1.0, image, Pose(np.eye(3), np.array([0.0, 0.0, 10.0])))
    pose, moved = tracked.T_world_cam, Pose(np.eye(3), np.array([0.5, 0.0, 10.0]))
    assert unusable_frame(None, pose, 2.0, tracked, GUARD) == MISSING
    assert unusable_frame(image.copy(), pose, 1.0, tracked, GUARD) == STALE
    assert unusable_frame(np.zeros_like(image), pose, 2.0, tracked, GUARD) == BLANK
    assert unusable_frame(np.full_like(image, 255), pose, 2.0, tracked, GUARD) == BLANK
    assert unusable_frame(image.copy(), moved, 2.0, tracked, GUARD) == FROZEN
    # the same pixels from the same pose (nothing moved) and a new image are usable
    assert unusable_frame(image.copy(), pose, 2.0, tracked, GUARD) is None
    assert unusable_frame(rng.integers(0, 256, image.shape, dtype=np.uint8), pose, 2.0, tracked, GUARD) is None


def test_predicted_out_of_view_beyond_the_margin_or_behind_the_camera():
    K = CameraIntrinsics.from_fov(100, 100, 90.0)  # f = 50 px, centre 49.5
    pose = Pose(np.eye(3), np.zeros(3))  # looking along world +z
    ahead = np.array([0.0, 0.0, 10.0])
    assert not predicted_out_of_view(ahead, pose, K, 0.25)
    assert not predicted_out_of_view(np.array([14.0, 0.0, 10.0]), pose, K, 0.25)  # u = 119.5 <= 99 + 25
    assert predicted_out_of_view(np.array([16.0, 0.0, 10.0]), pose, K, 0.25)  # u = 129.5
    assert predicted_out_of_view(-ahead, pose, K, 0.25)


@pytest.mark.parametrize("field, value", [("blank_max_range", -1), ("blank_max_range", 255), ("blank_max_range", 2.5),
                                          ("blank_max_range", True), ("frozen_min_motion_m", -1e-3),
                                          ("frozen_min_turn_rad", float("nan")),
                                          ("out_of_view_margin_fraction", float("inf"))])
def test_frame_guard_config_bad_value_raises_naming_field_and_value(field, value):
    with pytest.raises(ValueError, match=f"FrameGuardConfig.{field} must be .*, got {value!r}"):
        FrameGuardConfig(**{field: value})


def test_pipeline_blank_frame_coasts_on_trajectory_and_tracks_the_next_frame():
    scene, pipeline = _warmed_up()
    image, pose, t, _ = _frame(scene, WARM_UP_FRAMES)
    _assert_coasts(pipeline.step(np.zeros_like(image), pose, t), BLANK, pipeline, t)
    _assert_tracks_next_frame(scene, pipeline, WARM_UP_FRAMES + 1)


def test_pipeline_frozen_frame_identical_to_the_last_coasts():
    scene, pipeline = _warmed_up()
    last_image, _, _, _ = _frame(scene, WARM_UP_FRAMES - 1)
    _, pose, t, _ = _frame(scene, WARM_UP_FRAMES)
    _assert_coasts(pipeline.step(last_image.copy(), pose, t), FROZEN, pipeline, t)
    _assert_tracks_next_frame(scene, pipeline, WARM_UP_FRAMES + 1)


def test_pipeline_missing_and_stale_frames_coast_instead_of_raising():
    scene, pipeline = _warmed_up()
    image, pose, t, _ = _frame(scene, WARM_UP_FRAMES)
    _assert_coasts(pipeline.step(None, pose, t), MISSING, pipeline, t)
    last_t = (WARM_UP_FRAMES - 1) / FPS
    est = pipeline.step(image, pose, last_t)  # a duplicate of the last tracked frame's time
    assert est.coast_reason == STALE and est.box is None and not est.tracked
    _assert_tracks_next_frame(scene, pipeline, WARM_UP_FRAMES + 1)


def test_pipeline_target_predicted_out_of_view_coasts_with_guidance_only():
    scene, pipeline = _warmed_up(guidance=True)
    image, pose, t, _ = _frame(scene, WARM_UP_FRAMES, camera_offset_m=np.array([FAR_M, 0.0, 0.0]))
    _assert_coasts(pipeline.step(image, pose, t), OUT_OF_VIEW, pipeline, t)
    _assert_tracks_next_frame(scene, pipeline, WARM_UP_FRAMES + 1)
    _, unguided = _warmed_up(guidance=False)
    assert unguided.step(image, pose, t).coast_reason is None  # the dcf baseline has no prediction to refuse on


def test_pipeline_refuses_bad_images_and_non_finite_times():
    scene, pipeline = _warmed_up()
    image, pose, t, _ = _frame(scene, WARM_UP_FRAMES)
    with pytest.raises(ValueError, match="uint8"):
        pipeline.step(image.astype(np.float32), pose, t)
    with pytest.raises(ValueError, match="uint8"):
        pipeline.step(image[:, :-1], pose, t)
    with pytest.raises(ValueError, match="t_s"):
        pipeline.step(image, pose, float("nan"))
