"""Rocky desert layout: fractal dunes, boulders, a target car and identical decoy cars.

Owns `make_desert`; parked decoys flank the route, one decoy crosses it, one drives past beside it the other
way and one overtakes the target in a lane beside it.
"""

from __future__ import annotations

import cv2
import numpy as np

from trade_gym.sim.layout import (
    PLACEMENT_TRIES, Boulder, SceneLayout, clearance_m, direction, grid_for, left_normal, parked, timed_motion,
)
from trade_gym.sim.meshes import ROCK_PROTOTYPES, rock_radii_m
from trade_gym.sim.scenes import DECOY_NEAR_PATH_M, SceneSpec
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.terrain import Heightfield, distance_to_path, fractal_noise, smoothstep
from trade_gym.sim.vehicles import VehicleMotion

ROUTE_CONTROL_POINTS = 6
ROUTE_LATERAL_M = 7.0  # lateral wiggle of the route's control points [m]
DUNE_AMPLITUDE_M, DUNE_CELLS = 4.0, 3
ROUGH_AMPLITUDE_M, ROUGH_CELLS = 0.35, 40
TRACK_FLAT_M, TRACK_BLEND_M = 2.5, 6.0  # terrain smoothed within these distances of driven paths [m]
TRACK_SMOOTH_SIGMA_M = 2.5
CROSS_AT = (0.12, 0.2)  # fraction of the route where the crossing decoy crosses (within the first 10 s)
CROSS_ANGLE_DEG = (60.0, 120.0)
CROSS_HALF_LENGTH_M = 35.0
# The crossing decoy passes this long before/after the target: close enough that the two identical
# cars are side by side in the image (the paper's decoy encounter), with a few metres between them.
CROSS_GAP_S = (1.7, 2.4)
PASS_AT = (0.66, 0.8)  # fraction of the route where the oncoming decoy passes the target
PASS_OFFSET_M = (8.0, 11.0)
PASS_HALF_LENGTH_M = 25.0
PASS_MIN_CLEARANCE_M = 5.0
DECOY_SPEED_RATIO = (0.85, 1.15)
# The overtaking decoy drives a lane beside the route, draws level with the target this long after the start
# (within the paper's 15 s sequence) and pulls ahead: the same heading as the target, side by side.
OVERTAKE_LEVEL_S = (6.0, 10.0)
OVERTAKE_LATERAL_M = (3.0, 3.8)  # centre to centre: about 1-2 m between the two cars
OVERTAKE_SPEED_RATIO = (1.5, 1.8)
OVERTAKE_LEAD_IN_M = 5.0  # straight lane before the route's start, beyond the distance the decoy starts behind
LANE_SAMPLE_M = 4.0  # spacing of the lane's control points along the route [m]
MOVING_DECOY_KINDS = 3  # one crossing the route, one passing beside it, one overtaking
PARK_NEAR_LATERAL_M = (5.0, DECOY_NEAR_PATH_M - 2.0)
PARK_FAR_LATERAL_M = (20.0, 35.0)
PARK_ROUTE_SPAN = (0.1, 0.95)
PARK_PATH_CLEARANCE_M = 4.5
PARK_SPACING_M = 7.0
BOULDER_SPREAD = 0.42  # boulders within +-spread * terrain size of the centre
BOULDER_NEAR_ROUTE_FRACTION, BOULDER_FIELD_HALF_WIDTH_M = 0.6, 35.0  # the rock field the route crosses
BOULDER_CANDIDATES = 5  # candidates drawn per boulder
BOULDER_SIZE_PROBABILITY = (0.3, 0.3, 0.2, 0.13, 0.07)  # per meshes.ROCK_SIZE_CLASSES_M
BOULDER_EMBED = (0.3, 0.6)  # fraction of the z radius sunk below the lowest ground point
BOULDER_ROUTE_CLEARANCE_M, BOULDER_CLEARANCE_M = 4.5, 3.5


def _route(spec: SceneSpec, rng: np.random.Generator) -> CatmullRomSpline:
    """Wiggly route of about route_length_m through the terrain centre, random heading."""
    d = direction(rng.uniform(-np.pi, np.pi))
    along = np.linspace(-spec.route_length_m / 2, spec.route_length_m / 2, ROUTE_CONTROL_POINTS)
    lateral = rng.uniform(-ROUTE_LATERAL_M, ROUTE_LATERAL_M, ROUTE_CONTROL_POINTS)
    return CatmullRomSpline(along[:, None] * d + lateral[:, None] * left_normal(d))


def _crossing(route: CatmullRomSpline, speed: float, rng: np.random.Generator) -> VehicleMotion:
    """A car whose path crosses the route shortly before or after the target passes."""
    s_c = rng.uniform(*CROSS_AT) * route.length_m
    centre, tangent = route.position_m(s_c), route.tangent(s_c)
    angle = np.radians(rng.uniform(*CROSS_ANGLE_DEG)) * rng.choice([-1.0, 1.0])
    d = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]) @ tangent
    along = np.array([-1.0, -0.4, 0.0, 0.4, 1.0]) * CROSS_HALF_LENGTH_M
    bend = rng.uniform(-2.0, 2.0, len(along)) * np.array([1.0, 1.0, 0.0, 1.0, 1.0])
    path = CatmullRomSpline(centre + along[:, None] * d + bend[:, None] * left_normal(d))
    gap = rng.uniform(*CROSS_GAP_S) * rng.choice([-1.0, 1.0])
    return timed_motion(path, speed * rng.uniform(*DECOY_SPEED_RATIO), path.closest(centre)[1][0], s_c / speed + gap)


def _oncoming(route: CatmullRomSpline, speed: float, rng: np.random.Generator) -> VehicleMotion:
    """A car driving the other way beside the route, passing the target at 8-11 m."""
    s_m = rng.uniform(*PASS_AT) * route.length_m
    side, offset = rng.choice([-1.0, 1.0]), rng.uniform(*PASS_OFFSET_M)
    d = -route.tangent(s_m)
    bend = rng.uniform(-1.5, 1.5, 5)
    for _ in range(PLACEMENT_TRIES):
        meet = route.position_m(s_m) - side * offset * left_normal(d)
        along = np.linspace(-PASS_HALF_LENGTH_M, PASS_HALF_LENGTH_M, 5)
        path = CatmullRomSpline(meet + along[:, None] * d + bend[:, None] * left_normal(d))
        if route.closest(path.sample(1.0)[1])[0].min() >= PASS_MIN_CLEARANCE_M:
            break
        offset += 1.0
    return timed_motion(path, speed * rng.uniform(*DECOY_SPEED_RATIO), path.closest(meet)[1][0], s_m / speed)


def _overtaking(route: CatmullRomSpline, speed: float, rng: np.random.Generator) -> VehicleMotion:
    """A car in a lane 3-3.8 m beside the route, faster than the target, level with it 6-10 s after the start."""
    side, lateral = rng.choice([-1.0, 1.0]), rng.uniform(*OVERTAKE_LATERAL_M)
    level_s, ratio = rng.uniform(*OVERTAKE_LEVEL_S), rng.uniform(*OVERTAKE_SPEED_RATIO)
    behind_m = (ratio - 1.0) * speed * level_s + OVERTAKE_LEAD_IN_M  # lane length before the route's start

    def in_lane(s_m: np.ndarray) -> np.ndarray:
        """(N, 2) lane points beside route arc lengths s_m [m]."""
        return route.position_m(s_m) + side * lateral * left_normal(route.tangent(s_m))

    lane = in_lane(np.arange(0.0, route.length_m, LANE_SAMPLE_M))
    path = CatmullRomSpline(np.vstack([lane[0] - behind_m * route.tangent(0.0), lane]))
    level_at = path.closest(in_lane(np.array([speed * level_s])))[1][0]
    return timed_motion(path, speed * ratio, level_at, level_s)


def _parked(route: CatmullRomSpline, paths: list[CatmullRomSpline], spots: list[np.ndarray],
            lateral: tuple[float, float], span: tuple[float, float], rng: np.random.Generator) -> VehicleMotion:
    """A parked car `lateral` metres beside the route, clear of driven paths and other parked cars."""
    for _ in range(PLACEMENT_TRIES):
        s = rng.uniform(*span) * route.length_m
        xy = route.position_m(s) + rng.choice([-1.0, 1.0]) * rng.uniform(*lateral) * left_normal(route.tangent(s))
        if clearance_m(xy, paths, []) >= PARK_PATH_CLEARANCE_M and clearance_m(xy, [], spots) >= PARK_SPACING_M:
            break
    spots.append(xy)
    return parked(xy, rng.uniform(-np.pi, np.pi))


def _smooth_tracks(terrain: Heightfield, paths: list[CatmullRomSpline]) -> np.ndarray:
    """Blend h toward a Gaussian-smoothed copy near driven paths: h' = (1 - w) h + w G*h."""
    h = terrain.heights_m.astype(np.float64)
    smooth = cv2.GaussianBlur(h, (0, 0), TRACK_SMOOTH_SIGMA_M / terrain.spacing_m)
    dist = np.min([distance_to_path(terrain, path, TRACK_BLEND_M)[0] for path in paths], axis=0)
    w = 1.0 - smoothstep(TRACK_FLAT_M, TRACK_BLEND_M, dist)
    return (1.0 - w) * h + w * smooth


def _boulders(spec: SceneSpec, terrain: Heightfield, route: CatmullRomSpline, paths: list[CatmullRomSpline],
              spots: list[np.ndarray], rng: np.random.Generator) -> tuple[Boulder, ...]:
    """Rocks, mostly in a field along the route, clear of all paths and parked cars, half sunk in the ground."""
    n = spec.boulder_count * BOULDER_CANDIDATES
    anywhere = rng.uniform(-BOULDER_SPREAD, BOULDER_SPREAD, (n, 2)) * spec.terrain_size_m
    s = rng.uniform(0.0, route.length_m, n)
    lateral = rng.uniform(-1.0, 1.0, (n, 1)) * BOULDER_FIELD_HALF_WIDTH_M
    beside = route.position_m(s) + lateral * left_normal(route.tangent(s))
    xy = np.where((rng.uniform(0.0, 1.0, n) < BOULDER_NEAR_ROUTE_FRACTION)[:, None], beside, anywhere)
    proto = rng.integers(0, ROCK_PROTOTYPES, n)
    size = rng.choice(len(BOULDER_SIZE_PROBABILITY), n, p=BOULDER_SIZE_PROBABILITY)
    radii = np.array([rock_radii_m(a, b) for a, b in zip(proto, size)])
    reach = radii[:, :2].max(axis=1)
    ok = (route.closest(xy)[0] >= BOULDER_ROUTE_CLEARANCE_M + reach)
    ok &= clearance_m(xy, paths, spots) >= BOULDER_CLEARANCE_M + reach
    yaw, embed = rng.uniform(-np.pi, np.pi, n), rng.uniform(*BOULDER_EMBED, n)
    idx = np.flatnonzero(ok)[: spec.boulder_count]
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    low = np.min(terrain.height_m(xy[idx, None, 0] + ring[None, :, 0] * reach[idx, None],
                                  xy[idx, None, 1] + ring[None, :, 1] * reach[idx, None]), axis=1)
    z = low + radii[idx, 2] * (1.0 - embed[idx])
    return tuple(Boulder(np.array([*xy[k], zk]), float(yaw[k]), int(proto[k]), int(size[k])) for k, zk in zip(idx, z))


def make_desert(spec: SceneSpec, rng: np.random.Generator, speed: float) -> SceneLayout:
    """Desert layout; `speed` is the target's [m/s] (decoy timing depends on it)."""
    if spec.moving_decoys > MOVING_DECOY_KINDS:
        raise ValueError(f"desert supports at most {MOVING_DECOY_KINDS} moving decoys, got {spec.moving_decoys}")
    shape, grid = grid_for(spec)
    route = _route(spec, rng)
    heights = DUNE_AMPLITUDE_M * fractal_noise(shape, DUNE_CELLS, 3, 0.5, rng)
    heights += ROUGH_AMPLITUDE_M * fractal_noise(shape, ROUGH_CELLS, 3, 0.5, rng)
    makers = (_crossing, _oncoming, _overtaking)
    moving = [make(route, speed, rng) for make in makers[: spec.moving_decoys]]
    driven = [route] + [m.path for m in moving]
    spots: list[np.ndarray] = []
    near = [_parked(route, driven, spots, PARK_NEAR_LATERAL_M, PARK_ROUTE_SPAN, rng)
            for _ in range(spec.parked_decoys_near_path)]
    far = [_parked(route, driven, spots, PARK_FAR_LATERAL_M, PARK_ROUTE_SPAN, rng)
           for _ in range(spec.parked_decoys_far)]
    rough = Heightfield(heights.astype(np.float32), grid.spacing_m, grid.origin_m)
    terrain = Heightfield(_smooth_tracks(rough, driven).astype(np.float32), grid.spacing_m, grid.origin_m)
    boulders = _boulders(spec, terrain, route, driven[1:], spots, rng)
    start = route.position_m(0.0)
    drone = np.array([*start, float(terrain.height_m(*start)) + spec.follow_altitude_agl_m])
    return SceneLayout(spec, terrain, VehicleMotion(route, speed), tuple(near + moving + far), drone,
                       float(route.heading_rad(0.0)), boulders=boulders)
