"""Quadrotor airframe: its cascaded (position ->) velocity -> attitude controller and rigid-body flight (compiled in
`flight_kernel`), and its box in pybullet for contact queries, rays and renders.

Owns the airframe's configuration (mass, inertia, setpoint limits, gains) and the ground-truth DroneState.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.validation import is_finite_number, is_positive_number, require
from trade_gym.sim import flight_kernel as fk

FloatArray = npt.NDArray[np.float64]
_AIRFRAME_RGBA = (0.15, 0.15, 0.15, 1.0)
_RIGHT_ANGLE_DEG = 90.0
_MIN_UPRIGHTNESS = 0.5  # floor on world z of body z when dividing by it (tilt is limited far below 60 deg)
# velocity gain / position gain of a critically damped position -> velocity cascade (k_v^2 = 4 k_v k_p)
_CRITICAL_CASCADE_GAIN_RATIO = 4.0
_POSITIVE_FIELDS = (
    "mass_kg", "max_speed_horizontal_mps", "max_speed_vertical_mps", "max_accel_mps2", "max_yaw_rate_radps",
    "velocity_gain_horizontal_per_s", "velocity_gain_vertical_per_s", "attitude_natural_freq_radps",
    "attitude_damping_ratio", "max_yaw_lead_rad", "position_gain_horizontal_per_s", "position_gain_vertical_per_s",
    "yaw_gain_per_s",
)


@dataclass(frozen=True)
class QuadrotorConfig:
    """Airframe, setpoint limits and controller gains; SI units.

    Gains: velocity error -> acceleration by `velocity_gain_*_per_s` (first-order time constant
    1/gain); attitude tracked by a PD law with natural frequency `attitude_natural_freq_radps`
    and damping ratio `attitude_damping_ratio` (kR = w^2, kw = 2 zeta w, scaled by the inertia).
    With a position setpoint (`Quadrotor.set_position_setpoint`, as PX4 offboard holds one), position error ->
    velocity setpoint by `position_gain_*_per_s` and heading error -> yaw-rate setpoint by `yaw_gain_per_s`, both
    clipped to the setpoint limits. The position gains default to a quarter of the velocity gains: the cascade
    e'' + k_v e' + k_v k_p e = 0 is then critically damped (k_v^2 = 4 k_v k_p), so a step does not overshoot.
    """

    mass_kg: float = 1.5
    inertia_kgm2: tuple[float, float, float] = (0.029, 0.029, 0.055)  # principal, body x/y/z
    half_extents_m: tuple[float, float, float] = (0.25, 0.25, 0.06)
    max_speed_horizontal_mps: float = 8.0
    max_speed_vertical_mps: float = 3.0
    max_accel_mps2: float = 4.0  # bounds the horizontal norm and the vertical part separately
    max_tilt_deg: float = 30.0
    tilt_margin_deg: float = 0.5  # commanded tilt <= max_tilt - margin, so tracking lag stays inside
    max_yaw_rate_radps: float = 1.5
    max_thrust_to_weight: float = 2.5
    min_thrust_to_weight: float = 0.2
    velocity_gain_horizontal_per_s: float = 2.0
    velocity_gain_vertical_per_s: float = 3.0
    attitude_natural_freq_radps: float = 25.0
    attitude_damping_ratio: float = 1.0  # critically damped: no tilt overshoot
    max_yaw_lead_rad: float = 0.5  # yaw setpoint may run at most this far ahead of the yaw
    position_gain_horizontal_per_s: float = velocity_gain_horizontal_per_s / _CRITICAL_CASCADE_GAIN_RATIO
    position_gain_vertical_per_s: float = velocity_gain_vertical_per_s / _CRITICAL_CASCADE_GAIN_RATIO
    yaw_gain_per_s: float = 2.0  # heading error -> yaw rate; well below the attitude loop's 25 rad/s

    def __post_init__(self) -> None:
        c = "QuadrotorConfig"
        for name in ("inertia_kgm2", "half_extents_m"):
            value = getattr(self, name)
            require(isinstance(value, (tuple, list)) and len(value) == 3 and all(map(is_positive_number, value)),
                    f"{c}.{name}", value, "three finite numbers > 0")
            object.__setattr__(self, name, tuple(value))  # a list from a mapping (JSON) becomes the tuple
        for name in _POSITIVE_FIELDS:
            require(is_positive_number(getattr(self, name)), f"{c}.{name}", getattr(self, name), "a finite number > 0")
        require(is_positive_number(self.max_tilt_deg) and self.max_tilt_deg < _RIGHT_ANGLE_DEG, f"{c}.max_tilt_deg",
                self.max_tilt_deg, "in (0, 90)")
        require(is_finite_number(self.tilt_margin_deg) and 0.0 <= self.tilt_margin_deg < self.max_tilt_deg,
                f"{c}.tilt_margin_deg", self.tilt_margin_deg, "in [0, max_tilt_deg)")
        require(is_positive_number(self.min_thrust_to_weight) and self.min_thrust_to_weight < 1.0,
                f"{c}.min_thrust_to_weight", self.min_thrust_to_weight, "in (0, 1)")
        require(is_finite_number(self.max_thrust_to_weight) and self.max_thrust_to_weight > 1.0,
                f"{c}.max_thrust_to_weight", self.max_thrust_to_weight, "> 1")


@dataclass(frozen=True)
class DroneState:
    """Ground truth after a physics step.

    position_m: (3,) world; R_world_body: (3, 3); velocity_mps: (3,) world;
    angular_velocity_body_radps: (3,) body; yaw_rad: heading of body x in world;
    specific_force_body_mps2: (3,) body, R^T (a - g) (+9.81 on z when hovering); t_s: time since spawn.
    """

    position_m: FloatArray
    R_world_body: FloatArray
    velocity_mps: FloatArray
    angular_velocity_body_radps: FloatArray
    yaw_rad: float
    specific_force_body_mps2: FloatArray
    t_s: float


class Quadrotor:
    """A box-shaped quadrotor flown by velocity (heading frame) and yaw-rate setpoints, or by a position and heading
    setpoint (world frame) that its position controller turns into those at every physics step.

    The controller and the rigid-body dynamics run in `flight_kernel.fly` (compiled), `fly(n_steps, ...)` a frame
    at a time; the pybullet body is a kinematic copy of the airframe, posed after each `fly` for contact queries
    (`collided`), rays and renders. Gravity is read from the engine at `spawn()`; the controller compensates it
    exactly.
    """

    def __init__(self, client_id: int, config: QuadrotorConfig | None = None) -> None:
        self.client_id = int(client_id)
        self.config = config if config is not None else QuadrotorConfig()
        self.body_id: int | None = None
        self._params = np.zeros(fk.N_PARAMS)
        self._state = np.zeros(fk.N_STATE)
        self._command = np.zeros(fk.N_COMMAND)
        self._truth = np.zeros((0, fk.N_TRUTH))

    def _fill_params(self, gravity_z: float) -> None:
        cfg, prm = self.config, self._params
        prm[fk.MASS], prm[fk.GRAVITY_Z] = cfg.mass_kg, gravity_z
        prm[fk.JX], prm[fk.JY], prm[fk.JZ] = cfg.inertia_kgm2
        prm[fk.K_VEL_H], prm[fk.K_VEL_V] = cfg.velocity_gain_horizontal_per_s, cfg.velocity_gain_vertical_per_s
        prm[fk.A_MAX], prm[fk.MAX_YAW_LEAD] = cfg.max_accel_mps2, cfg.max_yaw_lead_rad
        prm[fk.TAN_TILT] = math.tan(math.radians(cfg.max_tilt_deg - cfg.tilt_margin_deg))
        prm[fk.MIN_T2W], prm[fk.MAX_T2W] = cfg.min_thrust_to_weight, cfg.max_thrust_to_weight
        prm[fk.K_ATT] = cfg.attitude_natural_freq_radps**2  # kR = w^2
        prm[fk.K_RATE] = 2.0 * cfg.attitude_damping_ratio * cfg.attitude_natural_freq_radps  # kw = 2 zeta w
        prm[fk.K_POS_H], prm[fk.K_POS_V] = cfg.position_gain_horizontal_per_s, cfg.position_gain_vertical_per_s
        prm[fk.K_YAW], prm[fk.MAX_YAW_RATE] = cfg.yaw_gain_per_s, cfg.max_yaw_rate_radps
        prm[fk.V_MAX_H], prm[fk.V_MAX_V] = cfg.max_speed_horizontal_mps, cfg.max_speed_vertical_mps
        prm[fk.MIN_UPRIGHTNESS] = _MIN_UPRIGHTNESS

    def spawn(self, position_m: npt.ArrayLike, yaw_rad: float) -> int:
        """Create the airframe at `position_m` (3,) world [m], level and at rest, heading `yaw_rad`; returns its id."""
        c, cfg = self.client_id, self.config
        pos = [float(v) for v in np.asarray(position_m, dtype=np.float64).reshape(3)]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=cfg.half_extents_m, physicsClientId=c)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=cfg.half_extents_m, rgbaColor=_AIRFRAME_RGBA,
                                  physicsClientId=c)
        quat = p.getQuaternionFromEuler((0.0, 0.0, float(yaw_rad)), physicsClientId=c)
        # mass 0 in maximal coordinates: a kinematic body stepSimulation leaves where `fly` puts it
        self.body_id = p.createMultiBody(0.0, col, vis, pos, quat, useMaximalCoordinates=True, physicsClientId=c)
        self._fill_params(float(p.getPhysicsEngineParameters(physicsClientId=c)["gravityAccelerationZ"]))
        state = self._state
        state[:] = 0.0
        state[fk.POS:fk.POS + 3] = pos
        state[fk.QUAT:fk.QUAT + 4] = quat
        state[fk.YAW_SP] = float(yaw_rad)
        state[fk.THRUST] = -cfg.mass_kg * self._params[fk.GRAVITY_Z]  # at rest: the IMU senses gravity
        self._command[:] = (fk.VELOCITY_MODE, 0.0, 0.0, 0.0, 0.0)
        return self.body_id

    def set_setpoint(self, velocity_heading_mps: npt.ArrayLike, yaw_rate_radps: float) -> None:
        """velocity_heading_mps: (3,) forward, left, up in the yaw-only heading frame [m/s], with the yaw rate
        [rad/s]; clipped to the setpoint limits (`QuadrotorConfig`). Ends any position setpoint."""
        fwd, left, up = (float(v) for v in np.asarray(velocity_heading_mps, dtype=np.float64).reshape(3))
        rate = float(yaw_rate_radps)
        if not all(math.isfinite(v) for v in (fwd, left, up, rate)):
            raise ValueError(f"setpoint must be finite, got velocity {(fwd, left, up)!r}, yaw rate {rate!r}")
        self._command[:] = (fk.VELOCITY_MODE, fwd, left, up, rate)

    def set_position_setpoint(self, position_m: npt.ArrayLike, yaw_rad: float) -> None:
        """Hold `position_m` (3,) world [m] and heading `yaw_rad` [rad] (PX4's offboard position setpoint) until the
        next setpoint: each physics step sets the velocity setpoint k_p (p_sp - p) (heading frame) and the yaw rate
        k_yaw wrap(yaw_sp - yaw), clipped to the setpoint limits (`QuadrotorConfig`)."""
        x, y, z = (float(v) for v in np.asarray(position_m, dtype=np.float64).reshape(3))
        yaw = float(yaw_rad)
        if not all(math.isfinite(v) for v in (x, y, z, yaw)):
            raise ValueError(f"position setpoint must be finite, got position {(x, y, z)!r}, yaw {yaw!r}")
        self._command[:] = (fk.POSITION_MODE, x, y, z, yaw)

    def fly(self, n_steps: int, dt_s: float, imu_truth: Callable[[FloatArray], None] | None = None) -> float:
        """Run `n_steps` physics steps of `dt_s` [s] (controller, then rigid-body step), pose the pybullet body, and
        hand `imu_truth` the (n_steps, 7) rows of time since spawn [s], specific force (3,) body [m/s^2] and body
        rates (3,) [rad/s] after each step; returns the new time since spawn [s]."""
        if self.body_id is None:
            raise RuntimeError("Quadrotor.fly called before spawn()")
        if len(self._truth) < n_steps:
            self._truth = np.zeros((n_steps, fk.N_TRUTH))
        truth = self._truth[:n_steps]
        t_s = fk.fly(self._state, self._command, self._params, int(n_steps), float(dt_s), truth)
        s = self._state.tolist()
        p.resetBasePositionAndOrientation(self.body_id, s[fk.POS:fk.POS + 3], s[fk.QUAT:fk.QUAT + 4],
                                          physicsClientId=self.client_id)
        if imu_truth is not None:
            imu_truth(truth)
        return float(t_s)

    def read_state(self) -> DroneState:
        """Ground truth after the last step; specific force (0, 0, thrust / mass) in the body frame."""
        if self.body_id is None:
            raise RuntimeError("Quadrotor state read before spawn()")
        s = self._state
        R = np.array(fk.rotation(s)).reshape(3, 3)
        return DroneState(
            position_m=s[fk.POS:fk.POS + 3].copy(),
            R_world_body=R,
            velocity_mps=s[fk.VEL:fk.VEL + 3].copy(),
            angular_velocity_body_radps=s[fk.RATES:fk.RATES + 3].copy(),
            yaw_rad=math.atan2(R[1, 0], R[0, 0]),
            specific_force_body_mps2=np.array((0.0, 0.0, s[fk.THRUST] / self.config.mass_kg)),
            t_s=float(s[fk.TIME]),
        )

    def collided(self, static_body_ids: Iterable[int] | None = None) -> bool:
        """True if the airframe touches any of `static_body_ids` (any body when None) where `fly` left it: a contact
        query only for the bodies whose bounding boxes overlap the airframe's (none when it flies clear of them)."""
        if self.body_id is None:
            return False
        c, b = self.client_id, self.body_id
        lo, hi = p.getAABB(b, physicsClientId=c)
        near = {o[0] for o in p.getOverlappingObjects(lo, hi, physicsClientId=c) or ()} - {b}
        if static_body_ids is not None:
            near &= static_body_ids if isinstance(static_body_ids, (set, frozenset)) else set(static_body_ids)
        return any(p.getClosestPoints(b, other, 0.0, physicsClientId=c) for other in near)
