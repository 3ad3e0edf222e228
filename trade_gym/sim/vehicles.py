"""Ground vehicles: box-built car/truck/tank meshes, kinematic motion along a path, terrain-hugging poses.

Owns `VehicleModel`, `VehicleMotion` (and the `Motion` protocol), `Vehicle` and `terrain_pose`; their visual-only
pybullet bodies are built with the world (`trade_gym.sim.world.build_world`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
import numpy.typing as npt

from trade_gym.sim.meshes import Mesh, box_mesh, merge_meshes
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import Heightfield

FloatArray = npt.NDArray[np.float64]
PlanarPose = tuple[float, float, float, float]  # x, y [m] and the unit heading (cos, sin)
PlanarVelocity = tuple[float, float, float, float]  # x, y [m] and the world velocity v_x, v_y [m/s]

# Palette texture: one row of solid 4x4-px cells (assets/textures/vehicle_palette.png, see make_assets.py).
PALETTE_RGB = (
    (178, 34, 34),  # 0 car body
    (35, 45, 60),  # 1 glass
    (22, 22, 22),  # 2 tyre
    (236, 236, 232),  # 3 truck white
    (140, 140, 140),  # 4 chassis grey
    (92, 100, 58),  # 5 tank olive
    (58, 62, 40),  # 6 tank dark
    (235, 215, 120),  # 7 lamp
)
PALETTE_CELL_PX = 4
# Parts: (x0, y0, z0, x1, y1, z1) corners [m] with z0 = 0 on the ground, top colour, side colour.
_PARTS = {
    "car": (
        ((1.05, 0.66, 0.0, 1.69, 0.9, 0.64), 2, 2), ((1.05, -0.9, 0.0, 1.69, -0.66, 0.64), 2, 2),
        ((-1.69, 0.66, 0.0, -1.05, 0.9, 0.64), 2, 2), ((-1.69, -0.9, 0.0, -1.05, -0.66, 0.64), 2, 2),
        ((-2.2, -0.88, 0.25, 2.2, 0.88, 0.85), 0, 0), ((2.12, -0.7, 0.55, 2.21, 0.7, 0.72), 7, 7),
        ((-1.4, -0.8, 0.85, 0.9, 0.8, 1.42), 0, 1), ((0.9, -0.75, 0.85, 1.55, 0.75, 1.2), 1, 1),
        ((-1.9, -0.75, 0.85, -1.4, 0.75, 1.15), 1, 1),
    ),
    "truck": (
        ((2.0, 0.95, 0.0, 2.9, 1.22, 0.9), 2, 2), ((2.0, -1.22, 0.0, 2.9, -0.95, 0.9), 2, 2),
        ((-2.4, 0.95, 0.0, -1.5, 1.22, 0.9), 2, 2), ((-2.4, -1.22, 0.0, -1.5, -0.95, 0.9), 2, 2),
        ((-3.6, 0.95, 0.0, -2.6, 1.22, 0.9), 2, 2), ((-3.6, -1.22, 0.0, -2.6, -0.95, 0.9), 2, 2),
        ((-3.75, -1.1, 0.6, 3.75, 1.1, 0.95), 4, 4), ((1.9, -1.2, 0.95, 3.75, 1.2, 2.7), 3, 1),
        ((-3.75, -1.25, 0.95, 1.75, 1.25, 3.2), 3, 3),
    ),
    "tank": (
        ((-3.5, 1.1, 0.0, 3.5, 1.8, 0.95), 6, 6), ((-3.5, -1.8, 0.0, 3.5, -1.1, 0.95), 6, 6),
        ((-3.3, -1.8, 0.95, 3.3, 1.8, 1.45), 5, 5), ((-1.7, -1.15, 1.45, 1.1, 1.15, 2.15), 5, 6),
        ((1.1, -0.13, 1.65, 3.6, 0.13, 1.91), 6, 6),
    ),
}
MOVING_EPS_MPS = 1e-9
_CORNER_SIGNS = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0], [0.0, 0.0]])  # FL FR RL RR centre


def palette_uv(index: int) -> tuple[float, float]:
    """Centre of palette cell `index` in texture coordinates (single row, so v = 0.5 either way up)."""
    return ((index + 0.5) / len(PALETTE_RGB), 0.5)


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """Mesh centred on the vehicle's bounding-box centre, body frame x fwd, y left, z up."""

    kind: str
    mesh: Mesh
    half_extents_m: FloatArray  # (3,) [m]


@lru_cache(maxsize=None)
def vehicle_model(kind: str) -> VehicleModel:
    """Cached model per kind (seed-independent)."""
    if kind not in _PARTS:
        raise ValueError(f"unknown vehicle kind {kind!r}; valid kinds: {sorted(_PARTS)}")
    corners = np.array([part[0] for part in _PARTS[kind]], dtype=np.float64).reshape(-1, 2, 3)
    lo, hi = corners.min(axis=(0, 1)), corners.max(axis=(0, 1))
    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    parts = [
        box_mesh((c[0] + c[1]) / 2.0 - centre, (c[1] - c[0]) / 2.0, palette_uv(top), palette_uv(side))
        for c, (_, top, side) in zip(corners, _PARTS[kind])
    ]
    half.setflags(write=False)
    return VehicleModel(kind, merge_meshes(parts), half)


@dataclass(frozen=True, eq=False)
class VehicleMotion:
    """Distance along `path`: s(t) = clip(start_s + speed (t - delay)^+, start_s, end_s) [m]."""

    path: CatmullRomSpline
    speed_mps: float
    start_s_m: float = 0.0
    end_s_m: float | None = None  # None: the path's end
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        end = self.path.length_m if self.end_s_m is None else float(self.end_s_m)
        object.__setattr__(self, "end_s_m", end)
        for name in ("speed_mps", "start_s_m", "delay_s"):  # plain floats keep the per-step scalar math fast
            object.__setattr__(self, name, float(getattr(self, name)))
        if not np.isfinite(self.speed_mps) or self.speed_mps < 0.0:
            raise ValueError(f"VehicleMotion.speed_mps must be finite and >= 0, got {self.speed_mps!r}")
        if not 0.0 <= self.start_s_m <= end <= self.path.length_m + 1e-9:
            raise ValueError(f"VehicleMotion needs 0 <= start_s_m <= end_s_m <= length, got {self.start_s_m}, {end}")
        if self.delay_s < 0.0:
            raise ValueError(f"VehicleMotion.delay_s must be >= 0, got {self.delay_s!r}")

    @property
    def stop_s_m(self) -> float:
        """Distance along the path where the vehicle stops [m]: end_s_m, or the path's end for None (which
        __post_init__ has already resolved)."""
        return self.path.length_m if self.end_s_m is None else self.end_s_m

    @property
    def is_moving(self) -> bool:
        return self.speed_mps > MOVING_EPS_MPS and self.stop_s_m > self.start_s_m

    @property
    def stop_time_s(self) -> float:
        """Time at which the vehicle reaches end_s and stops [s]."""
        if not self.is_moving:
            return 0.0
        return self.delay_s + (self.stop_s_m - self.start_s_m) / self.speed_mps

    def distance_m(self, t_s: float) -> float:
        """s(t) [m] for a scalar t [s] (conditional expressions: cheaper than builtin min/max calls)."""
        since = t_s - self.delay_s
        s = self.start_s_m + self.speed_mps * since if since > 0.0 else self.start_s_m
        end = self.stop_s_m
        return float(s) if s < end else end

    def planar_velocity_mps(self, t_s: float) -> FloatArray:
        """(2,) world x, y velocity [m/s]; zero before the delay and after the stop."""
        if not self.is_moving or t_s < self.delay_s or t_s >= self.stop_time_s:
            return np.zeros(2)
        return self.speed_mps * self.path.tangent(self.distance_m(t_s))

    def planar_pose(self, t_s: float) -> PlanarPose:
        """Position on the path at s(t) and the path's unit tangent there (the heading) at scalar t [s]."""
        return self.path.point_at(self.distance_m(t_s))

    def planar_velocity_at(self, t_s: float) -> PlanarVelocity | None:
        """(x, y, v_x, v_y) at scalar t [s]: speed times the unit tangent; None while standing."""
        if not self.is_moving or t_s < self.delay_s or t_s >= self.stop_time_s:
            return None
        x, y, tx, ty = self.path.point_at(self.distance_m(t_s))
        return x, y, self.speed_mps * tx, self.speed_mps * ty


class Motion(Protocol):
    """What poses and ground truth read of a vehicle's motion: `VehicleMotion`, or one of the target's behaviours
    (`trade_gym.sim.target_motion`). Scalar times [s]; the pose and velocity in the world's x, y."""

    @property
    def path(self) -> CatmullRomSpline: ...

    @property
    def is_moving(self) -> bool: ...

    @property
    def stop_time_s(self) -> float: ...

    def distance_m(self, t_s: float) -> float: ...

    def planar_pose(self, t_s: float) -> PlanarPose: ...

    def planar_velocity_at(self, t_s: float) -> PlanarVelocity | None: ...


@dataclass(frozen=True, eq=False)
class Vehicle:
    """A kinematic visual-only body (no collision shape, so rays pass through it)."""

    kind: str
    body_id: int
    half_extents_m: FloatArray  # (3,) x fwd, y left, z up [m]
    motion: Motion


def terrain_pose(
    terrain: Heightfield, xy_m: npt.ArrayLike, heading_rad: npt.ArrayLike, half_extents_m: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Pose of N boxes resting on the terrain: (N, 3) box centres [m] and (N, 3, 3) R_world_vehicle.
    (The vectorised reference; the step loop uses its scalar twin `vehicle_poses.pose_at`.)

    xy_m: (N, 2) [m], heading_rad: (N,), half_extents_m: (3,) or (N, 3) [m]. Pitch/roll from the plane
    through the footprint's corner heights; the bottom face's centre sits on the terrain at the box's
    x, y: centre = (x, y, h(x, y)) + half_z * n.
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    yaw = np.asarray(heading_rad, dtype=np.float64).reshape(-1)
    half = np.broadcast_to(np.asarray(half_extents_m, dtype=np.float64), (len(yaw), 3))
    c, s = np.cos(yaw), np.sin(yaw)
    fwd2, left2 = np.stack([c, s], -1), np.stack([-s, c], -1)  # (N, 2)
    # footprint corners FL, FR, RL, RR and the centre, one height query for all
    offsets = _CORNER_SIGNS[None, :, 0:1] * (half[:, None, 0:1] * fwd2[:, None]) \
        + _CORNER_SIGNS[None, :, 1:2] * (half[:, None, 1:2] * left2[:, None])
    pts = xy[:, None, :] + offsets  # (N, 5, 2)
    z = terrain.height_m(pts[..., 0], pts[..., 1])  # (N, 5)
    pitch_slope = (z[:, 0] + z[:, 1] - z[:, 2] - z[:, 3]) / (4.0 * half[:, 0])  # dz per metre forward
    roll_slope = (z[:, 0] + z[:, 2] - z[:, 1] - z[:, 3]) / (4.0 * half[:, 1])  # dz per metre left
    fwd = np.column_stack([fwd2, np.zeros_like(yaw)])
    n = np.column_stack([-pitch_slope[:, None] * fwd2 - roll_slope[:, None] * left2, np.ones_like(yaw)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    x_axis = fwd + pitch_slope[:, None] * np.array([0.0, 0.0, 1.0])
    x_axis /= np.linalg.norm(x_axis, axis=1, keepdims=True)
    R = np.stack([x_axis, np.cross(n, x_axis), n], axis=-1)  # columns are the vehicle axes in world
    return np.column_stack([xy, z[:, 4]]) + half[:, 2:3] * n, R
