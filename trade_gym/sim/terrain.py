"""Seeded procedural heightfields and their exact height/slope queries.

Owns `Heightfield` (the surface pybullet's GEOM_HEIGHTFIELD collides with; array and scalar queries),
fractal noise and route carving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
import numpy.typing as npt
from numba import njit

from trade_gym.sim.spline import CatmullRomSpline

FloatArray = npt.NDArray[np.float64]

PATH_RASTER_STEP_CELLS = 0.25  # path sampling step when rasterising it onto the grid [cells]
EXACT_DISTANCE_CHUNK = 4096  # grid nodes per chunk for exact distance-to-path refinement


@njit(cache=True)
def _cell(grid, x_m, y_m):
    """(i, j, fu, fv) of (x_m, y_m) on `Heightfield.grid`: the cell's node and the fractions in it, clamped to the
    grid; NaN in gives NaN fractions."""
    _, nx, ny, ox, oy, d = grid
    u = min(max((x_m - ox) / d, 0.0), nx - 1.0)
    v = min(max((y_m - oy) / d, 0.0), ny - 1.0)
    if u != u or v != v:
        return 0, 0, math.nan, math.nan
    i, j = min(int(u), nx - 2), min(int(v), ny - 2)  # u, v >= 0 so int() is floor()
    return i, j, u - i, v - j


@njit(cache=True)
def _corners(grid, i, j):
    """Heights h00, h10, h01, h11 [m] of cell (i, j), float32 widened exactly."""
    h, nx = grid[0], grid[1]
    k = j * nx + i
    return np.float64(h[k]), np.float64(h[k + 1]), np.float64(h[k + nx]), np.float64(h[k + nx + 1])


@njit(cache=True)
def grid_height(grid, x_m, y_m):
    """Scalar `Heightfield.height_m` [m] at (x_m, y_m) on `Heightfield.grid`: the same triangles, equations and
    rounding, clamped to the grid's edge; NaN in, NaN out."""
    i, j, fu, fv = _cell(grid, x_m, y_m)
    if fu != fu:
        return math.nan
    h00, h10, h01, h11 = _corners(grid, i, j)
    if fu + fv <= 1.0:
        return h00 + fu * (h10 - h00) + fv * (h01 - h00)
    return h11 + (1.0 - fu) * (h01 - h11) + (1.0 - fv) * (h10 - h11)


@njit(cache=True)
def grid_gradient(grid, x_m, y_m):
    """Scalar `Heightfield.gradient`: (dh/dx, dh/dy) of the triangle under (x_m, y_m) on `Heightfield.grid`; NaN in,
    NaN out."""
    i, j, fu, fv = _cell(grid, x_m, y_m)
    if fu != fu:
        return math.nan, math.nan
    h00, h10, h01, h11 = _corners(grid, i, j)
    d = grid[5]
    if fu + fv <= 1.0:
        return (h10 - h00) / d, (h01 - h00) / d
    return (h11 - h01) / d, (h11 - h10) / d


@dataclass(frozen=True, eq=False)
class Heightfield:
    """Regular grid of heights; node (j, i) sits at world (origin_x + i d, origin_y + j d).

    Each cell is split along its (i+1, j)-(i, j+1) diagonal, exactly as Bullet's
    btHeightfieldTerrainShape does, so `height_m` equals what a pybullet ray hits.
    """

    heights_m: npt.NDArray[np.float32]  # (ny, nx): row j along world y, column i along world x [m]
    spacing_m: float  # grid step d [m]
    origin_m: tuple[float, float]  # world x, y of node (0, 0) [m]

    def __post_init__(self) -> None:
        h = np.ascontiguousarray(self.heights_m, dtype=np.float32)
        if h.ndim != 2 or min(h.shape) < 2 or not np.all(np.isfinite(h)):
            raise ValueError(f"Heightfield.heights_m must be a finite (ny >= 2, nx >= 2) array, got {h.shape}")
        if not np.isfinite(self.spacing_m) or self.spacing_m <= 0.0:
            raise ValueError(f"Heightfield.spacing_m must be finite and > 0, got {self.spacing_m!r}")
        h.setflags(write=False)
        object.__setattr__(self, "heights_m", h)
        object.__setattr__(self, "origin_m", (float(self.origin_m[0]), float(self.origin_m[1])))

    @classmethod
    def centred(cls, heights_m: npt.ArrayLike, spacing_m: float) -> Heightfield:
        """Grid centred on the world origin."""
        ny, nx = np.shape(heights_m)
        return cls(np.asarray(heights_m, np.float32), spacing_m, (-(nx - 1) * spacing_m / 2, -(ny - 1) * spacing_m / 2))

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights_m.shape

    @property
    def x_m(self) -> FloatArray:
        """(nx,) world x of the grid columns [m]."""
        return self.origin_m[0] + self.spacing_m * np.arange(self.shape[1], dtype=np.float64)

    @property
    def y_m(self) -> FloatArray:
        """(ny,) world y of the grid rows [m]."""
        return self.origin_m[1] + self.spacing_m * np.arange(self.shape[0], dtype=np.float64)

    @property
    def centre_m(self) -> FloatArray:
        """(2,) world x, y of the grid centre [m] (the pybullet body's x, y)."""
        ny, nx = self.shape
        return np.array(self.origin_m) + self.spacing_m * np.array([nx - 1, ny - 1]) / 2.0

    @property
    def bullet_base_z_m(self) -> float:
        """Body z that puts Bullet's heightfield (centred on (min + max) / 2) at absolute heights."""
        return 0.5 * (float(self.heights_m.min()) + float(self.heights_m.max()))

    def _cell(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> tuple:
        """Cell indices (i, j) and in-cell fractions (fu, fv), coordinates clamped to the grid."""
        ny, nx = self.shape
        u = np.clip((np.asarray(x_m, dtype=np.float64) - self.origin_m[0]) / self.spacing_m, 0.0, nx - 1)
        v = np.clip((np.asarray(y_m, dtype=np.float64) - self.origin_m[1]) / self.spacing_m, 0.0, ny - 1)
        i = np.minimum(np.floor(u).astype(np.intp), nx - 2)
        j = np.minimum(np.floor(v).astype(np.intp), ny - 2)
        h = self.heights_m
        corners = (h[j, i].astype(np.float64), h[j, i + 1].astype(np.float64),
                   h[j + 1, i].astype(np.float64), h[j + 1, i + 1].astype(np.float64))
        return u - i, v - j, corners

    def height_m(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Surface height [m] at world x, y (any broadcastable shapes); clamped at the grid border.

        Lower triangle (fu + fv <= 1): h = h00 + fu (h10 - h00) + fv (h01 - h00);
        upper triangle: h = h11 + (1 - fu) (h01 - h11) + (1 - fv) (h10 - h11).
        """
        fu, fv, (h00, h10, h01, h11) = self._cell(x_m, y_m)
        lower = h00 + fu * (h10 - h00) + fv * (h01 - h00)
        upper = h11 + (1.0 - fu) * (h01 - h11) + (1.0 - fv) * (h10 - h11)
        return np.where(fu + fv <= 1.0, lower, upper)

    def gradient(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """(..., 2) surface gradient (dh/dx, dh/dy) of the triangle under each point."""
        fu, fv, (h00, h10, h01, h11) = self._cell(x_m, y_m)
        lower = fu + fv <= 1.0
        gx = np.where(lower, h10 - h00, h11 - h01) / self.spacing_m
        gy = np.where(lower, h01 - h00, h11 - h10) / self.spacing_m
        return np.stack([gx, gy], axis=-1)

    @cached_property
    def grid(self) -> tuple[npt.NDArray[np.float32], int, int, float, float, float]:
        """The compiled queries' grid: row-major heights (flat, float32), nx, ny, origin x, y [m], spacing [m]."""
        ny, nx = self.shape
        return self.heights_m.ravel(), nx, ny, self.origin_m[0], self.origin_m[1], self.spacing_m

    def height_at(self, x_m: float, y_m: float) -> float:
        """Scalar `height_m` [m] (compiled, `grid_height`): the same equations and rounding; NaN -> NaN."""
        return grid_height(self.grid, float(x_m), float(y_m))

    def gradient_at(self, x_m: float, y_m: float) -> tuple[float, float]:
        """Scalar `gradient` (compiled, `grid_gradient`): (dh/dx, dh/dy) of the triangle under (x, y); NaN in, NaN
        out."""
        return grid_gradient(self.grid, float(x_m), float(y_m))

    def slope_deg(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Surface inclination [deg]: atan(|grad h|)."""
        return np.degrees(np.arctan(np.linalg.norm(self.gradient(x_m, y_m), axis=-1)))

    def vertex_normals(self) -> npt.NDArray[np.float64]:
        """(ny, nx, 3) unit normals from central differences: n ~ (-dh/dx, -dh/dy, 1)."""
        gy, gx = np.gradient(self.heights_m.astype(np.float64), self.spacing_m)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


def value_noise(shape: tuple[int, int], cells: int, rng: np.random.Generator) -> FloatArray:
    """(ny, nx) smooth noise in about [-1, 1]: a (cells+1)^2 random lattice, bicubically upsampled."""
    lattice = rng.uniform(-1.0, 1.0, size=(cells + 1, cells + 1)).astype(np.float32)
    return cv2.resize(lattice, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC).astype(np.float64)


def fractal_noise(
    shape: tuple[int, int], base_cells: int, octaves: int, persistence: float, rng: np.random.Generator
) -> FloatArray:
    """Fractal Brownian motion: sum_k persistence^k noise(2^k base_cells), normalised to about [-1, 1]."""
    total = np.zeros(shape)
    for k in range(octaves):
        total += persistence**k * value_noise(shape, base_cells * 2**k, rng)
    return total / sum(persistence**k for k in range(octaves))


def ridged_noise(
    shape: tuple[int, int], base_cells: int, octaves: int, persistence: float, rng: np.random.Generator
) -> FloatArray:
    """Ridged multifractal in about [0, 1]: sum_k persistence^k (1 - |noise_k|)^2, sharp crests at zero crossings."""
    total = np.zeros(shape)
    for k in range(octaves):
        total += persistence**k * (1.0 - np.abs(value_noise(shape, base_cells * 2**k, rng))) ** 2
    return total / sum(persistence**k for k in range(octaves))


def smoothstep(edge0: float, edge1: float, x: npt.ArrayLike) -> FloatArray:
    """Hermite step: 0 below edge0, 1 above edge1, 3t^2 - 2t^3 between."""
    t = np.clip((np.asarray(x, dtype=np.float64) - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def distance_to_path(
    grid: Heightfield, path: CatmullRomSpline, exact_within_m: float
) -> tuple[FloatArray, FloatArray]:
    """(ny, nx) distance of every node to the path [m] and arc length of its foot [m].

    Euclidean distance transform of the rasterised path (cv2), refined by exact projection for
    nodes closer than `exact_within_m`.
    """
    ny, nx = grid.shape
    _, xy = path.sample(grid.spacing_m * PATH_RASTER_STEP_CELLS)
    s_samples = np.linspace(0.0, path.length_m, len(xy))
    col = np.round((xy[:, 0] - grid.origin_m[0]) / grid.spacing_m).astype(np.intp)
    row = np.round((xy[:, 1] - grid.origin_m[1]) / grid.spacing_m).astype(np.intp)
    inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
    if not np.any(inside):
        raise ValueError("path lies entirely outside the heightfield")
    src = np.full((ny, nx), 255, np.uint8)
    src[row[inside], col[inside]] = 0
    dist_cells, labels = cv2.distanceTransformWithLabels(src, cv2.DIST_L2, cv2.DIST_MASK_5,
                                                         labelType=cv2.DIST_LABEL_PIXEL)
    s_of_label = np.zeros(int(labels.max()) + 1)
    s_of_label[labels[row[inside], col[inside]]] = s_samples[inside]
    dist = dist_cells.astype(np.float64) * grid.spacing_m
    foot = s_of_label[labels]
    near = np.flatnonzero(dist.ravel() < exact_within_m + grid.spacing_m)
    gx, gy = np.meshgrid(grid.x_m, grid.y_m)
    nodes = np.stack([gx.ravel()[near], gy.ravel()[near]], axis=1)
    for start in range(0, len(near), EXACT_DISTANCE_CHUNK):
        idx = near[start : start + EXACT_DISTANCE_CHUNK]
        d, s = path.closest(nodes[start : start + EXACT_DISTANCE_CHUNK])
        dist.ravel()[idx] = d
        foot.ravel()[idx] = s
    return dist, foot
