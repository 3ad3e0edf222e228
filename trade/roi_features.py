"""ROI feature tracking around the target box: Harris corners in a 3x3 tiled ROI, tracked with KLT.

Owns the track set and each track's depth, triangulated against its first observation and fused by Gaussian
multiplication until it is promoted to a 3D point (paper, "ROI Feature tracking").

Depth parametrisation: a track's depth is d0, the z-depth in its *first* camera frame, i.e. the world point
X = C0 + d0 f0 on the first-observation ray f0 = R0 K^-1 [u0, v0, 1]^T. For a static point d0 is constant, so
every frame's two-view estimate of d0 is fused directly, as a Gaussian in inverse depth 1/d0: its two-view
error is near-Gaussian and of a spread that does not grow with the estimate, whereas fusing d0 itself weights
each estimate by 1/sigma(d0)^2 ~ 1/d0^4 and so pulls the fused depth towards the nearer estimates (REMODE,
LSD-SLAM and DSO filter inverse depth for the same reason). Outputs are converted to the current camera frame.

Drift: KLT chained frame to frame accumulates a small error per frame, and under steady image motion that
error has a steady sign: on images whose texture moves in whole-pixel steps (nearest-texel rendering, as
pybullet's TinyRenderer) a track 30 frames old lags its point by 0.2-0.5 px in the desert scene, which makes
young tracks' depths too far. Each chained position is therefore refined by KLT against the track's own
first image (its anchor), starting from the chained position; a correction larger than anchor_max_shift_px
is not trusted (the patch has changed too much) and the chained position is kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import cv2
import numpy as np
import numpy.typing as npt

from trade.anchor_klt import refine_from_first_images
from trade.geometry import CameraIntrinsics, Pose
from trade.types import BBox

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

GRID = 3  # the ROI is a GRID x GRID tile grid, row-major tile index 0..8
CENTRE_TILE = 4  # the box itself; never holds tracks
OUTER_TILES = tuple(k for k in range(GRID * GRID) if k != CENTRE_TILE)
_MIN_RAY_DET = 1e-12  # |f0 x f1|^2 below this: rays parallel, no triangulation


@dataclass(frozen=True)
class RoiConfig:
    """ROI geometry, Harris/KLT parameters and the depth filter's noise and thresholds."""

    roi_margin_factor: float = 2.0  # margin on each side = factor x the box's shorter side
    # Tracks are seeded in the ROI and kept until they leave it with its margins scaled by this (1: the ROI itself,
    # the paper's); the pipeline sets it for a pitched camera (`trade.camera_pitch.roi_config_for_pitch`).
    keep_margin_scale: float = 1.0
    max_features_per_tile: int = 25
    harris_quality_level: float = 0.01  # relative to the strongest corner of the tile
    harris_k: float = 0.04
    harris_block_size_px: int = 3
    min_feature_distance_px: float = 4.0  # between corners, new and existing
    klt_window_px: int = 11
    klt_pyramid_levels: int = 3
    klt_max_iterations: int = 20
    klt_epsilon_px: float = 0.03
    fb_threshold_px: float = 1.0  # forward-backward KLT round-trip error
    anchor_to_first_image: bool = True  # refine each chained KLT position against the track's first image
    anchor_max_shift_px: float = 1.0  # larger refinements are not trusted; the chained position is kept
    pixel_sigma_px: float = 0.5  # 1-sigma of a tracked pixel, propagated to depth
    min_parallax_deg: float = 0.5  # angle between first and current ray needed to triangulate
    max_ray_gap_px: float = 2.0  # closest-approach gap of the two rays, in current pixels; above: drop track
    promote_sigma_m: float = 0.5  # promoted once depth sigma <= this ...
    promote_relative_sigma: float = 0.02  # ... or <= this fraction of the depth

    def __post_init__(self) -> None:
        counts = ("max_features_per_tile", "harris_block_size_px", "klt_window_px", "klt_max_iterations")
        for name in (*counts, "klt_pyramid_levels"):
            value, low = getattr(self, name), 0 if name == "klt_pyramid_levels" else 1
            if int(value) != value or value < low:
                raise ValueError(f"RoiConfig.{name} must be an integer >= {low}, got {value!r}")
        if not (math.isfinite(self.keep_margin_scale) and self.keep_margin_scale >= 1.0):
            raise ValueError(f"RoiConfig.keep_margin_scale must be finite and >= 1, got {self.keep_margin_scale!r}")
        positive: tuple[str, ...] = ("roi_margin_factor", "harris_quality_level", "klt_epsilon_px", "fb_threshold_px")
        positive += ("pixel_sigma_px", "max_ray_gap_px", "promote_sigma_m", "anchor_max_shift_px")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"RoiConfig.{name} must be finite and > 0, got {value!r}")
        for name in ("harris_k", "min_feature_distance_px", "min_parallax_deg", "promote_relative_sigma"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"RoiConfig.{name} must be finite and >= 0, got {value!r}")


@dataclass(frozen=True)
class RoiFeatures:
    """Tracks alive after one step; depth and sigma refer to the current camera's z axis."""

    pixels: FloatArray  # (N, 2) current pixels
    first_pixels: FloatArray  # (N, 2) pixels of each track's first observation (in its first frame)
    points_world: FloatArray  # (N, 3) world [m]; NaN where never triangulated
    depth_m: FloatArray  # (N,) current camera z [m]; NaN where never triangulated
    sigma_m: FloatArray  # (N,) 1-sigma of depth_m [m]; inf where never triangulated
    promoted: BoolArray  # (N,) depth converged (sticky once set)
    track_ids: IntArray  # (N,) unique per reset
    tile: IntArray  # (N,) row-major tile index 0..8 (never CENTRE_TILE); -1 kept beyond the ROI (keep_margin_scale)
    roi: BBox  # ROI rectangle [px]; may extend past the image


@dataclass(frozen=True)
class TwoViewDepth:
    """Per-track depth along the first ray from two views; NaN/False where not triangulable."""

    depth_first_m: FloatArray  # (N,) d0, z in the first camera [m]
    sigma_first_m: FloatArray  # (N,) 1-sigma of d0 for a pixel_sigma_px error in the current view [m]
    valid: BoolArray  # (N,) in front of both cameras, enough parallax, finite sigma
    ray_gap_px: FloatArray  # (N,) closest-approach gap of the rays projected in the current view [px]


def roi_tile_edges(box: BBox, margin_factor: float) -> tuple[FloatArray, FloatArray]:
    """Column and row edges (4,), (4,) [px] of the 3x3 grid whose centre tile is `box`."""
    m = margin_factor * min(box.w_px, box.h_px)
    xs = np.array([box.x_px - m, box.x_px, box.x_px + box.w_px, box.x_px + box.w_px + m])
    ys = np.array([box.y_px - m, box.y_px, box.y_px + box.h_px, box.y_px + box.h_px + m])
    return xs, ys


def tile_index(pixels: FloatArray, xs: FloatArray, ys: FloatArray) -> IntArray:
    """pixels (N, 2) -> (N,) row-major tile 0..8 with tile k = [xs[c], xs[c+1]) x [ys[r], ys[r+1]); -1 outside."""
    col = np.searchsorted(xs, pixels[:, 0], side="right") - 1
    row = np.searchsorted(ys, pixels[:, 1], side="right") - 1
    inside = (col >= 0) & (col < GRID) & (row >= 0) & (row < GRID)
    return np.where(inside, row * GRID + col, -1).astype(np.int64)


def triangulate_first_ray(
    center0_w: FloatArray,
    ray0_w: FloatArray,
    center1_w: FloatArray,
    ray1_w: FloatArray,
    focal_px: float,
    config: RoiConfig,
) -> TwoViewDepth:
    """Midpoint triangulation of rays C0 + d0 f0 and C1 + d1 f1 (all (N, 3) world; C1 may be (3,)).

    f0, f1 have unit z in their own camera, so d0, d1 are camera z-depths. Normal equations of
    min |C0 + d0 f0 - C1 - d1 f1|^2 with b = C1 - C0:  [f0.f0, -f0.f1; -f0.f1, f1.f1] [d0; d1] = [f0.b; -f1.b].
    sigma(d0) from a pixel_sigma_px angular error at C1 (sine law, Pizzoli et al. 2014, REMODE).
    """
    b = center1_w - center0_w
    a, m, c = (np.einsum("ij,ij->i", u, v) for u, v in ((ray0_w, ray0_w), (ray0_w, ray1_w), (ray1_w, ray1_w)))
    p, q = np.einsum("ij,ij->i", ray0_w, b), np.einsum("ij,ij->i", ray1_w, b)
    det = a * c - m * m  # = |f0 x f1|^2
    with np.errstate(divide="ignore", invalid="ignore"):
        d0 = (c * p - m * q) / det  # Cramer's rule
        d1 = (m * p - a * q) / det
        gap_m = np.linalg.norm(d0[:, None] * ray0_w - d1[:, None] * ray1_w - b, axis=1)  # |X0 - X1|
        gap_px = focal_px * gap_m / d1
        parallax = np.arccos(np.clip(m / np.sqrt(a * c), -1.0, 1.0))
        # sine law in triangle C0, C1, X: |X - C0| = |b| sin(beta) / sin(pi - alpha - beta); beta += pixel angle
        norm0, norm_b = np.sqrt(a), np.linalg.norm(b, axis=1)
        to_x = d0[:, None] * ray0_w - b  # X - C1
        alpha = np.arccos(np.clip(p / (norm0 * norm_b), -1.0, 1.0))
        cos_beta = -np.einsum("ij,ij->i", to_x, b) / (np.linalg.norm(to_x, axis=1) * norm_b)
        pixel_angle = 2.0 * np.arctan(config.pixel_sigma_px / (2.0 * focal_px))
        beta_plus = np.arccos(np.clip(cos_beta, -1.0, 1.0)) + pixel_angle
        gamma = np.pi - alpha - beta_plus
        range_plus = norm_b * np.sin(beta_plus) / np.sin(gamma)
        sigma0 = np.abs(range_plus - d0 * norm0) / norm0  # along-ray range error -> first-camera z
    valid = (det > _MIN_RAY_DET * a * c) & (d0 > 0) & (d1 > 0) & (parallax >= np.radians(config.min_parallax_deg))
    valid &= (gamma > 0) & np.isfinite(sigma0) & (sigma0 > 0)
    return TwoViewDepth(np.where(valid, d0, np.nan), np.where(valid, sigma0, np.nan), valid, gap_px)


def fuse_gaussian(
    mu: FloatArray, precision: FloatArray, z: FloatArray, sigma: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Product of N(mu, 1/precision) and N(z, sigma^2), elementwise (N,); precision 0 = no prior.

    1/s^2 = 1/s1^2 + 1/s2^2;  mu = (mu1/s1^2 + mu2/s2^2) s^2.
    """
    w = 1.0 / np.square(sigma)
    new_precision = precision + w
    return (mu * precision + z * w) / new_precision, new_precision


def fuse_inverse_depth(
    inv_mu: FloatArray, precision: FloatArray, depth_m: FloatArray, sigma_m: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Fuse depth measurements N(depth_m, sigma_m^2) into Gaussians over inverse depth N(inv_mu, 1/precision)
    (precision 0 = no prior); the measurement's inverse-depth sigma is sigma_m / depth_m^2 (first order)."""
    inv_depth = 1.0 / depth_m
    return fuse_gaussian(inv_mu, precision, inv_depth, sigma_m * np.square(inv_depth))


def _oldest_per_tile(tiles: IntArray, ids: IntArray, cap: int) -> BoolArray:
    """(N,) keep-mask of the `cap` oldest (smallest id) tracks of each tile; tracks migrate between tiles."""
    order = np.lexsort((ids, tiles))  # by tile, then id
    sorted_tiles = tiles[order]
    rank = np.arange(len(order)) - np.searchsorted(sorted_tiles, sorted_tiles, side="left")
    keep = np.empty(len(order), bool)
    keep[order] = rank < cap
    return keep


class RoiFeatureTracker:
    """Keeps up to max_features_per_tile KLT tracks in each outer tile of the ROI and estimates their depth."""

    def __init__(self, config: RoiConfig, intrinsics: CameraIntrinsics) -> None:
        self.config = config
        self.intrinsics = intrinsics
        self._focal_px = 0.5 * (intrinsics.fx_px + intrinsics.fy_px)
        diameter_px = 2 * math.ceil(config.min_feature_distance_px) + 1
        self._erode_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter_px, diameter_px))
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, config.klt_max_iterations, config.klt_epsilon_px)
        self._lk: dict[str, Any] = dict(winSize=(config.klt_window_px,) * 2, maxLevel=config.klt_pyramid_levels, criteria=criteria)
        self._anchor_lk = {**self._lk, "maxLevel": 0}  # the start is within a pixel or two of the answer
        self.reset()

    def reset(self) -> None:
        """Forget all tracks and the previous image."""
        self._prev: npt.NDArray[np.uint8] | None = None
        self._next_id = 0
        self._ids = np.zeros(0, np.int64)
        self._px = np.zeros((0, 2), np.float32)  # current pixels
        self._first_px = np.zeros((0, 2))  # first observation: pixel ...
        self._first_center = np.zeros((0, 3))  # ... camera centre t0 of T_world_cam [m] ...
        self._first_ray = np.zeros((0, 3))  # ... and world ray f0 = R0 K^-1 [u0, v0, 1]
        self._inv_mu = np.zeros(0)  # fused 1/d0 [1/m]
        self._precision = np.zeros(0)  # 1 / sigma(1/d0)^2 [m^2]; 0 = not triangulated yet
        self._promoted = np.zeros(0, bool)
        self._birth = np.zeros(0, np.int64)  # frame index of each track's first observation
        self._frame = 0  # index of the next frame
        self._anchors: dict[int, npt.NDArray[np.uint8]] = {}  # first image of the live tracks, by frame index

    def step(self, gray: npt.NDArray[np.uint8], box: BBox, T_world_cam: Pose) -> RoiFeatures:
        """gray: (H, W) uint8 image; box: target box [px]; T_world_cam: current camera pose."""
        if gray.dtype != np.uint8 or gray.shape != (self.intrinsics.height_px, self.intrinsics.width_px):
            size = (self.intrinsics.height_px, self.intrinsics.width_px)
            raise ValueError(f"step needs a uint8 {size} image, got {gray.dtype} {gray.shape}")
        cfg = self.config
        xs, ys = roi_tile_edges(box, cfg.roi_margin_factor)
        alive = (self._track(self._prev, gray) if self._prev is not None and len(self._ids)
                 else np.ones(len(self._ids), bool))
        pixels = self._px.astype(np.float64)
        tiles = tile_index(pixels, xs, ys)
        wide = cfg.keep_margin_scale != 1.0  # else the kept zone is the ROI, whose tiles are at hand
        kept_zone = (tile_index(pixels, *roi_tile_edges(box, cfg.roi_margin_factor * cfg.keep_margin_scale))
                     if wide else tiles) >= 0
        keep = alive & kept_zone & (tiles != CENTRE_TILE)
        in_roi = keep & (tiles >= 0)  # the per-tile cap counts the ROI's tracks; those kept beyond it are extra
        keep[in_roi] = _oldest_per_tile(tiles[in_roi], self._ids[in_roi], cfg.max_features_per_tile)
        self._select(keep)
        self._fuse(T_world_cam)
        self._top_up(gray, xs, ys, T_world_cam)
        self._prev = gray.copy()
        self._keep_anchors(self._prev)
        self._frame += 1
        return self._output(T_world_cam, xs, ys)

    def _track(self, prev: npt.NDArray[np.uint8], gray: npt.NDArray[np.uint8]) -> BoolArray:
        """KLT prev -> current, then back; keep tracks with both found, round trip < fb threshold, in image."""
        p0 = self._px.reshape(-1, 1, 2)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev, gray, p0, None, **self._lk)
        p0_back, st2, _ = cv2.calcOpticalFlowPyrLK(gray, prev, p1, None, **self._lk)
        fb_px = np.linalg.norm((p0_back - p0).reshape(-1, 2), axis=1)
        # float32 points (OpenCV's stubs say only "an integer or float array")
        self._px = cast(npt.NDArray[np.float32], p1.reshape(-1, 2))
        found = st1.ravel().astype(bool) & st2.ravel().astype(bool) & (fb_px < self.config.fb_threshold_px)
        if self.config.anchor_to_first_image:
            self._refine_against_anchors(gray, found)
        x, y = self._px[:, 0], self._px[:, 1]
        in_image = (x >= 0) & (y >= 0) & (x <= self.intrinsics.width_px - 1) & (y <= self.intrinsics.height_px - 1)
        return found & in_image

    def _refine_against_anchors(self, gray: npt.NDArray[np.uint8], found: BoolArray) -> None:
        """KLT from each track's first image and pixel to `gray`, started at the chained position (no pyramid:
        the start is within a pixel or two); refinements within anchor_max_shift_px replace the chained pixel."""
        idx = np.flatnonzero(found)
        if not len(idx):
            return
        refined, status = refine_from_first_images(self._anchors, self._birth[idx], self._first_px[idx], gray,
                                                   self._px[idx], self._anchor_lk)
        shift_px = np.linalg.norm(refined - self._px[idx], axis=1)
        take = status & (shift_px <= self.config.anchor_max_shift_px)
        self._px[idx[take]] = refined[take]

    def _keep_anchors(self, image: npt.NDArray[np.uint8]) -> None:
        """Keep the first images of live tracks only, adding this frame's `image` if tracks started in it."""
        if not self.config.anchor_to_first_image:
            return
        live = set(np.unique(self._birth).tolist())
        self._anchors = {birth: image for birth, image in self._anchors.items() if birth in live}
        if self._frame in live:
            self._anchors[self._frame] = image

    def _select(self, keep: BoolArray) -> None:
        for name in ("_ids", "_px", "_first_px", "_first_center", "_first_ray", "_inv_mu", "_precision", "_promoted",
                     "_birth"):
            setattr(self, name, getattr(self, name)[keep])

    def _world_rays(self, pixels: FloatArray, T_world_cam: Pose) -> FloatArray:
        """pixels (N, 2) -> (N, 3) world directions R K^-1 [u, v, 1] (unit z in the camera)."""
        return self.intrinsics.rays(pixels) @ T_world_cam.R.T

    def _fuse(self, T_world_cam: Pose) -> None:
        """Triangulate every track against its first observation; fuse valid 1/d0; drop inconsistent tracks."""
        if not len(self._ids):
            return
        rays = self._world_rays(self._px.astype(np.float64), T_world_cam)
        cfg = self.config
        tv = triangulate_first_ray(self._first_center, self._first_ray, T_world_cam.t, rays, self._focal_px, cfg)
        use = tv.valid & (tv.ray_gap_px <= cfg.max_ray_gap_px)
        self._inv_mu[use], self._precision[use] = fuse_inverse_depth(
            self._inv_mu[use], self._precision[use], tv.depth_first_m[use], tv.sigma_first_m[use]
        )
        self._select(use | ~tv.valid)  # drop tracks whose rays miss each other: moving or mistracked

    def _top_up(self, gray: npt.NDArray[np.uint8], xs: FloatArray, ys: FloatArray, T_world_cam: Pose) -> None:
        """Add Harris corners to outer tiles holding fewer than max_features_per_tile tracks."""
        cfg, (h, w) = self.config, gray.shape
        counts = np.bincount(tile_index(self._px.astype(np.float64), xs, ys) + 1, minlength=GRID * GRID + 1)[1:]
        need = {k: cfg.max_features_per_tile - counts[k] for k in OUTER_TILES if counts[k] < cfg.max_features_per_tile}
        # integer pixel ranges [lo, hi) holding x with edge <= x < next edge, clipped to the image
        cx = np.clip(np.ceil(xs), 0, w).astype(int)
        cy = np.clip(np.ceil(ys), 0, h).astype(int)
        if not need or cx[3] <= cx[0] or cy[3] <= cy[0]:
            return
        # exclusion mask over the clipped ROI: 0 within min distance of an existing track (erosion of dots)
        mask = np.full((cy[3] - cy[0], cx[3] - cx[0]), 255, np.uint8)
        q = np.rint(self._px).astype(int) - (cx[0], cy[0])
        q = q[(q[:, 0] >= 0) & (q[:, 1] >= 0) & (q[:, 0] < mask.shape[1]) & (q[:, 1] < mask.shape[0])]
        mask[q[:, 1], q[:, 0]] = 0
        mask = cv2.erode(mask, self._erode_kernel)
        found = []
        for k, n in need.items():
            r, c = divmod(k, GRID)
            x0, x1, y0, y1 = cx[c], cx[c + 1], cy[r], cy[r + 1]
            if min(x1 - x0, y1 - y0) < cfg.harris_block_size_px:
                continue
            corners = cv2.goodFeaturesToTrack(
                gray[y0:y1, x0:x1],
                maxCorners=int(n),
                qualityLevel=cfg.harris_quality_level,
                minDistance=cfg.min_feature_distance_px,
                mask=mask[y0 - cy[0] : y1 - cy[0], x0 - cx[0] : x1 - cx[0]],
                blockSize=cfg.harris_block_size_px,
                useHarrisDetector=True,
                k=cfg.harris_k,
            )
            if corners is not None:
                found.append(corners.reshape(-1, 2) + (x0, y0))
        if found:
            self._add(np.concatenate(found).astype(np.float32), T_world_cam)

    def _add(self, pixels: npt.NDArray[np.float32], T_world_cam: Pose) -> None:
        n = len(pixels)
        first = pixels.astype(np.float64)
        self._ids = np.concatenate([self._ids, np.arange(self._next_id, self._next_id + n)])
        self._next_id += n
        self._px = np.concatenate([self._px, pixels])
        self._first_px = np.concatenate([self._first_px, first])
        self._first_center = np.concatenate([self._first_center, np.broadcast_to(T_world_cam.t, (n, 3))])
        self._first_ray = np.concatenate([self._first_ray, self._world_rays(first, T_world_cam)])
        self._inv_mu = np.concatenate([self._inv_mu, np.zeros(n)])
        self._precision = np.concatenate([self._precision, np.zeros(n)])
        self._promoted = np.concatenate([self._promoted, np.zeros(n, bool)])
        self._birth = np.concatenate([self._birth, np.full(n, self._frame, np.int64)])

    def _output(self, T_world_cam: Pose, xs: FloatArray, ys: FloatArray) -> RoiFeatures:
        """World point X = C0 + d0 f0; depth = z of R^T (X - C); sigma(d0) = d0^2 sigma(1/d0);
        sigma = |dz/dd0| sigma(d0) = |(R^T f0)_z| sigma(d0)."""
        known = self._precision > 0
        with np.errstate(divide="ignore"):  # inv_mu and precision are 0 where never triangulated
            d0 = np.where(known, 1.0 / self._inv_mu, np.nan)
            sigma0 = np.where(known, np.square(d0) / np.sqrt(self._precision), np.inf)
        points = np.where(known[:, None], self._first_center + d0[:, None] * self._first_ray, np.nan)
        depth = ((points - T_world_cam.t) @ T_world_cam.R)[:, 2]
        sigma = np.abs((self._first_ray @ T_world_cam.R)[:, 2]) * sigma0
        threshold = np.maximum(self.config.promote_sigma_m, self.config.promote_relative_sigma * depth)
        self._promoted |= known & (sigma <= threshold)
        pixels = self._px.astype(np.float64)
        roi = BBox(xs[0], ys[0], xs[3] - xs[0], ys[3] - ys[0])
        tiles = tile_index(pixels, xs, ys)
        return RoiFeatures(
            pixels, self._first_px.copy(), points, depth, sigma, self._promoted.copy(), self._ids.copy(), tiles, roi
        )
