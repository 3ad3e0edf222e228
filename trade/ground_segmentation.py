"""Ground-plane segmentation of a metric depth map around the target box (paper, "Ground Plane Segmentation").

Owns the tile grid over the ROI crop, batched per-tile plane fits, seeding, tile-wise region growing and the
pixel-level border refinement that turns the grown tiles into a ground mask in full-image coordinates.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics, Pose
from trade.planes import Plane
from trade.types import BBox

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

MIN_GRID_TILES = 3  # fewer tiles per side than this: no seeding ring around the box, segmentation gives up
PLANE_POINTS = 3  # points needed to define a plane
MIN_SPREAD_M2 = 1e-12  # in-plane scatter eigenvalue floor (collinear tile) in the tilt variance
N_MOMENTS = 11  # per pixel: 1, qx, qy, qz, qxx, qxy, qxz, qyy, qyz, qzz, camera z
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # scatter-matrix entries held by moments 4..9
DROP, KEEP, REFINE = 0, 1, 2  # tile status in the border refinement
NEIGHBOURS_4 = ((-1, 0), (1, 0), (0, -1), (0, 1))  # (d_row, d_col) of the region-growing search


@dataclass(frozen=True)
class GroundSegmentationConfig:
    """Paper values: 20x20 tiles, 8 seeds, alpha = 3 deg, tile MSE < 0.001, border at 9 x plane MSE.

    The rest is ours. Noise level s: the median over the crop's tiles of MSE / z^2 (z: the tile's mean
    camera depth); non-planar tiles (steps, edges) are a minority and do not move it; 0 on exact depth.
    Tile MSE (iii): MSE_c < max(tile_mse_threshold_m2 (z_c / mse_reference_depth_m)^2, mse_noise_factor
    s z_c^2). The first term is the paper's 0.001 m^2 held at 32 m (RMS 3 cm = 0.1 % of depth; the City
    and Mountain flights) and scaled with depth^2 so it means the same at 16 m and in the far rows of a
    tilted view (None: the paper's absolute value at every depth). On exact depth it rejects tiles that
    straddle the target (MSE / z^2 >= 4e-5 at 32 m) or a building edge (>= 3e-5). It also rejects every
    tile of a depth map with 1 % per-pixel noise (MSE / z^2 ~ 8e-5, i.e. 0.08 m^2 at 32 m), hence the
    second term; mse_noise_factor = 0 is the paper's rule.
    `fit_noise_sigmas` = k widens (i) and (ii) by k standard deviations of the two tile fits (normal tilt,
    centroid offset) predicted from s; on exact depth this adds nothing, and k = 0 is the paper's literal
    rule, under which 1 % noise (tile normals scattered by ~5 deg > alpha) stops the growth at a few tiles.
    Border refinement: the paper's "distance less than 9 times the plane MSE" mixes m and m^2; we read it
    as distance^2 < 9 MSE, i.e. |distance| < 3 RMS (a 3-sigma gate), with a floor relative to depth so
    that exact (noise-free) depth does not reject on-plane pixels by float rounding.
    """

    grid_tiles: int = 20  # tiles per side of the crop (fewer when tiles would be < min_tile_px)
    min_tile_px: int = 4
    min_tile_points: int = 6  # valid depths a tile needs for a plane fit
    n_seeds: int = 8
    growth_angle_deg: float = 3.0  # alpha of (ii): |n_s . (c_c - c_s)| < d sin(alpha)
    normal_threshold_deg: float = 10.0  # (i): angle(n_c, n_s) below this (the paper leaves it open)
    tile_mse_threshold_m2: float = 0.001  # (iii), paper
    mse_reference_depth_m: float | None = 32.0  # depth at which tile_mse_threshold_m2 holds; None: everywhere
    mse_noise_factor: float = 4.0  # (iii) threshold >= this x noise level s x z^2 (1 % noise: max MSE ~ 2 s)
    fit_noise_sigmas: float = 3.0
    max_ground_tilt_deg: float = 30.0  # seed and grown tiles must be this close to level (walls never join)
    ground_percentile: float = 10.0  # ground level = this percentile of seeding-tile mean heights
    min_object_height_m: float = 0.3  # clamp of the coarse object height
    max_object_height_m: float = 6.0
    border_mse_factor: float = 9.0  # border pixel kept if distance^2 < factor x region-plane MSE
    border_min_distance_rel: float = 0.002  # ... or distance < this fraction of its depth (noise-free floor)

    def __post_init__(self) -> None:
        ints = {"grid_tiles": MIN_GRID_TILES, "min_tile_px": 1, "min_tile_points": PLANE_POINTS, "n_seeds": 1}
        for name, lowest in ints.items():
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < lowest:
                raise ValueError(f"GroundSegmentationConfig.{name} must be an integer >= {lowest}, "
                                 f"got {value!r}")
        ref = self.mse_reference_depth_m
        checks = {  # field: (valid, expectation)
            "growth_angle_deg": (0.0 < self.growth_angle_deg < 90.0, "in (0, 90)"),
            "normal_threshold_deg": (0.0 < self.normal_threshold_deg < 90.0, "in (0, 90)"),
            "max_ground_tilt_deg": (0.0 < self.max_ground_tilt_deg <= 90.0, "in (0, 90]"),
            "tile_mse_threshold_m2": (0.0 < self.tile_mse_threshold_m2 < math.inf, "finite and > 0"),
            "mse_reference_depth_m": (ref is None or 0.0 < ref < math.inf, "None or finite and > 0"),
            "mse_noise_factor": (0.0 <= self.mse_noise_factor < math.inf, "finite and >= 0"),
            "fit_noise_sigmas": (0.0 <= self.fit_noise_sigmas < math.inf, "finite and >= 0"),
            "ground_percentile": (0.0 <= self.ground_percentile <= 100.0, "in [0, 100]"),
            "min_object_height_m": (0.0 <= self.min_object_height_m < math.inf, "finite and >= 0"),
            "max_object_height_m": (self.min_object_height_m <= self.max_object_height_m < math.inf,
                                    "finite and >= min_object_height_m"),
            "border_mse_factor": (0.0 < self.border_mse_factor < math.inf, "finite and > 0"),
            "border_min_distance_rel": (0.0 <= self.border_min_distance_rel < math.inf, "finite and >= 0"),
        }
        for name, (valid, expectation) in checks.items():
            if not valid:
                value = getattr(self, name)
                raise ValueError(f"GroundSegmentationConfig.{name} must be {expectation}, got {value!r}")


@dataclass(frozen=True)
class SegmentationTimings:
    """Wall time per stage [s]."""

    backproject_s: float = 0.0
    tile_fit_s: float = 0.0
    grow_s: float = 0.0
    refine_s: float = 0.0
    total_s: float = 0.0


@dataclass(frozen=True)
class GroundMask:
    """mask: (H, W) full image, True on ground; plane: world plane fitted to the mask pixels (None when
    nothing was segmented). object_height_m: mean distance of the box points above `plane` (the coarse
    estimate when plane is None); coarse_object_height_m: box mean height minus ground level, clamped
    (biased on slopes: the ground level is a low percentile of the ring around the box)."""

    mask: BoolArray
    plane: Plane | None
    object_height_m: float
    coarse_object_height_m: float
    ground_level_m: float  # world z [m] of the ground near the box (NaN when no seeding tile)
    n_seeds_used: int
    n_tiles_grown: int
    grid_shape: tuple[int, int]  # (rows, cols) of the tile grid; (0, 0) when the crop was too small
    timings: SegmentationTimings


@dataclass(frozen=True)
class _Crop:
    """Organised point cloud of crop rows [r0, r0 + h) x cols [c0, c0 + w) in the camera-centred,
    world-aligned frame: world point = q + origin, origin = camera centre."""

    r0: int
    c0: int
    q: FloatArray  # (3, h, w) [m], zero where invalid
    z_cam: FloatArray  # (h, w) camera depth [m], zero where invalid
    valid: BoolArray  # (h, w)
    origin: FloatArray  # (3,) world [m]


@dataclass(frozen=True)
class _Tiles:
    """Per-tile plane fits over a (R, C) grid, flattened row-major to T = R * C."""

    row_edges: npt.NDArray[np.int64]  # (R + 1,) crop rows
    col_edges: npt.NDArray[np.int64]  # (C + 1,) crop cols
    moments: FloatArray  # (N_MOMENTS, h * w) per-pixel moments of the crop, zero where invalid
    sums: FloatArray  # (T, N_MOMENTS) moment sums
    n: FloatArray  # (T,) valid points
    centroid: FloatArray  # (T, 3) camera-centred, world-aligned [m]
    normal: FloatArray  # (T, 3) unit, n_z >= 0
    mse: FloatArray  # (T,) mean squared orthogonal residual [m^2]
    tilt_var: FloatArray  # (T,) variance of the normal's direction [rad^2]
    offset_var: FloatArray  # (T,) variance of the centroid along the normal [m^2]
    depth: FloatArray  # (T,) mean camera depth [m]
    ok: BoolArray  # (T,) enough points for a fit
    noise_rel2: float  # s: median over fitted tiles of the unbiased residual variance / z^2


def _pixel_span(start_px: float, size_px: float, limit: int) -> tuple[int, int]:
    """Integer pixels u with start <= u < start + size, clipped to [0, limit): returns [lo, hi)."""
    return max(0, math.ceil(start_px)), min(limit, math.ceil(start_px + size_px))


def _backproject(depth_m: FloatArray, K: CameraIntrinsics, T_world_cam: Pose, roi: BBox) -> _Crop | None:
    r0, r1 = _pixel_span(roi.y_px, roi.h_px, K.height_px)
    c0, c1 = _pixel_span(roi.x_px, roi.w_px, K.width_px)
    if r1 <= r0 or c1 <= c0:
        return None
    z = depth_m[r0:r1, c0:c1].astype(np.float64)
    valid = np.isfinite(z) & (z > 0.0)
    z = np.where(valid, z, 0.0)
    # camera point p = z [(u - cx) / fx, (v - cy) / fy, 1]; q = R_world_cam p (invalid: p = 0)
    cam = np.empty((3, *z.shape))
    np.multiply(((np.arange(c0, c1) - K.cx_px) / K.fx_px)[None, :], z, out=cam[0])
    np.multiply(((np.arange(r0, r1) - K.cy_px) / K.fy_px)[:, None], z, out=cam[1])
    cam[2] = z
    q = (T_world_cam.R @ cam.reshape(3, -1)).reshape(cam.shape)
    return _Crop(r0, c0, q, z, valid, T_world_cam.t)


def _edges(n_px: int, config: GroundSegmentationConfig) -> npt.NDArray[np.int64]:
    n_tiles = min(config.grid_tiles, n_px // config.min_tile_px)
    return np.round(np.linspace(0.0, n_px, n_tiles + 1)).astype(np.int64)


def _tile_of(edges: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """(n_px,) tile index of each crop row (or column)."""
    return np.repeat(np.arange(edges.size - 1), np.diff(edges))


def _fit_tiles(crop: _Crop, config: GroundSegmentationConfig) -> _Tiles:
    """Moment images summed per tile as A_rows @ M @ A_cols (0/1 membership matrices), then one batched
    3x3 eigen-decomposition of all tile scatter matrices."""
    h, w = crop.valid.shape
    row_edges, col_edges = _edges(h, config), _edges(w, config)
    q = crop.q
    m = np.empty((N_MOMENTS, h, w))
    m[0] = crop.valid
    m[1:4] = q
    for k, (i, j) in enumerate(_UPPER):
        np.multiply(q[i], q[j], out=m[4 + k])
    m[10] = crop.z_cam
    a_rows = (_tile_of(row_edges)[None, :] == np.arange(row_edges.size - 1)[:, None]).astype(np.float64)
    a_cols = (_tile_of(col_edges)[:, None] == np.arange(col_edges.size - 1)[None, :]).astype(np.float64)
    sums = (a_rows @ m @ a_cols).reshape(N_MOMENTS, -1).T  # (T, N_MOMENTS)
    n = sums[:, 0]
    ok = n >= config.min_tile_points
    n_safe = np.where(ok, n, 1.0)
    centroid = sums[:, 1:4] / n_safe[:, None]
    # scatter S = sum q q^T - n c c^T; the normal is the eigenvector of its smallest eigenvalue
    scatter = np.empty((n.size, 3, 3))
    for k, (i, j) in enumerate(_UPPER):
        scatter[:, i, j] = scatter[:, j, i] = sums[:, 4 + k] - n * centroid[:, i] * centroid[:, j]
    scatter[~ok] = np.eye(3)
    eigval, eigvec = np.linalg.eigh(scatter)
    normal = eigvec[:, :, 0] * np.where(eigvec[:, 2, 0] < 0.0, -1.0, 1.0)[:, None]
    lam = np.maximum(eigval, 0.0)
    mse = lam[:, 0] / n_safe
    depth = sums[:, 10] / n_safe
    # depth noise sigma_t^2 = s z_t^2, s = median over tiles of the unbiased n MSE / (n - 3) / z^2
    rel = lam[ok, 0] / (n[ok] - PLANE_POINTS).clip(min=1.0) / depth[ok] ** 2
    noise_rel2 = float(np.median(rel)) if rel.size else 0.0
    sigma2 = noise_rel2 * depth**2
    # LS normal tilt variance along in-plane axis k: sigma^2 / lambda_k; centroid offset variance sigma^2 / n
    tilt_var = sigma2 * (1.0 / np.maximum(lam[:, 1], MIN_SPREAD_M2) + 1.0 / np.maximum(lam[:, 2], MIN_SPREAD_M2))
    return _Tiles(row_edges, col_edges, m.reshape(N_MOMENTS, -1), sums, n, centroid, normal, mse,
                  np.where(ok, tilt_var, 0.0), sigma2 / n_safe, depth, ok, noise_rel2)


def _dilate(grid: BoolArray, eight: bool) -> BoolArray:
    """Binary dilation of a (R, C) grid by one tile, 4- or 8-connected."""
    out = grid.copy()
    out[1:] |= grid[:-1]
    out[:-1] |= grid[1:]
    out[:, 1:] |= grid[:, :-1]
    out[:, :-1] |= grid[:, 1:]
    if eight:
        out[1:, 1:] |= grid[:-1, :-1]
        out[1:, :-1] |= grid[:-1, 1:]
        out[:-1, 1:] |= grid[1:, :-1]
        out[:-1, :-1] |= grid[1:, 1:]
    return out


def _box_tiles(tiles: _Tiles, crop: _Crop, box: BBox, shape: tuple[int, int]) -> tuple[BoolArray, BoolArray]:
    """(contained, touching) (R, C): tiles whose pixels all / some lie inside the target box."""
    b_r0, b_r1 = (v - crop.r0 for v in _pixel_span(box.y_px, box.h_px, shape[0]))
    b_c0, b_c1 = (v - crop.c0 for v in _pixel_span(box.x_px, box.w_px, shape[1]))
    re, ce = tiles.row_edges, tiles.col_edges
    rows_in, cols_in = (re[:-1] >= b_r0) & (re[1:] <= b_r1), (ce[:-1] >= b_c0) & (ce[1:] <= b_c1)
    rows_hit, cols_hit = (re[:-1] < b_r1) & (re[1:] > b_r0), (ce[:-1] < b_c1) & (ce[1:] > b_c0)
    return rows_in[:, None] & cols_in[None, :], rows_hit[:, None] & cols_hit[None, :]


def _growth_edges(tiles: _Tiles, member: BoolArray, config: GroundSegmentationConfig) -> list[list[bool]]:
    """accept[k][s]: tile s may add its neighbour c = s + NEIGHBOURS_4[k]. Criteria of the paper, each
    widened by k_sigma fit standard deviations: (i) angle(n_s, n_c) < theta + k sqrt(var_s + var_c);
    (ii) |n_s . (c_c - c_s)| < d sin(alpha) + k sqrt(off_s + off_c + d^2 var_s); (iii) member[c]."""
    n_rows, n_cols = member.shape
    grid = {name: getattr(tiles, name).reshape(n_rows, n_cols, -1)
            for name in ("centroid", "normal", "tilt_var", "offset_var")}
    k_sigma, sin_alpha = config.fit_noise_sigmas, math.sin(math.radians(config.growth_angle_deg))
    theta = math.radians(config.normal_threshold_deg)
    accept = np.zeros((len(NEIGHBOURS_4), n_rows, n_cols), dtype=bool)
    for k, (dr, dc) in enumerate(NEIGHBOURS_4):
        s_sl = (slice(max(0, -dr), n_rows - max(0, dr)), slice(max(0, -dc), n_cols - max(0, dc)))
        c_sl = (slice(max(0, dr), n_rows + min(0, dr)), slice(max(0, dc), n_cols + min(0, dc)))
        n_s, n_c = grid["normal"][s_sl], grid["normal"][c_sl]
        tv_s, tv_c = grid["tilt_var"][s_sl][..., 0], grid["tilt_var"][c_sl][..., 0]
        angle = np.arccos(np.clip(np.abs(np.sum(n_s * n_c, axis=-1)), 0.0, 1.0))
        normals_agree = angle < theta + k_sigma * np.sqrt(tv_s + tv_c)
        diff = grid["centroid"][c_sl] - grid["centroid"][s_sl]
        d2 = np.sum(diff * diff, axis=-1)
        off = np.abs(np.sum(n_s * diff, axis=-1))
        spread = grid["offset_var"][s_sl][..., 0] + grid["offset_var"][c_sl][..., 0] + d2 * tv_s
        coplanar = off < np.sqrt(d2) * sin_alpha + k_sigma * np.sqrt(spread)
        accept[k][s_sl] = normals_agree & coplanar & member[c_sl]
    return [a.ravel().tolist() for a in accept]


def _grow(seed: int, accept: list[list[bool]], in_region: list[bool], n_cols: int) -> int:
    """Breadth-first tile growth from `seed` over accepted 4-neighbour steps; returns tiles added."""
    moves = [(acc, dr * n_cols + dc) for acc, (dr, dc) in zip(accept, NEIGHBOURS_4)]
    queue, added = deque([seed]), 1
    in_region[seed] = True
    while queue:
        s = queue.popleft()
        for acc, step in moves:
            if acc[s] and not in_region[s + step]:
                in_region[s + step] = True
                queue.append(s + step)
                added += 1
    return added


def _seed_and_grow(tiles: _Tiles, member: BoolArray, seeds_ok: BoolArray, score: FloatArray,
                   config: GroundSegmentationConfig) -> tuple[BoolArray, int]:
    """Alternate seeding and growing: the lowest-score seed tile not yet in a region grows next, until
    `n_seeds` regions are grown or no seed is left (covers a ground split by an obstacle)."""
    accept = _growth_edges(tiles, member, config)
    in_region = [False] * member.size
    candidates = np.flatnonzero(seeds_ok.ravel())
    n_used = 0
    for seed in candidates[np.argsort(score[candidates], kind="stable")].tolist():
        if n_used == config.n_seeds:
            break
        if not in_region[seed]:
            _grow(seed, accept, in_region, member.shape[1])
            n_used += 1
    return np.array(in_region).reshape(member.shape), n_used


def _plane_from_sums(s: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """Total least squares (as `fit_plane_lstsq`) from summed moments s (N_MOMENTS,) of n >= 3 points:
    (centroid q [m], unit normal, MSE [m^2])."""
    n = s[0]
    centroid = s[1:4] / n
    scatter = np.empty((3, 3))
    for k, (i, j) in enumerate(_UPPER):
        scatter[i, j] = scatter[j, i] = s[4 + k] - n * centroid[i] * centroid[j]
    eigval, eigvec = np.linalg.eigh(scatter)
    return centroid, eigvec[:, 0], max(float(eigval[0]), 0.0) / n


def _refine(crop: _Crop, tiles: _Tiles, region: BoolArray, config: GroundSegmentationConfig) -> BoolArray:
    """Crop mask: interior region tiles whole; pixels of border tiles and of their outside neighbours kept
    when dist^2 < border_mse_factor x MSE of the region plane, or dist < border_min_distance_rel x z."""
    centroid, normal, mse = _plane_from_sums(tiles.sums[region.ravel()].sum(axis=0))
    border = region & _dilate(~region, eight=False)
    refine = border | (_dilate(region, eight=True) & ~region)
    status = np.where(region & ~border, KEEP, np.where(refine, REFINE, DROP)).astype(np.int8)
    status_px = np.repeat(np.repeat(status, np.diff(tiles.row_edges), axis=0), np.diff(tiles.col_edges), 1)
    keep_px, refine_px = status_px == KEEP, status_px == REFINE
    dist = np.tensordot(normal, crop.q, axes=1) - normal @ centroid  # n . (q - c)
    floor = config.border_min_distance_rel * crop.z_cam
    close = dist * dist < np.maximum(config.border_mse_factor * mse, floor * floor)
    return crop.valid & (keep_px | (refine_px & close))


def _box_points(crop: _Crop, box: BBox, shape: tuple[int, int]) -> FloatArray:
    """(M, 3) world points [m] of the valid crop pixels inside the target box."""
    h, w = crop.valid.shape
    r0, r1 = (min(max(v - crop.r0, 0), h) for v in _pixel_span(box.y_px, box.h_px, shape[0]))
    c0, c1 = (min(max(v - crop.c0, 0), w) for v in _pixel_span(box.x_px, box.w_px, shape[1]))
    return crop.q[:, r0:r1, c0:c1][:, crop.valid[r0:r1, c0:c1]].T + crop.origin


def _coarse_height(seed_heights: FloatArray, box_pts: FloatArray, config: GroundSegmentationConfig
                   ) -> tuple[float, float]:
    """(ground level, coarse object height) [m]: a low percentile of the seeding tiles' mean world heights, and
    the mean height of the box points (M, 3) world above it, clamped to the configured object heights."""
    ground = float(np.percentile(seed_heights, config.ground_percentile))
    coarse = config.min_object_height_m
    if box_pts.shape[0] > 0:
        coarse = float(np.mean(box_pts[:, 2])) - ground
    return ground, float(np.clip(coarse, config.min_object_height_m, config.max_object_height_m))


def _ground_tiles(tiles: _Tiles, contained: BoolArray, config: GroundSegmentationConfig
                  ) -> tuple[BoolArray, FloatArray]:
    """(member (R, C): fitted tiles outside the box, level within max_ground_tilt_deg and planar by (iii);
    score (T,): MSE / z^2, the seeding order, lowest first)."""
    grid = contained.shape
    depth2 = np.where(tiles.ok, tiles.depth, 1.0) ** 2  # unfitted tiles (never members): any depth > 0
    ref = config.mse_reference_depth_m
    paper = config.tile_mse_threshold_m2 * (1.0 if ref is None else depth2 / ref**2)
    planar = tiles.mse < np.maximum(paper, config.mse_noise_factor * tiles.noise_rel2 * depth2)
    level = tiles.normal[:, 2].reshape(grid) >= math.cos(math.radians(config.max_ground_tilt_deg))
    return tiles.ok.reshape(grid) & ~contained & level & planar.reshape(grid), tiles.mse / depth2


def _mask_plane(crop: _Crop, tiles: _Tiles, crop_mask: BoolArray) -> Plane | None:
    """World plane fitted to the valid points of `crop_mask` (h, w); None below PLANE_POINTS points."""
    sums = tiles.moments @ crop_mask.ravel().astype(np.float64)
    if sums[0] < PLANE_POINTS:
        return None
    centroid, normal, mse = _plane_from_sums(sums)
    return Plane(normal, -float(normal @ (centroid + crop.origin)), mse, int(sums[0]))


def _failed(shape: tuple[int, int], grid: tuple[int, int], t_start: float, coarse_m: float = math.nan,
            ground_m: float = math.nan) -> GroundMask:
    total = time.perf_counter() - t_start
    return GroundMask(np.zeros(shape, dtype=bool), None, coarse_m, coarse_m, ground_m, 0, 0, grid,
                      SegmentationTimings(total_s=total))


def segment_ground(
    depth_m: npt.ArrayLike,
    K: CameraIntrinsics,
    T_world_cam: Pose,
    box: BBox,
    roi: BBox,
    config: GroundSegmentationConfig,
) -> GroundMask:
    """depth_m: (H, W) metric camera-frame z [m] (NaN/<=0 = no depth); box, roi: [px], roi clipped to the
    image. Returns the ground mask around the target; an empty mask (plane None) when nothing seeds."""
    t_start = time.perf_counter()
    depth = np.asarray(depth_m)
    shape = (K.height_px, K.width_px)
    if depth.shape != shape:
        raise ValueError(f"depth_m must have shape {shape} (height, width of K), got {depth.shape}")
    crop = _backproject(depth, K, T_world_cam, roi)
    if crop is None or min(crop.valid.shape) // config.min_tile_px < MIN_GRID_TILES:
        return _failed(shape, (0, 0), t_start)
    t_back = time.perf_counter()
    tiles = _fit_tiles(crop, config)
    grid = (tiles.row_edges.size - 1, tiles.col_edges.size - 1)
    contained, touching = _box_tiles(tiles, crop, box, shape)
    height = (tiles.centroid[:, 2] + crop.origin[2]).reshape(grid)
    seeding = _dilate(touching, eight=True) & ~contained & tiles.ok.reshape(grid)
    box_pts = _box_points(crop, box, shape)
    if not np.any(seeding):
        return _failed(shape, grid, t_start)
    ground, coarse = _coarse_height(height[seeding], box_pts, config)
    member, score = _ground_tiles(tiles, contained, config)
    seeds_ok = seeding & member & (height <= ground + coarse)
    t_fit = time.perf_counter()
    region, n_seeds = _seed_and_grow(tiles, member, seeds_ok, score, config)
    t_grow = time.perf_counter()
    if n_seeds == 0:
        return _failed(shape, grid, t_start, coarse, ground)
    crop_mask = _refine(crop, tiles, region, config)
    mask = np.zeros(shape, dtype=bool)
    h, w = crop_mask.shape
    mask[crop.r0:crop.r0 + h, crop.c0:crop.c0 + w] = crop_mask
    plane = _mask_plane(crop, tiles, crop_mask)
    height_above = coarse
    if plane is not None and box_pts.shape[0] > 0:
        height_above = float(np.mean(plane.signed_distance(box_pts)))
    t_end = time.perf_counter()
    timings = SegmentationTimings(t_back - t_start, t_fit - t_back, t_grow - t_fit, t_end - t_grow,
                                  t_end - t_start)
    return GroundMask(mask, plane, height_above, coarse, ground, n_seeds, int(region.sum()), grid, timings)


def points_in_mask(pixels: npt.ArrayLike, mask: BoolArray) -> BoolArray:
    """pixels: (N, 2) (u, v) [px], pixel centres at integers -> (N,) True where the nearest pixel is in
    `mask` (H, W); False outside the image or for non-finite pixels."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    finite = np.all(np.isfinite(px), axis=1)
    uv = np.rint(np.where(finite[:, None], px, -1.0)).astype(np.int64)
    inside = finite & (uv[:, 0] >= 0) & (uv[:, 0] < mask.shape[1]) & (uv[:, 1] >= 0) & (uv[:, 1] < mask.shape[0])
    out = np.zeros(px.shape[0], dtype=bool)
    out[inside] = mask[uv[inside, 1], uv[inside, 0]]
    return out
