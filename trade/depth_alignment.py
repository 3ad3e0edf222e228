"""Affine fit of single-image relative inverse depth to ROI feature inverse depths, and metric depth from it.

Owns the paper's {theta0, theta1} = argmin sum (theta0 + rho'_i theta1 - rho_i)^2, in a 2-point RANSAC with a
minimum sample separation (the fit is degenerate on planes parallel to the image) or as one plain least-squares
fit over all features (the paper's Table 2 "without RANSAC"), the scale-only fallback when the features all
lie at one model value, and the model-map check.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

MIN_SAMPLE_POINTS = 2  # a line theta0 + theta1 rho' needs two correspondences
MAP_RANGE_PERCENTILES = (5.0, 95.0)  # robust range of the model map [rho' units]
FEATURE_SPREAD_PERCENTILES = (10.0, 90.0)  # robust spread of the features' rho' (one odd feature is not a spread)
PAIR_OVERSAMPLING = 4  # candidate pairs drawn per wanted hypothesis (invalid ones are discarded)


class FitStatus(enum.Enum):
    """Outcome of an alignment; anything but OK means: fall back (no metric depth from the model)."""

    OK = "ok"
    INVALID_MODEL_OUTPUT = "invalid_model_output"  # non-finite, negative or constant model map
    TOO_FEW_POINTS = "too_few_points"  # fewer usable correspondences than min_correspondences
    DEGENERATE = "degenerate"  # no sample pair far enough apart in rho' (and in the image)
    NO_CONSENSUS = "no_consensus"  # best hypothesis has too few inliers or a non-positive scale


@dataclass(frozen=True)
class AffineFitConfig:
    """RANSAC for rho = theta0 + theta1 rho' (rho: feature inverse depth [1/m], rho': model value)."""

    inlier_threshold_inv_m: float = 0.003  # |theta0 + theta1 rho' - rho| below this is an inlier [1/m]
    iterations: int = 100  # 2-point hypotheses scored
    min_model_separation_fraction: float = 0.1  # sample pair needs |rho'_a - rho'_b| >= this x ptp(rho')
    min_sample_distance_px: float = 5.0  # and (when pixels are given) this image distance
    min_correspondences: int = 6
    min_inlier_fraction: float = 0.3  # of the usable correspondences
    min_model_range_fraction: float = 1e-6  # model map with ptp <= this x max |value| counts as constant
    # Features whose rho' spread (FEATURE_SPREAD_PERCENTILES) is below this fraction of the map's robust range
    # (MAP_RANGE_PERCENTILES) lie on one depth level (ground parallel to the image, the usual nadir view):
    # theta1 is unobservable there and a 2-parameter fit turns model noise into metric noise (city frames:
    # theta1 of 1.5-8 turned the model's ~0.005 ripple into ~50 % depth noise), so only a scale is fitted,
    # rho = theta1 rho'.
    # 0 disables the check. RANSAC mode only.
    min_feature_range_fraction: float = 0.1

    def __post_init__(self) -> None:
        for name in ("inlier_threshold_inv_m", "min_model_range_fraction"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"AffineFitConfig.{name} must be finite and > 0, got {value!r}")
        if not (np.isfinite(self.min_sample_distance_px) and self.min_sample_distance_px >= 0.0):
            raise ValueError("AffineFitConfig.min_sample_distance_px must be finite and >= 0, "
                             f"got {self.min_sample_distance_px!r}")
        for name in ("min_model_separation_fraction", "min_inlier_fraction", "min_feature_range_fraction"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"AffineFitConfig.{name} must be in [0, 1], got {value!r}")
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise ValueError(f"AffineFitConfig.iterations must be an integer >= 1, got {self.iterations!r}")
        if int(self.min_correspondences) != self.min_correspondences or self.min_correspondences < MIN_SAMPLE_POINTS:
            raise ValueError(f"AffineFitConfig.min_correspondences must be an integer >= {MIN_SAMPLE_POINTS}, "
                             f"got {self.min_correspondences!r}")


@dataclass(frozen=True)
class AffineFit:
    """rho = theta0 + theta1 rho' [1/m]; inliers (M,) over the input correspondences (False where unusable);
    rms_inv_m: RMS residual of the final fit over its inliers [1/m] (NaN when failed); scale_only: theta0 was
    fixed at 0 because the features span too little of the model's range."""

    theta0: float
    theta1: float
    inliers: BoolArray
    status: FitStatus
    rms_inv_m: float = float("nan")
    scale_only: bool = False

    @property
    def ok(self) -> bool:
        return self.status is FitStatus.OK

    @classmethod
    def failed(cls, status: FitStatus, count: int) -> AffineFit:
        return cls(float("nan"), float("nan"), np.zeros(count, dtype=bool), status)


@dataclass(frozen=True)
class AlignedDepth:
    """Metric depth_m (H, W) float32 camera z [m] (NaN where theta0 + theta1 rho' <= 0 or on failure) and the fit."""

    depth_m: npt.NDArray[np.float32]
    fit: AffineFit

    @property
    def ok(self) -> bool:
        return self.fit.ok


def check_model_map(model_inv: npt.ArrayLike, config: AffineFitConfig) -> FitStatus:
    """OK if the relative inverse depth map is finite, >= 0 and not constant; INVALID_MODEL_OUTPUT otherwise."""
    m = np.asarray(model_inv, dtype=np.float64)
    if m.size == 0 or not np.all(np.isfinite(m)) or m.min() < 0.0:
        return FitStatus.INVALID_MODEL_OUTPUT
    if np.ptp(m) <= config.min_model_range_fraction * max(np.abs(m).max(), np.finfo(np.float64).tiny):
        return FitStatus.INVALID_MODEL_OUTPUT
    return FitStatus.OK


def _least_squares(x: FloatArray, y: FloatArray) -> tuple[float, float]:
    """(theta0, theta1) = argmin sum (theta0 + theta1 x - y)^2; theta1 = cov(x, y) / var(x)."""
    dx = x - x.mean()
    var = float(dx @ dx)
    theta1 = float(dx @ (y - y.mean())) / var if var > 0.0 else float("nan")
    return float(y.mean() - theta1 * x.mean()), theta1


def _sample_pairs(x: FloatArray, pixels: FloatArray | None, rng: np.random.Generator,
                  config: AffineFitConfig) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Up to `iterations` index pairs (a, b), a != b, separated by the configured rho' and pixel distances."""
    n, k = len(x), config.iterations * PAIR_OVERSAMPLING
    a, b = rng.integers(0, n, k), rng.integers(0, n, k)
    keep = (a != b) & (np.abs(x[a] - x[b]) >= config.min_model_separation_fraction * np.ptp(x))
    keep &= np.abs(x[a] - x[b]) > 0.0
    if pixels is not None:
        keep &= np.linalg.norm(pixels[a] - pixels[b], axis=1) >= config.min_sample_distance_px
    return a[keep][: config.iterations], b[keep][: config.iterations]


def fit_affine_inverse_depth(model_inv: npt.ArrayLike, feature_inv_m: npt.ArrayLike, rng: np.random.Generator,
                             config: AffineFitConfig | None = None,
                             pixels_px: npt.ArrayLike | None = None) -> AffineFit:
    """model_inv (M,) rho' at the features, feature_inv_m (M,) rho [1/m], pixels_px (M, 2) optional.

    RANSAC: 2-point hypotheses theta1 = (rho_b - rho_a) / (rho'_b - rho'_a), theta0 = rho_a - theta1 rho'_a
    (theta1 <= 0 rejected: inverse depth must grow with the model's), most inliers wins (ties: smallest squared
    inlier residual), then least squares on its inliers. Non-finite or non-positive rho are not used.
    """
    cfg = config if config is not None else AffineFitConfig()
    x_all, y_all, usable = _usable_pairs(model_inv, feature_inv_m)
    pix = None if pixels_px is None else np.asarray(pixels_px, dtype=np.float64).reshape(-1, 2)[usable]
    x, y, count = x_all[usable], y_all[usable], int(usable.sum())
    if count < cfg.min_correspondences:
        return AffineFit.failed(FitStatus.TOO_FEW_POINTS, x_all.size)
    a, b = _sample_pairs(x, pix, rng, cfg)
    if a.size == 0:
        return AffineFit.failed(FitStatus.DEGENERATE, x_all.size)
    theta1 = (y[b] - y[a]) / (x[b] - x[a])
    theta0 = y[a] - theta1 * x[a]
    # residuals (K, M) of every hypothesis on every correspondence
    r2 = (theta0[:, None] + theta1[:, None] * x[None, :] - y[None, :]) ** 2
    inl = (r2 < cfg.inlier_threshold_inv_m**2) & (theta1[:, None] > 0.0)
    counts = inl.sum(axis=1)
    cost = np.where(inl, r2, 0.0).sum(axis=1)
    best = int(np.lexsort((cost, -counts))[0])
    min_inliers = max(MIN_SAMPLE_POINTS, int(np.ceil(cfg.min_inlier_fraction * count)))
    if counts[best] < min_inliers:
        return AffineFit.failed(FitStatus.NO_CONSENSUS, x_all.size)
    t0, t1 = _least_squares(x[inl[best]], y[inl[best]])
    if not (np.isfinite(t1) and t1 > 0.0):  # refit collapsed: keep the sample hypothesis
        t0, t1 = float(theta0[best]), float(theta1[best])
    final = np.abs(t0 + t1 * x - y) < cfg.inlier_threshold_inv_m
    if final.sum() < min_inliers:
        return AffineFit.failed(FitStatus.NO_CONSENSUS, x_all.size)
    inliers = np.zeros(x_all.size, dtype=bool)
    inliers[np.flatnonzero(usable)[final]] = True
    return AffineFit(t0, t1, inliers, FitStatus.OK, _rms(t0, t1, x[final], y[final]))


def _usable_pairs(model_inv: npt.ArrayLike, feature_inv_m: npt.ArrayLike) -> tuple[FloatArray, FloatArray, BoolArray]:
    """(x_all, y_all) flattened, and the mask of pairs a fit may use: both finite, rho > 0."""
    x_all = np.asarray(model_inv, dtype=np.float64).reshape(-1)
    y_all = np.asarray(feature_inv_m, dtype=np.float64).reshape(-1)
    if x_all.shape != y_all.shape:
        raise ValueError(f"model_inv and feature_inv_m must have the same length, got {x_all.size}, {y_all.size}")
    return x_all, y_all, np.isfinite(x_all) & np.isfinite(y_all) & (y_all > 0.0)


def fit_affine_least_squares(model_inv: npt.ArrayLike, feature_inv_m: npt.ArrayLike,
                             config: AffineFitConfig | None = None) -> AffineFit:
    """model_inv (M,) rho', feature_inv_m (M,) rho [1/m] -> one least-squares fit over every usable pair.

    The paper's alignment without RANSAC: no outlier rejection, every finite pair with rho > 0 is an inlier.
    TOO_FEW_POINTS below min_correspondences, DEGENERATE when rho' is constant, NO_CONSENSUS when theta1 <= 0.
    """
    cfg = config if config is not None else AffineFitConfig()
    x_all, y_all, usable = _usable_pairs(model_inv, feature_inv_m)
    x, y = x_all[usable], y_all[usable]
    if x.size < cfg.min_correspondences:
        return AffineFit.failed(FitStatus.TOO_FEW_POINTS, x_all.size)
    t0, t1 = _least_squares(x, y)
    if not np.isfinite(t1):
        return AffineFit.failed(FitStatus.DEGENERATE, x_all.size)
    if t1 <= 0.0:
        return AffineFit.failed(FitStatus.NO_CONSENSUS, x_all.size)
    return AffineFit(t0, t1, usable.copy(), FitStatus.OK, _rms(t0, t1, x, y))


def fit_scale_only(model_inv: npt.ArrayLike, feature_inv_m: npt.ArrayLike,
                   config: AffineFitConfig | None = None) -> AffineFit:
    """model_inv (M,) rho', feature_inv_m (M,) rho [1/m] -> rho = theta1 rho' (theta0 = 0), robust.

    theta1 = median(rho / rho') over pairs with rho, rho' > 0; inliers |theta1 rho' - rho| < threshold; then
    theta1 = sum(rho' rho) / sum(rho'^2) over the inliers (least squares through the origin).
    """
    cfg = config if config is not None else AffineFitConfig()
    x_all = np.asarray(model_inv, dtype=np.float64).reshape(-1)
    y_all = np.asarray(feature_inv_m, dtype=np.float64).reshape(-1)
    usable = np.isfinite(x_all) & np.isfinite(y_all) & (y_all > 0.0) & (x_all > 0.0)
    x, y, count = x_all[usable], y_all[usable], int(usable.sum())
    if count < cfg.min_correspondences:
        return AffineFit.failed(FitStatus.TOO_FEW_POINTS, x_all.size)
    theta1 = float(np.median(y / x))
    final = np.abs(theta1 * x - y) < cfg.inlier_threshold_inv_m
    if final.sum() < max(MIN_SAMPLE_POINTS, int(np.ceil(cfg.min_inlier_fraction * count))):
        return AffineFit.failed(FitStatus.NO_CONSENSUS, x_all.size)
    theta1 = float(x[final] @ y[final]) / float(x[final] @ x[final])
    inliers = np.zeros(x_all.size, dtype=bool)
    inliers[np.flatnonzero(usable)[final]] = True
    return AffineFit(0.0, theta1, inliers, FitStatus.OK, _rms(0.0, theta1, x[final], y[final]), scale_only=True)


def _features_span_map(model_inv: FloatArray, model_at: FloatArray, config: AffineFitConfig) -> bool:
    """Whether the features' robust rho' spread is >= min_feature_range_fraction of the map's robust range."""
    finite = model_at[np.isfinite(model_at)]
    if finite.size == 0:
        return True  # nothing to decide on: the fit reports TOO_FEW_POINTS
    f_lo, f_hi = np.percentile(finite, FEATURE_SPREAD_PERCENTILES)
    lo, hi = np.percentile(model_inv, MAP_RANGE_PERCENTILES)
    return bool(f_hi - f_lo >= config.min_feature_range_fraction * (hi - lo))


def _rms(theta0: float, theta1: float, x: FloatArray, y: FloatArray) -> float:
    """sqrt(mean (theta0 + theta1 x - y)^2) [1/m]."""
    return float(np.sqrt(np.mean((theta0 + theta1 * x - y) ** 2)))


def metric_depth(model_inv: npt.ArrayLike, fit: AffineFit) -> npt.NDArray[np.float32]:
    """(H, W) camera z [m] = 1 / (theta0 + theta1 rho'); NaN where that is <= 0, everywhere if the fit failed."""
    m = np.asarray(model_inv, dtype=np.float64)
    if not fit.ok:
        return np.full(m.shape, np.nan, dtype=np.float32)
    rho = fit.theta0 + fit.theta1 * m
    positive = rho > 0.0
    return np.where(positive, 1.0 / np.where(positive, rho, 1.0), np.nan).astype(np.float32)


def sample_map(model_inv: npt.ArrayLike, pixels_px: npt.ArrayLike) -> FloatArray:
    """Bilinear values (M,) of the (H, W) map at pixels (M, 2) (u, v; border replicated)."""
    m = np.ascontiguousarray(np.asarray(model_inv, dtype=np.float32))
    px = np.asarray(pixels_px, dtype=np.float32).reshape(-1, 1, 2)
    if px.shape[0] == 0:
        return np.zeros(0)
    out = cv2.remap(m, px[..., 0], px[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1).astype(np.float64)


def align_model_depth(model_inv: npt.ArrayLike, pixels_px: npt.ArrayLike, feature_depth_m: npt.ArrayLike,
                      rng: np.random.Generator, config: AffineFitConfig | None = None,
                      ransac: bool = True) -> AlignedDepth:
    """Model map (H, W), ROI features at pixels (M, 2) with camera z feature_depth_m (M,) [m] -> metric depth.

    ransac: the 2-point RANSAC fit (default), or the scale-only fit when the features span too little of the
    map's range (`min_feature_range_fraction`); False: plain least squares over all features.
    Invalid model maps and failed fits are signalled in `.fit.status` (depth all NaN), never raised.
    """
    cfg = config if config is not None else AffineFitConfig()
    m = np.asarray(model_inv)
    pix = np.asarray(pixels_px, dtype=np.float64).reshape(-1, 2)
    if m.ndim != 2:
        raise ValueError(f"model_inv must be an (H, W) map, got shape {m.shape}")
    status = check_model_map(m, cfg)
    if status is not FitStatus.OK:
        return AlignedDepth(np.full(m.shape, np.nan, dtype=np.float32), AffineFit.failed(status, len(pix)))
    d = np.asarray(feature_depth_m, dtype=np.float64).reshape(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(d > 0.0, 1.0 / d, np.nan)  # rho = 1 / z; unusable where z <= 0 or NaN
    model_at = sample_map(m, pix)
    if not ransac:
        fit = fit_affine_least_squares(model_at, rho, cfg)
    elif _features_span_map(m, model_at, cfg):
        fit = fit_affine_inverse_depth(model_at, rho, rng, cfg, pix)
    else:
        fit = fit_scale_only(model_at, rho, cfg)
    return AlignedDepth(metric_depth(m, fit), fit)
