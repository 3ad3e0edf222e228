"""Quadrotor controller, limits, ground-truth state and IMU readings in hover (tiny pybullet world)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p
import pytest

from trade_gym.sim.imu import Imu, ImuConfig
from trade_gym.sim.quadrotor import Quadrotor, QuadrotorConfig

GRAVITY_MPS2 = 9.81
PHYSICS_DT_S = 1.0 / 240.0
STEPS_PER_FRAME = 8
SPEED_TOLERANCE_MPS = 1e-6  # "never exceeds" up to float rounding


@dataclass
class World:
    client: int
    ground_id: int
    box_id: int


def _build(cid: int) -> World:
    """Gravity, 240 Hz, a ground plane and one box far from the flight area."""
    p.setGravity(0, 0, -GRAVITY_MPS2, physicsClientId=cid)
    p.setTimeStep(PHYSICS_DT_S, physicsClientId=cid)
    ground = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), -1, [0, 0, 0],
                               physicsClientId=cid)
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1, 1, 1], physicsClientId=cid)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[1, 1, 1], rgbaColor=[1, 0, 0, 1], physicsClientId=cid)
    box = p.createMultiBody(0, col, vis, [50, 50, 1], physicsClientId=cid)
    return World(cid, ground, box)


@pytest.fixture()
def world():
    cid = p.connect(p.DIRECT)
    yield _build(cid)
    p.disconnect(physicsClientId=cid)


def _fly(quad: Quadrotor, seconds: float, imu: Imu | None = None) -> dict[str, np.ndarray]:
    """Run 240 Hz physics under the current setpoint; per-step truth, and IMU batches per 1/30 s frame."""
    log: dict[str, list] = {"v": [], "R": [], "yaw": [], "w": [], "f": [], "pos": [], "batches": []}
    for step in range(1, int(round(seconds / PHYSICS_DT_S)) + 1):
        quad.fly(1, PHYSICS_DT_S, None if imu is None else imu.add_truth_rows)
        s = quad.read_state()
        for key, value in (("v", s.velocity_mps), ("R", s.R_world_body), ("yaw", s.yaw_rad),
                           ("w", s.angular_velocity_body_radps), ("f", s.specific_force_body_mps2),
                           ("pos", s.position_m)):
            log[key].append(value)
        if imu is not None and step % STEPS_PER_FRAME == 0:
            log["batches"].append(imu.read())
    out = {k: np.array(v) for k, v in log.items() if k != "batches"}
    out["batches"] = log["batches"]
    return out


def _tilt_deg(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) attitudes -> (N,) angle between body z and world z [deg]."""
    return np.degrees(np.arccos(np.clip(R[:, 2, 2], -1.0, 1.0)))


def test_hover_zero_setpoint_imu_reads_gravity_on_body_z_and_zero_rates(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 10.0], 0.5)
    quad.set_setpoint([4.0, -1.0, 1.0], 0.8)  # stir first, then settle
    _fly(quad, 1.0)
    quad.set_setpoint([0.0, 0.0, 0.0], 0.0)
    _fly(quad, 3.0)
    start = quad.read_state()
    imu_config = ImuConfig(accel_initial_bias_sigma_mps2=0.0, gyro_initial_bias_sigma_radps=0.0)
    imu = Imu(imu_config, np.random.default_rng(0))
    imu.reset(start.t_s, np.random.default_rng(0))
    log = _fly(quad, 2.0, imu)
    counts = [len(b.t_s) for b in log["batches"]]
    assert set(counts) <= {6, 7} and sum(counts) == 400
    accel = np.concatenate([b.accel_mps2 for b in log["batches"]])
    gyro = np.concatenate([b.gyro_radps for b in log["batches"]])
    assert accel.mean(axis=0)[2] == pytest.approx(GRAVITY_MPS2, abs=0.05)
    assert np.all(np.abs(accel.mean(axis=0)[:2]) < 0.05)
    assert np.all(np.abs(gyro.mean(axis=0)) < 0.01)
    assert np.linalg.norm(log["pos"][-1] - start.position_m) < 0.05  # it really hovers


@pytest.mark.parametrize("max_tilt_deg", [30.0, 10.0])
def test_forward_setpoint_pitches_nose_down_reaches_speed_within_limits(world, max_tilt_deg):
    config = QuadrotorConfig(max_tilt_deg=max_tilt_deg)
    quad = Quadrotor(world.client, config)
    yaw = 0.7
    quad.spawn([0.0, 0.0, 20.0], yaw)
    quad.set_setpoint([20.0, 0.0, 0.0], 0.0)  # clipped to max_speed_horizontal_mps
    log = _fly(quad, 6.0)
    accelerating = slice(int(0.1 / PHYSICS_DT_S), int(1.0 / PHYSICS_DT_S))  # after the attitude transient
    assert np.all(_tilt_deg(log["R"][accelerating]) > 3.0)
    assert np.all(log["R"][accelerating, 2, 0] < -math.sin(math.radians(3.0)))  # body x below the horizon
    speed = np.linalg.norm(log["v"][:, :2], axis=1)
    assert speed[-1] == pytest.approx(config.max_speed_horizontal_mps, rel=0.1)
    heading = math.atan2(log["v"][-1, 1], log["v"][-1, 0])
    assert heading == pytest.approx(yaw, abs=0.01)  # forward = the drone's heading
    assert np.max(_tilt_deg(log["R"])) <= max_tilt_deg
    assert np.max(speed) <= config.max_speed_horizontal_mps + SPEED_TOLERANCE_MPS
    assert np.max(np.abs(log["v"][:, 2])) < 0.2


def test_extreme_setpoints_clipped_to_speed_and_yaw_rate_limits(world):
    config = QuadrotorConfig()
    quad = Quadrotor(world.client, config)
    quad.spawn([0.0, 0.0, 30.0], 0.0)
    quad.set_setpoint([30.0, 30.0, 10.0], 5.0)
    climb = _fly(quad, 4.0)
    quad.set_setpoint([-30.0, 0.0, -10.0], -5.0)
    descend = _fly(quad, 4.0)
    for log in (climb, descend):
        horizontal_speed = np.linalg.norm(log["v"][:, :2], axis=1)
        assert np.max(horizontal_speed) <= config.max_speed_horizontal_mps + SPEED_TOLERANCE_MPS
        assert np.max(np.abs(log["v"][:, 2])) <= config.max_speed_vertical_mps + SPEED_TOLERANCE_MPS
        assert np.max(_tilt_deg(log["R"])) <= config.max_tilt_deg
    assert climb["v"][-1, 2] == pytest.approx(config.max_speed_vertical_mps, rel=0.05)
    assert descend["v"][-1, 2] == pytest.approx(-config.max_speed_vertical_mps, rel=0.05)
    yaw_rate = np.diff(np.unwrap(climb["yaw"])) / PHYSICS_DT_S
    assert np.median(yaw_rate[-240:]) == pytest.approx(config.max_yaw_rate_radps, rel=0.05)


def test_yaw_rate_setpoint_followed_in_hover(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 10.0], -2.0)
    quad.set_setpoint([0.0, 0.0, 0.0], 1.0)
    log = _fly(quad, 2.0)
    settled = slice(int(0.5 / PHYSICS_DT_S), None)
    yaw_rate = np.diff(np.unwrap(log["yaw"])) / PHYSICS_DT_S
    np.testing.assert_allclose(yaw_rate[settled], 1.0, rtol=0.02)
    np.testing.assert_allclose(log["w"][settled, 2], 1.0, rtol=0.02)  # body gyro z


def test_specific_force_is_pure_body_thrust_in_free_flight(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 15.0], 0.0)
    quad.set_setpoint([5.0, 3.0, 1.0], 0.5)
    log = _fly(quad, 2.0)
    # no drag or contact: a - g is the thrust, which acts along body z only
    assert np.max(np.abs(log["f"][:, :2])) < 1e-6
    assert np.max(log["f"][:, 2]) > GRAVITY_MPS2 + 0.5  # accelerating: thrust above weight


def test_collided_true_on_ground_contact_only(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 5.0], 0.0)
    _fly(quad, 0.2)
    assert not quad.collided({world.ground_id, world.box_id})
    quad.set_setpoint([0.0, 0.0, -3.0], 0.0)
    _fly(quad, 2.5)
    assert quad.collided({world.ground_id})
    assert quad.collided([world.ground_id, world.box_id])
    assert not quad.collided({world.box_id})


def test_spawn_after_reset_simulation_rebuilds_airframe(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 10.0], 0.0)
    quad.set_setpoint([3.0, 0.0, 0.0], 0.0)
    _fly(quad, 1.0)
    p.resetSimulation(physicsClientId=world.client)
    _build(world.client)
    body = quad.spawn([5.0, -2.0, 8.0], 1.0)
    state = quad.read_state()
    assert p.getNumBodies(physicsClientId=world.client) == 3 and body >= 0
    np.testing.assert_allclose(state.position_m, [5.0, -2.0, 8.0])
    assert state.yaw_rad == pytest.approx(1.0) and state.t_s == 0.0
    np.testing.assert_allclose(state.specific_force_body_mps2, [0.0, 0.0, GRAVITY_MPS2], atol=1e-9)
    _fly(quad, 1.0)  # setpoint reset to zero by spawn: hovers in place
    np.testing.assert_allclose(quad.read_state().position_m, [5.0, -2.0, 8.0], atol=0.02)


def test_quadrotor_config_invalid_tilt_raises_naming_field():
    with pytest.raises(ValueError, match="max_tilt_deg"):
        QuadrotorConfig(max_tilt_deg=95.0)
    with pytest.raises(ValueError, match="mass_kg"):
        QuadrotorConfig(mass_kg=0.0)


# Position setpoints (PX4 offboard style): the critically damped cascade reaches a step's goal without overshoot. On
# these steps the measured overshoot along the step is 0 (the drone stops short and creeps in) and the heading's
# 0.004 rad; the bounds leave room for float drift, not for a ringing controller. While the drone tilts to
# accelerate, its heading (body x projected on the ground) swings by up to 0.040 rad (measured) and comes back.
POSITION_OVERSHOOT_BOUND_M = 0.05
YAW_OVERSHOOT_BOUND_RAD = 0.01
HEADING_SWING_BOUND_RAD = 0.05
ANGLE_ROUNDING_RAD = 1e-9  # "never exceeds" up to float rounding
GOAL_RADIUS_M = 0.3
YAW_TOLERANCE_RAD = 0.02
POSITION_STEPS = [  # world offset [m], heading change [rad], time to come within GOAL_RADIUS_M [s] (measured 3.2-7.1)
    ([5.0, 0.0, 0.0], 0.0, 6.0), ([14.0, 14.0, 0.0], 0.0, 8.0), ([3.0, 4.0, 2.0], 0.0, 6.0),
    ([0.0, 0.0, -5.0], 0.0, 4.0), ([0.0, 0.0, 0.0], 1.0, 2.0), ([-20.0, 0.0, 0.0], -math.pi / 2, 8.0),
]


@pytest.mark.parametrize("offset_m, yaw_change_rad, settle_s", POSITION_STEPS)
def test_position_setpoint_reached_and_held_without_overshoot(world, offset_m, yaw_change_rad, settle_s):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 30.0], 0.3)
    start = quad.read_state()
    goal = start.position_m + np.array(offset_m)
    quad.set_position_setpoint(goal, start.yaw_rad + yaw_change_rad)
    log = _fly(quad, settle_s + 2.0)
    error = np.linalg.norm(log["pos"] - goal, axis=1)
    settled = slice(int(settle_s / PHYSICS_DT_S), None)
    assert np.all(error[settled] < GOAL_RADIUS_M)  # reached by settle_s and held for 2 s more
    distance = np.linalg.norm(offset_m)
    if distance > 0.0:
        along = (log["pos"] - start.position_m) @ (np.array(offset_m) / distance)
        assert np.max(along) <= distance + POSITION_OVERSHOOT_BOUND_M
    turned = np.unwrap(log["yaw"]) - start.yaw_rad
    assert abs(turned[-1] - yaw_change_rad) < YAW_TOLERANCE_RAD
    if yaw_change_rad:
        assert np.max(np.sign(yaw_change_rad) * (turned - yaw_change_rad)) <= YAW_OVERSHOOT_BOUND_RAD
    else:
        assert np.max(np.abs(turned)) <= HEADING_SWING_BOUND_RAD


def test_position_controller_flies_within_the_setpoint_limits(world):
    config = QuadrotorConfig()
    quad = Quadrotor(world.client, config)
    quad.spawn([0.0, 0.0, 30.0], 0.0)
    quad.set_position_setpoint([100.0, -80.0, 80.0], math.pi)  # far: every limit binds
    log = _fly(quad, 6.0)
    assert np.max(np.linalg.norm(log["v"][:, :2], axis=1)) <= config.max_speed_horizontal_mps + SPEED_TOLERANCE_MPS
    assert np.max(np.abs(log["v"][:, 2])) <= config.max_speed_vertical_mps + SPEED_TOLERANCE_MPS
    assert np.max(_tilt_deg(log["R"])) <= config.max_tilt_deg


def test_heading_setpoint_turns_no_faster_than_the_yaw_rate_limit(world):
    config = QuadrotorConfig()
    quad = Quadrotor(world.client, config)
    quad.spawn([0.0, 0.0, 30.0], 0.0)
    quad.set_position_setpoint([0.0, 0.0, 30.0], math.pi)  # half a turn: the rate setpoint saturates
    log = _fly(quad, 4.0)
    t_s = np.arange(1, len(log["yaw"]) + 1) * PHYSICS_DT_S
    turned = np.abs(np.unwrap(log["yaw"]))  # never ahead of a turn at the limit (+ one physics step's turn)
    assert np.all(turned <= config.max_yaw_rate_radps * (t_s + PHYSICS_DT_S) + ANGLE_ROUNDING_RAD)
    assert turned[-1] == pytest.approx(math.pi, abs=YAW_TOLERANCE_RAD)


def test_velocity_setpoint_ends_a_position_setpoint(world):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 10.0], 0.0)
    quad.set_position_setpoint([10.0, 0.0, 10.0], 0.0)
    _fly(quad, 1.0)
    quad.set_setpoint([0.0, 0.0, 0.0], 0.0)
    _fly(quad, 3.0)  # settles into hover, then stays: no pull back to the old setpoint
    before = quad.read_state().position_m
    _fly(quad, 1.0)
    np.testing.assert_allclose(quad.read_state().position_m, before, atol=0.02)


@pytest.mark.parametrize("position, yaw", [([0.0, math.nan, 5.0], 0.0), ([0.0, 0.0, 5.0], math.inf)])
def test_non_finite_position_setpoint_raises_value_error(world, position, yaw):
    quad = Quadrotor(world.client, QuadrotorConfig())
    quad.spawn([0.0, 0.0, 10.0], 0.0)
    with pytest.raises(ValueError, match="position setpoint must be finite"):
        quad.set_position_setpoint(position, yaw)
