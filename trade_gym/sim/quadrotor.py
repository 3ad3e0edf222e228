"""Quadrotor airframe in pybullet and its cascaded (position ->) velocity -> attitude controller.

Owns the rigid body (a box with mass and inertia), the setpoint limits and the ground-truth DroneState.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.validation import is_finite_number, is_positive_number, require

FloatArray = npt.NDArray[np.float64]
_Vec3 = tuple[float, float, float]
# pybullet's state as read: position (3,), velocity (3,), row-major R_world_body (9,), body rates (3,)
# (`_query_reading`); and position, velocity, angular velocity, R_world_body, body rates, specific force (`_sample`)
_Read = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], _Vec3]
_Reading = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, ...], _Vec3, _Vec3]

_BODY_LINK = -1  # pybullet link index of a multibody's base
_ORIGIN = (0.0, 0.0, 0.0)  # thrust acts at the centre of mass
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

    Per physics step: `physics_step(dt_s)`, then `p.stepSimulation`, then `read_state()`.
    `physics_step` reuses the reading of a `read_state()` made since the last step, and readings between two
    steps reuse the first (each pybullet state query copies ~30 kB: two per reading), so move the airframe
    only through `spawn()`, never between those calls.
    Gravity is read from the engine at `spawn()`; the controller compensates it exactly.
    """

    def __init__(self, client_id: int, config: QuadrotorConfig | None = None) -> None:
        self.client_id = int(client_id)
        self.config = config if config is not None else QuadrotorConfig()
        cfg = self.config
        self._tan_tilt = math.tan(math.radians(cfg.max_tilt_deg - cfg.tilt_margin_deg))
        self._k_att = cfg.attitude_natural_freq_radps**2  # kR = w^2
        self._k_rate = 2.0 * cfg.attitude_damping_ratio * cfg.attitude_natural_freq_radps  # kw = 2 zeta w
        self.body_id: int | None = None
        self._reset_internal(0.0)

    def _reset_internal(self, yaw_rad: float) -> None:
        self._setpoint = (0.0, 0.0, 0.0, 0.0)  # forward, left, up [m/s], yaw rate [rad/s]
        self._position_sp: tuple[float, float, float, float] | None = None  # x, y, z [m] world, yaw [rad]
        self._yaw_sp = float(yaw_rad)
        self._t_s = 0.0
        self._dt_s = 0.0
        self._v_pre: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._m_pre: tuple[float, ...] | None = None  # row-major R_world_body before the last step
        self._gravity_z = 0.0
        self._last_read: _Read | None = None  # (v, R, body rates) of read_state()
        self._reading: _Reading | None = None  # `_sample()` since the last step

    def spawn(self, position_m: npt.ArrayLike, yaw_rad: float) -> int:
        """Create the airframe at `position_m` (3,) world [m], level, heading `yaw_rad`; returns its id."""
        c, cfg = self.client_id, self.config
        pos = [float(v) for v in np.asarray(position_m, dtype=np.float64).reshape(3)]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=cfg.half_extents_m, physicsClientId=c)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=cfg.half_extents_m, rgbaColor=_AIRFRAME_RGBA,
                                  physicsClientId=c)
        quat = p.getQuaternionFromEuler((0.0, 0.0, float(yaw_rad)), physicsClientId=c)
        body = p.createMultiBody(cfg.mass_kg, col, vis, pos, quat, physicsClientId=c)
        p.changeDynamics(body, _BODY_LINK, linearDamping=0.0, angularDamping=0.0,
                         localInertiaDiagonal=cfg.inertia_kgm2,
                         activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=c)
        self.body_id = body
        self._reset_internal(yaw_rad)
        self._gravity_z = float(p.getPhysicsEngineParameters(physicsClientId=c)["gravityAccelerationZ"])
        return body

    def set_setpoint(self, velocity_heading_mps: npt.ArrayLike, yaw_rate_radps: float) -> None:
        """velocity_heading_mps: (3,) forward, left, up in the yaw-only heading frame [m/s]; clipped. Ends any
        position setpoint."""
        fwd, left, up = (float(v) for v in np.asarray(velocity_heading_mps, dtype=np.float64).reshape(3))
        rate = float(yaw_rate_radps)
        if not all(math.isfinite(v) for v in (fwd, left, up, rate)):
            raise ValueError(f"setpoint must be finite, got velocity {(fwd, left, up)!r}, yaw rate {rate!r}")
        self._position_sp = None
        self._set_clipped(fwd, left, up, rate)

    def set_position_setpoint(self, position_m: npt.ArrayLike, yaw_rad: float) -> None:
        """Hold `position_m` (3,) world [m] and heading `yaw_rad` [rad] (PX4's offboard position setpoint) until the
        next setpoint: each physics step sets the velocity setpoint k_p (p_sp - p) (heading frame) and the yaw rate
        k_yaw wrap(yaw_sp - yaw), clipped to the setpoint limits (`QuadrotorConfig`)."""
        x, y, z = (float(v) for v in np.asarray(position_m, dtype=np.float64).reshape(3))
        yaw = float(yaw_rad)
        if not all(math.isfinite(v) for v in (x, y, z, yaw)):
            raise ValueError(f"position setpoint must be finite, got position {(x, y, z)!r}, yaw {yaw!r}")
        self._position_sp = (x, y, z, yaw)

    def _hold_position(self, position_sp: tuple[float, float, float, float], pos: tuple[float, ...],
                       yaw: float) -> None:
        """The velocity and yaw-rate setpoints of the position controller holding `position_sp` (x, y, z [m], yaw
        [rad]) at position `pos` (3,) and heading `yaw`."""
        cfg = self.config
        x, y, z, yaw_sp = position_sp
        kh = cfg.position_gain_horizontal_per_s
        vx, vy = kh * (x - pos[0]), kh * (y - pos[1])  # world [m/s]
        cy, sy = math.cos(yaw), math.sin(yaw)
        # heading frame = Rz(yaw)^T world; the velocity controller rotates it back with the same yaw
        self._set_clipped(cy * vx + sy * vy, -sy * vx + cy * vy, cfg.position_gain_vertical_per_s * (z - pos[2]),
                          cfg.yaw_gain_per_s * _wrap(yaw_sp - yaw))

    def _set_clipped(self, fwd: float, left: float, up: float, rate: float) -> None:
        """The velocity (heading frame) [m/s] and yaw-rate [rad/s] setpoint, clipped to the setpoint limits."""
        cfg = self.config
        horizontal = math.hypot(fwd, left)
        if horizontal > cfg.max_speed_horizontal_mps:  # clip the horizontal norm, keep the direction
            scale = cfg.max_speed_horizontal_mps / horizontal
            fwd, left = fwd * scale, left * scale
        up = min(max(up, -cfg.max_speed_vertical_mps), cfg.max_speed_vertical_mps)
        rate = min(max(rate, -cfg.max_yaw_rate_radps), cfg.max_yaw_rate_radps)
        self._setpoint = (fwd, left, up, rate)

    def physics_step(self, dt_s: float) -> None:
        """Compute and apply thrust and torques (body frame) for the next physics step of `dt_s` [s]."""
        if self.body_id is None:
            raise RuntimeError("Quadrotor.physics_step called before spawn()")
        c, b, cfg = self.client_id, self.body_id, self.config
        # the reading of a read_state() since the last step (same pybullet state), else a fresh one
        pos, vel, m, w_body = self._last_read or self._query_reading()
        self._last_read = None
        yaw = math.atan2(m[3], m[0])
        if self._position_sp is not None:  # waypoint mode only: velocity mode pays no call per physics step
            self._hold_position(self._position_sp, pos, yaw)
        f = self._desired_specific_thrust(yaw, vel)
        rate_sp = self._setpoint[3]
        self._advance_yaw_setpoint(yaw, rate_sp, dt_s)
        torque = self._attitude_torque(m, w_body, f, rate_sp)
        # collective thrust T = m f_z / z_b,z realises the vertical acceleration whatever the attitude lag
        weight = -cfg.mass_kg * self._gravity_z
        thrust = cfg.mass_kg * f[2] / max(m[8], _MIN_UPRIGHTNESS)
        thrust = min(max(thrust, 0.0), cfg.max_thrust_to_weight * weight)
        p.applyExternalForce(b, _BODY_LINK, (0.0, 0.0, thrust), _ORIGIN, p.LINK_FRAME, physicsClientId=c)
        p.applyExternalTorque(b, _BODY_LINK, torque, p.LINK_FRAME, physicsClientId=c)
        self._v_pre, self._m_pre, self._dt_s = vel, m, float(dt_s)
        self._reading = None  # the caller steps the simulation next
        self._t_s += float(dt_s)

    def _query_reading(self) -> _Read:
        """(position (3,) world [m], velocity (3,) world [m/s], row-major R_world_body (9,), body rates (3,) [rad/s])
        from pybullet."""
        c, b = self.client_id, self.body_id
        pos, quat = p.getBasePositionAndOrientation(b, physicsClientId=c)
        vel, omega_w = p.getBaseVelocity(b, physicsClientId=c)
        m = p.getMatrixFromQuaternion(quat, physicsClientId=c)  # row-major R_world_body
        return pos, vel, m, _body_rates(m, omega_w)

    def _advance_yaw_setpoint(self, yaw: float, rate_sp: float, dt_s: float) -> None:
        """Yaw setpoint psi_d += r dt [rad], kept within max_yaw_lead of the current `yaw`."""
        lead = _wrap(self._yaw_sp + rate_sp * dt_s - yaw)
        lead = min(max(lead, -self.config.max_yaw_lead_rad), self.config.max_yaw_lead_rad)
        self._yaw_sp = yaw + lead

    def _attitude_torque(self, m: tuple[float, ...], w_body: tuple[float, float, float],
                         f: tuple[float, float, float], rate_sp: float) -> tuple[float, float, float]:
        """Body torque [N m] steering body z to the thrust direction `f` (3,) world and body x to the yaw
        setpoint (geometric SO(3) PD law); m: row-major R_world_body (9,), w_body (3,) [rad/s]."""
        fx, fy, fz = f
        fn = math.sqrt(fx * fx + fy * fy + fz * fz)
        zdx, zdy, zdz = fx / fn, fy / fn, fz / fn  # desired body z
        cy, sy = math.cos(self._yaw_sp), math.sin(self._yaw_sp)
        # y_d = z_d x x_c / |.| with x_c = (cos psi_d, sin psi_d, 0); x_d = y_d x z_d
        ydx, ydy, ydz = -zdz * sy, zdz * cy, zdx * sy - zdy * cy
        yn = math.sqrt(ydx * ydx + ydy * ydy + ydz * ydz)
        ydx, ydy, ydz = ydx / yn, ydy / yn, ydz / yn
        xdx, xdy, xdz = ydy * zdz - ydz * zdy, ydz * zdx - ydx * zdz, ydx * zdy - ydy * zdx
        # body axes: the columns of R; x_b = (m0, m3, m6), y_b = (m1, m4, m7), z_b = (m2, m5, m8)
        m0, m1, m2, m3, m4, m5, m6, m7, m8 = m
        # e_R = 1/2 vee(Rd^T R - R^T Rd); (Rd^T R)_ij = col_i(Rd) . col_j(R)
        ex = 0.5 * ((zdx * m1 + zdy * m4 + zdz * m7) - (ydx * m2 + ydy * m5 + ydz * m8))
        ey = 0.5 * ((xdx * m2 + xdy * m5 + xdz * m8) - (zdx * m0 + zdy * m3 + zdz * m6))
        ez = 0.5 * ((ydx * m0 + ydy * m3 + ydz * m6) - (xdx * m1 + xdy * m4 + xdz * m7))
        # yawing at r with z_d fixed turns R_d about z_d at W = r (e_z . z_d) / (1 - (x_c . z_d)^2);
        # desired body rate w_d = W R^T z_d
        xc_dot_zd = cy * zdx + sy * zdy
        spin = rate_sp * zdz / (1.0 - xc_dot_zd * xc_dot_zd)
        wx, wy, wz = w_body
        ewx = wx - spin * (m0 * zdx + m3 * zdy + m6 * zdz)
        ewy = wy - spin * (m1 * zdx + m4 * zdy + m7 * zdz)
        ewz = wz - spin * (m2 * zdx + m5 * zdy + m8 * zdz)
        jx, jy, jz = self.config.inertia_kgm2
        ka, kr = self._k_att, self._k_rate
        # tau = J (-kR e_R - kw e_w) + w x J w
        return (
            jx * (-ka * ex - kr * ewx) + (jz - jy) * wy * wz,
            jy * (-ka * ey - kr * ewy) + (jx - jz) * wz * wx,
            jz * (-ka * ez - kr * ewz) + (jy - jx) * wx * wy,
        )

    def fly(self, n_steps: int, dt_s: float, t_s: float,
            imu_truth: Callable[[float, tuple[float, ...], tuple[float, ...]], None]) -> float:
        """Run `n_steps` physics steps of `dt_s` [s] from time `t_s` [s]: controller, pybullet step, then
        `imu_truth(t, specific force (3,) body [m/s^2], rate (3,) body [rad/s])` after each; returns the
        new time. Equivalent to the documented per-step sequence, in one call for the env's hot loop."""
        c = self.client_id
        for _ in range(n_steps):
            self.physics_step(dt_s)
            p.stepSimulation(physicsClientId=c)
            t_s += dt_s
            sample = self._sample()
            imu_truth(t_s, sample[5], sample[4])
        return t_s

    def _desired_specific_thrust(self, yaw: float, vel: tuple[float, ...]) -> tuple[float, float, float]:
        """Thrust per mass (3,) world [m/s^2]: f = clip(a_d) - g with tilt and thrust limits."""
        cfg = self.config
        fwd, left, up, _ = self._setpoint
        cy, sy = math.cos(yaw), math.sin(yaw)
        # v_sp world = Rz(yaw) (fwd, left, up); a_d = K (v_sp - v), |a_d,xy| <= a_max, |a_d,z| <= a_max
        kh, kv = cfg.velocity_gain_horizontal_per_s, cfg.velocity_gain_vertical_per_s
        a_max = cfg.max_accel_mps2
        ax = kh * (cy * fwd - sy * left - vel[0])
        ay = kh * (sy * fwd + cy * left - vel[1])
        az = min(max(kv * (up - vel[2]), -a_max), a_max)
        an = math.hypot(ax, ay)
        if an > a_max:
            s = a_max / an
            ax, ay = ax * s, ay * s
        g = -self._gravity_z
        fz = max(az + g, cfg.min_thrust_to_weight * g)
        horizontal = math.hypot(ax, ay)
        h_max = fz * self._tan_tilt  # tilt limit: |f_xy| <= f_z tan(max_tilt)
        if horizontal > h_max:
            s = h_max / horizontal
            ax, ay = ax * s, ay * s
        return ax, ay, fz

    def _sample(self) -> _Reading:
        """Raw state after the last step: position, velocity, angular velocity (world), row-major
        R_world_body, body rates R^T w and specific force R_pre^T ((v - v_pre)/dt - g)."""
        if self.body_id is None:
            raise RuntimeError("Quadrotor state read before spawn()")
        if self._reading is not None:  # no step since: the same state
            pos, vel, w, m, w_body, f_body = self._reading
            self._last_read = (pos, vel, m, w_body)
            return self._reading
        c, b = self.client_id, self.body_id
        pos, quat = p.getBasePositionAndOrientation(b, physicsClientId=c)
        vel, w = p.getBaseVelocity(b, physicsClientId=c)
        m = p.getMatrixFromQuaternion(quat, physicsClientId=c)  # row-major R_world_body
        w_body = _body_rates(m, w)
        self._last_read = (pos, vel, m, w_body)
        if self._m_pre is None:  # nothing stepped yet: at rest
            ax = ay = az = 0.0
            mp = m
        else:  # a = (v - v_pre) / dt, exact for the semi-implicit Euler step
            inv_dt, v0 = 1.0 / self._dt_s, self._v_pre
            ax, ay, az = (vel[0] - v0[0]) * inv_dt, (vel[1] - v0[1]) * inv_dt, (vel[2] - v0[2]) * inv_dt
            mp = self._m_pre
        az -= self._gravity_z  # f = a - g
        f_body = (mp[0] * ax + mp[3] * ay + mp[6] * az, mp[1] * ax + mp[4] * ay + mp[7] * az,
                  mp[2] * ax + mp[5] * ay + mp[8] * az)
        self._reading = (pos, vel, w, m, w_body, f_body)
        return self._reading

    def read_imu_truth(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(specific force (3,) body [m/s^2], angular rate (3,) body [rad/s]) after the last step:
        the cheap read for physics sub-steps where only the IMU needs the state."""
        _, _, _, _, w_body, f_body = self._sample()
        return f_body, w_body

    def read_state(self) -> DroneState:
        """Ground truth after the last step; specific force R_pre^T ((v - v_pre)/dt - g)."""
        pos, vel, _, m, w_body, f_body = self._sample()
        # one array: position (3), R (9), velocity (3), body rates (3), specific force (3)
        flat = np.array((*pos, *m, *vel, *w_body, *f_body))
        return DroneState(
            position_m=flat[0:3],
            R_world_body=flat[3:12].reshape(3, 3),
            velocity_mps=flat[12:15],
            angular_velocity_body_radps=flat[15:18],
            yaw_rad=math.atan2(m[3], m[0]),
            specific_force_body_mps2=flat[18:21],
            t_s=self._t_s,
        )

    def collided(self, static_body_ids: Iterable[int] | None = None) -> bool:
        """True if the airframe touches any of `static_body_ids` (any body when None) after the last step."""
        if self.body_id is None:
            return False
        contacts = p.getContactPoints(bodyA=self.body_id, physicsClientId=self.client_id)
        if static_body_ids is None:
            return len(contacts) > 0
        ids = static_body_ids if isinstance(static_body_ids, (set, frozenset)) else set(static_body_ids)
        return any(contact[2] in ids for contact in contacts)


def _body_rates(m: tuple[float, ...], w_world: tuple[float, ...]) -> tuple[float, float, float]:
    """Body rates w_b = R^T w_world [rad/s] from row-major R_world_body (9,) and world rates (3,)."""
    return (m[0] * w_world[0] + m[3] * w_world[1] + m[6] * w_world[2],
            m[1] * w_world[0] + m[4] * w_world[1] + m[7] * w_world[2],
            m[2] * w_world[0] + m[5] * w_world[1] + m[8] * w_world[2])


def _wrap(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi
