"""The compiled rigid-body step of the airframe: closed forms, and agreement with Bullet's own integration of the same
free body under the same thrust and torque."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from trade_gym.sim import flight_kernel as fk
from trade_gym.sim.quadrotor import Quadrotor, QuadrotorConfig

GRAVITY_MPS2 = 9.81
DT_S = 1.0 / 240.0
STEPS = 240
# Bullet and the kernel round differently (seen: 1e-13 m after 450 frames of flight); far below any effect
AGREEMENT_TOL = 1e-9


def _params(config: QuadrotorConfig) -> np.ndarray:
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -GRAVITY_MPS2, physicsClientId=client)
        quad = Quadrotor(client, config)
        quad.spawn([0.0, 0.0, 10.0], 0.0)
        return quad._params.copy()
    finally:
        p.disconnect(client)


def _state(position_m, quat_xyzw, rates_radps) -> np.ndarray:
    state = np.zeros(fk.N_STATE)
    state[fk.POS:fk.POS + 3] = position_m
    state[fk.QUAT:fk.QUAT + 4] = quat_xyzw
    state[fk.RATES:fk.RATES + 3] = rates_radps
    return state


def test_a_torque_free_spin_about_body_z_turns_the_heading_by_rate_times_time():
    prm = _params(QuadrotorConfig())
    state = _state((0.0, 0.0, 10.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.7))
    for _ in range(STEPS):
        fk._integrate(state, fk.rotation(state), 0.0, 0.0, 0.0, 0.0, DT_S, prm)
    R = np.array(fk.rotation(state)).reshape(3, 3)
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(0.7 * STEPS * DT_S, abs=1e-12)
    assert state[fk.RATES + 2] == 0.7 and R[2, 2] == pytest.approx(1.0, abs=1e-12)


def test_zero_thrust_falls_as_semi_implicit_euler():
    prm = _params(QuadrotorConfig())
    state = _state((1.0, 2.0, 50.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    for _ in range(STEPS):
        fk._integrate(state, fk.rotation(state), 0.0, 0.0, 0.0, 0.0, DT_S, prm)
    # v_n = -g n dt; z_n = z_0 - g dt^2 n (n + 1) / 2 (velocity first, then position with it)
    assert state[fk.VEL + 2] == pytest.approx(-GRAVITY_MPS2 * STEPS * DT_S, rel=1e-12)
    assert state[fk.POS + 2] == pytest.approx(50.0 - GRAVITY_MPS2 * DT_S**2 * STEPS * (STEPS + 1) / 2, rel=1e-12)
    assert state[fk.POS:fk.POS + 2].tolist() == [1.0, 2.0]


def test_the_step_agrees_with_bullets_integration_of_the_same_free_body():
    config = QuadrotorConfig()
    prm = _params(config)
    thrust_n, torque_nm = 1.3 * config.mass_kg * GRAVITY_MPS2, (0.004, -0.003, 0.002)
    client = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -GRAVITY_MPS2, physicsClientId=client)
        p.setTimeStep(DT_S, physicsClientId=client)
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=config.half_extents_m, physicsClientId=client)
        body = p.createMultiBody(config.mass_kg, shape, -1, [0.0, 0.0, 10.0], [0.0, 0.0, 0.0, 1.0],
                                 physicsClientId=client)
        p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, localInertiaDiagonal=config.inertia_kgm2,
                         activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=client)
        state = _state((0.0, 0.0, 10.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
        for _ in range(STEPS):
            p.applyExternalForce(body, -1, (0.0, 0.0, thrust_n), (0.0, 0.0, 0.0), p.LINK_FRAME,
                                 physicsClientId=client)
            p.applyExternalTorque(body, -1, torque_nm, p.LINK_FRAME, physicsClientId=client)
            p.stepSimulation(physicsClientId=client)
            fk._integrate(state, fk.rotation(state), thrust_n, *torque_nm, DT_S, prm)
        position, quat = p.getBasePositionAndOrientation(body, physicsClientId=client)
        velocity, _ = p.getBaseVelocity(body, physicsClientId=client)
    finally:
        p.disconnect(client)
    np.testing.assert_allclose(state[fk.POS:fk.POS + 3], position, atol=AGREEMENT_TOL)
    np.testing.assert_allclose(state[fk.VEL:fk.VEL + 3], velocity, atol=AGREEMENT_TOL)
    np.testing.assert_allclose(state[fk.QUAT:fk.QUAT + 4], quat, atol=AGREEMENT_TOL)
    assert np.linalg.norm(state[fk.POS:fk.POS + 2]) > 0.05  # the torque tilted it: the test covers rotation


def test_fly_writes_one_truth_row_per_step_with_the_thrust_on_body_z():
    prm = _params(QuadrotorConfig())
    state = _state((0.0, 0.0, 10.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
    command = np.array((fk.VELOCITY_MODE, 2.0, 0.0, 0.0, 0.0))
    truth = np.zeros((8, fk.N_TRUTH))
    state[fk.TIME] = 1.0
    t_s = fk.fly(state, command, prm, 8, DT_S, truth)
    assert t_s == pytest.approx(1.0 + 8 * DT_S)
    np.testing.assert_allclose(truth[:, 0], 1.0 + DT_S * np.arange(1, 9), atol=1e-12)
    assert np.all(truth[:, 1:3] == 0.0) and np.all(truth[:, 3] > 0.0)
    assert truth[-1, 3] == state[fk.THRUST] / prm[fk.MASS]
