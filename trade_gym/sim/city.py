"""City layout: a street grid with box buildings, a ~30 m take-off building beside the truck's street.

Owns `make_city`; built in a local frame (main street along x) then turned by a random grid symmetry.
"""

from __future__ import annotations

import numpy as np

from trade_gym.sim.layout import PLACEMENT_TRIES, SceneLayout, grid_for, parked, timed_motion
from trade_gym.sim.scenes import SceneSpec
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import Heightfield, fractal_noise
from trade_gym.sim.vehicles import VehicleMotion

STREET_HALF_WIDTH_M = 8.0
BLOCK_PITCH_M = 60.0
CROSS_STREET_X_M = -15.0  # one north-south street centreline; the others every BLOCK_PITCH_M
BORDER_MARGIN_M = 5.0  # buildings stay this far inside the terrain
TAKEOFF_LENGTH_M, TAKEOFF_DEPTH_M = (30.0, 38.0), (16.0, 22.0)
TAKEOFF_SETBACK_M = 2.5  # from the street edge [m]
LOT_SPLITS_X, LOT_SPLITS_Y = (1, 4), (1, 3)  # [low, high) number of lots per block side
LOT_GAP_M = (1.0, 2.5)
LOT_MIN_M = 6.0
BUILDING_HEIGHT_M = (6.0, 24.0)  # other buildings stay below the drone's 32 m
BUILDING_SINK_M = 0.3
CITY_RELIEF_M, CITY_RELIEF_CELLS = 0.08, 6
LANE_OFFSET_M, LANE_JITTER_M = 3.2, 0.3
PARKING_OFFSET_M = 6.3
DRONE_ROOF_INSET_M = 0.3  # drone starts this far inside the roof edge (the roof hides < atan(0.3/2))
DRONE_FROM_ROOF_END_M = (2.0, 5.0)
TRUCK_FROM_DRONE_M = (-2.0, 4.0)  # truck start x relative to the drone, along the street
ONCOMING_SPEED_MPS, ONCOMING_MEET = (2.5, 4.0), (0.3, 0.6)
PARK_MARGIN_M, PARK_SPACING_M = 10.0, 7.5


def _street_intervals(first_street_m: float, extent_m: float) -> list[tuple[float, float]]:
    """Open intervals between street edges along one axis, clipped to +-extent."""
    k = np.arange(-10, 11)
    edges = first_street_m + k * BLOCK_PITCH_M
    lo, hi = edges[:-1] + STREET_HALF_WIDTH_M, edges[1:] - STREET_HALF_WIDTH_M
    lo, hi = np.maximum(lo, -extent_m), np.minimum(hi, extent_m)
    return [(a, b) for a, b in zip(lo, hi) if b - a >= LOT_MIN_M]


def _lots(x0: float, x1: float, y0: float, y1: float, rng: np.random.Generator) -> list[tuple]:
    """Split a rectangle into lots with gaps; (x0, y0, x1, y1, height) per building."""
    if x1 - x0 < LOT_MIN_M or y1 - y0 < LOT_MIN_M:
        return []
    xs = np.sort(np.concatenate([[x0, x1], rng.uniform(x0, x1, rng.integers(*LOT_SPLITS_X) - 1)]))
    ys = np.sort(np.concatenate([[y0, y1], rng.uniform(y0, y1, rng.integers(*LOT_SPLITS_Y) - 1)]))
    out = []
    for a, b in zip(xs[:-1], xs[1:]):
        for c, d in zip(ys[:-1], ys[1:]):
            g = rng.uniform(*LOT_GAP_M, 4) / 2.0
            if b - a - g[0] - g[1] >= LOT_MIN_M and d - c - g[2] - g[3] >= LOT_MIN_M:
                out.append((a + g[0], c + g[2], b - g[1], d - g[3], rng.uniform(*BUILDING_HEIGHT_M)))
    return out


def _buildings(spec: SceneSpec, rng: np.random.Generator) -> tuple[list[tuple], tuple]:
    """All buildings in the local frame; the take-off building is first."""
    extent = spec.terrain_size_m / 2 - BORDER_MARGIN_M
    bx0, bx1 = CROSS_STREET_X_M - BLOCK_PITCH_M + STREET_HALF_WIDTH_M, CROSS_STREET_X_M - STREET_HALF_WIDTH_M
    by0, by1 = STREET_HALF_WIDTH_M, BLOCK_PITCH_M - STREET_HALF_WIDTH_M
    x0 = bx0 + rng.uniform(1.0, 3.0)
    x1 = min(x0 + rng.uniform(*TAKEOFF_LENGTH_M), bx1 - 1.0)
    y0 = by0 + TAKEOFF_SETBACK_M
    y1 = y0 + rng.uniform(*TAKEOFF_DEPTH_M)
    takeoff = (x0, y0, x1, y1, spec.takeoff_building_height_m)
    gap = rng.uniform(*LOT_GAP_M)
    out = [takeoff] + _lots(bx0, bx1, y1 + gap, by1, rng) + _lots(x1 + gap, bx1, by0, y1, rng)
    for ax0, ax1 in _street_intervals(CROSS_STREET_X_M, extent):
        for ay0, ay1 in _street_intervals(0.0, extent):
            if (ax0, ay0) != (bx0, by0):
                out += _lots(ax0, ax1, ay0, ay1, rng)
    return out, takeoff


def _parked_cars(spec: SceneSpec, x_start: float, rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """Cars at the kerbs of the main street along the route (local frame): (x, y) and yaw."""
    cross = CROSS_STREET_X_M + BLOCK_PITCH_M * np.arange(-3, 4)
    lo, hi = x_start - spec.route_length_m - PARK_MARGIN_M, x_start + PARK_MARGIN_M
    cars: list[tuple[np.ndarray, float]] = []
    for _ in range(spec.parked_decoys_near_path):
        for _ in range(PLACEMENT_TRIES):
            side, x = rng.choice([-1.0, 1.0]), rng.uniform(lo, hi)
            clear_street = np.min(np.abs(x - cross)) > STREET_HALF_WIDTH_M + PARK_SPACING_M / 2
            spaced = all(abs(x - c[0][0]) >= PARK_SPACING_M or c[0][1] != side * PARKING_OFFSET_M for c in cars)
            if clear_street and spaced:
                break
        cars.append((np.array([x, side * PARKING_OFFSET_M]), np.pi if side > 0 else 0.0))
    return cars


def make_city(spec: SceneSpec, rng: np.random.Generator, speed: float) -> SceneLayout:
    """City layout; the drone starts just inside the take-off roof's street edge, 32 m above the street."""
    shape, grid = grid_for(spec)
    boxes, takeoff = _buildings(spec, rng)
    x_drone = takeoff[2] - rng.uniform(*DRONE_FROM_ROOF_END_M)
    drone_xy = np.array([x_drone, takeoff[1] + DRONE_ROOF_INSET_M])
    x_start = x_drone + rng.uniform(*TRUCK_FROM_DRONE_M)
    xs = x_start - np.linspace(0.0, spec.route_length_m, 4)
    route_pts = np.column_stack([xs, LANE_OFFSET_M + rng.uniform(-LANE_JITTER_M, LANE_JITTER_M, 4)])
    extent = spec.terrain_size_m / 2 - BORDER_MARGIN_M
    oncoming_pts = np.array([[-extent, -LANE_OFFSET_M], [0.0, -LANE_OFFSET_M], [extent, -LANE_OFFSET_M]])
    cars = _parked_cars(spec, x_start, rng)
    # random symmetry of the street grid: rotation by k * 90 deg after an optional mirror in y
    k, mirror = int(rng.integers(0, 4)), float(rng.choice([-1.0, 1.0]))
    c, s = np.round(np.cos(k * np.pi / 2)), np.round(np.sin(k * np.pi / 2))
    M = np.array([[c, -s], [s, c]]) @ np.diag([1.0, mirror])
    tf = lambda pts: np.asarray(pts, dtype=np.float64) @ M.T  # noqa: E731
    tf_yaw = lambda yaw: float(np.arctan2(*(M @ [np.cos(yaw), np.sin(yaw)])[::-1]))  # noqa: E731
    heights = CITY_RELIEF_M * fractal_noise(shape, CITY_RELIEF_CELLS, 2, 0.5, rng)
    terrain = Heightfield(heights.astype(np.float32), grid.spacing_m, grid.origin_m)
    b = np.array(boxes)
    corners = np.stack([tf(b[:, [0, 1]]), tf(b[:, [2, 3]])], 1)  # (B, 2, 2)
    lo_xy, hi_xy = corners.min(axis=1), corners.max(axis=1)
    foot_x = np.stack([lo_xy[:, 0], hi_xy[:, 0], lo_xy[:, 0], hi_xy[:, 0]], 1)
    foot_y = np.stack([lo_xy[:, 1], lo_xy[:, 1], hi_xy[:, 1], hi_xy[:, 1]], 1)
    z0 = terrain.height_m(foot_x, foot_y).min(axis=1) - BUILDING_SINK_M
    z1 = terrain.height_m(*((lo_xy + hi_xy) / 2).T) + b[:, 4]
    route = CatmullRomSpline(tf(route_pts))
    target = VehicleMotion(route, speed)
    oncoming_path = CatmullRomSpline(tf(oncoming_pts))
    t_meet = rng.uniform(*ONCOMING_MEET) * route.length_m / speed
    meet_xy = route.position_m(speed * t_meet)
    s_meet = oncoming_path.closest(meet_xy)[1][0]
    oncoming = timed_motion(oncoming_path, rng.uniform(*ONCOMING_SPEED_MPS), s_meet, t_meet)
    decoys = [parked(tf(xy), tf_yaw(yaw)) for xy, yaw in cars] + [oncoming][: spec.moving_decoys]
    start = tf(drone_xy)
    drone = np.array([*start, float(terrain.height_m(*start)) + spec.follow_altitude_agl_m])
    return SceneLayout(spec, terrain, target, tuple(decoys), drone, float(route.heading_rad(0.0)),
                       buildings_lo_m=np.column_stack([lo_xy, z0]), buildings_hi_m=np.column_stack([hi_xy, z1]),
                       takeoff_building=0)
