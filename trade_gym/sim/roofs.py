"""Roof heights of axis-aligned box buildings at world x, y, for the world's surface-height queries.

Owns `RoofIndex`: a vectorised query for arrays and a bucket-grid scalar query for the per-step drone check.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

BUCKET_M = 8.0  # side of a bucket-grid cell [m]; each cell lists the buildings whose footprint touches it


class RoofIndex:
    """Highest roof over (x, y): max hi_z of the boxes with lo_xy <= (x, y) <= hi_xy, -inf where there is none."""

    def __init__(self, lo_m: npt.ArrayLike, hi_m: npt.ArrayLike, bucket_m: float = BUCKET_M) -> None:
        """lo_m, hi_m: (B, 3) box min and max corners [m]; bucket_m: grid cell side [m]."""
        self.lo_m = np.asarray(lo_m, dtype=np.float64).reshape(-1, 3)
        self.hi_m = np.asarray(hi_m, dtype=np.float64).reshape(-1, 3)
        if self.lo_m.shape != self.hi_m.shape or np.any(self.hi_m < self.lo_m):
            raise ValueError(f"RoofIndex needs matching (B, 3) lo_m <= hi_m, got {self.lo_m.shape}, {self.hi_m.shape}")
        if not np.isfinite(bucket_m) or bucket_m <= 0.0:
            raise ValueError(f"RoofIndex.bucket_m must be finite and > 0, got {bucket_m!r}")
        self.bucket_m = float(bucket_m)
        self._buckets: dict[tuple[int, int], tuple[tuple[float, float, float, float, float], ...]] = {}
        if len(self.lo_m):
            self._origin = (float(self.lo_m[:, 0].min()), float(self.lo_m[:, 1].min()))
            self._fill()

    def _cell(self, x_m: float, y_m: float) -> tuple[int, int]:
        """Bucket of a point: floor((p - origin) / bucket); monotone in p, so a box's corner cells bound it."""
        return math.floor((x_m - self._origin[0]) / self.bucket_m), math.floor((y_m - self._origin[1]) / self.bucket_m)

    def _fill(self) -> None:
        cells: dict[tuple[int, int], list[tuple[float, float, float, float, float]]] = {}
        for lo, hi in zip(self.lo_m.tolist(), self.hi_m.tolist()):
            (i0, j0), (i1, j1) = self._cell(lo[0], lo[1]), self._cell(hi[0], hi[1])
            box = (lo[0], lo[1], hi[0], hi[1], hi[2])
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    cells.setdefault((i, j), []).append(box)
        self._buckets = {key: tuple(boxes) for key, boxes in cells.items()}

    def height_at(self, x_m: float, y_m: float) -> float:
        """Scalar query [m]: only the boxes listed in (x, y)'s bucket are tested; non-finite x, y -> -inf."""
        if not (self._buckets and -math.inf < x_m < math.inf and -math.inf < y_m < math.inf):
            return -math.inf
        best = -math.inf
        for x0, y0, x1, y1, z in self._buckets.get(self._cell(x_m, y_m), ()):
            if x0 <= x_m <= x1 and y0 <= y_m <= y1 and z > best:
                best = z
        return best

    def heights(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Vectorised query for broadcastable x, y [m] (tests every box: (..., B) work)."""
        x, y = np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64)
        if not len(self.lo_m):
            return np.full(np.broadcast_shapes(x.shape, y.shape), -np.inf)
        lo, hi = self.lo_m, self.hi_m
        xe, ye = x[..., None], y[..., None]
        inside = (xe >= lo[:, 0]) & (xe <= hi[:, 0]) & (ye >= lo[:, 1]) & (ye <= hi[:, 1])
        return np.max(np.where(inside, hi[:, 2], -np.inf), axis=-1)
