"""Spec of the depth-only mode (trade.depth_only, paper Table 2) and the alignment fits it uses: plain least
squares and the scale-only fallback of trade.depth_alignment. Scenes are analytic: a pitched pinhole camera
over the ground plane z = 0; the "model" is an exact affine map of the true inverse depth (plus noise)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.depth_alignment import (
    AffineFitConfig, FitStatus, align_model_depth, fit_affine_inverse_depth, fit_affine_least_squares,
    fit_scale_only,
)
from trade.depth_only import DepthOnlyConfig, DepthOnlyLocaliser, box_window_depth
from trade.geometry import CameraIntrinsics, Pose
from trade.roi_features import RoiFeatures
from trade.types import BBox

K = CameraIntrinsics.from_fov(128, 128, 90.0)
ALTITUDE_M = 20.0
MODEL_SHIFT, MODEL_SCALE = 0.3, 25.0  # model rho' = shift + scale / z (an affine map of inverse depth)
BOX = BBox.from_center(64.0, 64.0, 12.0, 8.0)
ROI = BBox.from_center(64.0, 64.0, 60.0, 56.0)
IMAGE = np.zeros((K.height_px, K.width_px, 3), dtype=np.uint8)  # the stub model ignores the pixels


def pitched_pose(pitch_deg: float) -> Pose:
    """Camera ALTITUDE_M above the origin, optical axis pitched by pitch_deg from nadir towards +x."""
    p = math.radians(pitch_deg)
    z_axis = np.array([math.sin(p), 0.0, -math.cos(p)])
    x_axis = np.array([0.0, -1.0, 0.0])
    return Pose(np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis]), np.array([0.0, 0.0, ALTITUDE_M]))


def ground_depth(pose: Pose) -> np.ndarray:
    """(H, W) camera z [m] of the plane z = 0: z = -h / (R ray)_z for rays with camera z = 1."""
    v, u = np.mgrid[0:K.height_px, 0:K.width_px]
    rays_world = K.rays(np.c_[u.ravel(), v.ravel()].astype(np.float64)) @ pose.R.T
    return (-pose.t[2] / rays_world[:, 2]).reshape(K.height_px, K.width_px)


class StubModel:
    """Relative inverse depth shift + scale / z of a known depth map, optionally noisy; counts calls."""

    def __init__(self, depth_m: np.ndarray, noise: float = 0.0, seed: int = 0) -> None:
        self.depth_m, self.noise, self.calls = depth_m, noise, 0
        self._rng = np.random.default_rng(seed)

    def predict(self, rgb: np.ndarray) -> np.ndarray:
        self.calls += 1
        inv = MODEL_SHIFT + MODEL_SCALE / self.depth_m
        return (inv + self.noise * self._rng.standard_normal(inv.shape)).astype(np.float32)


def roi_features(depth_m: np.ndarray, count: int, rng: np.random.Generator, outlier_fraction: float = 0.0,
                 roi: BBox = ROI) -> RoiFeatures:
    """Promoted tracks at random pixels of the ROI outside the box with the true depth; a fraction of them
    carries a wrong depth (x U(1.5, 3))."""
    pixels = np.empty((0, 2))
    while len(pixels) < count:
        cand = rng.uniform([roi.x_px, roi.y_px], [roi.x_px + roi.w_px - 1, roi.y_px + roi.h_px - 1], (count, 2))
        in_box = ((cand[:, 0] >= BOX.x_px) & (cand[:, 0] <= BOX.x_px + BOX.w_px)
                  & (cand[:, 1] >= BOX.y_px) & (cand[:, 1] <= BOX.y_px + BOX.h_px))
        pixels = np.vstack([pixels, cand[~in_box]])[:count]
    pixels = np.rint(pixels)  # pixel centres: the features' depths are exactly the map's values there
    uv = pixels.astype(int)
    depth = depth_m[uv[:, 1], uv[:, 0]].astype(np.float64)
    n_out = int(round(outlier_fraction * count))
    depth[:n_out] *= rng.uniform(1.5, 3.0, n_out)
    n = len(pixels)
    return RoiFeatures(pixels, pixels.copy(), np.full((n, 3), np.nan), depth, np.full(n, 0.1), np.ones(n, bool),
                       np.arange(n), np.zeros(n, dtype=np.int64), roi)


def localiser(model: StubModel, ransac: bool = True, **config) -> DepthOnlyLocaliser:
    return DepthOnlyLocaliser(DepthOnlyConfig(**config), K, model, np.random.default_rng(0), ransac)


# ------------------------------------------------------------------ alignment fits
def test_fit_least_squares_clean_correspondences_recover_scale_and_shift():
    rng = np.random.default_rng(1)
    model = rng.uniform(0.5, 3.0, 50)
    fit = fit_affine_least_squares(model, 0.01 + 0.02 * model)
    assert fit.ok and not fit.scale_only and fit.inliers.all()
    assert fit.theta0 == pytest.approx(0.01, abs=1e-12) and fit.theta1 == pytest.approx(0.02, rel=1e-12)
    assert fit.rms_inv_m == pytest.approx(0.0, abs=1e-12)


def test_fit_least_squares_outliers_pull_it_off_where_ransac_holds():
    rng = np.random.default_rng(2)
    model = rng.uniform(0.5, 3.0, 100)
    rho = 0.01 + 0.02 * model
    rho[:30] = rng.uniform(0.01, 0.1, 30)
    plain = fit_affine_least_squares(model, rho)
    robust = fit_affine_inverse_depth(model, rho, np.random.default_rng(0))
    assert plain.ok and robust.ok
    assert abs(robust.theta1 - 0.02) < 1e-3 < abs(plain.theta1 - 0.02)


@pytest.mark.parametrize(("model", "rho", "status"), [
    (np.arange(4.0), 0.01 + 0.02 * np.arange(4.0), FitStatus.TOO_FEW_POINTS),  # < min_correspondences
    (np.full(10, 1.5), np.linspace(0.02, 0.05, 10), FitStatus.DEGENERATE),  # constant model values
    (np.arange(10.0), 0.5 - 0.02 * np.arange(10.0), FitStatus.NO_CONSENSUS),  # inverse depth falls: theta1 < 0
])
def test_fit_least_squares_unusable_input_flags_status_not_raised(model, rho, status):
    fit = fit_affine_least_squares(model, rho)
    assert fit.status is status and not fit.ok and np.isnan(fit.theta1)


def test_fit_scale_only_outliers_rejected_scale_recovered():
    rng = np.random.default_rng(3)
    model = rng.uniform(1.0, 1.05, 40)
    rho = 0.03 * model
    rho[:10] *= 2.0
    fit = fit_scale_only(model, rho)
    assert fit.ok and fit.scale_only and fit.theta0 == 0.0
    assert fit.theta1 == pytest.approx(0.03, rel=1e-9)
    assert not fit.inliers[:10].any() and fit.inliers[10:].all()


def test_align_features_on_one_depth_level_fit_scale_only_and_avoid_noise_gain():
    # nadir view: the ground is parallel to the image, so the features' rho' differ by model noise only and a
    # two-parameter fit has no scale information; the tilted far part of the map gives the map its range
    depth = ground_depth(pitched_pose(0.0))
    depth[:, 96:] = ground_depth(pitched_pose(40.0))[:, 96:]  # a far slope at the image's right edge
    model = StubModel(depth, noise=0.002, seed=4).predict(IMAGE)
    feats = roi_features(depth, 30, np.random.default_rng(5), roi=BBox.from_center(48.0, 64.0, 40.0, 40.0))
    guarded = align_model_depth(model, feats.pixels, feats.depth_m, np.random.default_rng(0))
    free = align_model_depth(model, feats.pixels, feats.depth_m, np.random.default_rng(0),
                             AffineFitConfig(min_feature_range_fraction=0.0))
    assert guarded.ok and guarded.fit.scale_only and not free.fit.scale_only
    patch = (slice(44, 84), slice(28, 68))
    err_guarded = np.nanmax(np.abs(guarded.depth_m[patch] / depth[patch] - 1.0))
    err_free = np.nanmax(np.abs(free.depth_m[patch] / depth[patch] - 1.0)) if free.ok else np.inf
    assert err_guarded < 0.03 < err_free


# ------------------------------------------------------------------ reading the map
def test_box_window_depth_median_of_central_window_ignores_nan():
    d = np.full((20, 20), 50.0)
    d[8:12, 8:12] = 10.0  # the target's centre
    d[9, 9] = np.nan
    box = BBox(6.0, 6.0, 8.0, 8.0)  # centre (10, 10); half window 2 px
    assert box_window_depth(d, box, 0.5) == 10.0
    assert box_window_depth(d, box, 1.0) == 50.0  # the whole box: the background dominates
    assert math.isnan(box_window_depth(np.full((20, 20), np.nan), box, 0.5))


def test_depth_only_exact_model_reads_true_depth_at_box():
    pose = pitched_pose(30.0)
    depth = ground_depth(pose)
    est = localiser(StubModel(depth)).update(IMAGE, roi_features(depth, 40, np.random.default_rng(6)), BOX, pose)
    truth = box_window_depth(depth, BOX, DepthOnlyConfig().box_window_fraction)
    assert est.fit is not None and est.fit.ok and not est.fit.scale_only
    assert est.depth_m == pytest.approx(truth, rel=1e-4)
    assert est.sigma_m == DepthOnlyConfig().min_depth_sigma_m  # exact fit: the floor
    assert abs(est.position_world_m[2]) < 1e-3 * truth  # the box centre's ray at that depth: on the ground
    np.testing.assert_allclose(est.depth_map_m, depth, rtol=1e-4)


def test_depth_only_outlier_features_ransac_beats_least_squares():
    pose = pitched_pose(30.0)
    depth = ground_depth(pose)
    truth = box_window_depth(depth, BOX, DepthOnlyConfig().box_window_fraction)
    errors = {}
    for ransac in (True, False):
        feats = roi_features(depth, 40, np.random.default_rng(7), outlier_fraction=0.3)
        est = localiser(StubModel(depth, noise=0.001), ransac).update(IMAGE, feats, BOX, pose)
        errors[ransac] = abs(est.depth_m - truth) / truth
    assert errors[True] < 0.01
    assert errors[False] > 5 * errors[True]


def test_depth_only_runs_model_every_nth_frame_and_reads_last_map_between():
    pose = pitched_pose(30.0)
    depth = ground_depth(pose)
    model = StubModel(depth)
    loc = localiser(model, every_n_frames=3)
    feats = roi_features(depth, 40, np.random.default_rng(8))
    ests = [loc.update(IMAGE, feats, BOX, pose) for _ in range(7)]
    assert model.calls == 3  # frames 0, 3, 6
    assert [e.fit is not None for e in ests] == [True, False, False, True, False, False, True]
    assert ests[1].depth_map_m is ests[0].depth_map_m and np.isfinite(ests[2].depth_m)


def test_depth_only_lost_target_no_depth_but_map_kept_for_ground_depth():
    pose = pitched_pose(30.0)
    depth = ground_depth(pose)
    est = localiser(StubModel(depth)).update(IMAGE, roi_features(depth, 40, np.random.default_rng(9)), None, pose)
    assert math.isnan(est.depth_m) and np.all(np.isnan(est.position_world_m))
    assert est.depth_map_m is not None


def test_depth_only_too_few_converged_features_no_map_no_depth():
    pose = pitched_pose(30.0)
    depth = ground_depth(pose)
    model = StubModel(depth)
    est = localiser(model).update(IMAGE, roi_features(depth, 5, np.random.default_rng(10)), BOX, pose)
    assert model.calls == 0 and est.depth_map_m is None and math.isnan(est.depth_m)


@pytest.mark.parametrize(("field", "value"), [("every_n_frames", 0), ("min_promoted_features", 1),
                                              ("box_window_fraction", 0.0), ("box_window_fraction", 1.5),
                                              ("min_depth_sigma_m", 0.0)])
def test_depth_only_config_invalid_field_raises_value_error_naming_it(field, value):
    with pytest.raises(ValueError, match=field):
        DepthOnlyConfig(**{field: value})
