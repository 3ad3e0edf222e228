"""The target's behaviours along its route: cruise (constant speed), stop-and-go (a drawn speed profile), evasive.

Owns `TARGET_MOTIONS`, `TargetMotion` (the per-reset option, as `DecoyTier` is for the decoys), `StopAndGoMotion`,
`draw_stop_and_go` and `motion_summary`; the evasive target is `trade_gym.sim.evasive.EvasiveMotion`.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from trade_gym.sim.evasive import EvasiveMotion
from trade_gym.sim.layout import SceneLayout
from trade_gym.sim.spline import CatmullRomSpline
from trade_gym.sim.vehicles import MOVING_EPS_MPS, Motion, PlanarPose, PlanarVelocity, VehicleMotion

TARGET_MOTIONS = ("cruise", "stop_and_go", "evasive")

# Stop-and-go (`draw_stop_and_go`): drives between stops, each made of legs at a drawn multiple of the scene's target
# speed; speeds change linearly (ramps), so the speed, the distance and the velocity stay continuous.
STOP_GO_DRIVE_S = (6.0, 16.0)  # driving time between two stops, ramps included [s]: below 20 s, so every 20 s
#                                of driving holds a stop (and the first stop starts within 16 s of the reset)
STOP_GO_STOP_S = (0.5, 3.0)  # standing still at a stop [s]
STOP_GO_SPEED_FACTORS = (0.5, 2.0)  # a leg's speed over the scene's target speed
STOP_GO_LEG_S = (2.0, 6.0)  # time a leg holds its speed after its ramp [s] (cut to fit its drive)
# Time to change the speed by the scene's target speed [s] (2 m/s^2 at the desert's 3 m/s); so ramps up to and down
# from the fastest leg take at most 4 x 1.5 = 6 s, within the shortest drive.
STOP_GO_RAMP_S = 1.5
SUMMARY_DECIMALS = 3  # of the times, factors and lengths in `motion_summary`


@dataclass(frozen=True, eq=False)
class StopAndGoMotion:
    """Distance along `base.path` under a piecewise-linear speed profile (a `Motion`).

    Knots (tau_k, f_k): at tau = t - base.delay_s the speed is v f(tau), v = base.speed_mps, f linear between knots
    and held after the last. On [tau_k, tau_k+1], with a_k = (f_k+1 - f_k) / (tau_k+1 - tau_k):
    s(t) = start_s + s_k + v (f_k (tau - tau_k) + a_k (tau - tau_k)^2 / 2), clipped to base.end_s_m, where s_k is
    the distance driven by tau_k. `stops` are (start [s], duration [s]) of each stop, `speed_factors` each leg's f.
    """

    base: VehicleMotion
    knot_times_s: tuple[float, ...]  # since base.delay_s, from 0, increasing
    knot_factors: tuple[float, ...]  # >= 0
    stops: tuple[tuple[float, float], ...] = ()
    speed_factors: tuple[float, ...] = ()
    # derived in __post_init__: each knot's speed-factor slope [1/s], the distance driven by each knot [m] and the
    # time the route's end is reached [s]
    _slopes: tuple[float, ...] = field(init=False, repr=False)
    _driven_m: tuple[float, ...] = field(init=False, repr=False)
    _stop_time_s: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        times, factors = self.knot_times_s, self.knot_factors
        if len(times) != len(factors) or not times or times[0] != 0.0 or any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"StopAndGoMotion needs knot times from 0, increasing, one per factor; got {times!r}")
        if not all(math.isfinite(f) and f >= 0.0 for f in factors):
            raise ValueError(f"StopAndGoMotion.knot_factors must be finite and >= 0, got {factors!r}")
        slopes = [(f1 - f0) / (t1 - t0) for f0, f1, t0, t1 in zip(factors, factors[1:], times, times[1:])] + [0.0]
        driven, v = [0.0], self.base.speed_mps
        for k in range(len(times) - 1):  # trapezoid: exact for a linear speed
            driven.append(driven[-1] + v * (factors[k] + factors[k + 1]) / 2.0 * (times[k + 1] - times[k]))
        object.__setattr__(self, "_slopes", tuple(slopes))
        object.__setattr__(self, "_driven_m", tuple(driven))
        object.__setattr__(self, "_stop_time_s", self._time_to_end_s())

    @property
    def path(self) -> CatmullRomSpline:
        return self.base.path

    @property
    def is_moving(self) -> bool:
        return self.base.is_moving

    @property
    def stop_time_s(self) -> float:
        """Time at which the target reaches the route's end and stops [s]."""
        return self._stop_time_s

    def _knot(self, tau_s: float) -> tuple[int, float]:
        k = bisect_right(self.knot_times_s, tau_s) - 1
        return k, tau_s - self.knot_times_s[k]

    def speed_mps(self, t_s: float) -> float:
        """v f(t) [m/s]; 0 before the delay and from the stop at the route's end."""
        tau = t_s - self.base.delay_s
        if not self.is_moving or tau < 0.0 or t_s >= self._stop_time_s:
            return 0.0
        k, dt = self._knot(tau)
        return self.base.speed_mps * (self.knot_factors[k] + self._slopes[k] * dt)

    def distance_m(self, t_s: float) -> float:
        """s(t) [m] for a scalar t [s]."""
        base, tau = self.base, t_s - self.base.delay_s
        if tau <= 0.0 or not self.is_moving:
            return base.start_s_m
        k, dt = self._knot(tau)
        s = base.start_s_m + self._driven_m[k] + base.speed_mps * (self.knot_factors[k] + self._slopes[k] * dt / 2) * dt
        end = base.stop_s_m
        return s if s < end else end

    def planar_pose(self, t_s: float) -> PlanarPose:
        return self.path.point_at(self.distance_m(t_s))

    def planar_velocity_at(self, t_s: float) -> PlanarVelocity | None:
        """(x, y, v_x, v_y): the speed along the unit tangent; None while standing (at a stop, at the end)."""
        speed = self.speed_mps(t_s)
        if speed <= MOVING_EPS_MPS:
            return None
        x, y, tx, ty = self.path.point_at(self.distance_m(t_s))
        return x, y, speed * tx, speed * ty

    def summary(self) -> dict[str, Any]:
        """The mode and the drawn profile up to the route's end: stops (start, duration) [s], legs' speed factors."""
        r = SUMMARY_DECIMALS
        return {"mode": "stop_and_go",
                "stops_s": tuple((round(a, r), round(b, r)) for a, b in self.stops if a < self._stop_time_s),
                "speed_factors": tuple(round(f, r) for f in self.speed_factors)}

    def _time_to_end_s(self) -> float:
        """The t at which s(t) reaches base.end_s_m: the root of the quadratic in the segment where it does."""
        base = self.base
        if not base.is_moving:
            return 0.0
        route, driven, v = base.stop_s_m - base.start_s_m, self._driven_m, base.speed_mps
        k = max(bisect_right(driven, route) - 1, 0)
        if k == len(driven) - 1 and route > driven[k] and self.knot_factors[k] <= 0.0:
            return math.inf  # ends standing short of the route's end
        left_m, b, a = route - driven[k], v * self.knot_factors[k], v * self._slopes[k]
        # a dt^2 / 2 + b dt = left, in the form without cancellation: dt = 2 left / (b + sqrt(b^2 + 2 a left))
        dt = 0.0 if left_m <= 0.0 else 2.0 * left_m / (b + math.sqrt(max(b * b + 2.0 * a * left_m, 0.0)))
        return base.delay_s + self.knot_times_s[k] + dt


class _Profile:
    """Knots (tau, f) built ramp by hold, with the distance driven so far [m]."""

    def __init__(self, factor: float, speed_mps: float) -> None:
        self.times_s, self.factors, self.speed_mps, self.distance_m = [0.0], [factor], speed_mps, 0.0

    def _to(self, duration_s: float, factor: float) -> None:
        end_s = self.times_s[-1] + duration_s
        if end_s > self.times_s[-1]:  # a segment too short to move the time is left out (its change is as small)
            self.distance_m += self.speed_mps * (self.factors[-1] + factor) / 2.0 * (end_s - self.times_s[-1])
            self.times_s.append(end_s)
            self.factors.append(factor)

    def ramp_to(self, factor: float) -> None:
        self._to(abs(factor - self.factors[-1]) * STOP_GO_RAMP_S, factor)

    def hold(self, duration_s: float) -> None:
        self._to(duration_s, self.factors[-1])


def _drive_legs(rng: np.random.Generator, budget_s: float, factor: float,
                first: float | None) -> list[tuple[float, float]]:
    """(speed factor, hold [s]) of one drive's legs from speed factor `factor`: ramps, holds and the final ramp down
    to the stop fit in budget_s [s]; the first leg's factor is `first` when given."""
    legs: list[tuple[float, float]] = []
    while True:
        new = first if first is not None and not legs else float(rng.uniform(*STOP_GO_SPEED_FACTORS))
        ramps_s = (abs(new - factor) + new) * STOP_GO_RAMP_S  # up (or down) to the leg, and from it to the stop
        hold_s = min(float(rng.uniform(*STOP_GO_LEG_S)), budget_s - ramps_s)
        if hold_s <= 0.0 and legs:
            return legs
        legs.append((new, max(hold_s, 0.0)))
        budget_s -= abs(new - factor) * STOP_GO_RAMP_S + max(hold_s, 0.0)
        factor = new


def draw_stop_and_go(base: VehicleMotion, rng: np.random.Generator) -> StopAndGoMotion:
    """A stop-and-go profile over `base`'s route: drives of STOP_GO_DRIVE_S between stops of STOP_GO_STOP_S, each
    drive legs at factors drawn from STOP_GO_SPEED_FACTORS; at t = 0 the target already drives its first leg's speed
    (as cruise drives its own). Drawn until the route is covered."""
    route_m, first_factor = base.stop_s_m - base.start_s_m, float(rng.uniform(*STOP_GO_SPEED_FACTORS))
    first: float | None = first_factor  # the first drive's first leg's factor; None for the later drives
    profile, stops, factors = _Profile(first_factor, base.speed_mps), [], []
    while base.is_moving:
        for factor, hold_s in _drive_legs(rng, float(rng.uniform(*STOP_GO_DRIVE_S)), profile.factors[-1], first):
            profile.ramp_to(factor)
            profile.hold(hold_s)
            factors.append(factor)
        profile.ramp_to(0.0)
        first = None
        if profile.distance_m >= route_m:
            break
        stops.append((base.delay_s + profile.times_s[-1], float(rng.uniform(*STOP_GO_STOP_S))))
        profile.hold(stops[-1][1])
    return StopAndGoMotion(base, tuple(profile.times_s), tuple(profile.factors), tuple(stops), tuple(factors))


@dataclass(frozen=True)
class TargetMotion:
    """How the target drives its route: "cruise" (the layout's constant speed, as before issue 19), "stop_and_go"
    (`draw_stop_and_go`: stops of 0.5-3 s within every 20 s of driving, speeds of 0.5-2 times the scene's) or
    "evasive" (`EvasiveMotion`: faster and swerving within the drivable area while the drone is overhead).

    Each mode drives the layout's route on the terrain as cruise does. The draws come from a child stream of the
    world's generator spawned after the decoys' (`DecoyTier`), so the rest of the world is the same in every mode and
    "cruise" spawns nothing. (The spawn moves the generator's later children: with pose_source="vio" VIO's
    velocity-error stream is another, equally distributed one.) With `world_seed` the drawn profile belongs to the
    world; otherwise to the reset seed. `camera_fov_deg` sets the evasive target's overhead radius.
    """

    mode: str = "cruise"
    camera_fov_deg: float = 110.0

    def __post_init__(self) -> None:
        if self.mode not in TARGET_MOTIONS:
            raise ValueError(f"target_motion must be one of {TARGET_MOTIONS}, got {self.mode!r}")

    def build(self, layout: SceneLayout, half_extents_m: npt.ArrayLike, rng: np.random.Generator) -> Motion:
        """The target's motion over `layout` (its decoys as built), for a target of `half_extents_m` (3,) [m]."""
        if self.mode == "cruise":
            return layout.target
        child = rng.spawn(1)[0]
        if self.mode == "stop_and_go":
            return draw_stop_and_go(layout.target, child)
        return EvasiveMotion.for_layout(layout, np.asarray(half_extents_m, dtype=np.float64), self.camera_fov_deg,
                                        child)


def motion_summary(motion: Motion) -> dict[str, Any]:
    """What a user can read of the target's motion (`info["target_motion"]` at reset): the mode and what was drawn."""
    summary = getattr(motion, "summary", None)
    return {"mode": "cruise"} if summary is None else summary()
