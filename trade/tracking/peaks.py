"""Correlation filter score maps and the choice of the target location in them.

Owns the score-map-to-image geometry, the paper's softmax + NMS + nearest-candidate rule and the highest peak.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class ResponseMap:
    """Scores on the search grid; cell `origin_cell` = (h // 2, w // 2) is the search centre `origin_px`.

    scores: (h, w) float32; scale: box size factor the tracker chose (1 = unchanged);
    origin_px: (2,) window centre (x, y) [px]; px_per_cell: (2,) cell pitch along (x, y) [px].
    """

    scores: npt.NDArray[np.float32]
    scale: float
    origin_px: FloatArray
    px_per_cell: FloatArray

    def __post_init__(self) -> None:
        if self.scores.ndim != 2 or min(self.scores.shape) < 1:
            raise ValueError(f"ResponseMap.scores must be a non-empty (h, w) array, got shape {self.scores.shape}")
        if np.shape(self.origin_px) != (2,) or not np.all(np.isfinite(self.origin_px)):
            raise ValueError(f"ResponseMap.origin_px must be a finite (2,) array, got {self.origin_px!r}")
        if np.shape(self.px_per_cell) != (2,) or not np.all(np.asarray(self.px_per_cell) > 0):
            raise ValueError(f"ResponseMap.px_per_cell must be a positive (2,) array, got {self.px_per_cell!r}")
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"ResponseMap.scale must be finite and > 0, got {self.scale!r}")

    @property
    def origin_cell(self) -> FloatArray:
        """(2,) (row, col) of the cell at the search centre."""
        return np.array([self.scores.shape[0] // 2, self.scores.shape[1] // 2], dtype=np.float64)

    def cell_to_image_px(self, cell_rc: npt.ArrayLike) -> FloatArray:
        """(..., 2) (row, col) cells, fractional allowed -> (..., 2) image (x, y) [px].

        x = origin_x + (col - origin_col) * pitch_x, y = origin_y + (row - origin_row) * pitch_y.
        """
        offset_rc = np.asarray(cell_rc, dtype=np.float64) - self.origin_cell
        return np.asarray(self.origin_px) + offset_rc[..., ::-1] * np.asarray(self.px_per_cell)

    def image_px_to_cell(self, point_xy: npt.ArrayLike) -> FloatArray:
        """(..., 2) image (x, y) [px] -> (..., 2) fractional (row, col) cells; inverse of cell_to_image_px."""
        offset_xy = (np.asarray(point_xy, dtype=np.float64) - np.asarray(self.origin_px)) / self.px_per_cell
        return self.origin_cell + offset_xy[..., ::-1]


@dataclass(frozen=True)
class PeakConfig:
    """Peak selection: candidates are NMS peaks with softmax >= candidate_fraction * top softmax."""

    softmax_temperature: float = 0.1  # T in p = exp(s / T) / sum exp(s / T); scores are ~1 at a perfect match
    nms_radius_cells: int = 2  # a peak is the maximum of the disc of this radius around it
    candidate_fraction: float = 0.5  # of the top peak's softmax value
    subcell_refinement: bool = True  # parabola fit through the peak and its 4 neighbours

    def __post_init__(self) -> None:
        if not (np.isfinite(self.softmax_temperature) and self.softmax_temperature > 0):
            raise ValueError(
                f"PeakConfig.softmax_temperature must be finite and > 0, got {self.softmax_temperature!r}"
            )
        if int(self.nms_radius_cells) != self.nms_radius_cells or self.nms_radius_cells < 1:
            raise ValueError(f"PeakConfig.nms_radius_cells must be a positive integer, got {self.nms_radius_cells!r}")
        if not (0 < self.candidate_fraction <= 1):
            raise ValueError(f"PeakConfig.candidate_fraction must be in (0, 1], got {self.candidate_fraction!r}")


@dataclass(frozen=True, eq=False)
class PeakChoice:
    """Chosen location (x, y) [px], its raw score and softmax value, and how many candidates competed."""

    location_px: FloatArray
    score: float
    probability: float
    n_candidates: int
    ambiguous: bool  # more than one candidate remained after NMS and the fraction test


def softmax_map(scores: npt.ArrayLike, temperature: float) -> FloatArray:
    """(h, w) p = exp((s - max s) / T) / sum exp((s - max s) / T); sums to 1."""
    s = np.asarray(scores, dtype=np.float64)
    e = np.exp((s - s.max()) / temperature)
    return e / e.sum()


def local_maxima(scores: npt.ArrayLike, radius_cells: int) -> IntArray:
    """(K, 2) (row, col) of cells equal to the maximum of the disc of `radius_cells` around them."""
    s = np.asarray(scores, dtype=np.float32)
    side = 2 * radius_cells + 1
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (side, side))
    # dilate(s)(p) = max over the disc around p; outside the map counts as -inf
    dilated = cv2.dilate(s, disc, borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    return np.argwhere(s >= dilated)


def parabola_vertex_offset(values: npt.ArrayLike, index: int) -> float:
    """Offset in [-1/2, 1/2] of the vertex of the parabola through values[index - 1 .. index + 1].

    delta = (v[-1] - v[+1]) / (2 (v[-1] - 2 v[0] + v[+1])); 0 at the ends or without a maximum.
    """
    v = np.asarray(values, dtype=np.float64)
    if index <= 0 or index >= len(v) - 1:
        return 0.0
    left, mid, right = v[index - 1], v[index], v[index + 1]
    curvature = left - 2.0 * mid + right
    if curvature >= 0:
        return 0.0
    return float(np.clip((left - right) / (2.0 * curvature), -0.5, 0.5))


def refine_peak(scores: npt.ArrayLike, cell_rc: npt.ArrayLike) -> FloatArray:
    """(2,) fractional (row, col) of the peak at integer `cell_rc`, by a parabola along each axis."""
    s = np.asarray(scores)  # the parabolas convert their row and column to float64
    row, col = (int(v) for v in np.asarray(cell_rc).reshape(2))
    return np.array([row + parabola_vertex_offset(s[:, col], row), col + parabola_vertex_offset(s[row, :], col)])


def _suppress_near(cells: IntArray, order: IntArray, radius_cells: int) -> IntArray:
    """Indices (into cells) kept by greedy NMS in `order`: drop cells within radius of a kept one (plateaus)."""
    kept: list[int] = []
    remaining = np.asarray(order, dtype=np.intp)
    while remaining.size:  # one pass per kept cell, each vectorised over the remaining ones
        kept.append(int(remaining[0]))
        offset = cells[remaining] - cells[remaining[0]]
        remaining = remaining[np.einsum("ij,ij->i", offset, offset) > radius_cells**2]
    return np.asarray(kept, dtype=np.intp)


def _choice(resp: ResponseMap, cell_rc: IntArray, prob: FloatArray, n: int, refine: bool) -> PeakChoice:
    peak = refine_peak(resp.scores, cell_rc) if refine else cell_rc.astype(np.float64)
    return PeakChoice(
        location_px=resp.cell_to_image_px(peak),
        score=float(resp.scores[cell_rc[0], cell_rc[1]]),
        probability=float(prob[cell_rc[0], cell_rc[1]]),
        n_candidates=n,
        ambiguous=n > 1,
    )


def select_peak(resp: ResponseMap, config: PeakConfig) -> PeakChoice:
    """The paper's selection: softmax, NMS, keep peaks with p >= fraction * p_max, take the nearest
    to the search centre (the predicted location); distances in image px, ties to the higher score."""
    prob = softmax_map(resp.scores, config.softmax_temperature)
    peaks = local_maxima(resp.scores, config.nms_radius_cells)
    peak_prob = prob[peaks[:, 0], peaks[:, 1]]
    keep = peak_prob >= config.candidate_fraction * peak_prob.max()
    candidates, cand_prob = peaks[keep], peak_prob[keep]
    order = np.argsort(-cand_prob, kind="stable")
    candidates = candidates[_suppress_near(candidates, order, config.nms_radius_cells)]
    distance = np.linalg.norm(resp.cell_to_image_px(candidates) - resp.origin_px, axis=1)
    cand_scores = resp.scores[candidates[:, 0], candidates[:, 1]]
    best = np.lexsort((-cand_scores, distance))[0]  # nearest first, then highest score
    return _choice(resp, candidates[best], prob, len(candidates), config.subcell_refinement)


def peaks_above(resp: ResponseMap, min_score: float, config: PeakConfig) -> list[PeakChoice]:
    """Every NMS peak scoring at least `min_score`, highest first; each flagged ambiguous when there are
    several (re-detection weighs them against the trajectory prediction itself)."""
    prob = softmax_map(resp.scores, config.softmax_temperature)
    peaks = local_maxima(resp.scores, config.nms_radius_cells)
    peaks = peaks[resp.scores[peaks[:, 0], peaks[:, 1]] >= min_score]
    order = np.argsort(-resp.scores[peaks[:, 0], peaks[:, 1]], kind="stable")
    kept = peaks[_suppress_near(peaks, order, config.nms_radius_cells)]
    return [_choice(resp, cell, prob, len(kept), config.subcell_refinement) for cell in kept]


def highest_peak(resp: ResponseMap, config: PeakConfig | None = None) -> PeakChoice:
    """The plain tracker rule ("dcf" baseline): the global maximum wins and is never ambiguous.

    From `config` only the temperature (reported probability) and sub-cell refinement are used.
    """
    config = config if config is not None else PeakConfig()
    cell = np.asarray(np.unravel_index(int(np.argmax(resp.scores)), resp.scores.shape), dtype=np.intp)
    prob = softmax_map(resp.scores, config.softmax_temperature)
    return _choice(resp, cell, prob, 1, config.subcell_refinement)
