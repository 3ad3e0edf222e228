"""Spec of ROI feature tracking and per-track depth fusion (trade/roi_features.py), on synthetic scenes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trade.geometry import CameraIntrinsics, Pose, project_world
from trade.roi_features import (
    CENTRE_TILE,
    RoiConfig,
    RoiFeatureTracker,
    fuse_gaussian,
    fuse_inverse_depth,
    roi_tile_edges,
    tile_index,
    triangulate_first_ray,
)
from trade.types import BBox

SIZE_PX = 256
FOV_DEG = 60.0
HEIGHT_M = 10.0  # camera height above the ground plane z = 0
PITCH_DEG = 15.0  # camera tilted about its x axis, so depth varies across the image
STEP_M = 0.1  # sideways camera motion per frame (~2.2 px image shift at the centre)
TEXTURE_PX = 768
TEXTURE_FOCAL_PX = 200.0  # texture = nadir view from HEIGHT_M over the origin
BOX = BBox.from_center(SIZE_PX / 2, SIZE_PX / 2, 30.0, 30.0)
R_DOWN = np.diag([1.0, -1.0, -1.0])  # camera x = world x, camera z = world -z (nadir)
N_WORLD = np.array([0.0, 0.0, 1.0])


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _camera_pose(x_m: float) -> Pose:
    return Pose(R_DOWN @ _rot_x(np.radians(PITCH_DEG)), np.array([x_m, 0.0, HEIGHT_M]))


def _texture(rng: np.random.Generator) -> np.ndarray:
    noise = cv2.GaussianBlur(rng.random((TEXTURE_PX, TEXTURE_PX)), (0, 0), 1.5)
    return cv2.normalize(noise, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _render(texture: np.ndarray, K: CameraIntrinsics, T_world_cam: Pose, interpolation: int = cv2.INTER_LINEAR
            ) -> np.ndarray:
    """Ground plane z = 0 seen from T_world_cam: warp by H = K (R + t n^T / d) K_tex^-1 (plane n . X = d)."""
    K_tex = np.array([[TEXTURE_FOCAL_PX, 0, TEXTURE_PX / 2], [0, TEXTURE_FOCAL_PX, TEXTURE_PX / 2], [0, 0, 1]])
    T_world_tex = Pose(R_DOWN, np.array([0.0, 0.0, HEIGHT_M]))
    T_cam_tex = T_world_cam.inverse().compose(T_world_tex)
    n_tex, d_tex = T_world_tex.R.T @ N_WORLD, -N_WORLD @ T_world_tex.t
    H = K.K @ (T_cam_tex.R + np.outer(T_cam_tex.t, n_tex) / d_tex) @ np.linalg.inv(K_tex)
    return cv2.warpPerspective(texture, H, (K.width_px, K.height_px), flags=interpolation)


def _plane_depth(K: CameraIntrinsics, T_world_cam: Pose, pixels: np.ndarray) -> np.ndarray:
    """Camera z of the ground plane along each pixel's ray: z = d_c / (n_c . r)."""
    n_cam, d_cam = T_world_cam.R.T @ N_WORLD, -N_WORLD @ T_world_cam.t
    return d_cam / (K.rays(pixels) @ n_cam)


def _plane_point(K: CameraIntrinsics, T_world_cam: Pose, pixels: np.ndarray) -> np.ndarray:
    return T_world_cam.apply(K.backproject(pixels, _plane_depth(K, T_world_cam, pixels)))


def _run_sequence(n_frames: int):
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    texture = _texture(np.random.default_rng(7))
    tracker = RoiFeatureTracker(RoiConfig(), K)
    outputs, poses = [], []
    for k in range(n_frames):
        pose = _camera_pose(k * STEP_M)
        outputs.append(tracker.step(_render(texture, K, pose), BOX, pose))
        poses.append(pose)
    return K, outputs, poses


@pytest.fixture(scope="module")
def sequence():
    return _run_sequence(n_frames=30)


def test_step_features_fill_outer_tiles_only(sequence) -> None:
    _, outputs, _ = sequence
    first = outputs[0]
    counts = np.bincount(first.tile, minlength=9)
    assert counts[CENTRE_TILE] == 0 and np.all(first.tile >= 0)
    assert np.all(counts[np.arange(9) != CENTRE_TILE] >= 20) and np.all(counts <= 25)
    for out in outputs:
        in_box = (out.pixels[:, 0] >= BOX.x_px) & (out.pixels[:, 0] < BOX.x_px + BOX.w_px)
        in_box &= (out.pixels[:, 1] >= BOX.y_px) & (out.pixels[:, 1] < BOX.y_px + BOX.h_px)
        assert not np.any(in_box)
        assert np.all(np.bincount(out.tile, minlength=9) <= 25)


def test_klt_shifted_texture_keeps_most_tracks_on_true_positions(sequence) -> None:
    K, outputs, poses = sequence
    first_seen: dict[int, tuple[np.ndarray, Pose]] = {}
    for k in range(1, len(outputs)):
        prev, out = outputs[k - 1], outputs[k]
        assert np.isin(prev.track_ids, out.track_ids).mean() >= 0.85
        for i, px in zip(prev.track_ids, prev.pixels):
            first_seen.setdefault(int(i), (px, poses[k - 1]))
    last, pose = outputs[-1], poses[-1]
    errors = []
    for i, px in zip(last.track_ids, last.pixels):
        if int(i) in first_seen:  # transfer the first observation through the ground plane
            px0, pose0 = first_seen[int(i)]
            truth = project_world(K, pose, _plane_point(K, pose0, px0[None]))[0]
            errors.append(np.linalg.norm(px - truth))
    assert len(errors) >= 100
    assert np.median(errors) < 0.3 and np.percentile(errors, 95) < 1.0


def test_depth_textured_plane_promoted_points_within_2_percent(sequence) -> None:
    K, outputs, poses = sequence
    last, pose = outputs[-1], poses[-1]
    promoted = last.promoted
    assert promoted.sum() >= 120
    truth = _plane_depth(K, pose, last.pixels[promoted])
    rel = np.abs(last.depth_m[promoted] - truth) / truth
    assert np.median(rel) < 0.01 and np.max(rel) < 0.02
    assert np.all(np.abs(last.points_world[promoted, 2]) < 0.2)  # on the ground plane z = 0
    assert np.all(last.sigma_m[promoted] <= 0.5)
    untriangulated = ~np.isfinite(last.depth_m)
    assert np.all(np.isinf(last.sigma_m[untriangulated])) and not np.any(last.promoted[untriangulated])


def _static_points(seed: int, n: int, depth_range_m: tuple[float, float]):
    """n static world points seen at random pixels and depths from the first camera pose."""
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    rng = np.random.default_rng(seed)
    pose0 = _camera_pose(0.0)
    pixels0 = rng.uniform(40, SIZE_PX - 40, (n, 2))
    depth0 = rng.uniform(*depth_range_m, n)
    return K, rng, pose0, pixels0, depth0, pose0.apply(K.backproject(pixels0, depth0))


def test_depth_filter_static_point_translating_camera_converges_within_2_percent() -> None:
    config = RoiConfig(pixel_sigma_px=0.3)
    n = 20
    K, rng, pose0, pixels0, depth0, points = _static_points(11, n, (12.0, 25.0))
    noisy0 = pixels0 + rng.normal(0.0, 0.3, (n, 2))
    center0 = np.broadcast_to(pose0.t, (n, 3))
    ray0 = K.rays(noisy0) @ pose0.R.T
    inv_mu, precision = np.zeros(n), np.zeros(n)
    sigmas = []
    for k in range(1, 61):
        pose = _camera_pose(k * 0.2)
        pixels = project_world(K, pose, points) + rng.normal(0.0, 0.3, (n, 2))
        tv = triangulate_first_ray(center0, ray0, pose.t, K.rays(pixels) @ pose.R.T, K.fx_px, config)
        assert np.all(tv.ray_gap_px[tv.valid] < 2.0)
        inv_mu[tv.valid], precision[tv.valid] = fuse_inverse_depth(
            inv_mu[tv.valid], precision[tv.valid], tv.depth_first_m[tv.valid], tv.sigma_first_m[tv.valid]
        )
        if k >= 5:  # every point triangulated by now (parallax >= min_parallax_deg)
            sigmas.append(np.square(1.0 / inv_mu) / np.sqrt(precision))  # sigma(d) = d^2 sigma(1/d)
    assert np.all(np.abs(1.0 / inv_mu - depth0) / depth0 < 0.02)
    assert np.all(np.diff(np.array(sigmas), axis=0) <= 0)  # fusion never increases the uncertainty
    assert np.all(sigmas[-1] < 0.01 * depth0)


def test_inverse_depth_fusion_is_less_biased_than_depth_fusion_at_small_parallax() -> None:
    """Two-view depths from short baselines: fusing them in depth pulls towards the near estimates (weights
    1/sigma^2 fall as depth^-4); fusing inverse depth keeps the mean within 2 % after 12 frames of 5 cm."""
    config = RoiConfig(pixel_sigma_px=0.5)
    n = 2000
    K, rng, pose0, pixels0, depth0, points = _static_points(3, n, (15.0, 25.0))
    center0, ray0 = np.broadcast_to(pose0.t, (n, 3)), K.rays(pixels0) @ pose0.R.T
    mu, precision, inv_mu, inv_precision = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    for k in range(1, 13):
        pose = _camera_pose(k * 0.05)
        pixels = project_world(K, pose, points) + rng.normal(0.0, 0.5, (n, 2))
        tv = triangulate_first_ray(center0, ray0, pose.t, K.rays(pixels) @ pose.R.T, K.fx_px, config)
        v = tv.valid
        mu[v], precision[v] = fuse_gaussian(mu[v], precision[v], tv.depth_first_m[v], tv.sigma_first_m[v])
        inv_mu[v], inv_precision[v] = fuse_inverse_depth(inv_mu[v], inv_precision[v], tv.depth_first_m[v],
                                                         tv.sigma_first_m[v])
    assert np.all(inv_precision > 0)
    bias_depth = np.mean((mu - depth0) / depth0)
    bias_inverse = np.mean((1.0 / inv_mu - depth0) / depth0)
    assert bias_depth < -0.03  # the near pull this module avoids
    assert abs(bias_inverse) < 0.02 and abs(bias_inverse) < 0.5 * abs(bias_depth)


def _track_errors_px(anchor: bool, n_frames: int, step_m: float) -> np.ndarray:
    """Pixel errors of the tracks alive at the end of a slow sideways pass over the textured plane, rendered
    with nearest-texel sampling as pybullet's TinyRenderer does (the image moves in whole-pixel steps)."""
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    texture = _texture(np.random.default_rng(5))
    tracker = RoiFeatureTracker(RoiConfig(anchor_to_first_image=anchor), K)
    first_seen: dict[int, tuple[np.ndarray, Pose]] = {}
    for k in range(n_frames):
        pose = _camera_pose(k * step_m)
        out = tracker.step(_render(texture, K, pose, cv2.INTER_NEAREST), BOX, pose)
        for i, px in zip(out.track_ids, out.first_pixels):
            first_seen.setdefault(int(i), (px, pose))
    errors = [np.linalg.norm(px - project_world(K, pose, _plane_point(K, first_seen[int(i)][1], px0[None]))[0])
              for i, px, px0 in zip(out.track_ids, out.pixels, out.first_pixels) if first_seen[int(i)][1] is not pose]
    return np.asarray(errors)


def test_anchoring_to_first_image_keeps_long_tracks_on_their_points() -> None:
    """60 frames of ~0.2 px image motion: chained frame to frame, KLT drifts by about a pixel (median);
    refined against their first image, tracks stay within a few tenths of a pixel of the true projection."""
    anchored = _track_errors_px(anchor=True, n_frames=60, step_m=0.01)
    chained = _track_errors_px(anchor=False, n_frames=60, step_m=0.01)
    assert len(anchored) >= 100 and len(chained) >= 100
    assert np.median(anchored) < 0.2 and np.percentile(anchored, 95) < 0.6
    assert np.median(chained) > 3.0 * np.median(anchored)


def test_triangulate_moving_point_large_ray_gap() -> None:
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    pose0, pose1 = _camera_pose(0.0), _camera_pose(1.0)
    point0 = np.array([[0.5, 2.0, 0.0]])
    moved = point0 + np.array([[0.0, 1.0, 0.0]])  # moved across the epipolar plane

    def two_view(point1: np.ndarray):
        ray0 = K.rays(project_world(K, pose0, point0)) @ pose0.R.T
        ray1 = K.rays(project_world(K, pose1, point1)) @ pose1.R.T
        return triangulate_first_ray(pose0.t[None], ray0, pose1.t, ray1, K.fx_px, RoiConfig())

    static, moving = two_view(point0), two_view(moved)
    assert static.valid[0] and static.ray_gap_px[0] < 1e-6
    assert static.depth_first_m[0] == pytest.approx(pose0.inverse().apply(point0)[0, 2])
    assert moving.ray_gap_px[0] > 5.0


def test_step_box_at_image_corner_keeps_features_inside_image_and_roi() -> None:
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    texture = _texture(np.random.default_rng(5))
    tracker = RoiFeatureTracker(RoiConfig(), K)
    box = BBox(-10.0, 200.0, 30.0, 40.0)  # partly outside: ROI clipped by the left and bottom borders
    xs, ys = roi_tile_edges(box, RoiConfig().roi_margin_factor)
    assert xs[1] < 0 and 0 < ys[2] < SIZE_PX < ys[3]  # left tile column entirely outside the image
    for k in range(5):
        out = tracker.step(_render(texture, K, _camera_pose(k * STEP_M)), box, _camera_pose(k * STEP_M))
        assert len(out.track_ids) > 0
        assert np.all((out.pixels >= 0) & (out.pixels <= SIZE_PX - 1))
        assert np.all(out.tile >= 0) and not np.any(out.tile == CENTRE_TILE)
        assert not np.any(np.isin(out.tile, [0, 3, 6]))


def test_fuse_gaussian_matches_product_of_gaussians() -> None:
    mu, precision = fuse_gaussian(np.array([10.0]), np.array([1.0 / 4.0]), np.array([12.0]), np.array([1.0]))
    assert precision[0] == pytest.approx(1.25)  # 1/s^2 = 1/4 + 1/1
    assert mu[0] == pytest.approx((10.0 / 4.0 + 12.0) / 1.25)


def test_tile_index_grid_edges_and_outside() -> None:
    xs, ys = roi_tile_edges(BBox(100.0, 100.0, 20.0, 40.0), 2.0)
    np.testing.assert_allclose(xs, [60.0, 100.0, 120.0, 160.0])
    np.testing.assert_allclose(ys, [60.0, 100.0, 140.0, 180.0])
    px = np.array([[60.0, 60.0], [110.0, 120.0], [159.9, 179.9], [160.0, 100.0], [59.9, 100.0]])
    np.testing.assert_array_equal(tile_index(px, xs, ys), [0, CENTRE_TILE, 8, -1, -1])


def test_reset_clears_tracks_and_restarts_detection() -> None:
    K = CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG)
    image = _render(_texture(np.random.default_rng(3)), K, _camera_pose(0.0))
    tracker = RoiFeatureTracker(RoiConfig(), K)
    first = tracker.step(image, BOX, _camera_pose(0.0))
    tracker.reset()
    again = tracker.step(image, BOX, _camera_pose(0.0))
    np.testing.assert_array_equal(first.track_ids, again.track_ids)
    np.testing.assert_array_equal(first.pixels, again.pixels)
    assert len(np.unique(first.track_ids)) == len(first.track_ids)


def test_step_wrong_image_shape_raises() -> None:
    tracker = RoiFeatureTracker(RoiConfig(), CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG))
    with pytest.raises(ValueError, match="uint8"):
        tracker.step(np.zeros((SIZE_PX, SIZE_PX + 1), np.uint8), BOX, Pose.identity())


def test_config_invalid_margin_names_field() -> None:
    with pytest.raises(ValueError, match="roi_margin_factor"):
        RoiConfig(roi_margin_factor=0.0)
