"""Plane model, least-squares plane fit and multi-model RANSAC (MSAC) ground-plane selection.

Paper section "Multi-RANSAC plane fitting": the N largest distinct planes, the flattest wins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from trade.validation import is_int_at_least, require

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

SAMPLE_SIZE = 3  # points per minimal plane hypothesis
MIN_SAMPLE_SIN = 1e-3  # |e1 x e2| / (|e1||e2|) below this: collinear sample, discarded
MIN_NORMAL_Z = 1e-12  # below this a plane is vertical: its height at an (x, y) is undefined


@dataclass(frozen=True)
class Plane:
    """Plane n·x + d = 0 in world frame; n unit, oriented with n_z >= 0 (points "up")."""

    normal: FloatArray  # (3,) unit normal
    offset_m: float  # d [m]
    mse_m2: float = 0.0  # mean squared inlier residual [m^2]
    n_inliers: int = 0

    def __post_init__(self) -> None:
        n = np.asarray(self.normal, dtype=np.float64).reshape(3)
        norm = float(np.linalg.norm(n))
        require(np.isfinite(norm) and norm > 0.0, "Plane.normal", self.normal, "finite and non-zero")
        require(bool(np.isfinite(self.offset_m)), "Plane.offset_m", self.offset_m, "finite")
        sign = -1.0 if n[2] < 0.0 else 1.0  # orient n_z >= 0; (n, d) and (-n, -d) are the same plane
        object.__setattr__(self, "normal", sign * n / norm)
        object.__setattr__(self, "offset_m", sign * float(self.offset_m) / norm)

    def signed_distance(self, points: FloatArray) -> FloatArray:
        """points: (N, 3) world [m] -> (N,) signed distance n·x + d [m], positive above."""
        return np.atleast_2d(points) @ self.normal + self.offset_m

    @property
    def tilt_rad(self) -> float:
        """Angle between the normal and world z [rad], in [0, pi/2]."""
        return float(np.arccos(np.clip(self.normal[2], -1.0, 1.0)))

    @property
    def tilt_deg(self) -> float:
        return float(np.degrees(self.tilt_rad))

    def height_at(self, xy: FloatArray) -> float:
        """World z [m] of the plane above (x, y): z = -(n_x x + n_y y + d) / n_z; inf if vertical."""
        if self.normal[2] < MIN_NORMAL_Z:
            return float("inf")
        x, y = (float(v) for v in np.asarray(xy, dtype=np.float64).reshape(2))
        return -(self.normal[0] * x + self.normal[1] * y + self.offset_m) / self.normal[2]

    def lifted(self, height_m: float) -> Plane:
        """The plane shifted by height_m along n: n·(x - h n) + d = 0  =>  d' = d - h."""
        return Plane(self.normal, self.offset_m - float(height_m), self.mse_m2, self.n_inliers)


def fit_plane_lstsq(points: FloatArray) -> Plane:
    """Total least squares: n minimises sum (n·(x_i - c))^2 over the centred points, d = -n·c.

    points: (N >= 3, 3) world [m]. mse_m2 = mean squared orthogonal residual, n_inliers = N.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < SAMPLE_SIZE:
        raise ValueError(f"fit_plane_lstsq needs (N >= {SAMPLE_SIZE}, 3) points, got shape {pts.shape}")
    centroid = pts.mean(axis=0)
    centred = pts - centroid
    # n = eigenvector of the smallest eigenvalue of the 3x3 scatter S = X^T X (= smallest right
    # singular vector of X); mse = lambda_min / N is the mean squared orthogonal residual
    eigval, eigvec = np.linalg.eigh(centred.T @ centred)
    normal = eigvec[:, 0]
    mse = max(float(eigval[0]), 0.0) / pts.shape[0]
    return Plane(normal, -float(normal @ centroid), mse, int(pts.shape[0]))


@dataclass(frozen=True)
class MultiRansacConfig:
    """Multi-model MSAC. Paper defaults; the last three fields are ours (see `select_ground`).

    A candidate is a duplicate of an accepted solution when it shares more than
    `max_shared_inlier_fraction` of its own inliers with it, or when its normal is within
    `min_normal_angle_deg` of it and (our extension) the two planes lie closer than
    `parallel_min_separation_m` to each other's points. `parallel_min_separation_m = inf`
    is the paper's literal rule: a roof parallel to the ground then hides the ground.
    """

    inlier_threshold_m: float = 0.5
    max_solutions: int = 4
    min_normal_angle_deg: float = 15.0
    max_shared_inlier_fraction: float = 0.8
    min_inlier_fraction_of_best: float = 0.5
    max_iterations: int = 512  # hypotheses cap
    min_iterations: int = 64  # hypotheses before the adaptive stop may fire
    hypotheses_per_chunk: int = 64  # hypotheses scored per (chunk, N) residual matrix
    confidence: float = 0.99  # P(an all-inlier sample of the smallest admissible plane)
    n_refine_iterations: int = 2  # extra rounds of: LS fit on inliers, re-select inliers
    parallel_min_separation_m: float = 1.0  # 2 x inlier threshold: inlier bands do not overlap
    flatness_tolerance_deg: float = 3.0  # solutions this close to the flattest tie; lowest wins
    # No ground plane steeper than this (ours): a ground vehicle drives no steeper slope (30 deg is a 58 %
    # grade; the targets' paths stay under 10 deg over 6 m on development worlds 0-9 of every scene). A fit
    # whose flattest solution is steeper spans a roof edge or a wall and the ground, and gives no plane.
    max_ground_tilt_deg: float = 30.0

    def __post_init__(self) -> None:
        checks = {  # field: (valid, expectation)
            "inlier_threshold_m": (0.0 < self.inlier_threshold_m < np.inf, "finite and > 0"),
            "max_solutions": (is_int_at_least(self.max_solutions, 1), "an integer >= 1"),
            "max_iterations": (is_int_at_least(self.max_iterations, 1), "an integer >= 1"),
            "min_iterations": (is_int_at_least(self.min_iterations, 1) and self.min_iterations
                               <= self.max_iterations, "an integer in [1, max_iterations]"),
            "hypotheses_per_chunk": (is_int_at_least(self.hypotheses_per_chunk, 1), "an integer >= 1"),
            "n_refine_iterations": (is_int_at_least(self.n_refine_iterations, 0), "an integer >= 0"),
            "min_normal_angle_deg": (0.0 <= self.min_normal_angle_deg <= 90.0, "in [0, 90]"),
            "flatness_tolerance_deg": (0.0 <= self.flatness_tolerance_deg <= 90.0, "in [0, 90]"),
            "max_ground_tilt_deg": (0.0 <= self.max_ground_tilt_deg <= 90.0, "in [0, 90]"),
            "max_shared_inlier_fraction": (0.0 <= self.max_shared_inlier_fraction <= 1.0, "in [0, 1]"),
            "min_inlier_fraction_of_best": (0.0 < self.min_inlier_fraction_of_best <= 1.0, "in (0, 1]"),
            "confidence": (0.0 < self.confidence < 1.0, "in (0, 1)"),
            "parallel_min_separation_m": (self.parallel_min_separation_m > 0.0, "> 0 (inf: paper's rule)"),
        }
        for name, (valid, expectation) in checks.items():
            require(bool(valid), f"MultiRansacConfig.{name}", getattr(self, name), expectation)


@dataclass(frozen=True)
class MultiPlaneResult:
    """selected: the ground plane; solutions: distinct planes, lowest MSAC cost first."""

    selected: Plane
    solutions: tuple[Plane, ...]
    inlier_mask: BoolArray  # (N,) inliers of `selected` among the input points
    n_hypotheses: int  # hypotheses scored before the (adaptive) stop


@dataclass(frozen=True)
class _Hypotheses:
    normal: FloatArray  # (H, 3) unit, centred frame
    offset: FloatArray  # (H,) [m], centred frame
    sample_centroid: FloatArray  # (H, 3) centred frame [m]
    cost: FloatArray  # (H,) MSAC cost [m^2]
    count: npt.NDArray[np.int64]  # (H,) inliers


def _required_iterations(inlier_fraction: float, config: MultiRansacConfig) -> float:
    """k = log(1 - p) / log(1 - w^3), w = smallest admissible plane's inlier fraction."""
    w_sample = (config.min_inlier_fraction_of_best * inlier_fraction) ** SAMPLE_SIZE
    if w_sample >= 1.0:
        return 0.0
    if w_sample <= 0.0:
        return float("inf")
    return float(np.log1p(-config.confidence) / np.log1p(-w_sample))


def _sample_planes(pts: FloatArray, n_samples: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Planes through random point triples: n = (e1 x e2)/|e1 x e2|, d = -n·p0. Collinear triples
    (|e1 x e2| <= MIN_SAMPLE_SIN |e1||e2|, incl. repeated indices) are dropped.
    Returns plane_h (H, 4) = [n, d] and sample centroids (H, 3)."""
    sample = pts[rng.integers(0, pts.shape[0], size=(n_samples, SAMPLE_SIZE))]  # (n, 3, 3)
    e1, e2 = sample[:, 1] - sample[:, 0], sample[:, 2] - sample[:, 0]
    cross = np.stack([e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
                      e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
                      e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)
    cross_norm = np.sqrt(np.einsum("hj,hj->h", cross, cross))
    ok = cross_norm > MIN_SAMPLE_SIN * np.sqrt(np.einsum("hj,hj->h", e1, e1) * np.einsum("hj,hj->h", e2, e2))
    plane_h = np.empty((int(ok.sum()), 4))
    plane_h[:, :3] = cross[ok] / cross_norm[ok, None]
    plane_h[:, 3] = -np.einsum("hj,hj->h", plane_h[:, :3], sample[ok, 0])
    return plane_h, sample[ok].mean(axis=1)


def _score_hypotheses(pts: FloatArray, config: MultiRansacConfig, rng: np.random.Generator) -> _Hypotheses:
    """Score minimal-sample planes chunk by chunk, cost_h = sum_i min(r_hi^2, t^2) (MSAC), until
    `_required_iterations` (adaptive) or `max_iterations` hypotheses have been drawn."""
    n_pts, t2 = pts.shape[0], config.inlier_threshold_m**2
    pts_h = np.vstack([pts.T, np.ones(n_pts)])  # (4, N) homogeneous: r = [n, d] @ [x; 1]
    plane_h, centroid = _sample_planes(pts, config.max_iterations, rng)
    cost, count = np.empty(plane_h.shape[0]), np.empty(plane_h.shape[0], dtype=np.int64)
    n_scored, best_count, step = 0, 0, config.hypotheses_per_chunk
    while n_scored < plane_h.shape[0]:
        r2 = plane_h[n_scored : n_scored + step] @ pts_h  # (chunk, N) residuals n·x + d
        np.multiply(r2, r2, out=r2)
        np.minimum(r2, t2, out=r2)  # truncated quadratic; inliers stay strictly < t^2
        chunk = slice(n_scored, n_scored + r2.shape[0])
        cost[chunk], count[chunk] = r2.sum(axis=1), np.count_nonzero(r2 < t2, axis=1)
        n_scored += r2.shape[0]
        best_count = max(best_count, int(count[chunk].max()))
        if n_scored >= max(config.min_iterations, _required_iterations(best_count / n_pts, config)):
            break
    return _Hypotheses(plane_h[:n_scored, :3], plane_h[:n_scored, 3], centroid[:n_scored],
                       cost[:n_scored], count[:n_scored])


def _select_distinct(pts: FloatArray, hyp: _Hypotheses, config: MultiRansacConfig) -> list[BoolArray]:
    """Greedy, lowest cost first: accept a hypothesis unless it duplicates an accepted one."""
    order = np.argsort(hyp.cost, kind="stable")
    order = order[hyp.count[order] >= config.min_inlier_fraction_of_best * hyp.count[order[0]]]
    normal, offset, centroid = hyp.normal[order], hyp.offset[order], hyp.sample_centroid[order]
    alive = np.ones(order.size, dtype=bool)
    cos_min_angle, t2 = np.cos(np.radians(config.min_normal_angle_deg)), config.inlier_threshold_m**2
    masks: list[BoolArray] = []
    while len(masks) < config.max_solutions and np.any(alive):
        j = int(np.argmax(alive))
        alive[j] = False
        mask = (pts @ normal[j] + offset[j]) ** 2 < t2
        n_in = max(int(mask.sum()), 1)
        if any(np.count_nonzero(mask & m) / n_in > config.max_shared_inlier_fraction for m in masks):
            continue
        masks.append(mask)
        # near-parallel hypotheses close to this plane (both ways) are duplicates
        c_j = pts[mask].mean(axis=0)
        close = np.abs(normal @ normal[j]) > cos_min_angle
        if np.isfinite(config.parallel_min_separation_m):
            gap = np.minimum(np.abs(centroid @ normal[j] + offset[j]), np.abs(normal @ c_j + offset))
            close &= gap < config.parallel_min_separation_m
        alive &= ~close
    return masks


def _refine(pts: FloatArray, mask: BoolArray, config: MultiRansacConfig) -> tuple[Plane, BoolArray]:
    """Repeat: least squares on the inliers, re-select inliers |n·x + d| < t. The returned mask is
    the band of the returned plane; mse_m2 and n_inliers are measured on it."""
    plane = fit_plane_lstsq(pts[mask])
    mask = np.abs(plane.signed_distance(pts)) < config.inlier_threshold_m
    for _ in range(config.n_refine_iterations):
        if np.count_nonzero(mask) < SAMPLE_SIZE:
            break
        plane = fit_plane_lstsq(pts[mask])
        mask = np.abs(plane.signed_distance(pts)) < config.inlier_threshold_m
    residual = plane.signed_distance(pts[mask])
    mse = float(np.mean(residual**2)) if residual.size else 0.0
    return Plane(plane.normal, plane.offset_m, mse, int(residual.size)), mask


def _drop_converged(
    refined: list[tuple[Plane, BoolArray]], config: MultiRansacConfig
) -> list[tuple[Plane, BoolArray]]:
    """Refinement can pull two solutions onto one surface: keep the first of any pair sharing more
    than `max_shared_inlier_fraction` of inliers, then drop planes below the inlier fraction of best."""
    kept: list[tuple[Plane, BoolArray]] = []
    for plane, mask in refined:
        n_in = max(plane.n_inliers, 1)
        if all(np.count_nonzero(mask & m) / n_in <= config.max_shared_inlier_fraction for _, m in kept):
            kept.append((plane, mask))
    best_count = max(p.n_inliers for p, _ in kept)
    return [(p, m) for p, m in kept if p.n_inliers >= config.min_inlier_fraction_of_best * best_count]


def select_ground(solutions: tuple[Plane, ...], query_xy: FloatArray, flatness_tolerance_deg: float) -> int:
    """Index of the ground plane: the flattest wins (paper); among solutions whose tilt is within
    `flatness_tolerance_deg` of the flattest, the lowest at `query_xy` (ours: roofs, rocks and
    canopies lie above the ground the target stands on; 0 deg gives the strict paper rule)."""
    tilt = np.array([p.tilt_deg for p in solutions])
    ties = np.flatnonzero(tilt <= tilt.min() + flatness_tolerance_deg)
    heights = np.array([solutions[i].height_at(query_xy) for i in ties])
    return int(ties[np.argmin(heights)]) if np.any(np.isfinite(heights)) else int(ties[np.argmin(tilt[ties])])


def multi_ransac(
    points: FloatArray,
    config: MultiRansacConfig,
    rng: np.random.Generator,
    query_xy: FloatArray | None = None,
) -> MultiPlaneResult | None:
    """points: (N, 3) world [m]; query_xy: (2,) world [m] where "lowest" is judged (default:
    the points' centroid). Returns None with fewer than 3 finite points, no plane hypothesis, or a selected
    plane steeper than `max_ground_tilt_deg`."""
    pts_world = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    finite = np.all(np.isfinite(pts_world), axis=1)
    if np.count_nonzero(finite) < SAMPLE_SIZE:
        return None
    origin = pts_world[finite].mean(axis=0)
    pts = pts_world[finite] - origin  # centred for conditioning; d_world = d - n·origin
    hyp = _score_hypotheses(pts, config, rng)
    if hyp.cost.size == 0:
        return None
    refined = _drop_converged([_refine(pts, m, config) for m in _select_distinct(pts, hyp, config)], config)
    solutions = tuple(Plane(p.normal, p.offset_m - float(p.normal @ origin), p.mse_m2, p.n_inliers)
                      for p, _ in refined)
    query = origin[:2] if query_xy is None else np.asarray(query_xy, dtype=np.float64).reshape(2)
    k = select_ground(solutions, query, config.flatness_tolerance_deg)
    if solutions[k].tilt_deg > config.max_ground_tilt_deg:
        return None
    mask = np.zeros(pts_world.shape[0], dtype=bool)
    mask[finite] = refined[k][1]
    return MultiPlaneResult(solutions[k], solutions, mask, int(hyp.cost.size))
