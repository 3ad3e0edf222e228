"""Tests of peak selection on correlation filter score maps (softmax, NMS, nearest candidate)."""

from __future__ import annotations

import numpy as np
import pytest

from trade.tracking import PeakConfig, ResponseMap, highest_peak, select_peak
from trade.tracking.peaks import local_maxima, peaks_above, refine_peak, softmax_map

MAP_SIDE_CELLS = 25  # origin cell (12, 12)
PEAK_SIGMA_CELLS = 1.2


def _bumps(peaks_rc_height: list[tuple[float, float, float]]) -> np.ndarray:
    """(25, 25) float32 map: sum of Gaussian bumps at (row, col) with the given heights."""
    rows, cols = np.mgrid[0:MAP_SIDE_CELLS, 0:MAP_SIDE_CELLS]
    scores = np.zeros((MAP_SIDE_CELLS, MAP_SIDE_CELLS))
    for row, col, height in peaks_rc_height:
        scores += height * np.exp(-((rows - row) ** 2 + (cols - col) ** 2) / (2 * PEAK_SIGMA_CELLS**2))
    return scores.astype(np.float32)


def _response(scores: np.ndarray, px_per_cell: tuple[float, float] = (3.0, 3.0)) -> ResponseMap:
    return ResponseMap(scores=scores, scale=1.0, origin_px=np.array([100.0, 50.0]), px_per_cell=np.array(px_per_cell))


@pytest.mark.parametrize("near_col", [8, 17])
def test_select_peak_two_equal_peaks_picks_nearer_origin(near_col: int) -> None:
    far_col = 2 if near_col < 12 else 23
    resp = _response(_bumps([(12, near_col, 1.0), (12, far_col, 1.0)]))
    choice = select_peak(resp, PeakConfig())
    expected = resp.cell_to_image_px(np.array([12.0, near_col]))
    np.testing.assert_allclose(choice.location_px, expected, atol=0.3)
    assert choice.n_candidates == 2 and choice.ambiguous


def test_select_peak_nearer_peak_in_pixels_not_cells_wins() -> None:
    # 4 cells away along rows (4 px each) versus 5 cells along columns (1 px each): columns are nearer
    resp = _response(_bumps([(16, 12, 1.0), (12, 17, 1.0)]), px_per_cell=(1.0, 4.0))
    choice = select_peak(resp, PeakConfig())
    np.testing.assert_allclose(choice.location_px, resp.cell_to_image_px(np.array([12.0, 17.0])), atol=0.3)


def test_select_peak_single_dominant_peak_not_ambiguous() -> None:
    resp = _response(_bumps([(6, 18, 1.0), (12, 11, 0.4)]))
    choice = select_peak(resp, PeakConfig())
    assert not choice.ambiguous and choice.n_candidates == 1
    np.testing.assert_allclose(choice.location_px, resp.cell_to_image_px(np.array([6.0, 18.0])), atol=0.3)
    assert choice.score == pytest.approx(1.0, abs=1e-3)


def test_select_peak_two_near_equal_peaks_ambiguous() -> None:
    resp = _response(_bumps([(6, 18, 1.0), (14, 9, 0.97)]))
    choice = select_peak(resp, PeakConfig())
    assert choice.ambiguous and choice.n_candidates == 2
    # the lower but nearer peak is chosen
    np.testing.assert_allclose(choice.location_px, resp.cell_to_image_px(np.array([14.0, 9.0])), atol=0.3)


def test_select_peak_flat_topped_peak_counts_once() -> None:
    scores = _bumps([(12, 12, 0.5)])
    scores[5, 5:7] = 1.0  # two adjacent cells share the maximum
    choice = select_peak(_response(scores), PeakConfig(subcell_refinement=False))
    assert choice.n_candidates == 1 and not choice.ambiguous


def test_peaks_above_lists_every_peak_over_the_score_highest_first() -> None:
    resp = _response(_bumps([(6, 18, 0.5), (14, 9, 0.9), (20, 20, 0.15)]))
    peaks = peaks_above(resp, 0.2, PeakConfig())
    assert [round(p.score, 2) for p in peaks] == [0.9, 0.5]  # the 0.15 bump is below the score
    for peak, cell in zip(peaks, ([14.0, 9.0], [6.0, 18.0])):
        np.testing.assert_allclose(peak.location_px, resp.cell_to_image_px(np.array(cell)), atol=0.3)
        assert peak.ambiguous and peak.n_candidates == 2
    assert peaks_above(resp, 0.95, PeakConfig()) == []


def test_peaks_above_counts_a_flat_top_once() -> None:
    scores = _bumps([(12, 12, 0.5)])
    scores[5, 5:7] = 1.0
    peaks = peaks_above(_response(scores), 0.2, PeakConfig(subcell_refinement=False))
    assert [p.score for p in peaks] == [1.0, pytest.approx(0.5, abs=1e-3)]


def test_select_peak_lower_temperature_drops_weaker_candidate() -> None:
    resp = _response(_bumps([(6, 18, 1.0), (14, 9, 0.9)]))
    assert select_peak(resp, PeakConfig(softmax_temperature=0.2)).ambiguous
    assert not select_peak(resp, PeakConfig(softmax_temperature=0.05)).ambiguous


def test_highest_peak_two_peaks_picks_global_max_even_if_far() -> None:
    resp = _response(_bumps([(2, 2, 1.0), (12, 13, 0.9)]))
    choice = highest_peak(resp)
    np.testing.assert_allclose(choice.location_px, resp.cell_to_image_px(np.array([2.0, 2.0])), atol=0.3)
    assert choice.n_candidates == 1 and not choice.ambiguous


def test_refine_peak_fractional_bump_recovered_within_0_1_cells() -> None:
    scores = _bumps([(10.3, 14.6, 1.0)])
    peak = np.unravel_index(int(np.argmax(scores)), scores.shape)
    np.testing.assert_allclose(refine_peak(scores, peak), [10.3, 14.6], atol=0.1)


def test_response_map_cell_and_pixel_maps_are_inverse_and_origin_fixed() -> None:
    resp = _response(_bumps([(12, 12, 1.0)]), px_per_cell=(2.0, 3.5))
    np.testing.assert_allclose(resp.cell_to_image_px(resp.origin_cell), resp.origin_px)
    cells = np.array([[0.0, 0.0], [3.25, 20.5], [24.0, 7.0]])
    np.testing.assert_allclose(resp.image_px_to_cell(resp.cell_to_image_px(cells)), cells)
    # one column right is +2 px in x, one row down is +3.5 px in y
    np.testing.assert_allclose(resp.cell_to_image_px([13.0, 13.0]) - resp.origin_px, [2.0, 3.5])


def test_softmax_map_sums_to_one_and_keeps_order() -> None:
    scores = _bumps([(4, 4, 1.0), (20, 20, 0.5)])
    prob = softmax_map(scores, 0.1)
    assert prob.sum() == pytest.approx(1.0)
    assert prob[4, 4] > prob[20, 20] > prob[12, 12]


def test_local_maxima_finds_each_separated_bump() -> None:
    maxima = local_maxima(_bumps([(4, 4, 1.0), (20, 18, 0.5)]), radius_cells=2)
    assert {tuple(cell) for cell in maxima} >= {(4, 4), (20, 18)}


@pytest.mark.parametrize(
    ("field", "value"), [("softmax_temperature", 0.0), ("candidate_fraction", 1.5), ("nms_radius_cells", 0)]
)
def test_peak_config_invalid_value_raises_naming_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        PeakConfig(**{field: value})


def test_select_peak_flat_map_returns_a_location_quickly() -> None:
    resp = _response(np.zeros((MAP_SIDE_CELLS, MAP_SIDE_CELLS), dtype=np.float32))
    choice = select_peak(resp, PeakConfig())
    np.testing.assert_allclose(choice.location_px, resp.origin_px)  # every cell ties: the origin is nearest
    assert choice.ambiguous
