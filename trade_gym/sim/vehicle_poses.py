"""Per-time vehicle poses for the env's step loop: scalar terrain-hugging poses, a per-time cache, body placement.

Owns `VehiclePoses` and `pose_at` (one vehicle at a time, its terrain pose compiled: `terrain_pose`).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pybullet as p
from numba import njit

from trade.geometry import matrix_to_quat_xyzw
from trade_gym.sim.terrain import Heightfield, grid_height
from trade_gym.sim.vehicles import Vehicle

FloatArray = npt.NDArray[np.float64]
Pose12 = tuple[float, ...]  # centre x, y, z [m], then R_world_vehicle row-major (9)


def pose_at(terrain: Heightfield, v: Vehicle, t_s: float) -> Pose12:
    """Scalar `vehicles.terrain_pose` of `v` at time t_s: the box rests on the plane through its footprint
    (`terrain_pose`, compiled)."""
    x, y, c, s = v.motion.planar_pose(t_s)  # heading (c, s) = (cos, sin): the path's tangent unless it swerves
    hx, hy, hz = v.half_extents_m.tolist()
    return terrain_pose(terrain.grid, x, y, c, s, hx, hy, hz)


@njit(cache=True)
def terrain_pose(grid, x, y, c, s, hx, hy, hz):
    """Centre (3) and row-major R_world_vehicle (9) of a box of half extents (hx, hy, hz) [m] at (x, y) heading
    (c, s) = (cos, sin) on the terrain `grid` (`Heightfield.grid`).

    Corners FL, FR, RL, RR at (x, y) +- half_x fwd +- half_y left; slopes along fwd and left from their heights;
    n = (-pitch fwd - roll left, 1) / |.|, x_axis = (fwd, pitch) / |.|, y_axis = n x x_axis, and the
    bottom face's centre on the terrain: centre = (x, y, h(x, y)) + half_z n.
    """
    fx, fy, lx, ly = c * hx, s * hx, -s * hy, c * hy
    z_fl = grid_height(grid, x + (fx + lx), y + (fy + ly))
    z_fr = grid_height(grid, x + (fx - lx), y + (fy - ly))
    z_rl = grid_height(grid, x + (lx - fx), y + (ly - fy))
    z_rr = grid_height(grid, x + (-fx - lx), y + (-fy - ly))
    pitch = (z_fl + z_fr - z_rl - z_rr) / (4.0 * hx)  # dz per metre forward
    roll = (z_fl + z_rl - z_fr - z_rr) / (4.0 * hy)  # dz per metre left
    nx, ny = -pitch * c + roll * s, -pitch * s - roll * c
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + 1.0)
    nx, ny, nz = nx * inv, ny * inv, inv
    inv = 1.0 / math.sqrt(c * c + s * s + pitch * pitch)
    ax, ay, az = c * inv, s * inv, pitch * inv
    bx, by, bz = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax  # n x x_axis
    return (x + hz * nx, y + hz * ny, grid_height(grid, x, y) + hz * nz, ax, bx, nx, ay, by, ny, az, bz, nz)


def _arrays(pose: Pose12) -> tuple[FloatArray, FloatArray]:
    """(3,) centre and (3, 3) R_world_vehicle, read-only views of one (4, 3) buffer."""
    buf = np.array(pose, dtype=np.float64).reshape(4, 3)
    buf.setflags(write=False)
    return buf[0], buf[1:]


class VehiclePoses:
    """Poses of a world's vehicles as pure functions of time, each computed once per time.

    Parked vehicles are posed and placed in pybullet once; `update(t)` computes the moving ones at t;
    `place_bodies()` moves their pybullet bodies there. Vehicles carry no collision shape, so only
    rendering needs the bodies placed, and a step that does not render skips it. `pose(v, t)` returns
    the cached arrays when t is that time (or v is parked) and computes the same function otherwise, so
    the result never depends on whether `update(t)` ran. (An evasive target's motion is the one function that
    also depends on the drone: `World.update` advances it first; see `trade_gym.sim.evasive`.)
    """

    def __init__(self, client_id: int, terrain: Heightfield, vehicles: tuple[Vehicle, ...]) -> None:
        self.client_id = client_id
        self.terrain = terrain
        self._moving = tuple(v for v in vehicles if v.motion.is_moving)
        self._cache: dict[int, tuple[float | None, FloatArray, FloatArray]] = {}
        self._t_s: float | None = None
        self._unplaced: dict[int, Pose12] = {}  # body id -> pose its pybullet body has not been moved to
        for v in vehicles:
            if not v.motion.is_moving:
                self._cache_pose(v, None, pose_at(terrain, v, 0.0))
        self.place_bodies()

    def _cache_pose(self, v: Vehicle, t_s: float | None, pose: Pose12) -> None:
        """Cache the pose (t None: valid at any time); its body is moved at the next `place_bodies`."""
        self._cache[v.body_id] = (t_s, *_arrays(pose))
        self._unplaced[v.body_id] = pose

    def update(self, t_s: float) -> None:
        """Pose the moving vehicles at time t_s [s] (no work if already there)."""
        t = float(t_s)
        if t == self._t_s:
            return
        for v in self._moving:
            self._cache_pose(v, t, pose_at(self.terrain, v, t))
        self._t_s = t

    def place_bodies(self) -> None:
        """Move the pybullet bodies to the latest poses (before rendering)."""
        for body_id, pose in self._unplaced.items():
            p.resetBasePositionAndOrientation(body_id, pose[:3], matrix_to_quat_xyzw(pose[3:]),
                                              physicsClientId=self.client_id)
        self._unplaced.clear()

    def pose(self, v: Vehicle, t_s: float) -> tuple[FloatArray, FloatArray]:
        """(3,) box centre [m] and (3, 3) R_world_vehicle at time t_s, read-only arrays."""
        cached = self._cache.get(v.body_id)
        if cached is not None and (cached[0] is None or cached[0] == t_s):
            return cached[1], cached[2]
        return _arrays(pose_at(self.terrain, v, float(t_s)))
