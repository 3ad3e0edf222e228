"""Planar Catmull-Rom paths with arc-length parametrisation for vehicles and roads.

Owns `CatmullRomSpline`: position, unit tangent and heading at a travelled distance [m] (arrays or scalars).
"""

from __future__ import annotations

import math
from bisect import bisect_right

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

CENTRIPETAL_ALPHA = 0.5  # knot exponent: 0 uniform, 0.5 centripetal (no cusps), 1 chordal
SAMPLES_PER_SEGMENT = 96  # dense samples per control segment for the arc-length table
_MIN_KNOT_STEP = 1e-9  # guards coincident control points


def _dense_samples(points: FloatArray, alpha: float, samples: int) -> FloatArray:
    """points: (N, 2) control points -> (M, 2) dense curve samples through all of them.

    Barry-Goldman pyramid for Catmull-Rom with knots t_{i+1} = t_i + |P_{i+1} - P_i|^alpha;
    phantom end points P_{-1} = 2 P_0 - P_1 and P_N = 2 P_{N-1} - P_{N-2}.
    """
    ext = np.vstack([2.0 * points[0] - points[1], points, 2.0 * points[-1] - points[-2]])
    p0, p1, p2, p3 = ext[:-3], ext[1:-2], ext[2:-1], ext[3:]  # (S, 2) each, S = N - 1 segments
    step = lambda a, b: np.maximum(np.linalg.norm(b - a, axis=1) ** alpha, _MIN_KNOT_STEP)  # noqa: E731
    t0 = np.zeros(len(p0))
    t1 = t0 + step(p0, p1)
    t2 = t1 + step(p1, p2)
    t3 = t2 + step(p2, p3)
    u = np.linspace(0.0, 1.0, samples, endpoint=False)
    t = (t1[:, None] + u[None, :] * (t2 - t1)[:, None])[..., None]  # (S, samples, 1)
    k = [x[:, None, None] for x in (t0, t1, t2, t3)]
    q = [x[:, None, :] for x in (p0, p1, p2, p3)]
    # A_i = lerp of P over knot intervals, B_i = lerp of A, C = lerp of B (Barry-Goldman).
    a1 = (k[1] - t) / (k[1] - k[0]) * q[0] + (t - k[0]) / (k[1] - k[0]) * q[1]
    a2 = (k[2] - t) / (k[2] - k[1]) * q[1] + (t - k[1]) / (k[2] - k[1]) * q[2]
    a3 = (k[3] - t) / (k[3] - k[2]) * q[2] + (t - k[2]) / (k[3] - k[2]) * q[3]
    b1 = (k[2] - t) / (k[2] - k[0]) * a1 + (t - k[0]) / (k[2] - k[0]) * a2
    b2 = (k[3] - t) / (k[3] - k[1]) * a2 + (t - k[1]) / (k[3] - k[1]) * a3
    c = (k[2] - t) / (k[2] - k[1]) * b1 + (t - k[1]) / (k[2] - k[1]) * b2
    return np.vstack([c.reshape(-1, 2), points[-1:]])


class CatmullRomSpline:
    """C1 curve through planar control points, queried by distance travelled s [m].

    Queries clamp s to [0, length_m]; all accept scalars or arrays.
    """

    def __init__(
        self,
        control_points_m: npt.ArrayLike,
        alpha: float = CENTRIPETAL_ALPHA,
        samples_per_segment: int = SAMPLES_PER_SEGMENT,
    ) -> None:
        """control_points_m: (N >= 2, 2) world x, y [m]; consecutive points must differ."""
        pts = np.asarray(control_points_m, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise ValueError(f"control_points_m must be a finite (N >= 2, 2) array, got shape {pts.shape}")
        if np.any(np.linalg.norm(np.diff(pts, axis=0), axis=1) <= 0.0):
            raise ValueError("control_points_m has repeated consecutive points")
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha!r}")
        if samples_per_segment < 2:
            raise ValueError(f"samples_per_segment must be >= 2, got {samples_per_segment!r}")
        self.control_points_m = pts
        self._xy = _dense_samples(pts, alpha, samples_per_segment)  # (M, 2)
        seg = np.linalg.norm(np.diff(self._xy, axis=0), axis=1)
        keep = np.concatenate([[True], seg > 0.0])
        self._xy = self._xy[keep]
        self._s = np.concatenate([[0.0], np.cumsum(seg[seg > 0.0])])  # (M,) arc length [m]
        d = np.gradient(self._xy, self._s, axis=0)
        self._tangent = d / np.linalg.norm(d, axis=1, keepdims=True)  # (M, 2) unit
        # the same tables as Python lists, for `point_at` (scalar queries without numpy call overhead)
        self._s_list: list[float] = self._s.tolist()
        self._rows: list[tuple[float, float, float, float]] = [
            tuple(r) for r in np.column_stack([self._xy, self._tangent]).tolist()
        ]

    @property
    def length_m(self) -> float:
        return float(self._s[-1])

    def position_m(self, s_m: npt.ArrayLike) -> FloatArray:
        """s_m: (...) distance [m] -> (..., 2) world x, y [m] (np.interp clamps to the ends)."""
        s = np.asarray(s_m, dtype=np.float64)
        return np.stack([np.interp(s, self._s, self._xy[:, 0]), np.interp(s, self._s, self._xy[:, 1])], axis=-1)

    def tangent(self, s_m: npt.ArrayLike) -> FloatArray:
        """s_m: (...) -> (..., 2) unit direction of travel."""
        s = np.asarray(s_m, dtype=np.float64)
        d = np.stack([np.interp(s, self._s, self._tangent[:, 0]), np.interp(s, self._s, self._tangent[:, 1])], -1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def heading_rad(self, s_m: npt.ArrayLike) -> FloatArray:
        """s_m: (...) -> (...) yaw of travel, atan2(dy, dx) [rad]."""
        d = self.tangent(s_m)
        return np.arctan2(d[..., 1], d[..., 0])

    def point_at(self, s_m: float) -> tuple[float, float, float, float]:
        """Scalar s [m] -> (x, y, t_x, t_y): position [m] and unit tangent, equal to `position_m`/`tangent`.

        np.interp's rule on the table: y = y_k + (s - s_k) (y_{k+1} - y_k) / (s_{k+1} - s_k), clamped at the ends.
        """
        s_tab, rows = self._s_list, self._rows
        k = bisect_right(s_tab, s_m) - 1
        if k < 0:
            x, y, tx, ty = rows[0]
        elif k >= len(s_tab) - 1:
            x, y, tx, ty = rows[-1]
        else:
            (x0, y0, tx0, ty0), (x1, y1, tx1, ty1) = rows[k], rows[k + 1]
            ds = s_m - s_tab[k]
            step = s_tab[k + 1] - s_tab[k]
            x, y = (x1 - x0) / step * ds + x0, (y1 - y0) / step * ds + y0
            tx, ty = (tx1 - tx0) / step * ds + tx0, (ty1 - ty0) / step * ds + ty0
        norm = math.sqrt(tx * tx + ty * ty)
        return x, y, tx / norm, ty / norm

    def sample(self, spacing_m: float) -> tuple[FloatArray, FloatArray]:
        """Evenly spaced points along the curve: (K,) distances [m] and (K, 2) positions [m]."""
        if spacing_m <= 0.0:
            raise ValueError(f"spacing_m must be > 0, got {spacing_m!r}")
        count = max(int(np.ceil(self.length_m / spacing_m)), 1) + 1
        s = np.linspace(0.0, self.length_m, count)
        return s, self.position_m(s)

    def closest(self, points_m: npt.ArrayLike, spacing_m: float = 1.0) -> tuple[FloatArray, FloatArray]:
        """points_m: (P, 2) -> (P,) distance to the curve [m] and (P,) arc length of the foot [m].

        Exact projection onto the polyline of samples `spacing_m` apart (chord error ~ s^2 kappa / 8).
        """
        pts = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
        s, xy = self.sample(spacing_m)
        a, ab = xy[:-1], np.diff(xy, axis=0)  # (K-1, 2)
        ab2 = np.einsum("ij,ij->i", ab, ab)
        rel = pts[:, None, :] - a[None, :, :]  # (P, K-1, 2)
        # foot parameter w = clip(<p - a, b - a> / |b - a|^2, 0, 1) per segment
        w = np.clip(np.einsum("pkj,kj->pk", rel, ab) / ab2[None, :], 0.0, 1.0)
        d2 = np.sum((rel - w[..., None] * ab[None]) ** 2, axis=-1)
        k = np.argmin(d2, axis=1)
        rows = np.arange(len(pts))
        return np.sqrt(d2[rows, k]), s[k] + w[rows, k] * np.sqrt(ab2[k])
