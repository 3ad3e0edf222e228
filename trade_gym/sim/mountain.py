"""Mountain layout: ridged high-relief terrain, a flat lake and a carved dirt road with a 65 deg turn.

Owns `make_mountain`; the tank follows the road, identical parked tanks stand on its shoulder.
"""

from __future__ import annotations

import numpy as np

from trade_gym.sim.layout import (
    PLACEMENT_TRIES, Lake, Road, SceneLayout, direction, grid_for, left_normal, parked,
)
from trade_gym.sim.scenes import SceneSpec
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import Heightfield, distance_to_path, fractal_noise, ridged_noise, smoothstep
from trade_gym.sim.vehicles import VehicleMotion

ROAD_HALF_WIDTH_M = 3.0
ROAD_FLAT_M, ROAD_BLEND_M = 4.0, 8.5  # terrain flat across the road within, blended up to [m]
ROAD_EXTENSION_M = 25.0  # road continues this far beyond both ends of the route
ROAD_PROFILE_WINDOW_M = 15.0  # moving-average window of the road's height profile
ROAD_PROFILE_STEP_M = 1.0
SECOND_LEG_POINTS = 3
RIDGE_AMPLITUDE_M, RIDGE_CELLS, RIDGE_OCTAVES, RIDGE_PERSISTENCE = 20.0, 3, 3, 0.45
RISE_AMPLITUDE_M, RISE_FROM_M, RISE_TO_M = 50.0, 6.0, 58.0  # valley walls climb with distance from the basin
RIDGE_FROM_M, RIDGE_TO_M = 10.0, 45.0  # ridges fade in over this distance from the basin
LAKE_SIDE_GAIN, LAKE_GAIN_RADIUS_M = 0.6, 50.0  # relief next to the lake, recovering over this distance
ROLLING_AMPLITUDE_M, ROLLING_CELLS = 2.5, 4
ROUGH_AMPLITUDE_M, ROUGH_CELLS = 0.25, 48
LAKE_ALONG_M, LAKE_SEMI_ALONG_M, LAKE_SEMI_ACROSS_M = (18.0, 30.0), (30.0, 42.0), (16.0, 24.0)
LAKE_SHORE_GAP_M = (7.0, 10.0)  # from the road edge to the lake [m]
LAKE_DROP_M = 1.2  # lake level below the lowest road point beside it
LAKE_SHORE_BLEND = 0.35  # shore rises over this fraction of the ellipse radius
TANK_LATERAL_M = (7.5, 9.5)
TANK_ROAD_CLEARANCE_M, TANK_SPACING_M, TANK_LAKE_CLEARANCE = 6.5, 12.0, 1.3


def _road(spec: SceneSpec, rng: np.random.Generator) -> tuple[CatmullRomSpline, float, float, float]:
    """Road spline, route start/end arc lengths [m] and the side (+1 left) facing away from the turn."""
    d0 = direction(rng.uniform(-np.pi, np.pi))
    turn = rng.choice([-1.0, 1.0])
    a = np.radians(spec.turn_deg) * turn
    d1 = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ d0
    leg2 = spec.route_length_m - spec.turn_after_m
    corner = spec.turn_after_m * d0
    points = [-ROAD_EXTENSION_M * d0, np.zeros(2), corner / 2, corner]
    points += [corner + leg2 * k / (SECOND_LEG_POINTS - 1) * d1 for k in range(1, SECOND_LEG_POINTS)]
    points.append(corner + (leg2 + ROAD_EXTENSION_M) * d1)
    pts = np.array(points)
    pts -= (pts[1] + pts[-2]) / 2.0  # centre the route on the origin
    road = CatmullRomSpline(pts)
    _, s = road.closest(np.array([pts[1], pts[-2]]))
    return road, float(s[0]), float(s[1]), -float(turn)


def _lake(road: CatmullRomSpline, s0: float, side: float, rng: np.random.Generator) -> Lake:
    """Elliptical lake beside the first leg, on the outside of the turn (level set later)."""
    s = s0 + rng.uniform(*LAKE_ALONG_M)
    a, b = rng.uniform(*LAKE_SEMI_ALONG_M), rng.uniform(*LAKE_SEMI_ACROSS_M)
    offset = ROAD_HALF_WIDTH_M + rng.uniform(*LAKE_SHORE_GAP_M) + b
    t = road.tangent(s)
    centre = road.position_m(s) + side * offset * left_normal(t)
    return Lake(centre, np.array([a, b]), float(np.arctan2(t[1], t[0])), 0.0)


def _relief(grid: Heightfield, road: CatmullRomSpline, lake: Lake, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Valley terrain whose walls rise away from both the road and the lake basin (lower near the lake);
    also returns node distance and foot arc length to the road, and the node coordinates."""
    shape = grid.shape
    dist, foot = distance_to_path(grid, road, ROAD_BLEND_M)
    gx, gy = np.meshgrid(grid.x_m, grid.y_m)
    # metric distance outside the lake ~ (r - 1) * shorter semi-axis
    from_lake = np.maximum(lake.normalised_radius(gx, gy) - 1.0, 0.0) * lake.semi_axes_m.min()
    gain = LAKE_SIDE_GAIN + (1.0 - LAKE_SIDE_GAIN) * smoothstep(0.0, LAKE_GAIN_RADIUS_M, from_lake)
    basin = np.minimum(dist, from_lake)
    ridges = RIDGE_AMPLITUDE_M * ridged_noise(shape, RIDGE_CELLS, RIDGE_OCTAVES, RIDGE_PERSISTENCE, rng)
    rise = RISE_AMPLITUDE_M * smoothstep(RISE_FROM_M, RISE_TO_M, basin)
    h = gain * (rise + ridges * smoothstep(RIDGE_FROM_M, RIDGE_TO_M, basin))
    h += ROLLING_AMPLITUDE_M * fractal_noise(shape, ROLLING_CELLS, 2, 0.5, rng)
    off_road = smoothstep(ROAD_FLAT_M, ROAD_BLEND_M, dist)
    h += ROUGH_AMPLITUDE_M * fractal_noise(shape, ROUGH_CELLS, 2, 0.5, rng) * off_road
    return h, dist, foot, gx, gy


def _road_profile(grid: Heightfield, h: np.ndarray, road: CatmullRomSpline) -> tuple[np.ndarray, np.ndarray]:
    """(K,) arc lengths [m] and road heights [m]: terrain under the road, moving-averaged."""
    s, xy = road.sample(ROAD_PROFILE_STEP_M)
    raw = Heightfield(h.astype(np.float32), grid.spacing_m, grid.origin_m).height_m(xy[:, 0], xy[:, 1])
    k = max(int(ROAD_PROFILE_WINDOW_M / ROAD_PROFILE_STEP_M), 1) | 1  # odd window keeps the length
    return s, np.convolve(np.pad(raw, k // 2, mode="edge"), np.ones(k) / k, mode="valid")


def _shore(h: np.ndarray, level: float, r: np.ndarray, r_flat: float) -> np.ndarray:
    """Flat at `level` for r <= r_flat; the shore rises back to the terrain: h' = lerp(level, h, w),
    lifted by max(level - h', 0) (1 - w) so it does not dip below the water next to it."""
    w = smoothstep(r_flat, r_flat + LAKE_SHORE_BLEND, r)
    blended = level + (h - level) * w
    return np.where(r <= r_flat, level, blended + np.maximum(level - blended, 0.0) * (1.0 - w))


def _carve(h: np.ndarray, s: np.ndarray, profile: np.ndarray, dist: np.ndarray, foot: np.ndarray) -> np.ndarray:
    """Flatten across the road: h' = (1 - w) h + w h_road(s_foot), w = 1 within ROAD_FLAT_M."""
    w = 1.0 - smoothstep(ROAD_FLAT_M, ROAD_BLEND_M, dist)
    return (1.0 - w) * h + w * np.interp(foot, s, profile)


def _tanks(spec: SceneSpec, road: CatmullRomSpline, s0: float, s1: float, lake: Lake,
           rng: np.random.Generator) -> list[VehicleMotion]:
    """Parked tanks on the road's shoulder along the route, away from the lake and each other."""
    spots: list[np.ndarray] = []
    for _ in range(spec.parked_decoys_near_path):
        for _ in range(PLACEMENT_TRIES):
            s = rng.uniform(s0 + 0.1 * (s1 - s0), s1)
            lateral = rng.choice([-1.0, 1.0]) * rng.uniform(*TANK_LATERAL_M)
            xy = road.position_m(s) + lateral * left_normal(road.tangent(s))
            ok = road.closest(xy)[0][0] >= TANK_ROAD_CLEARANCE_M and lake.normalised_radius(*xy) > TANK_LAKE_CLEARANCE
            if ok and all(np.linalg.norm(xy - q) >= TANK_SPACING_M for q in spots):
                break
        spots.append(xy)
    return [parked(xy, rng.uniform(-np.pi, np.pi)) for xy in spots]


def make_mountain(spec: SceneSpec, rng: np.random.Generator, speed: float) -> SceneLayout:
    """Mountain layout; the target drives the road from s0 to s1 (route_length_m with the turn)."""
    shape, grid = grid_for(spec)
    road, s0, s1, lake_side = _road(spec, rng)
    lake = _lake(road, s0, lake_side, rng)
    h, dist, foot, gx, gy = _relief(grid, road, lake, rng)
    s, profile = _road_profile(grid, h, road)
    level = float(np.min(profile)) - LAKE_DROP_M
    r = lake.normalised_radius(gx, gy)
    # nodes up to one cell diagonal outside the shore are flat too, so every triangle over the lake is flat
    r_flat = 1.0 + np.sqrt(2.0) * grid.spacing_m / float(lake.semi_axes_m.min())
    h = _carve(_shore(h, level, r, r_flat), s, profile, dist, foot)
    h[r <= r_flat] = level  # the carve never reaches the lake; keep it exactly flat regardless
    lake = Lake(lake.centre_m, lake.semi_axes_m, lake.yaw_rad, level)
    terrain = Heightfield(h.astype(np.float32), grid.spacing_m, grid.origin_m)
    decoys = _tanks(spec, road, s0, s1, lake, rng)
    start = road.position_m(s0)
    drone = np.array([*start, float(terrain.height_m(*start)) + spec.follow_altitude_agl_m])
    return SceneLayout(spec, terrain, VehicleMotion(road, speed, start_s_m=s0, end_s_m=s1), tuple(decoys), drone,
                       float(road.heading_rad(s0)), lake=lake, road=Road(road, ROAD_HALF_WIDTH_M))
