"""Spec of trade.depth_alignment: 2-point RANSAC affine fit of model inverse depth to feature inverse depth."""

from __future__ import annotations

import numpy as np
import pytest

from trade.depth_alignment import (
    AffineFit, AffineFitConfig, FitStatus, align_model_depth, check_model_map, fit_affine_inverse_depth, metric_depth,
    sample_map,
)

THETA0, THETA1 = 0.012, 0.021  # rho = theta0 + theta1 rho' [1/m]


def _correspondences(rng: np.random.Generator, count: int, outlier_fraction: float, noise_inv_m: float = 2e-4):
    """rho' ~ U(0.5, 3); rho = THETA0 + THETA1 rho' + noise; a fraction replaced by U(0.01, 0.1) outliers."""
    model = rng.uniform(0.5, 3.0, count)
    rho = THETA0 + THETA1 * model + rng.normal(0.0, noise_inv_m, count)
    outlier = np.zeros(count, dtype=bool)
    outlier[rng.choice(count, int(round(outlier_fraction * count)), replace=False)] = True
    rho[outlier] = rng.uniform(0.01, 0.1, outlier.sum())
    return model, rho, outlier


def test_fit_affine_30_percent_outliers_recovers_scale_and_shift():
    rng = np.random.default_rng(3)
    model, rho, outlier = _correspondences(rng, 200, 0.3)
    fit = fit_affine_inverse_depth(model, rho, np.random.default_rng(0))
    assert fit.ok and fit.status is FitStatus.OK
    assert fit.theta1 == pytest.approx(THETA1, rel=0.02)
    assert fit.theta0 == pytest.approx(THETA0, abs=5e-4)
    # nearly all true inliers kept; outliers kept only where they happen to lie on the line
    assert fit.inliers[~outlier].mean() > 0.95
    residual = np.abs(THETA0 + THETA1 * model - rho)
    assert np.all(residual[fit.inliers] < AffineFitConfig().inlier_threshold_inv_m + 1e-3)


def test_fit_affine_plain_least_squares_beaten_by_ransac_with_outliers():
    model, rho, _ = _correspondences(np.random.default_rng(4), 200, 0.3)
    ls_theta1 = np.polyfit(model, rho, 1)[0]
    fit = fit_affine_inverse_depth(model, rho, np.random.default_rng(1))
    assert abs(fit.theta1 - THETA1) < 0.25 * abs(ls_theta1 - THETA1)


def test_fit_affine_all_equal_model_values_is_degenerate_not_raised():
    rho = np.random.default_rng(5).uniform(0.02, 0.05, 50)
    fit = fit_affine_inverse_depth(np.full(50, 1.7), rho, np.random.default_rng(0))
    assert fit.status is FitStatus.DEGENERATE and not fit.ok
    assert np.isnan(fit.theta0) and np.isnan(fit.theta1) and not fit.inliers.any()


def test_fit_affine_samples_closer_than_min_pixel_distance_are_degenerate():
    model, rho, _ = _correspondences(np.random.default_rng(6), 40, 0.0)
    pixels = np.full((40, 2), 50.0) + np.random.default_rng(7).uniform(0.0, 2.0, (40, 2))  # all within 3 px
    fit = fit_affine_inverse_depth(model, rho, np.random.default_rng(0), AffineFitConfig(min_sample_distance_px=5.0),
                                   pixels)
    assert fit.status is FitStatus.DEGENERATE


def test_fit_affine_min_model_separation_rejects_near_pairs():
    # two tight clusters in rho': with a separation of half the spread only cross-cluster pairs are sampled,
    # so every hypothesis spans both clusters and the exact line is found
    rng = np.random.default_rng(8)
    model = np.concatenate([1.0 + rng.uniform(0, 0.01, 30), 2.0 + rng.uniform(0, 0.01, 30)])
    rho = THETA0 + THETA1 * model
    fit = fit_affine_inverse_depth(model, rho, rng, AffineFitConfig(min_model_separation_fraction=0.5))
    assert fit.ok and fit.theta1 == pytest.approx(THETA1, rel=1e-9)


def test_fit_affine_too_few_points_flags_status():
    fit = fit_affine_inverse_depth([1.0, 2.0, 3.0], [0.02, 0.03, np.nan], np.random.default_rng(0))
    assert fit.status is FitStatus.TOO_FEW_POINTS and fit.inliers.shape == (3,)


def test_fit_affine_no_consensus_when_all_points_are_noise():
    rng = np.random.default_rng(9)
    fit = fit_affine_inverse_depth(rng.uniform(0, 1, 60), rng.uniform(0.01, 0.5, 60), rng,
                                   AffineFitConfig(inlier_threshold_inv_m=1e-4, min_inlier_fraction=0.5))
    assert fit.status is FitStatus.NO_CONSENSUS


def test_fit_affine_same_seed_same_result():
    model, rho, _ = _correspondences(np.random.default_rng(10), 100, 0.3)
    a = fit_affine_inverse_depth(model, rho, np.random.default_rng(2))
    b = fit_affine_inverse_depth(model, rho, np.random.default_rng(2))
    assert (a.theta0, a.theta1) == (b.theta0, b.theta1) and np.array_equal(a.inliers, b.inliers)


@pytest.mark.parametrize("bad", ["nan", "inf", "negative", "constant", "empty"])
def test_align_model_depth_invalid_model_output_flags_fallback(bad):
    model = np.random.default_rng(11).uniform(0.5, 3.0, (32, 32))
    if bad == "nan":
        model[3, 4] = np.nan
    elif bad == "inf":
        model[0, 0] = np.inf
    elif bad == "negative":
        model[5, 5] = -0.1
    elif bad == "constant":
        model[:] = 2.0
    else:
        model = np.zeros((0, 32))
    pixels = np.array([[3.0, 4.0], [10.0, 20.0], [25.0, 5.0]])
    assert check_model_map(model, AffineFitConfig()) is FitStatus.INVALID_MODEL_OUTPUT
    out = align_model_depth(model, pixels, np.array([20.0, 25.0, 30.0]), np.random.default_rng(0))
    assert not out.ok and out.fit.status is FitStatus.INVALID_MODEL_OUTPUT
    assert out.depth_m.shape == model.shape and np.all(np.isnan(out.depth_m))


def test_align_model_depth_tilted_plane_recovers_metric_depth():
    # ground plane seen by a pitched camera: 1/z = a + b v (affine in the image row); the "model" is an
    # arbitrary affine map of it, and 25 % of the features carry wrong depths
    h, w = 64, 80
    v = np.arange(h, dtype=np.float64)[:, None] * np.ones((1, w))
    true_inv = 0.02 + 0.0006 * v  # [1/m]: 50 m at the top row, ~17 m at the bottom
    model = (true_inv - THETA0) / THETA1
    rng = np.random.default_rng(12)
    pixels = np.stack([rng.uniform(0, w - 1, 80), rng.uniform(0, h - 1, 80)], 1)
    depth = 1.0 / (0.02 + 0.0006 * pixels[:, 1])
    depth[:20] *= rng.uniform(1.5, 3.0, 20)
    out = align_model_depth(model, pixels, depth, rng)
    assert out.ok
    np.testing.assert_allclose(out.depth_m, 1.0 / true_inv, rtol=1e-4)
    assert not out.fit.inliers[:20].any() and out.fit.inliers[20:].all()


def test_metric_depth_nonpositive_aligned_inverse_depth_is_nan():
    fit = AffineFit(-0.01, 0.02, np.ones(2, dtype=bool), FitStatus.OK)
    depth = metric_depth(np.array([[0.25, 0.5, 1.0]]), fit)  # rho = -0.005, 0, 0.01
    assert np.isnan(depth[0, 0]) and np.isnan(depth[0, 1]) and depth[0, 2] == pytest.approx(100.0)


def test_sample_map_bilinear_between_pixels():
    m = np.arange(12, dtype=np.float64).reshape(3, 4)  # value = 4 v + u
    np.testing.assert_allclose(sample_map(m, [[1.5, 0.5], [3.0, 2.0]]), [3.5, 11.0], atol=1e-5)


@pytest.mark.parametrize("field,value", [("inlier_threshold_inv_m", 0.0), ("iterations", 0),
                                         ("min_model_separation_fraction", 1.5), ("min_correspondences", 1),
                                         ("min_sample_distance_px", -1.0), ("min_inlier_fraction", -0.1)])
def test_config_invalid_field_raises_value_error_naming_it(field, value):
    with pytest.raises(ValueError, match=field):
        AffineFitConfig(**{field: value})
