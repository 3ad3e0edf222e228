"""What a generated scene contains, before any pybullet body exists (pure numpy, seeded).

Owns `SceneLayout` and its parts (boulders, buildings, lake, road) and the placement helpers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from trade_gym.sim.meshes import rock_radii_m
from trade_gym.sim.scenes import SceneSpec
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import Heightfield
from trade_gym.sim.vehicles import VehicleMotion

FloatArray = npt.NDArray[np.float64]

PARKED_PATH_LENGTH_M = 1.0  # parked vehicles sit at the start of a short straight "path" giving their heading
LAKE_OUTLINE_POINTS = 72
PLACEMENT_TRIES = 200  # rejection-sampling budget per placed object


@dataclass(frozen=True, eq=False)
class Boulder:
    centre_m: FloatArray  # (3,) body origin [m]
    yaw_rad: float
    prototype: int  # rock mesh prototype index
    size_class: int  # index into meshes.ROCK_SIZE_CLASSES_M

    @property
    def radii_m(self) -> FloatArray:
        """(3,) ellipsoid semi-axes [m] before yaw."""
        return rock_radii_m(self.prototype, self.size_class)


@dataclass(frozen=True, eq=False)
class Lake:
    """Flat elliptical water surface at `level_m`."""

    centre_m: FloatArray  # (2,) [m]
    semi_axes_m: FloatArray  # (2,) along and across the ellipse's yaw [m]
    yaw_rad: float
    level_m: float

    def normalised_radius(self, x_m: npt.ArrayLike, y_m: npt.ArrayLike) -> FloatArray:
        """Ellipse metric r: 1 on the shore line, < 1 inside."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        dx, dy = np.asarray(x_m) - self.centre_m[0], np.asarray(y_m) - self.centre_m[1]
        return np.hypot((c * dx + s * dy) / self.semi_axes_m[0], (-s * dx + c * dy) / self.semi_axes_m[1])

    def outline_m(self, count: int = LAKE_OUTLINE_POINTS) -> FloatArray:
        """(count, 2) shore points, counter-clockwise."""
        a = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
        local = np.stack([self.semi_axes_m[0] * np.cos(a), self.semi_axes_m[1] * np.sin(a)], 1)
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        return local @ np.array([[c, s], [-s, c]]) + self.centre_m


@dataclass(frozen=True, eq=False)
class Road:
    path: CatmullRomSpline
    half_width_m: float


@dataclass(frozen=True, eq=False)
class SceneLayout:
    """Everything `World` turns into bodies; vehicles as motions (kinds come from `spec`)."""

    spec: SceneSpec
    terrain: Heightfield
    target: VehicleMotion
    decoys: tuple[VehicleMotion, ...]
    drone_start_m: FloatArray  # (3,) [m]
    drone_yaw_rad: float
    boulders: tuple[Boulder, ...] = ()
    buildings_lo_m: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))  # (B, 3) box min corners
    buildings_hi_m: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))  # (B, 3) box max corners
    takeoff_building: int = -1  # index into buildings, -1 if none
    lake: Lake | None = None
    road: Road | None = None


def grid_for(spec: SceneSpec) -> tuple[tuple[int, int], Heightfield]:
    """Node shape and a flat centred grid (for node coordinates) of the scene's terrain."""
    n = int(round(spec.terrain_size_m / spec.terrain_spacing_m)) + 1
    return (n, n), Heightfield.centred(np.zeros((n, n), np.float32), spec.terrain_spacing_m)


def direction(yaw_rad: float) -> FloatArray:
    return np.array([np.cos(yaw_rad), np.sin(yaw_rad)])


def left_normal(d: FloatArray) -> FloatArray:
    """Unit vector 90 deg counter-clockwise of d (..., 2)."""
    return np.stack([-d[..., 1], d[..., 0]], axis=-1)


def parked(xy_m: FloatArray, yaw_rad: float) -> VehicleMotion:
    """A vehicle standing at xy with heading yaw."""
    xy = np.asarray(xy_m, dtype=np.float64)
    return VehicleMotion(CatmullRomSpline([xy, xy + PARKED_PATH_LENGTH_M * direction(yaw_rad)]), speed_mps=0.0)


def timed_motion(path: CatmullRomSpline, speed_mps: float, s_at_m: float, t_at_s: float) -> VehicleMotion:
    """Motion along `path` at `speed_mps` that passes arc length `s_at_m` at time `t_at_s`.

    delay = t_at - s_at / v; a negative delay starts the vehicle part-way along instead.
    """
    delay = t_at_s - s_at_m / speed_mps
    if delay >= 0.0:
        return VehicleMotion(path, speed_mps, start_s_m=0.0, delay_s=delay)
    return VehicleMotion(path, speed_mps, start_s_m=min(-delay * speed_mps, path.length_m), delay_s=0.0)


def clearance_m(points_m: FloatArray, paths: list[CatmullRomSpline], spots_m: list[FloatArray]) -> FloatArray:
    """(P,) distance from each point to the nearest path or spot [m] (inf when there are none)."""
    pts = np.atleast_2d(points_m)
    best = np.full(len(pts), np.inf)
    for path in paths:
        best = np.minimum(best, path.closest(pts)[0])
    if spots_m:
        spots = np.asarray(spots_m).reshape(-1, 2)
        best = np.minimum(best, np.min(np.linalg.norm(pts[:, None] - spots[None], axis=-1), axis=1))
    return best
