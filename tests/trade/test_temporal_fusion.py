"""Spec tests for trade.temporal_fusion: gating, ring buffer, reuse and re-initialisation."""

from __future__ import annotations

import numpy as np
import pytest

from trade.planes import MultiRansacConfig
from trade.temporal_fusion import TemporalFusionConfig, TemporalPlaneFusion

NOISE_M = 0.05
N_PER_FRAME = 120


def ground_frame(rng: np.random.Generator, z_m: float = 0.0, n: int = N_PER_FRAME, slope: float = 0.05) -> np.ndarray:
    """n points on z = z_m + slope * x over a 30 m patch, noise NOISE_M."""
    xy = rng.uniform(-15.0, 15.0, (n, 2))
    return np.c_[xy, z_m + slope * xy[:, 0] + rng.normal(0.0, NOISE_M, n)]


def steady_fusion(n_frames: int = 5, **overrides: int) -> tuple[TemporalPlaneFusion, np.random.Generator]:
    rng = np.random.default_rng(0)
    fusion = TemporalPlaneFusion(TemporalFusionConfig(**overrides), np.random.default_rng(1))
    for _ in range(n_frames):
        res = fusion.update(ground_frame(rng))
        assert not res.reused and res.n_accepted >= 0.95 * N_PER_FRAME  # all, unless the gate is < 10 sigma
    return fusion, rng


def test_fusion_sudden_5m_plane_jump_is_gated_out_and_plane_stays() -> None:
    fusion, rng = steady_fusion()
    before = fusion.plane
    assert before is not None and abs(before.height_at([0.0, 0.0])) < 0.05
    res = fusion.update(ground_frame(rng, z_m=5.0))
    assert res.n_accepted == 0 and res.n_rejected == N_PER_FRAME and res.reused
    assert res.plane is before and res.n_buffered == 5 * N_PER_FRAME
    assert 0.5 <= res.gate_m < 5.0


def test_fusion_frame_within_gate_is_accepted_and_refits() -> None:
    fusion, rng = steady_fusion()
    res = fusion.update(ground_frame(rng, z_m=0.1))
    assert res.n_accepted == N_PER_FRAME and not res.reused and res.plane is not None
    assert res.n_buffered == 6 * N_PER_FRAME and abs(res.plane.height_at([0.0, 0.0])) < 0.1


def test_fusion_gate_is_mse_factor_times_rms_of_buffer_fit_with_floor() -> None:
    fusion, rng = steady_fusion(gate_min_m=0.01)  # floor out of the way: 3 x 0.05 m noise
    assert fusion.update(ground_frame(rng)).gate_m == pytest.approx(3.0 * NOISE_M, rel=0.15)
    floored, rng2 = steady_fusion()
    assert floored.update(ground_frame(rng2)).gate_m == pytest.approx(0.5)


def test_fusion_buffer_never_exceeds_size_and_drops_oldest_first() -> None:
    fusion = TemporalPlaneFusion(TemporalFusionConfig(), np.random.default_rng(2))
    rng, frames = np.random.default_rng(3), []
    for k in range(12):  # 12 x 120 = 1440 points > 1000
        frame = ground_frame(rng)
        frame[:, 1] = 1000.0 * k + np.arange(N_PER_FRAME)  # y tags (frame, index); still planar
        frames.append(frame)
        res = fusion.update(frame)
        assert res.n_buffered == min((k + 1) * N_PER_FRAME, 1000) and res.n_accepted == N_PER_FRAME
    np.testing.assert_array_equal(fusion.buffered_points, np.concatenate(frames)[-1000:])


def test_fusion_frame_larger_than_buffer_keeps_its_newest_points() -> None:
    cfg = TemporalFusionConfig(buffer_size=50, min_points=10)
    fusion = TemporalPlaneFusion(cfg, np.random.default_rng(4))
    frame = ground_frame(np.random.default_rng(5), n=80)
    fusion.update(frame[:30])
    res = fusion.update(frame[30:])
    assert res.n_buffered == 50
    np.testing.assert_array_equal(fusion.buffered_points, frame[30:])


def test_fusion_too_few_points_reuses_stored_plane_without_buffering() -> None:
    fusion, rng = steady_fusion()
    before = fusion.plane
    res = fusion.update(ground_frame(rng, n=5))
    assert res.reused and res.plane is before and res.n_buffered == 5 * N_PER_FRAME
    assert fusion.update(np.zeros((0, 3))).reused


def test_fusion_first_frame_buffers_only_its_own_multi_ransac_inliers() -> None:
    rng = np.random.default_rng(6)
    outliers = np.c_[rng.uniform(-15.0, 15.0, (30, 2)), rng.uniform(10.0, 30.0, 30)]
    fusion = TemporalPlaneFusion(TemporalFusionConfig(), np.random.default_rng(7))
    res = fusion.update(np.r_[ground_frame(rng), outliers, [[np.nan, 0.0, 0.0]]])
    assert res.n_accepted == N_PER_FRAME and res.n_rejected == 31 and not res.reused
    assert np.all(fusion.buffered_points[:, 2] < 2.0)


def test_fusion_ground_that_moved_for_good_reinitialises_after_max_gated_frames() -> None:
    fusion, rng = steady_fusion(max_gated_frames=3)
    results = [fusion.update(ground_frame(rng, z_m=5.0)) for _ in range(3)]
    assert [r.reused for r in results] == [True, True, False]
    assert results[-1].reinitialised and results[-1].n_buffered == N_PER_FRAME
    assert results[-1].plane is not None and abs(results[-1].plane.height_at([0.0, 0.0]) - 5.0) < 0.1


@pytest.mark.parametrize("outvoted_reinit", [True, False])
def test_fusion_plane_of_a_few_roof_points_is_outvoted_by_the_first_street_frame_with_more(outvoted_reinit) -> None:
    """A first plane from 6 points on a roof 20 m up, then frames of 30 street points: they are gated out and
    outnumber the roof plane's inliers, so the fusion starts over on the street at once (without the vote, the
    street stays gated out until max_gated_frames)."""
    rng = np.random.default_rng(0)
    config = TemporalFusionConfig(min_points=6, outvoted_reinit=outvoted_reinit)
    fusion = TemporalPlaneFusion(config, np.random.default_rng(1))
    roof = fusion.update(ground_frame(rng, z_m=20.0, n=6))
    assert roof.plane is not None and roof.plane.n_inliers == 6
    street = fusion.update(ground_frame(rng, n=30))
    assert street.reinitialised is outvoted_reinit
    if outvoted_reinit:
        assert abs(street.plane.height_at([0.0, 0.0])) < 0.1 and street.n_buffered == 30
    else:
        assert street.reused and street.plane is roof.plane and street.n_accepted == 0


def test_fusion_plane_of_many_frames_is_not_outvoted_by_one_frame_off_it() -> None:
    fusion, rng = steady_fusion()  # 5 frames of 120 points
    res = fusion.update(ground_frame(rng, z_m=5.0, n=2 * N_PER_FRAME))
    assert res.reused and not res.reinitialised and abs(res.plane.height_at([0.0, 0.0])) < 0.05


def test_fusion_reset_forgets_plane_and_buffer() -> None:
    fusion, _ = steady_fusion()
    fusion.reset()
    assert fusion.plane is None and fusion.buffered_points.shape == (0, 3)
    res = fusion.update(np.zeros((2, 3)))
    assert res.plane is None and not res.reused


def test_fusion_same_seed_same_planes() -> None:
    a, _ = steady_fusion()
    b, _ = steady_fusion()
    assert a.plane is not None and b.plane is not None
    np.testing.assert_array_equal(a.plane.normal, b.plane.normal)


@pytest.mark.parametrize(
    ("field", "value"),
    [("buffer_size", 2), ("min_points", 2000), ("gate_mse_factor", 0.0), ("gate_min_m", -1.0), ("max_gated_frames", -1),
     ("max_age_frames", -1), ("max_age_frames", 1.5)],
)
def test_fusion_config_bad_field_raises_naming_it(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        TemporalFusionConfig(**{field: value})


def test_fusion_uses_injected_ransac_config() -> None:
    cfg = TemporalFusionConfig(ransac=MultiRansacConfig(inlier_threshold_m=0.05, min_iterations=16))
    fusion = TemporalPlaneFusion(cfg, np.random.default_rng(8))
    res = fusion.update(ground_frame(np.random.default_rng(9)))
    assert res.n_accepted < N_PER_FRAME  # a 5 cm band drops part of the 5 cm-noise points


def _crest_frame(rng: np.random.Generator, centre_x_m: float, n: int = 8) -> np.ndarray:
    """n points within 5 m of x = centre_x_m on ground that climbs at 10 % up to x = -10 m and is level
    (z = 0) after it; y in [-4, 4] m, noise NOISE_M."""
    xy = np.c_[rng.uniform(centre_x_m - 5.0, centre_x_m + 5.0, n), rng.uniform(-4.0, 4.0, n)]
    z = np.minimum(0.1 * (xy[:, 0] + 10.0), 0.0)
    return np.c_[xy, z + rng.normal(0.0, NOISE_M, n)]


@pytest.mark.parametrize(("max_age_frames", "fits_level_ground"), [(0, False), (15, True)])
def test_fusion_max_age_keeps_old_sparse_ground_out_of_the_fit(max_age_frames: int, fits_level_ground: bool) -> None:
    """8 points per frame around a target driving over a crest onto level ground: 1000 points span the whole
    drive, the plane stays on the slope behind (0.8 m off at the target, the level points gated out) unless
    old points leave the fit."""
    rng = np.random.default_rng(3)
    config = TemporalFusionConfig(min_points=6, max_age_frames=max_age_frames)
    fusion = TemporalPlaneFusion(config, np.random.default_rng(4))
    centres_m = np.arange(-40.0, 0.25, 0.5)
    for centre in centres_m:
        res = fusion.update(_crest_frame(rng, centre))
    error_m = abs(res.plane.height_at(np.array([0.0, 0.0])))
    assert (error_m < 0.1) == fits_level_ground, error_m


def test_fusion_bootstrap_from_a_too_steep_frame_keeps_nothing_then_starts_on_the_ground() -> None:
    """Before any plane, a frame whose points only fit a plane steeper than the ground tilt limit (a roof
    edge and the street) is not buffered; the first frame of real ground starts the fusion."""
    rng = np.random.default_rng(3)
    fusion = TemporalPlaneFusion(TemporalFusionConfig(), np.random.default_rng(4))
    steep = fusion.update(ground_frame(rng, slope=1.5))  # 56 deg
    assert steep.plane is None and steep.n_accepted == 0 and steep.n_buffered == 0
    ground = fusion.update(ground_frame(rng))
    assert ground.plane is not None and ground.n_accepted >= 0.95 * N_PER_FRAME
    assert abs(ground.plane.height_at([0.0, 0.0])) < 0.05
