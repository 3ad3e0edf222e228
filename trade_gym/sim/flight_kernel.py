"""The airframe's physics sub-steps, compiled: cascaded controller and rigid-body integration in one loop.

A frame of flight is `physics_steps_per_frame` sub-steps at 240 Hz, each a position/velocity -> attitude controller
and a rigid-body step. In the interpreter that loop cost a quarter of an oracle-mode env step, so it runs here as
one numba function per frame (`fly`), called by `Quadrotor.fly`. The numbers in the arrays are SI units; the
layouts are the index constants below, filled by `quadrotor.py`.

Rigid body: semi-implicit Euler as Bullet steps a free body (velocity first, then position with the new velocity);
the body rates by Euler's equation J w' = tau - w x J w; the attitude quaternion turned by the exact rotation of the
new body rates over the step (then normalised). Thrust acts along body z through the centre of mass, so the
specific force the IMU senses is (0, 0, thrust / mass) in the body frame.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]

# state (N_STATE,): position (3) world [m], velocity (3) world [m/s], quaternion x, y, z, w (R_world_body), body rates
# (3) [rad/s], the yaw setpoint [rad], the last thrust [N], the time since spawn [s]
POS, VEL, QUAT, RATES, YAW_SP, THRUST, TIME = 0, 3, 6, 10, 13, 14, 15
N_STATE = 16
# command (N_COMMAND,): MODE (VELOCITY_MODE: forward, left, up [m/s] heading frame and yaw rate [rad/s];
# POSITION_MODE: x, y, z [m] world and yaw [rad]) then those four numbers
MODE, SETPOINT = 0, 1
VELOCITY_MODE, POSITION_MODE = 0.0, 1.0
N_COMMAND = 5
# params (N_PARAMS,)
(MASS, JX, JY, JZ, GRAVITY_Z, K_VEL_H, K_VEL_V, A_MAX, TAN_TILT, MIN_T2W, MAX_T2W, K_ATT, K_RATE, MAX_YAW_LEAD,
 K_POS_H, K_POS_V, K_YAW, V_MAX_H, V_MAX_V, MAX_YAW_RATE, MIN_UPRIGHTNESS) = range(21)
N_PARAMS = 21
# one row per sub-step of `fly`'s output: time [s], specific force (3) body [m/s^2], body rates (3) [rad/s]
N_TRUTH = 7


@njit(cache=True)
def _wrap(angle_rad):
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _clip_setpoint(fwd, left, up, rate, prm):
    """The velocity (heading frame) and yaw-rate setpoint clipped to the setpoint limits (horizontal by norm)."""
    horizontal = math.hypot(fwd, left)
    if horizontal > prm[V_MAX_H]:
        scale = prm[V_MAX_H] / horizontal
        fwd, left = fwd * scale, left * scale
    up = min(max(up, -prm[V_MAX_V]), prm[V_MAX_V])
    rate = min(max(rate, -prm[MAX_YAW_RATE]), prm[MAX_YAW_RATE])
    return fwd, left, up, rate


@njit(cache=True)
def _velocity_setpoint(command, state, yaw, prm):
    """(forward, left, up [m/s], yaw rate [rad/s]) this sub-step: the command, or in position mode the position
    controller's k_p (p_sp - p) (heading frame) and k_yaw wrap(yaw_sp - yaw); clipped to the limits."""
    a, b, c, d = command[SETPOINT], command[SETPOINT + 1], command[SETPOINT + 2], command[SETPOINT + 3]
    if command[MODE] == POSITION_MODE:
        vx, vy = prm[K_POS_H] * (a - state[POS]), prm[K_POS_H] * (b - state[POS + 1])  # world [m/s]
        cy, sy = math.cos(yaw), math.sin(yaw)
        a, b = cy * vx + sy * vy, -sy * vx + cy * vy  # heading frame = Rz(yaw)^T world
        c, d = prm[K_POS_V] * (c - state[POS + 2]), prm[K_YAW] * _wrap(d - yaw)
    return _clip_setpoint(a, b, c, d, prm)


@njit(cache=True)
def _specific_thrust(fwd, left, up, yaw, state, prm):
    """Thrust per mass (3,) world [m/s^2]: f = clip(K (v_sp - v)) - g with the tilt and thrust limits."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    a_max = prm[A_MAX]
    ax = prm[K_VEL_H] * (cy * fwd - sy * left - state[VEL])
    ay = prm[K_VEL_H] * (sy * fwd + cy * left - state[VEL + 1])
    az = min(max(prm[K_VEL_V] * (up - state[VEL + 2]), -a_max), a_max)
    an = math.hypot(ax, ay)
    if an > a_max:
        ax, ay = ax * (a_max / an), ay * (a_max / an)
    g = -prm[GRAVITY_Z]
    fz = max(az + g, prm[MIN_T2W] * g)
    horizontal = math.hypot(ax, ay)
    h_max = fz * prm[TAN_TILT]  # tilt limit: |f_xy| <= f_z tan(max_tilt)
    if horizontal > h_max:
        ax, ay = ax * (h_max / horizontal), ay * (h_max / horizontal)
    return ax, ay, fz


@njit(cache=True)
def rotation(state):
    """Row-major R_world_body (9 numbers) of the state's unit quaternion."""
    x, y, z, w = state[QUAT], state[QUAT + 1], state[QUAT + 2], state[QUAT + 3]
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


@njit(cache=True)
def _attitude_torque(m, fx, fy, fz, yaw_sp, rate_sp, state, prm):
    """Body torque [N m] steering body z to the thrust direction f and body x to the yaw setpoint (geometric SO(3)
    PD law, tau = J (-kR e_R - kw e_w) + w x J w); m: row-major R_world_body."""
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    zdx, zdy, zdz = fx / fn, fy / fn, fz / fn  # desired body z
    cy, sy = math.cos(yaw_sp), math.sin(yaw_sp)
    ydx, ydy, ydz = -zdz * sy, zdz * cy, zdx * sy - zdy * cy  # y_d = z_d x x_c / |.|, x_c = (cos, sin, 0)
    yn = math.sqrt(ydx * ydx + ydy * ydy + ydz * ydz)
    ydx, ydy, ydz = ydx / yn, ydy / yn, ydz / yn
    xdx, xdy, xdz = ydy * zdz - ydz * zdy, ydz * zdx - ydx * zdz, ydx * zdy - ydy * zdx
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = m  # body axes are R's columns
    # e_R = 1/2 vee(Rd^T R - R^T Rd); (Rd^T R)_ij = col_i(Rd) . col_j(R)
    ex = 0.5 * ((zdx * m1 + zdy * m4 + zdz * m7) - (ydx * m2 + ydy * m5 + ydz * m8))
    ey = 0.5 * ((xdx * m2 + xdy * m5 + xdz * m8) - (zdx * m0 + zdy * m3 + zdz * m6))
    ez = 0.5 * ((ydx * m0 + ydy * m3 + ydz * m6) - (xdx * m1 + xdy * m4 + xdz * m7))
    # yawing at r with z_d fixed turns R_d about z_d at W = r (e_z . z_d) / (1 - (x_c . z_d)^2); w_d = W R^T z_d
    xc_dot_zd = cy * zdx + sy * zdy
    spin = rate_sp * zdz / (1.0 - xc_dot_zd * xc_dot_zd)
    wx, wy, wz = state[RATES], state[RATES + 1], state[RATES + 2]
    ewx = wx - spin * (m0 * zdx + m3 * zdy + m6 * zdz)
    ewy = wy - spin * (m1 * zdx + m4 * zdy + m7 * zdz)
    ewz = wz - spin * (m2 * zdx + m5 * zdy + m8 * zdz)
    jx, jy, jz, ka, kr = prm[JX], prm[JY], prm[JZ], prm[K_ATT], prm[K_RATE]
    return (jx * (-ka * ex - kr * ewx) + (jz - jy) * wy * wz,
            jy * (-ka * ey - kr * ewy) + (jx - jz) * wz * wx,
            jz * (-ka * ez - kr * ewz) + (jy - jx) * wx * wy)


@njit(cache=True)
def _integrate(state, m, thrust, tx, ty, tz, dt, prm):
    """One semi-implicit Euler step of `dt` [s] under body thrust `thrust` [N] and body torque (tx, ty, tz) [N m]."""
    acc = thrust / prm[MASS]
    state[VEL] += m[2] * acc * dt
    state[VEL + 1] += m[5] * acc * dt
    state[VEL + 2] += (m[8] * acc + prm[GRAVITY_Z]) * dt
    for i in range(3):
        state[POS + i] += state[VEL + i] * dt
    jx, jy, jz = prm[JX], prm[JY], prm[JZ]
    wx, wy, wz = state[RATES], state[RATES + 1], state[RATES + 2]
    wx, wy, wz = (wx + (tx - (jz - jy) * wy * wz) / jx * dt, wy + (ty - (jx - jz) * wz * wx) / jy * dt,
                  wz + (tz - (jy - jx) * wx * wy) / jz * dt)
    state[RATES], state[RATES + 1], state[RATES + 2] = wx, wy, wz
    angle = math.sqrt(wx * wx + wy * wy + wz * wz) * dt  # q <- q (x) exp(w dt / 2), body-frame rates
    if angle > 0.0:
        s = math.sin(0.5 * angle) / (angle / dt)
        dx, dy, dz, dw = wx * s, wy * s, wz * s, math.cos(0.5 * angle)
        x, y, z, w = state[QUAT], state[QUAT + 1], state[QUAT + 2], state[QUAT + 3]
        x, y, z, w = (w * dx + x * dw + y * dz - z * dy, w * dy - x * dz + y * dw + z * dx,
                      w * dz + x * dy - y * dx + z * dw, w * dw - x * dx - y * dy - z * dz)
        n = math.sqrt(x * x + y * y + z * z + w * w)
        state[QUAT], state[QUAT + 1], state[QUAT + 2], state[QUAT + 3] = x / n, y / n, z / n, w / n


@njit(cache=True)
def fly(state, command, prm, n_steps, dt, truth):
    """`n_steps` sub-steps of `dt` [s]: controller, then rigid-body step; `state` (N_STATE,) is advanced in place,
    its time included, and `truth` (>= n_steps, N_TRUTH) receives each sub-step's time, specific force and body
    rates. Returns the new time [s]."""
    for k in range(n_steps):
        m = rotation(state)
        yaw = math.atan2(m[3], m[0])
        fwd, left, up, rate_sp = _velocity_setpoint(command, state, yaw, prm)
        fx, fy, fz = _specific_thrust(fwd, left, up, yaw, state, prm)
        lead = _wrap(state[YAW_SP] + rate_sp * dt - yaw)  # the yaw setpoint runs at most max_yaw_lead ahead
        state[YAW_SP] = yaw + min(max(lead, -prm[MAX_YAW_LEAD]), prm[MAX_YAW_LEAD])
        tx, ty, tz = _attitude_torque(m, fx, fy, fz, state[YAW_SP], rate_sp, state, prm)
        # collective thrust T = m f_z / z_b,z realises the vertical acceleration whatever the attitude lag
        weight = -prm[MASS] * prm[GRAVITY_Z]
        thrust = prm[MASS] * fz / max(m[8], prm[MIN_UPRIGHTNESS])
        thrust = min(max(thrust, 0.0), prm[MAX_T2W] * weight)
        _integrate(state, m, thrust, tx, ty, tz, dt, prm)
        state[THRUST] = thrust
        state[TIME] += dt
        truth[k, 0] = state[TIME]
        truth[k, 1], truth[k, 2], truth[k, 3] = 0.0, 0.0, thrust / prm[MASS]
        truth[k, 4], truth[k, 5], truth[k, 6] = state[RATES], state[RATES + 1], state[RATES + 2]
    return state[TIME]
