"""Spec tests for trade.ground_segmentation (and the ground filter's track labels) on depth maps ray-cast
analytically from a pinhole camera: a ground plane (flat or sloped), an axis-aligned target box and buildings."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest

from trade.geometry import CameraIntrinsics, Pose
from trade.ground_filter import GroundFilter, GroundFilterConfig
from trade.ground_segmentation import GroundMask, GroundSegmentationConfig, points_in_mask, segment_ground
from trade.planes import Plane
from trade.roi_features import RoiFeatures
from trade.types import BBox

K = CameraIntrinsics.from_fov(256, 256, 110.0)
ALTITUDE_M = 32.0  # camera height above the ground under the target (city scene)
TARGET_SIZE_M = (6.0, 3.0, 1.5)  # length (x), width (y), height (z): a truck
ROI_SIDE_PX = 120.0
GROUND, TARGET, SKY = 0, 1, -1  # labels; buildings are 2, 3, ...
CONFIG = GroundSegmentationConfig()


@dataclass(frozen=True)
class Scene:
    depth: np.ndarray  # (H, W) float32 camera z [m]
    labels: np.ndarray  # (H, W) int: GROUND, TARGET, SKY or building index
    pose: Pose  # T_world_cam
    box: BBox  # target box [px]
    roi: BBox  # ROI_SIDE_PX square centred on the box
    ground: Plane


def camera_pose(pitch_deg: float, target_xy: np.ndarray, ground: Plane, altitude_m: float) -> Pose:
    """Camera `altitude_m` above the ground point `target_xy`, optical axis through it, tilted by pitch
    towards +x; image right = world -y; pitch 0 looks straight down with image up = world +x."""
    p = math.radians(pitch_deg)
    z_axis = np.array([math.sin(p), 0.0, -math.cos(p)])
    x_axis = np.array([0.0, -1.0, 0.0])
    R = np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])
    ground_pt = np.array([*target_xy, ground.height_at(target_xy)])
    return Pose(R, ground_pt - z_axis * altitude_m / math.cos(p))


def ray_boxes(origin: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Slab test: (N,) ray parameter of the first hit of origin + t dirs with the box [lo, hi]; inf if none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - origin) / dirs, (hi - origin) / dirs
    t_near = np.nanmax(np.minimum(t0, t1), axis=1)
    t_far = np.nanmin(np.maximum(t0, t1), axis=1)
    return np.where((t_near <= t_far) & (t_near > 0.0), t_near, np.inf)


def render(pitch_deg: float = 0.0, slope_deg: float = 0.0, buildings: tuple[tuple[float, ...], ...] = (),
           altitude_m: float = ALTITUDE_M, roi_side_px: float = ROI_SIDE_PX) -> Scene:
    """Ray-cast depth (camera z) per pixel. buildings: (x0, x1, y0, y1, height above z = 0 ground) [m];
    the ground rises towards +y with `slope_deg`; the target stands on it at the world origin."""
    s = math.radians(slope_deg)
    ground = Plane(np.array([0.0, -math.sin(s), math.cos(s)]), 0.0)
    xy = np.zeros(2)
    pose = camera_pose(pitch_deg, xy, ground, altitude_m)
    v, u = np.mgrid[0:K.height_px, 0:K.width_px]
    pix = np.c_[u.ravel(), v.ravel()].astype(np.float64)
    dirs = K.rays(pix) @ pose.R.T  # camera z = 1 per ray: the ray parameter is the camera depth
    with np.errstate(divide="ignore"):
        t_ground = -(ground.signed_distance(pose.t)) / (dirs @ ground.normal)
    hits = [np.where(t_ground > 0.0, t_ground, np.inf)]
    ground_z = ground.height_at(xy)
    half = np.array(TARGET_SIZE_M[:2]) / 2.0
    lo = np.array([*(xy - half), ground_z - 10.0])
    hits.append(ray_boxes(pose.t, dirs, lo, np.array([*(xy + half), ground_z + TARGET_SIZE_M[2]])))
    for x0, x1, y0, y1, height in buildings:
        hits.append(ray_boxes(pose.t, dirs, np.array([x0, y0, -50.0]), np.array([x1, y1, height])))
    hits_arr = np.stack(hits, axis=1)
    label = np.argmin(hits_arr, axis=1)
    depth = hits_arr[np.arange(label.size), label]
    label = np.where(np.isfinite(depth), label, SKY)
    corners = np.array([[x, y, z] for x in (lo[0], xy[0] + half[0]) for y in (lo[1], xy[1] + half[1])
                        for z in (ground_z - half[1] * math.tan(s), ground_z + TARGET_SIZE_M[2])])
    uv = K.project(pose.inverse().apply(corners))
    box = BBox(*uv.min(axis=0), *(uv.max(axis=0) - uv.min(axis=0)))
    roi = BBox.from_center(*box.center, roi_side_px, roi_side_px)
    shape = (K.height_px, K.width_px)
    return Scene(depth.reshape(shape).astype(np.float32), label.reshape(shape), pose, box, roi, ground)


def roi_slice(scene: Scene) -> tuple[slice, slice]:
    """Pixel rows, cols of the ROI clipped to the image (pixel u inside when x <= u < x + w)."""
    r = slice(max(0, math.ceil(scene.roi.y_px)), min(K.height_px, math.ceil(scene.roi.y_px + scene.roi.h_px)))
    c = slice(max(0, math.ceil(scene.roi.x_px)), min(K.width_px, math.ceil(scene.roi.x_px + scene.roi.w_px)))
    return r, c


def ground_truth(scene: Scene) -> np.ndarray:
    """(H, W) analytic ground pixels inside the ROI."""
    truth = np.zeros(scene.labels.shape, dtype=bool)
    rows, cols = roi_slice(scene)
    truth[rows, cols] = scene.labels[rows, cols] == GROUND
    return truth


def mask_iou(mask: np.ndarray, truth: np.ndarray) -> float:
    return float(np.count_nonzero(mask & truth) / np.count_nonzero(mask | truth))


def noisy(depth: np.ndarray, relative_sigma: float, seed: int) -> np.ndarray:
    """Per-pixel Gaussian depth noise with sigma = relative_sigma x depth."""
    rng = np.random.default_rng(seed)
    return (depth * (1.0 + relative_sigma * rng.standard_normal(depth.shape))).astype(np.float32)


def segment(scene: Scene, depth: np.ndarray | None = None,
            config: GroundSegmentationConfig = CONFIG) -> GroundMask:
    return segment_ground(scene.depth if depth is None else depth, K, scene.pose, scene.box, scene.roi, config)


def world_points(scene: Scene, mask: np.ndarray) -> np.ndarray:
    """(N, 3) world points [m] of the `mask` pixels of the scene's depth."""
    v, u = np.nonzero(mask)
    return scene.pose.apply(K.backproject(np.c_[u, v], scene.depth[v, u]))


def plane_errors(fit: Plane, truth: Plane) -> tuple[float, float]:
    """(angle between normals [deg], height gap at the target's (x, y) = origin [m])."""
    angle = math.degrees(math.acos(min(1.0, abs(float(fit.normal @ truth.normal)))))
    return angle, abs(fit.height_at(np.zeros(2)) - truth.height_at(np.zeros(2)))


# Buildings: (x0, x1, y0, y1, height) [m]; they reach past the ROI, so no ground hides behind them
# (ground cut off from the box is unreachable by region growing from the box, by design).
TOWER = (6.0, 60.0, -60.0, 60.0, 30.0)  # city: a 30 m building 3 m ahead of the truck's front
BLOCK = (5.0, 60.0, -60.0, 60.0, 10.0)  # a 10 m building whose roof is in view at nadir
SPLIT = ((3.0, 40.0, -2.5, 2.5, 10.0), (-40.0, -3.0, -2.5, 2.5, 10.0))  # touch the truck front and back


@pytest.mark.parametrize(("pitch_deg", "building"), [(0.0, TOWER), (20.0, TOWER), (0.0, BLOCK), (30.0, BLOCK)])
def test_segment_ground_building_in_roi_mask_matches_ground_and_stops_at_height_step(
    pitch_deg: float, building: tuple[float, ...]
) -> None:
    scene = render(pitch_deg=pitch_deg, buildings=(building,))
    result = segment(scene)
    assert np.count_nonzero(scene.labels[roi_slice(scene)] >= 2) > 1000  # the building fills part of the ROI
    assert mask_iou(result.mask, ground_truth(scene)) >= 0.9
    assert not np.any(result.mask & (scene.labels >= 2))
    # target pixels only where its side meets the ground: every mask pixel lies on the true ground
    assert np.max(np.abs(scene.ground.signed_distance(world_points(scene, result.mask)))) < 0.1
    assert result.grid_shape == (CONFIG.grid_tiles, CONFIG.grid_tiles)


@pytest.mark.parametrize("pitch_deg", [0.0, 30.0, 45.0])
def test_segment_ground_sloped_ground_is_segmented(pitch_deg: float) -> None:
    scene = render(pitch_deg=pitch_deg, slope_deg=10.0)
    assert mask_iou(segment(scene).mask, ground_truth(scene)) >= 0.9


@pytest.mark.parametrize(("pitch_deg", "slope_deg", "buildings"),
                         [(30.0, 10.0, ()), (45.0, 10.0, ()), (20.0, 0.0, (TOWER,))])
def test_segment_ground_mask_plane_matches_true_ground(pitch_deg: float, slope_deg: float,
                                                      buildings: tuple[tuple[float, ...], ...]) -> None:
    scene = render(pitch_deg=pitch_deg, slope_deg=slope_deg, buildings=buildings)
    result = segment(scene)
    assert result.plane is not None
    angle_deg, gap_m = plane_errors(result.plane, scene.ground)
    assert angle_deg < 1.0
    assert gap_m < 0.1


@pytest.mark.parametrize(("pitch_deg", "slope_deg", "buildings"),
                         [(0.0, 0.0, (TOWER,)), (20.0, 0.0, (TOWER,)), (30.0, 10.0, ()), (0.0, 0.0, (BLOCK,))])
def test_segment_ground_one_percent_depth_noise_keeps_iou(pitch_deg: float, slope_deg: float,
                                                         buildings: tuple[tuple[float, ...], ...]) -> None:
    scene = render(pitch_deg=pitch_deg, slope_deg=slope_deg, buildings=buildings)
    result = segment(scene, noisy(scene.depth, 0.01, seed=7))
    assert mask_iou(result.mask, ground_truth(scene)) >= 0.8
    assert result.plane is not None
    angle_deg, gap_m = plane_errors(result.plane, scene.ground)
    assert angle_deg < 1.0
    assert gap_m < 0.1


@pytest.mark.parametrize("altitude_m", [16.0, 32.0])
@pytest.mark.parametrize("pitch_deg", [0.0, 20.0, 45.0])
def test_segment_ground_object_height_of_truck_within_half_metre(altitude_m: float, pitch_deg: float) -> None:
    scene = render(pitch_deg=pitch_deg, altitude_m=altitude_m, buildings=(TOWER,))
    result = segment(scene)
    assert result.object_height_m == pytest.approx(TARGET_SIZE_M[2], abs=0.5)
    assert result.coarse_object_height_m == pytest.approx(TARGET_SIZE_M[2], abs=0.5)
    assert result.ground_level_m == pytest.approx(0.0, abs=0.1)


def test_segment_ground_object_height_on_slope_is_measured_from_mask_plane() -> None:
    scene = render(pitch_deg=30.0, slope_deg=10.0)
    result = segment(scene, noisy(scene.depth, 0.01, seed=3))
    assert result.object_height_m == pytest.approx(TARGET_SIZE_M[2], abs=0.5)


def test_segment_ground_split_ground_is_covered_by_reseeding() -> None:
    scene = render(buildings=SPLIT)
    truth = ground_truth(scene)
    left_half = np.arange(K.width_px)[None, :] < scene.box.center[0]
    sides = (truth & left_half, truth & ~left_half)
    single = segment(scene, config=replace(CONFIG, n_seeds=1))
    full = segment(scene)
    single_cover = sorted(np.count_nonzero(single.mask & side) / np.count_nonzero(side) for side in sides)
    full_cover = [np.count_nonzero(full.mask & side) / np.count_nonzero(side) for side in sides]
    assert single_cover[0] < 0.1  # one seed grows one side only: the building splits the ground
    assert single_cover[1] > 0.9
    assert min(full_cover) > 0.9
    assert full.n_seeds_used >= 2
    assert not np.any(full.mask & (scene.labels >= 2))


def test_segment_ground_small_roi_uses_fewer_larger_tiles() -> None:
    scene = render(buildings=(BLOCK,), roi_side_px=48.0)
    result = segment(scene)
    assert result.grid_shape == (48 // CONFIG.min_tile_px,) * 2
    assert mask_iou(result.mask, ground_truth(scene)) >= 0.9


def test_segment_ground_roi_past_image_edge_is_clipped() -> None:
    scene = render(pitch_deg=20.0)
    roi = BBox(scene.box.x_px - 40.0, -30.0, 100.0, scene.box.y_px + scene.box.h_px + 70.0)
    result = segment_ground(scene.depth, K, scene.pose, scene.box, roi, CONFIG)
    assert not np.any(result.mask[:, : math.ceil(roi.x_px)])
    assert not np.any(result.mask[math.ceil(roi.y_px + roi.h_px):])
    assert mask_iou(result.mask, ground_truth(replace(scene, roi=roi))) >= 0.9


def test_segment_ground_missing_depth_is_never_in_mask() -> None:
    scene = render(buildings=(TOWER,))
    depth = scene.depth.copy()
    rows, cols = roi_slice(scene)
    hole = (slice(rows.start, rows.start + 30), slice(cols.start, cols.start + 30))
    depth[hole] = np.nan
    depth[rows.stop - 10:rows.stop, cols] = 0.0
    result = segment(scene, depth)
    assert not np.any(result.mask[hole])
    assert not np.any(result.mask[rows.stop - 10:rows.stop, cols])
    assert mask_iou(result.mask, ground_truth(scene) & np.isfinite(depth) & (depth > 0)) >= 0.9


def test_segment_ground_roi_too_small_for_grid_returns_empty_mask() -> None:
    scene = render()
    roi = BBox.from_center(*scene.box.center, 10.0, 10.0)
    result = segment_ground(scene.depth, K, scene.pose, scene.box, roi, CONFIG)
    assert result.plane is None
    assert not np.any(result.mask)
    assert result.n_seeds_used == 0


def test_segment_ground_depth_shape_mismatch_raises() -> None:
    scene = render()
    with pytest.raises(ValueError, match="depth_m"):
        segment_ground(scene.depth[:-1], K, scene.pose, scene.box, scene.roi, CONFIG)


def test_points_in_mask_rounds_to_nearest_pixel_and_rejects_outside() -> None:
    mask = np.zeros((4, 5), dtype=bool)
    mask[2, 3] = True
    pixels = np.array([[3.0, 2.0], [3.4, 1.6], [2.6, 2.4], [3.6, 2.0], [np.nan, 2.0], [-3.0, 2.0], [3.0, 9.0]])
    np.testing.assert_array_equal(points_in_mask(pixels, mask), [True, True, True, False, False, False, False])


@pytest.mark.parametrize(("field", "value"), [
    ("grid_tiles", 2), ("grid_tiles", 20.0), ("min_tile_px", 0), ("min_tile_points", 2), ("n_seeds", 0),
    ("growth_angle_deg", 0.0), ("normal_threshold_deg", 95.0), ("tile_mse_threshold_m2", -1e-3),
    ("mse_reference_depth_m", 0.0), ("mse_noise_factor", -1.0), ("fit_noise_sigmas", math.inf),
    ("max_ground_tilt_deg", 0.0), ("ground_percentile", 101.0), ("min_object_height_m", -0.1),
    ("max_object_height_m", 0.1), ("border_mse_factor", 0.0), ("border_min_distance_rel", math.nan),
])
def test_ground_segmentation_config_bad_field_is_named(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"GroundSegmentationConfig.{field} "):
        GroundSegmentationConfig(**{field: value})


# ------------------------------------------------------------------ ground filter labels (trade.ground_filter)
class _AffineInverseDepth:
    """Stub depth model: 0.3 + 25 / z of the scene's exact depth (an affine map of inverse depth)."""

    def __init__(self, depth_m: np.ndarray) -> None:
        self.depth_m = depth_m

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        return (0.3 + 25.0 / self.depth_m).astype(np.float32)


def test_ground_filter_converged_track_with_contradicting_depth_is_not_ground() -> None:
    # City seed 0: tracks on a moving car triangulate to 1-4 m, slide onto the street and sat in the mask;
    # the plane fit then chose them. A converged track is ground only if its depth agrees with the scaled map.
    scene = render(pitch_deg=20.0, buildings=(TOWER,))
    rng = np.random.default_rng(11)
    v, u = np.nonzero(ground_truth(scene))
    pick = rng.choice(len(v), 40, replace=False)
    pixels = np.c_[u[pick], v[pick]].astype(np.float64)
    depth = scene.depth[v[pick], u[pick]].astype(np.float64) * (1.0 + 0.01 * rng.standard_normal(40))
    depth[:4] = rng.uniform(1.0, 4.0, 4)  # wrong depths on street pixels
    promoted = np.ones(40, dtype=bool)
    promoted[-5:] = False  # not converged: labelled by the mask alone
    n = len(pixels)
    roi = RoiFeatures(pixels, pixels.copy(), np.full((n, 3), np.nan), depth, np.full(n, 0.3), promoted,
                      np.arange(n), np.zeros(n, dtype=np.int64), scene.roi)
    ground_filter = GroundFilter(GroundFilterConfig(), K, _AffineInverseDepth(scene.depth), np.random.default_rng(0))
    labels = ground_filter.update(np.zeros((K.height_px, K.width_px, 3), np.uint8), roi, scene.box, scene.pose)
    assert labels.ran_model and labels.mask is not None
    assert mask_iou(labels.mask.mask, ground_truth(scene)) >= 0.9
    assert not labels.ground[:4].any()  # in the mask, but their depth contradicts the map
    assert labels.ground[4:].mean() >= 0.9  # agreeing and unconverged street tracks stay ground
    np.testing.assert_array_equal(ground_filter.labels(roi), labels.ground)  # persisted for box-less frames


@pytest.mark.parametrize(("field", "value"), [("depth_agreement_sigmas", 0.0), ("depth_agreement_sigmas", math.inf)])
def test_ground_filter_config_bad_field_is_named(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"GroundFilterConfig.{field} "):
        GroundFilterConfig(**{field: value})
