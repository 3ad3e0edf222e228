"""Spec tests for trade.planes: Plane helpers, least-squares fit, multi-model MSAC selection."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.planes import MultiRansacConfig, Plane, fit_plane_lstsq, multi_ransac, select_ground

NOISE_M = 0.05
QUERY_XY = np.array([10.0, 10.0])  # target position, on the ground patch
ROOF_XY = np.array([-12.5, -12.5])  # centre of the roof patch


def plane_points(rng: np.random.Generator, n: int, plane: Plane, lo: float, hi: float) -> np.ndarray:
    """n points on `plane` over x, y in [lo, hi], with Gaussian noise NOISE_M along the normal."""
    xy = rng.uniform(lo, hi, (n, 2))
    z = -(xy @ plane.normal[:2] + plane.offset_m) / plane.normal[2]
    return np.c_[xy, z] + rng.normal(0.0, NOISE_M, (n, 1)) * plane.normal


def tilted(tilt_deg: float, offset_m: float = 0.0, azimuth_deg: float = 30.0) -> Plane:
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    return Plane(np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)]), offset_m)


def angle_deg(a: Plane, b: Plane) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(a.normal @ b.normal)))))


def max_gap_m(fit: Plane, truth: Plane, lo: float, hi: float) -> float:
    """Largest distance from `fit` of the true plane's points over the patch corners."""
    corners = np.array([[x, y] for x in (lo, hi) for y in (lo, hi)], dtype=float)
    z = -(corners @ truth.normal[:2] + truth.offset_m) / truth.normal[2]
    return float(np.max(np.abs(fit.signed_distance(np.c_[corners, z]))))


def roof_scene(rng: np.random.Generator, ground: Plane, n: int = 300) -> np.ndarray:
    """40 % roof 30 m up (west), 30 % ground (east), 30 % uniform outliers."""
    roof = plane_points(rng, int(0.4 * n), Plane(np.array([0.0, 0.0, 1.0]), -30.0), -20.0, -5.0)
    grd = plane_points(rng, int(0.3 * n), ground, 0.0, 20.0)
    n_out = n - roof.shape[0] - grd.shape[0]
    outliers = np.c_[rng.uniform(-20.0, 20.0, (n_out, 2)), rng.uniform(-5.0, 35.0, n_out)]
    return np.r_[roof, grd, outliers]


def test_plane_downward_normal_is_flipped_and_normalised() -> None:
    p = Plane(np.array([0.0, 0.0, -2.0]), 4.0)  # -2z + 4 = 0  <=>  z = 2
    np.testing.assert_allclose(p.normal, [0.0, 0.0, 1.0])
    assert p.offset_m == pytest.approx(-2.0)
    assert p.height_at([5.0, -3.0]) == pytest.approx(2.0)


@pytest.mark.parametrize("normal", [[0.0, 0.0, 0.0], [np.nan, 0.0, 1.0]])
def test_plane_invalid_normal_raises(normal: list[float]) -> None:
    with pytest.raises(ValueError, match="normal"):
        Plane(np.array(normal), 0.0)


def test_plane_lifted_moves_every_point_up_along_normal() -> None:
    p = tilted(25.0, offset_m=3.0)
    pts = plane_points(np.random.default_rng(1), 20, Plane(p.normal, p.offset_m), -5.0, 5.0)
    on_plane = pts - np.outer(p.signed_distance(pts), p.normal)
    np.testing.assert_allclose(p.lifted(0.8).signed_distance(on_plane + 0.8 * p.normal), 0.0, atol=1e-12)
    np.testing.assert_allclose(p.lifted(0.8).signed_distance(on_plane), -0.8, atol=1e-12)
    assert p.tilt_deg == pytest.approx(25.0)


def test_fit_plane_lstsq_noise_free_points_recovers_plane_and_zero_mse() -> None:
    truth = tilted(40.0, offset_m=-7.0)
    pts = plane_points(np.random.default_rng(2), 50, truth, -10.0, 10.0)
    pts -= np.outer(truth.signed_distance(pts), truth.normal)  # project noise away
    fit = fit_plane_lstsq(pts)
    assert angle_deg(fit, truth) < 1e-6 and fit.offset_m == pytest.approx(truth.offset_m)
    assert fit.mse_m2 < 1e-18 and fit.n_inliers == 50


def test_fit_plane_lstsq_mse_equals_mean_squared_residual() -> None:
    pts = np.random.default_rng(3).normal(size=(40, 3)) * [10.0, 10.0, 0.3]
    fit = fit_plane_lstsq(pts)
    assert fit.mse_m2 == pytest.approx(float(np.mean(fit.signed_distance(pts) ** 2)))


@pytest.mark.parametrize(
    ("field", "value"),
    [("inlier_threshold_m", 0.0), ("max_solutions", 0), ("min_normal_angle_deg", 91.0),
     ("max_shared_inlier_fraction", 1.5), ("min_inlier_fraction_of_best", 0.0), ("confidence", 1.0),
     ("min_iterations", 1000), ("parallel_min_separation_m", 0.0), ("flatness_tolerance_deg", -1.0)],
)
def test_multi_ransac_config_bad_field_raises_naming_it(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        MultiRansacConfig(**{field: value})


@pytest.mark.parametrize("seed", range(5))
def test_multi_ransac_tilted_plane_with_30pct_outliers_within_1deg_and_10cm(seed: int) -> None:
    rng = np.random.default_rng(seed)
    truth = tilted(20.0, offset_m=4.0, azimuth_deg=70.0)
    inl = plane_points(rng, 210, truth, -15.0, 15.0)
    out = np.c_[rng.uniform(-15.0, 15.0, (90, 2)), rng.uniform(-12.0, 12.0, 90)]
    res = multi_ransac(np.r_[inl, out], MultiRansacConfig(), np.random.default_rng(100 + seed))
    assert res is not None
    assert angle_deg(res.selected, truth) < 1.0
    assert max_gap_m(res.selected, truth, -15.0, 15.0) < 0.1
    assert res.inlier_mask[:210].mean() > 0.95 and res.inlier_mask[210:].mean() < 0.2


@pytest.mark.parametrize("seed", range(5))
def test_multi_ransac_larger_roof_30m_above_ground_selects_the_lower_ground(seed: int) -> None:
    ground = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
    pts = roof_scene(np.random.default_rng(seed), ground)
    res = multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(100 + seed), QUERY_XY)
    assert res is not None
    assert angle_deg(res.selected, ground) < 1.0
    assert abs(res.selected.height_at(QUERY_XY)) < 0.1  # at the target; band outliers 30 m off tilt it
    assert any(abs(p.height_at(ROOF_XY) - 30.0) < 0.2 for p in res.solutions), "roof should be a solution"
    assert res.solutions[0].n_inliers > res.selected.n_inliers, "roof is the largest, ground still wins"


def test_multi_ransac_paper_literal_rule_parallel_roof_hides_the_ground() -> None:
    """With parallel_min_separation_m = inf, planes < 15 deg apart are duplicates (paper text):
    the larger roof suppresses the ground; this is the failure the ground mask exists for."""
    pts = roof_scene(np.random.default_rng(7), Plane(np.array([0.0, 0.0, 1.0]), 0.0))
    cfg = MultiRansacConfig(parallel_min_separation_m=math.inf)
    res = multi_ransac(pts, cfg, np.random.default_rng(8), QUERY_XY)
    assert res is not None and len(res.solutions) == 1
    assert res.selected.height_at(ROOF_XY) == pytest.approx(30.0, abs=0.2)


def test_multi_ransac_ground_2deg_vs_flat_roof_tie_break_depends_on_tolerance() -> None:
    ground = tilted(2.0)
    pts = roof_scene(np.random.default_rng(9), ground)
    lowest = multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(10), QUERY_XY)
    strict = multi_ransac(pts, MultiRansacConfig(flatness_tolerance_deg=0.0), np.random.default_rng(10), QUERY_XY)
    assert lowest is not None and strict is not None
    assert angle_deg(lowest.selected, ground) < 1.0  # within 3 deg of the flattest: lowest wins
    assert strict.selected.height_at(ROOF_XY) == pytest.approx(30.0, abs=0.2)  # strictly flattest


def test_multi_ransac_larger_steep_slope_loses_to_flatter_ground() -> None:
    rng = np.random.default_rng(11)
    ground, slope = tilted(3.0, offset_m=1.0), tilted(35.0, offset_m=-2.0, azimuth_deg=200.0)
    pts = np.r_[plane_points(rng, 150, slope, -20.0, 0.0), plane_points(rng, 90, ground, 0.0, 20.0),
                np.c_[rng.uniform(-20.0, 20.0, (60, 2)), rng.uniform(-10.0, 20.0, 60)]]
    res = multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(12), QUERY_XY)
    assert res is not None and len(res.solutions) >= 2
    assert angle_deg(res.selected, ground) < 1.0
    assert abs(res.selected.height_at(QUERY_XY) - ground.height_at(QUERY_XY)) < 0.1
    assert angle_deg(res.solutions[0], slope) < 1.0, "the slope has the lowest MSAC cost"


@pytest.mark.parametrize("seed", range(3))
def test_multi_ransac_solutions_respect_count_and_distinctness_limits(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pts = np.r_[roof_scene(rng, tilted(4.0)), plane_points(rng, 100, tilted(30.0, -5.0), 5.0, 20.0)]
    cfg = MultiRansacConfig()
    res = multi_ransac(pts, cfg, np.random.default_rng(50 + seed), QUERY_XY)
    assert res is not None and 1 <= len(res.solutions) <= cfg.max_solutions
    best = max(p.n_inliers for p in res.solutions)
    masks = [np.abs(p.signed_distance(pts)) < cfg.inlier_threshold_m for p in res.solutions]
    for i, (p, m) in enumerate(zip(res.solutions, masks, strict=True)):
        assert p.n_inliers >= cfg.min_inlier_fraction_of_best * best
        assert p.n_inliers == int(m.sum())
        for q, mq in zip(res.solutions[:i], masks[:i], strict=True):
            assert np.count_nonzero(m & mq) / m.sum() <= cfg.max_shared_inlier_fraction
            parallel_and_close = angle_deg(p, q) < cfg.min_normal_angle_deg and abs(
                q.signed_distance(pts[m].mean(axis=0))[0]) < cfg.parallel_min_separation_m
            assert not parallel_and_close


def test_multi_ransac_inlier_mask_is_selected_planes_band_and_skips_nonfinite_rows() -> None:
    rng = np.random.default_rng(13)
    pts = np.r_[plane_points(rng, 100, tilted(10.0), -10.0, 10.0), [[np.nan, 0.0, 0.0]]]
    cfg = MultiRansacConfig()
    res = multi_ransac(pts, cfg, rng)
    assert res is not None and res.inlier_mask.shape == (101,) and not res.inlier_mask[-1]
    expected = np.abs(res.selected.signed_distance(pts[:-1])) < cfg.inlier_threshold_m
    np.testing.assert_array_equal(res.inlier_mask[:-1], expected)


def test_multi_ransac_same_seed_gives_identical_result() -> None:
    pts = roof_scene(np.random.default_rng(14), tilted(5.0))
    a = multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(15), QUERY_XY)
    b = multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(15), QUERY_XY)
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.selected.normal, b.selected.normal)
    np.testing.assert_array_equal(a.inlier_mask, b.inlier_mask)


@pytest.mark.parametrize("pts", [np.zeros((2, 3)), np.c_[np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)]])
def test_multi_ransac_too_few_or_collinear_points_returns_none(pts: np.ndarray) -> None:
    assert multi_ransac(pts, MultiRansacConfig(), np.random.default_rng(0)) is None


def test_select_ground_vertical_planes_fall_back_to_flattest() -> None:
    wall, slope = Plane(np.array([1.0, 0.0, 0.0]), 0.0), tilted(60.0)
    assert select_ground((wall, slope), QUERY_XY, 3.0) == 1


@pytest.mark.parametrize("seed", range(5))
def test_multi_ransac_paper_rule_ground_majority_with_roof_30m_up_and_30pct_outliers(seed: int) -> None:
    """The configuration the pipeline runs (paper rule): 40 % ground, 30 % roof 30 m higher, 30 %
    outliers; the ground is found within 1 deg and 0.1 m."""
    from trade.pipeline import PAPER_RANSAC

    rng = np.random.default_rng(seed)
    ground = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
    grd = plane_points(rng, 120, ground, 0.0, 20.0)
    roof = plane_points(rng, 90, Plane(np.array([0.0, 0.0, 1.0]), -30.0), -20.0, -5.0)
    outliers = np.c_[rng.uniform(-20.0, 20.0, (90, 2)), rng.uniform(-5.0, 35.0, 90)]
    res = multi_ransac(np.r_[grd, roof, outliers], PAPER_RANSAC, np.random.default_rng(100 + seed), QUERY_XY)
    assert res is not None
    assert angle_deg(res.selected, ground) < 1.0
    assert abs(res.selected.height_at(QUERY_XY)) < 0.1
    assert res.inlier_mask[:120].mean() > 0.95 and res.inlier_mask[120:210].mean() < 0.05


@pytest.mark.parametrize("tilt_deg", [40.0, 60.0])
def test_multi_ransac_only_planes_steeper_than_the_tilt_limit_gives_no_ground(tilt_deg: float) -> None:
    """A roof edge and the ground below it fit a steep plane; no vehicle drives on one."""
    pts = plane_points(np.random.default_rng(21), 60, tilted(tilt_deg), -10.0, 10.0)
    cfg = MultiRansacConfig()
    assert tilt_deg > cfg.max_ground_tilt_deg
    assert multi_ransac(pts, cfg, np.random.default_rng(22), QUERY_XY) is None
    steep_allowed = multi_ransac(pts, MultiRansacConfig(max_ground_tilt_deg=90.0), np.random.default_rng(22),
                                 QUERY_XY)
    assert steep_allowed is not None and angle_deg(steep_allowed.selected, tilted(tilt_deg)) < 1.0


def test_multi_ransac_tilt_limit_rejects_a_bad_value() -> None:
    with pytest.raises(ValueError, match="max_ground_tilt_deg"):
        MultiRansacConfig(max_ground_tilt_deg=120.0)
