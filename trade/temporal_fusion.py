"""Temporal fusion of ground points: gated ring buffer + multi-RANSAC refit of the fused plane.

Paper section "Temporal fusion": buffer inliers across frames, gate by distance to the past plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from trade.planes import SAMPLE_SIZE, MultiRansacConfig, Plane, fit_plane_lstsq, multi_ransac

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TemporalFusionConfig:
    """buffer_size: fused points kept (oldest dropped first); gate: a point is accepted when
    |n·x + d| <= max(gate_min_m, gate_mse_factor * sqrt(MSE of the LS plane of all buffered points));
    min_points: accepted points a frame needs to refit (else the stored plane is reused);
    max_gated_frames: consecutive frames with enough points but all gated out before the buffer is
    re-initialised from the current frame (the ground really moved, e.g. a cliff); 0 never does;
    max_age_frames: points buffered more than this many updates ago leave the refit and the gate's RMS
    (they stay in the buffer until overwritten); 0: the buffer size alone bounds the memory. The paper's
    1000 points hold 4-5 frames of its up to 225 ROI features per frame (3x3 tiles x 25), but seconds of a
    masked ground that yields a few points per frame: the age limit keeps the fit to the recent ground."""

    buffer_size: int = 1000
    gate_mse_factor: float = 3.0  # 3-sigma gate on the orthogonal residual
    gate_min_m: float = 0.5  # = MSAC inlier threshold: never gate tighter than a plane inlier
    min_points: int = 10
    max_gated_frames: int = 30  # 1 s at 30 fps
    max_age_frames: int = 45  # 1.5 s at 30 fps
    # Re-initialise from a gated-out frame whose own plane (its multi-RANSAC inliers) has more inliers than the
    # fused plane: a plane fitted to a handful of roof points is outvoted by the first frame of street points
    # instead of gating them out for max_gated_frames; a plane of hundreds of points holds through a passing roof.
    outvoted_reinit: bool = True
    ransac: MultiRansacConfig = field(default_factory=MultiRansacConfig)

    def __post_init__(self) -> None:
        c = "TemporalFusionConfig"
        if int(self.buffer_size) != self.buffer_size or self.buffer_size < SAMPLE_SIZE:
            raise ValueError(f"{c}.buffer_size must be an integer >= {SAMPLE_SIZE}, got {self.buffer_size!r}")
        if int(self.min_points) != self.min_points or not SAMPLE_SIZE <= self.min_points <= self.buffer_size:
            raise ValueError(f"{c}.min_points must be an integer in [{SAMPLE_SIZE}, buffer_size], got {self.min_points!r}")
        for name in ("max_gated_frames", "max_age_frames"):
            value = getattr(self, name)
            if int(value) != value or value < 0:
                raise ValueError(f"{c}.{name} must be a non-negative integer, got {value!r}")
        for name in ("gate_mse_factor", "gate_min_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{c}.{name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True)
class FusionResult:
    """plane: fused ground plane (None before the first fit); solutions: the fused multi-RANSAC
    solutions (for `raycast.depth_uncertainty`); n_accepted: points appended to the buffer this
    frame, n_rejected: the other input rows (gated out, non-finite, or a frame below min_points);
    reused: the stored plane was returned without a refit; gate_m: gate used (inf when ungated)."""

    plane: Plane | None
    solutions: tuple[Plane, ...]
    n_buffered: int
    n_accepted: int
    n_rejected: int
    reused: bool
    reinitialised: bool
    gate_m: float


class TemporalPlaneFusion:
    """Stateful fusion: `update` once per frame with that frame's ground inlier points."""

    def __init__(self, config: TemporalFusionConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._buffer = np.empty((config.buffer_size, 3))
        self._born = np.zeros(config.buffer_size, dtype=np.int64)  # update count at which each slot was written
        self._updates = 0
        self.reset()

    def reset(self) -> None:
        """Forget all points and the fused plane."""
        self._head = 0  # next write slot
        self._count = 0
        self._plane: Plane | None = None
        self._solutions: tuple[Plane, ...] = ()
        self._gate_m = float("inf")
        self._n_gated_frames = 0

    @property
    def plane(self) -> Plane | None:
        return self._plane

    @property
    def buffered_points(self) -> FloatArray:
        """(n_buffered, 3) world [m], oldest first (a copy)."""
        if self._count < self.config.buffer_size:
            return self._buffer[: self._count].copy()
        return np.roll(self._buffer, -self._head, axis=0)

    def _append(self, points: FloatArray) -> None:
        """Ring write: slot (head + i) mod size; when more than size arrive only the newest stay."""
        size = self.config.buffer_size
        points = points[-size:]
        slots = (self._head + np.arange(points.shape[0])) % size
        self._buffer[slots] = points
        self._born[slots] = self._updates
        self._head = int((self._head + points.shape[0]) % size)
        self._count = min(self._count + points.shape[0], size)

    def _bootstrap_inliers(self, points: FloatArray, query_xy: FloatArray | None) -> FloatArray:
        """Without a past plane the frame gates itself: keep its own multi-RANSAC inliers, none when its
        points give no admissible ground plane (e.g. one steeper than the RANSAC's tilt limit)."""
        if points.shape[0] < self.config.min_points:
            return points
        fit = multi_ransac(points, self.config.ransac, self._rng, query_xy)
        return points[:0] if fit is None else points[fit.inlier_mask]

    def _outvoting_inliers(self, plane: Plane, points: FloatArray, query_xy: FloatArray | None) -> FloatArray | None:
        """The gated-out frame's own plane inliers when they outnumber the fused `plane`'s (`outvoted_reinit`), else
        None. A frame with no more points than the fused plane's inliers cannot outvote it and is not fitted."""
        if not self.config.outvoted_reinit or points.shape[0] <= plane.n_inliers:
            return None
        own = self._bootstrap_inliers(points, query_xy)
        return own if own.shape[0] > plane.n_inliers else None

    def update(self, points_world: FloatArray, query_xy: FloatArray | None = None) -> FusionResult:
        """points_world: (N, 3) world [m] ground inliers of this frame; query_xy: (2,) world [m]
        passed to multi-RANSAC's lowest-plane tie-break (default: buffer centroid)."""
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        self._updates += 1
        n_in = pts.shape[0]
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        gate_m, reinitialised = self._gate_m, False
        if self._plane is None:
            accepted = self._bootstrap_inliers(pts, query_xy)
        else:
            accepted = pts[np.abs(self._plane.signed_distance(pts)) <= gate_m]
            gated_out = pts.shape[0] >= self.config.min_points > accepted.shape[0]
            self._n_gated_frames = self._n_gated_frames + 1 if gated_out else 0
            own = self._outvoting_inliers(self._plane, pts, query_xy) if gated_out else None
            if own is not None or (gated_out and 0 < self.config.max_gated_frames <= self._n_gated_frames):
                self.reset()  # the ground moved for good, or the plane was outvoted: start over from this frame
                gate_m, reinitialised = float("inf"), True
                accepted = own if own is not None else self._bootstrap_inliers(pts, query_xy)
        n_acc = accepted.shape[0]
        if n_acc < self.config.min_points:
            return self._result(0, n_in, reused=self._plane is not None, reinit=reinitialised, gate_m=gate_m)
        self._append(accepted)
        buffered = self._buffer[: self._count]  # fit order is irrelevant: no roll needed
        if self.config.max_age_frames > 0:  # the frame just appended is always recent enough
            recent = self._updates - self._born[: self._count] < self.config.max_age_frames
            buffered = buffered if recent.all() else buffered[recent]
        fit = multi_ransac(buffered, self.config.ransac, self._rng, query_xy)
        if fit is None:
            return self._result(n_acc, n_in - n_acc, self._plane is not None, reinitialised, gate_m)
        self._plane, self._solutions = fit.selected, fit.solutions
        # gate for the next frame: factor * RMS residual of the LS plane through all buffered points
        rms_m = float(np.sqrt(fit_plane_lstsq(buffered).mse_m2))
        self._gate_m = max(self.config.gate_min_m, self.config.gate_mse_factor * rms_m)
        return self._result(n_acc, n_in - n_acc, reused=False, reinit=reinitialised, gate_m=gate_m)

    def _result(self, n_acc: int, n_rej: int, reused: bool, reinit: bool, gate_m: float) -> FusionResult:
        return FusionResult(self._plane, self._solutions, self._count, n_acc, n_rej, reused, reinit, gate_m)
