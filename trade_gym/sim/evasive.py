"""The evasive target: faster, and swerving within the drivable area, while the drone is overhead.

Owns `EvasiveMotion` (a `Motion` whose state the world advances each frame with the drone's position),
`LateralBounds`/`lateral_bounds`, `evasive_radius_m` and `swerve_angle_rad`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from trade_gym.sim.layout import SceneLayout, left_normal
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.vehicles import MOVING_EPS_MPS, PlanarPose, PlanarVelocity, VehicleMotion, vehicle_model

FloatArray = npt.NDArray[np.float64]

# "Overhead": the drone's horizontal distance to the target is below h tan(fov / 2), the half-width of a downward
# camera's ground footprint at the scene's follow height h (`evasive_radius_m`): the target is in the drone's view.
EVASIVE_SPEED_FACTOR = 1.6  # speed while the drone is overhead over the cruise speed (inside stop-and-go's 0.5-2)
EVASIVE_RAMP_S = 1.5  # time to change the speed by the cruise speed [s] (stop-and-go's ramps)
# Largest angle between the heading and the path while swerving: EVASIVE_SWERVE_DEG, or less for a long target, so
# that its corners swing out at most EVASIVE_SWING_M (asin(swing / half length), `swerve_angle_rad`): 13 deg for
# the car, 8 for the truck and the tank.
EVASIVE_SWERVE_DEG = 20.0  # [deg]
EVASIVE_SWING_M = 0.5  # [m]
EVASIVE_LATERAL_RESPONSE_S = 1.0  # the lateral speed changes by its limit (v sin(swerve)) in this time at most [s]
EVASIVE_SWERVE_FRACTION = (0.5, 1.0)  # each swerve's amplitude over the lateral bound on its side, drawn per swerve
# A swerve turns to the other side this close to its amplitude; back from swerving, the target snaps onto its
# centre line this close to it [m].
EVASIVE_SWERVE_TOLERANCE_M = 0.02
EVASIVE_STEP_S = 1.0 / 240.0  # integration step [s]: the physics rate (8 steps per camera frame)
# Lateral bounds (`lateral_bounds`): on a road (the target drives it) the road's half width less the target's half
# width (its sides stay on the road; a corner may swing out by EVASIVE_SWING_M), off road EVASIVE_OFFROAD_LATERAL_M;
# both shrunk where the band the target sweeps (its half width, plus its corners' swing) would come closer than
# EVASIVE_CLEARANCE_M to a building, a parked vehicle or a rock, or nearer than EVASIVE_EDGE_MARGIN_M to the terrain's
# edge. Moving decoys are not avoided (every vehicle is visual only). The routes have no branches to turn off into.
EVASIVE_OFFROAD_LATERAL_M = 3.0  # about a lane's width [m]
EVASIVE_CLEARANCE_M = 0.25  # beyond the band the target sweeps, its corners' swing included [m]
EVASIVE_EDGE_MARGIN_M = 10.0  # as the parked decoys' (world.PARK_EDGE_MARGIN_M) [m]
EVASIVE_BOUND_ALONG_M, EVASIVE_BOUND_ACROSS_M = 1.0, 0.25  # sampling of the bounds along and across the route [m]
TANGENT_STEP_M = 0.5  # half the arc-length step of the tangent's central difference (the path's curvature) [m]
MIN_STRETCH = 0.1  # floor of 1 - kappa d, the offset curve's length per path length (d < 1/kappa on the routes)
SUMMARY_DECIMALS = 3


def evasive_radius_m(follow_height_m: float, camera_fov_deg: float) -> float:
    """h tan(fov / 2) [m]: within it (horizontal distance) the drone counts as overhead."""
    return follow_height_m * math.tan(math.radians(camera_fov_deg) / 2.0)


def swerve_angle_rad(half_length_m: float) -> float:
    """The largest swerve angle of a target half_length_m long (half its length) [rad]: its corners swing out at
    most EVASIVE_SWING_M, and the angle stays within EVASIVE_SWERVE_DEG."""
    return min(math.radians(EVASIVE_SWERVE_DEG), math.asin(min(EVASIVE_SWING_M / half_length_m, 1.0)))


@dataclass(frozen=True, eq=False)
class LateralBounds:
    """How far the target may leave its route's centre line, per side, by arc length: samples every `step_m` from
    `start_s_m`. `here_*` holds at a sample for the target's whole length, `ahead_*` also for the distance it needs
    to steer back from the widest swerve (a swerve aims within `ahead_*`, the offset never leaves `here_*`)."""

    start_s_m: float
    step_m: float
    here_right_m: tuple[float, ...]
    here_left_m: tuple[float, ...]
    ahead_right_m: tuple[float, ...]
    ahead_left_m: tuple[float, ...]

    def _index(self, s_m: float) -> int:
        return min(max(int((s_m - self.start_s_m) / self.step_m), 0), len(self.here_left_m) - 1)

    def here(self, s_m: float) -> tuple[float, float]:
        k = self._index(s_m)
        return self.here_right_m[k], self.here_left_m[k]

    def ahead(self, s_m: float) -> tuple[float, float]:
        k = self._index(s_m)
        return self.ahead_right_m[k], self.ahead_left_m[k]


def _box_distance_m(points_m: FloatArray, centres_m: FloatArray, yaw_rad: FloatArray, half_m: FloatArray) -> FloatArray:
    """(..., R) distance [m] from points (..., 2) to R boxes (centre (R, 2), yaw (R,), half sides (R, 2)); 0 inside."""
    rel = points_m[..., None, :] - centres_m
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    local = np.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]], axis=-1)
    return np.linalg.norm(np.maximum(np.abs(local) - half_m, 0.0), axis=-1)


def _clear(layout: SceneLayout, points_m: FloatArray, reach_m: float) -> npt.NDArray[np.bool_]:
    """(...) whether points (..., 2) are reach_m clear of buildings, parked vehicles and rocks, and on the terrain."""
    edge = layout.spec.terrain_size_m / 2.0 - EVASIVE_EDGE_MARGIN_M
    ok = np.all(np.abs(points_m) < edge, axis=-1)
    lo, hi = layout.buildings_lo_m[:, :2], layout.buildings_hi_m[:, :2]
    if len(lo):
        ok &= np.all(_box_distance_m(points_m, (lo + hi) / 2.0, np.zeros(len(lo)), (hi - lo) / 2.0) >= reach_m, -1)
    parked = [m for m in layout.decoys if not m.is_moving]
    if parked:
        centres = np.array([m.path.position_m(m.start_s_m) for m in parked])
        yaw = np.array([float(m.path.heading_rad(m.start_s_m)) for m in parked])
        half = np.broadcast_to(vehicle_model(layout.spec.decoy_kind).half_extents_m[:2], (len(parked), 2))
        ok &= np.all(_box_distance_m(points_m, centres, yaw, half) >= reach_m, -1)
    if layout.boulders:
        centres = np.array([b.centre_m[:2] for b in layout.boulders])
        radii = np.array([float(np.max(b.radii_m[:2])) for b in layout.boulders])
        ok &= np.all(np.linalg.norm(points_m[..., None, :] - centres, axis=-1) - radii >= reach_m, -1)
    return ok


def _window_min(values: FloatArray, behind: int, ahead: int) -> tuple[float, ...]:
    """Minimum of values[k - behind : k + ahead + 1] for each k (the ends padded with the end values)."""
    padded = np.concatenate([np.full(behind, values[0]), values, np.full(ahead, values[-1])])
    return tuple(np.lib.stride_tricks.sliding_window_view(padded, behind + ahead + 1).min(axis=1).tolist())


def lateral_bounds(layout: SceneLayout, half_extents_m: FloatArray, top_speed_mps: float,
                   swerve_rad: float) -> LateralBounds:
    """The target's lateral bounds along its route (the rule beside EVASIVE_OFFROAD_LATERAL_M): per side, the widest
    offset up to which every offset across is clear, sampled every EVASIVE_BOUND_ALONG_M; for a target of
    half_extents_m (3,) [m] driving at most top_speed_mps [m/s] and turning at most swerve_rad off its path."""
    m, along = layout.target, EVASIVE_BOUND_ALONG_M
    s = np.append(np.arange(m.start_s_m, m.stop_s_m, along), m.stop_s_m)
    xy, normal = m.path.position_m(s), left_normal(m.path.tangent(s))
    half_x, half_y = float(half_extents_m[0]), float(half_extents_m[1])
    widest = EVASIVE_OFFROAD_LATERAL_M if layout.road is None else max(layout.road.half_width_m - half_y, 0.0)
    offsets = np.arange(0, int(widest / EVASIVE_BOUND_ACROSS_M + 1e-9) + 1) * EVASIVE_BOUND_ACROSS_M  # (O,) from 0
    # a swerve from the widest offset back to the centre line: its length at the largest angle, plus speeding the
    # lateral rate up and down again at the top speed
    back_m = widest / math.tan(swerve_rad) + 2.0 * top_speed_mps * EVASIVE_LATERAL_RESPONSE_S
    # the band a target turned by up to the swerve angle sweeps either side of its centre (corners included: swerving
    # away from an obstacle swings the rear toward it, so the centre line itself must be that clear)
    sweep_m = half_y * math.cos(swerve_rad) + half_x * math.sin(swerve_rad) + EVASIVE_CLEARANCE_M
    reach, back = math.ceil(half_x / along), math.ceil(back_m / along)  # samples: half the target, steering back
    bounds = []
    for side in (-1.0, 1.0):  # right, left
        points = xy[:, None, :] + side * offsets[None, :, None] * normal[:, None, :]  # (K, O, 2)
        clear = _clear(layout, points, sweep_m)
        clear_to = np.where(clear.all(axis=1), len(offsets), np.argmin(clear, axis=1))  # clear from the centre line
        bound = offsets[np.maximum(clear_to - 1, 0)]  # 0 where not even the centre line is clear
        bounds.append((_window_min(bound, reach, reach), _window_min(bound, reach, reach + back)))
    (here_right, ahead_right), (here_left, ahead_left) = bounds
    return LateralBounds(float(m.start_s_m), along, here_right, here_left, ahead_right, ahead_left)


class EvasiveMotion:
    """A `Motion` along `base.path` that reacts to the drone: while the drone is overhead (horizontally within
    `radius_m`) the speed ramps to EVASIVE_SPEED_FACTOR times the cruise speed and the target swerves from side to
    side within `bounds`, back to cruise speed and the centre line otherwise.

    State at time t: s = min(base s(t) + extra, end), the lateral offset d (left of the path, + ) and its rate.
    `advance(t, drone)` integrates to t in EVASIVE_STEP_S steps with the reaction of the previous call (the target
    reacts to where the drone was one frame before), then looks at the drone. While the drone has never been
    overhead, extra = d = 0 and the motion is `base`'s exactly. Position P = c(s) + d n(s), velocity
    P' = s' (c'(s) + d n'(s)) + d' n(s) with |P'| = the speed (the factor times cruise's: swerving trades speed along
    the path for speed across it); heading along the velocity. At a time other than the last `advance`'s the pose
    and velocity are a prediction: the current rates held. `stop_time_s` is cruise's (the latest the target stops).
    The swerves' sides and amplitudes are drawn from `rng` as they come.
    """

    def __init__(self, base: VehicleMotion, bounds: LateralBounds, radius_m: float, swerve_rad: float,
                 rng: np.random.Generator) -> None:
        self.base, self.bounds, self.radius_m, self.swerve_rad = base, bounds, float(radius_m), float(swerve_rad)
        self._rng = rng
        self._side = 1.0 if rng.uniform() < 0.5 else -1.0
        self._fraction = float(rng.uniform(*EVASIVE_SWERVE_FRACTION))
        self._first_side = "left" if self._side > 0 else "right"
        self._sin_swerve = math.sin(self.swerve_rad)
        self._t_s, self._extra_m, self._factor, self._d_m, self._d_rate_mps = 0.0, 0.0, 1.0, 0.0, 0.0
        self._alert = False
        self._s_rate_mps = self._forward_speed_mps(0.0)

    @classmethod
    def for_layout(cls, layout: SceneLayout, half_extents_m: FloatArray, camera_fov_deg: float,
                   rng: np.random.Generator) -> EvasiveMotion:
        swerve = swerve_angle_rad(float(half_extents_m[0]))
        bounds = lateral_bounds(layout, half_extents_m, EVASIVE_SPEED_FACTOR * layout.target.speed_mps, swerve)
        radius = evasive_radius_m(layout.spec.follow_altitude_agl_m, camera_fov_deg)
        return cls(layout.target, bounds, radius, swerve, rng)

    @property
    def path(self) -> CatmullRomSpline:
        return self.base.path

    @property
    def is_moving(self) -> bool:
        return self.base.is_moving

    @property
    def stop_time_s(self) -> float:
        return self.base.stop_time_s

    @property
    def alert(self) -> bool:
        """Whether the drone was overhead at the last `advance`."""
        return self._alert

    def advance(self, t_s: float, drone_position_m: npt.ArrayLike | None) -> None:
        """Integrate to t_s [s] (not before the last call's), then note whether the drone, at (2+,) world [m]
        (None: no drone), is overhead."""
        t = float(t_s)
        if t < self._t_s:
            raise ValueError(f"EvasiveMotion.advance: t_s must not decrease, got {t!r} after {self._t_s!r}")
        if t > self._t_s:
            steps = max(math.ceil((t - self._t_s) / EVASIVE_STEP_S - 1e-9), 1)
            dt = (t - self._t_s) / steps
            for k in range(steps):
                self._step(self._t_s + k * dt, dt)
            self._t_s = t
            self._s_rate_mps = self._forward_speed_mps(t)
        if drone_position_m is None:
            self._alert = False
            return
        drone = np.asarray(drone_position_m, dtype=np.float64).tolist()
        x, y = self.planar_pose(t)[:2]
        self._alert = math.hypot(drone[0] - x, drone[1] - y) < self.radius_m

    def _s_m(self, t_s: float) -> float:
        s, end = self.base.distance_m(t_s) + self._extra_m, self.base.stop_s_m
        return s if s < end else end

    def _driving(self, t_s: float, s_m: float) -> bool:
        base = self.base
        return base.is_moving and t_s >= base.delay_s and s_m < base.stop_s_m

    def _tangent_rate(self, s_m: float) -> tuple[float, float, float, float]:
        """The unit tangent t(s) and its derivative t'(s) [1/m] (central difference); n'(s) = (-t'_y, t'_x)."""
        _, _, tx, ty = self.path.point_at(s_m)
        _, _, ax, ay = self.path.point_at(s_m - TANGENT_STEP_M)
        _, _, bx, by = self.path.point_at(s_m + TANGENT_STEP_M)
        return tx, ty, (bx - ax) / (2.0 * TANGENT_STEP_M), (by - ay) / (2.0 * TANGENT_STEP_M)

    def _path_rate_mps(self, s_m: float, speed_mps: float) -> float:
        """s' [m/s] at world speed `speed_mps` with the current lateral offset and rate: |P'| = speed, so
        s' (1 - kappa d) = sqrt(speed^2 - d'^2) with P = c(s) + d n(s) and kappa the path's signed curvature."""
        if self._d_m == 0.0 and self._d_rate_mps == 0.0:
            return speed_mps
        tx, ty, kx, ky = self._tangent_rate(s_m)
        stretch = max(1.0 - (tx * ky - ty * kx) * self._d_m, MIN_STRETCH)
        return math.sqrt(max(speed_mps * speed_mps - self._d_rate_mps * self._d_rate_mps, 0.0)) / stretch

    def _forward_speed_mps(self, t_s: float) -> float:
        s = self._s_m(t_s)
        return self._path_rate_mps(s, self._factor * self.base.speed_mps) if self._driving(t_s, s) else 0.0

    def _step(self, t_s: float, dt: float) -> None:
        """One step from t_s [s]: the speed factor ramps toward its goal, the offset and the extra distance follow."""
        goal = EVASIVE_SPEED_FACTOR if self._alert else 1.0
        ramp = dt / EVASIVE_RAMP_S
        self._factor += min(max(goal - self._factor, -ramp), ramp)
        s = self._s_m(t_s)
        if not self._driving(t_s, s):
            self._d_rate_mps = 0.0  # standing: no sideways motion either
            return
        speed = self._factor * self.base.speed_mps
        self._steer(s, speed, dt)
        self._extra_m += (self._path_rate_mps(s, speed) - self.base.speed_mps) * dt

    def _steer(self, s_m: float, speed_mps: float, dt: float) -> None:
        """Lateral rate toward the swerve's goal: at most speed sin(swerve), changed by at most that per response
        time, slowing as sqrt(a |e|) near the goal (half the braking curve's sqrt(2 a |e|): it does not overshoot)."""
        right, left = self.bounds.ahead(s_m)
        goal = (left if self._side > 0 else -right) * self._fraction if self._alert else 0.0
        rate_max = speed_mps * self._sin_swerve
        accel = rate_max / EVASIVE_LATERAL_RESPONSE_S
        error = goal - self._d_m
        wanted = math.copysign(min(rate_max, math.sqrt(accel * abs(error))), error)
        self._d_rate_mps += min(max(wanted - self._d_rate_mps, -accel * dt), accel * dt)
        d = self._d_m + self._d_rate_mps * dt
        right, left = self.bounds.here(s_m)
        if d > left or d < -right:
            d, self._d_rate_mps = min(max(d, -right), left), 0.0
        self._d_m = d
        if self._alert and abs(error) < EVASIVE_SWERVE_TOLERANCE_M:
            self._side, self._fraction = -self._side, float(self._rng.uniform(*EVASIVE_SWERVE_FRACTION))
        elif not self._alert and abs(d) < EVASIVE_SWERVE_TOLERANCE_M and abs(self._d_rate_mps) <= accel * dt:
            self._d_m = self._d_rate_mps = 0.0

    def _state(self, t_s: float) -> tuple[float, float, float, float]:
        """s [m], d [m], s' and d' [m/s] at t_s: the state at the last `advance`, held rates elsewhere."""
        s, d, s_rate, d_rate = self._s_m(self._t_s), self._d_m, self._s_rate_mps, self._d_rate_mps
        if t_s != self._t_s:
            base, dt = self.base, t_s - self._t_s
            right, left = self.bounds.here(s)
            s = min(max(s + s_rate * dt, base.start_s_m), base.stop_s_m)
            d = min(max(d + d_rate * dt, -right), left)
        return s, d, s_rate, d_rate

    def _kinematics(self, t_s: float) -> tuple[float, float, float, float, float, float]:
        """x, y [m], v_x, v_y [m/s] (v = s' (t + d n') + d' n) and the path's unit tangent there."""
        s, d, s_rate, d_rate = self._state(t_s)
        x, y, tx, ty = self.path.point_at(s)
        if d == 0.0:
            return x, y, s_rate * tx - d_rate * ty, s_rate * ty + d_rate * tx, tx, ty
        _, _, kx, ky = self._tangent_rate(s)
        vx = s_rate * (tx - d * ky) - d_rate * ty
        vy = s_rate * (ty + d * kx) + d_rate * tx
        return x - d * ty, y + d * tx, vx, vy, tx, ty

    def distance_m(self, t_s: float) -> float:
        return self._state(t_s)[0]

    def planar_pose(self, t_s: float) -> PlanarPose:
        if self._extra_m == 0.0 and self._d_m == 0.0 and self._d_rate_mps == 0.0:
            return self.base.planar_pose(t_s)
        x, y, vx, vy, tx, ty = self._kinematics(t_s)
        speed = math.hypot(vx, vy)
        return (x, y, vx / speed, vy / speed) if speed > MOVING_EPS_MPS else (x, y, tx, ty)

    def planar_velocity_at(self, t_s: float) -> PlanarVelocity | None:
        if self._extra_m == 0.0 and self._d_m == 0.0 and self._d_rate_mps == 0.0:
            return self.base.planar_velocity_at(t_s)
        x, y, vx, vy, _, _ = self._kinematics(t_s)
        return (x, y, vx, vy) if math.hypot(vx, vy) > MOVING_EPS_MPS else None

    def summary(self) -> dict[str, Any]:
        """The mode, its overhead radius [m], speed factor, largest swerve angle [deg], widest bounds (right, left) [m]
        and its first swerve's side."""
        r = SUMMARY_DECIMALS
        return {"mode": "evasive", "radius_m": round(self.radius_m, r), "speed_factor": EVASIVE_SPEED_FACTOR,
                "swerve_deg": round(math.degrees(self.swerve_rad), r),
                "lateral_bound_m": (round(max(self.bounds.here_right_m), r), round(max(self.bounds.here_left_m), r)),
                "first_swerve": self._first_side}
