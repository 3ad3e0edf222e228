"""Target motions (issue 19): cruise as before, stop-and-go (drawn stops, speeds), evasive (reacts to the drone)."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from trade_gym.agents import ScriptedFollower
from trade_gym.config import EnvConfig
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.evasive import EVASIVE_OFFROAD_LATERAL_M, EVASIVE_SPEED_FACTOR, evasive_radius_m
from trade_gym.sim.scenes import SCENES
from trade_gym.sim.target_motion import (
    STOP_GO_RAMP_S, STOP_GO_SPEED_FACTORS, STOP_GO_STOP_S, TargetMotion, draw_stop_and_go,
)
from trade_gym.sim.world import DecoyTier, World, build_world, make_layout
from tests.trade_gym.env_checks import check_env_strict

SEED = 4
FRAME_S = 1.0 / 30.0
STOP_GO_EPISODE_S = 20.0
MIN_STOP_S = 0.5
EVERY_DRIVE_S = 20.0  # a stop in every 20 s of driving
PROFILE_SEEDS = 40
PROFILE_STEP_S = 1.0 / 240.0
OVERHEAD_FRAMES = 450  # 15 s with the drone held over the target
DRONE_ABOVE_M = 20.0
FAR_M = 1.0e4
FOOTPRINT_GRID = 5  # points per side of the target's footprint checked against obstacles
VELOCITY_TOLERANCE_MPS = 0.15  # central differences of the frame poses against the reported velocity
SPEED_UP_FRACTION = 0.9  # the speed reaches this fraction of the evasive factor within the 15 s overhead
MIN_SWERVE_M = 0.5


@pytest.fixture
def client():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def _world(client: int, scene: str, mode: str, seed: int = SEED, **kwargs) -> World:
    p.resetSimulation(physicsClientId=client)
    return build_world(client, scene, np.random.default_rng(seed), target_motion=TargetMotion(mode), **kwargs)


def _drive(world: World, frames: int, drone_at) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, 3) target centres, (F, 3, 3) rotations and (F, 3) velocities at frames 1..F; the drone is at
    drone_at(target centre at the previous frame)."""
    centres, rotations, velocities = [], [], []
    for k in range(1, frames + 1):
        previous, _ = world.vehicle_pose(world.target, (k - 1) * FRAME_S)
        world.update(k * FRAME_S, drone_at(previous))
        centre, R = world.vehicle_pose(world.target, k * FRAME_S)
        centres.append(centre)
        rotations.append(R)
        velocities.append(world.target_velocity_mps(k * FRAME_S))
    return np.array(centres), np.array(rotations), np.array(velocities)


def _overhead(target_centre: np.ndarray) -> np.ndarray:
    return target_centre + np.array([0.0, 0.0, DRONE_ABOVE_M])


def _far(_: np.ndarray) -> np.ndarray:
    return np.array([FAR_M, FAR_M, DRONE_ABOVE_M])


def _episode(mode: str, seed: int, seconds: float, scene: str = "desert", **kwargs) -> tuple[dict, list[dict]]:
    """The reset's info and every step's, a scripted follower flying (oracle perception: no rendering)."""
    env = TradeFollowEnv(scene=scene, perception="oracle", target_motion=mode, episode_duration_s=seconds, **kwargs)
    try:
        obs, reset_info = env.reset(seed=seed)
        policy, infos = ScriptedFollower(), []
        for k in range(env.config.max_episode_steps):
            action, _ = policy.predict(obs, episode_start=np.array([k == 0]))
            obs, _, terminated, truncated, info = env.step(action)
            infos.append(info)
            if terminated or truncated:
                break
        return reset_info, infos
    finally:
        env.close()


def _trajectory_bytes(infos: list[dict]) -> bytes:
    return np.array([info["target_position_m"] for info in infos]).tobytes()


@pytest.mark.parametrize("mode", ["stop_and_go", "evasive"])
def test_same_reset_seed_same_target_motion_and_other_seed_another(mode):
    first, second, other = (_episode(mode, seed, 8.0) for seed in (SEED, SEED, SEED + 1))
    assert first[0]["target_motion"] == second[0]["target_motion"]
    assert _trajectory_bytes(first[1]) == _trajectory_bytes(second[1])
    assert _trajectory_bytes(first[1]) != _trajectory_bytes(other[1])
    cruise = _episode("cruise", SEED, 8.0)
    assert _trajectory_bytes(first[1]) != _trajectory_bytes(cruise[1])
    if mode == "stop_and_go":
        assert first[0]["target_motion"] != other[0]["target_motion"]


@pytest.mark.parametrize("scene", SCENES)
def test_stop_and_go_target_stands_still_at_least_half_a_second_within_20_s(scene):
    reset_info, infos = _episode("stop_and_go", SEED, STOP_GO_EPISODE_S, scene=scene)
    positions = np.array([info["target_position_m"] for info in infos])
    still = np.all(positions[1:] == positions[:-1], axis=1)  # frame to frame, exactly
    longest, run = 0, 0
    for s in still:
        run = run + 1 if s else 0
        longest = max(longest, run)
    assert longest * FRAME_S >= MIN_STOP_S - 1e-9
    summary = reset_info["target_motion"]
    assert summary["mode"] == "stop_and_go" and summary["stops_s"]
    assert all(STOP_GO_SPEED_FACTORS[0] <= f <= STOP_GO_SPEED_FACTORS[1] for f in summary["speed_factors"])
    assert all(STOP_GO_STOP_S[0] <= d <= STOP_GO_STOP_S[1] for _, d in summary["stops_s"])
    speed = np.linalg.norm(np.diff(positions[:, :2], axis=0), axis=1) / FRAME_S
    assert speed.max() <= STOP_GO_SPEED_FACTORS[1] * SCENES[scene].target_speed_mps * 1.05  # the terrain's slope


@pytest.mark.parametrize("scene", SCENES)
def test_stop_and_go_profiles_stop_in_every_20_s_of_driving_with_speeds_of_half_to_twice(scene):
    spec = SCENES[scene]
    base = make_layout(spec, np.random.default_rng(SEED), spec.target_speed_mps).target
    for seed in range(PROFILE_SEEDS):
        m = draw_stop_and_go(base, np.random.default_rng(seed))
        t = np.arange(0.0, m.stop_time_s, PROFILE_STEP_S)
        speed = np.array([m.speed_mps(x) for x in t])
        s = np.array([m.distance_m(x) for x in t])
        assert m.distance_m(m.stop_time_s) == pytest.approx(base.end_s_m) and m.speed_mps(m.stop_time_s) == 0.0
        # ds/dt is the speed: the trapezoid over one step, exact but where a step straddles a knot (a kink), off
        # there by less than the speed changes in one step
        kink_mps = base.speed_mps / STOP_GO_RAMP_S * PROFILE_STEP_S
        np.testing.assert_allclose(np.diff(s) / PROFILE_STEP_S, (speed[1:] + speed[:-1]) / 2.0, atol=kink_mps)
        assert speed.max() <= STOP_GO_SPEED_FACTORS[1] * base.speed_mps + 1e-9
        driving, longest = 0.0, 0.0
        for v in speed:
            driving = driving + PROFILE_STEP_S if v > 0.0 else 0.0
            longest = max(longest, driving)
        assert longest < EVERY_DRIVE_S
        assert all(STOP_GO_STOP_S[0] <= d <= STOP_GO_STOP_S[1] for _, d in m.stops)
        assert all(STOP_GO_SPEED_FACTORS[0] <= f <= STOP_GO_SPEED_FACTORS[1] for f in m.speed_factors)
        for start, duration in m.stops:  # standing still through each stop
            assert m.distance_m(start) == m.distance_m(start + duration) and m.speed_mps(start + duration / 2) == 0.0


def _drivable_violations(world: World, centres: np.ndarray, rotations: np.ndarray) -> list[str]:
    """What the target's footprint (a grid of points) overlaps at each frame: a building, a parked vehicle, a rock,
    the terrain's edge."""
    hx, hy, _ = world.target.half_extents_m
    u = np.linspace(-1.0, 1.0, FOOTPRINT_GRID)
    local = np.array([[a * hx, b * hy] for a in u for b in u])  # (P, 2) in the target's frame
    points = centres[:, None, :2] + np.einsum("fij,pj->fpi", rotations[:, :2, :2], local)  # (F, P, 2)
    found = []
    lo, hi = world.buildings_lo_m[:, :2], world.buildings_hi_m[:, :2]
    inside = np.all((points[..., None, :] > lo) & (points[..., None, :] < hi), axis=-1)
    if inside.any():
        found.append("building")
    for decoy in (d for d in world.decoys if not d.motion.is_moving):
        centre, R = world.vehicle_pose(decoy, 0.0)
        rel = np.einsum("ji,fpj->fpi", R[:2, :2], points - centre[:2])
        if np.any(np.all(np.abs(rel) < decoy.half_extents_m[:2], axis=-1)):
            found.append("parked vehicle")
    for rock in world.layout.boulders:
        if np.any(np.linalg.norm(points - rock.centre_m[:2], axis=-1) < np.max(rock.radii_m[:2])):
            found.append("rock")
    if np.any(np.abs(points) >= world.spec.terrain_size_m / 2.0):
        found.append("terrain edge")
    return found


@pytest.mark.parametrize("scene", SCENES)
def test_evasive_target_with_drone_overhead_speeds_up_and_swerves_within_the_drivable_area(client, scene):
    world = _world(client, scene, "evasive")
    centres, rotations, velocities = _drive(world, OVERHEAD_FRAMES, _overhead)
    cruise_mps = world.layout.target.speed_mps
    speed = np.linalg.norm(velocities[:, :2], axis=1)
    assert speed.max() > SPEED_UP_FRACTION * EVASIVE_SPEED_FACTOR * cruise_mps
    # bounded: swerving trades speed along the path for speed across it (to the curvature's central difference)
    assert speed.max() <= EVASIVE_SPEED_FACTOR * cruise_mps * (1.0 + 1e-3)
    offset, _ = world.target.motion.path.closest(centres[:, :2], spacing_m=0.25)
    road = world.layout.road
    widest = EVASIVE_OFFROAD_LATERAL_M if road is None else road.half_width_m - world.target.half_extents_m[1]
    assert MIN_SWERVE_M < offset.max() <= widest + 0.05  # the sampled centre line's chord error
    assert _drivable_violations(world, centres, rotations) == []
    driving = speed > 0.0  # the velocity holds but where the target stops at once at the route's end
    around = driving[:-2] & driving[1:-1] & driving[2:]
    central = (centres[2:] - centres[:-2]) / (2.0 * FRAME_S)
    np.testing.assert_allclose(central[around], velocities[1:-1][around], atol=VELOCITY_TOLERANCE_MPS)
    heading = rotations[:, :2, 0] / np.linalg.norm(rotations[:, :2, 0], axis=1, keepdims=True)
    along = np.einsum("fi,fi->f", heading[driving], velocities[driving, :2] / speed[driving, None])
    assert np.all(along > math.cos(math.radians(1.0)))  # it faces where it drives


@pytest.mark.parametrize("scene", SCENES)
def test_evasive_target_with_drone_far_away_is_cruise_exactly(client, scene):
    cruise = _drive(_world(client, scene, "cruise"), OVERHEAD_FRAMES, _far)
    evasive_world = _world(client, scene, "evasive")
    evasive = _drive(evasive_world, OVERHEAD_FRAMES, _far)
    for a, b in zip(cruise, evasive, strict=True):
        assert a.tobytes() == b.tobytes()
    assert not evasive_world.target.motion.alert


@pytest.mark.parametrize("scene", SCENES)
def test_every_mode_leaves_the_rest_of_the_world_as_cruise_draws_it(client, scene):
    def snapshot(mode: str, decoys: str) -> bytes:
        w = _world(client, scene, mode, decoys=DecoyTier(decoys))
        poses = [np.concatenate([c, R.ravel()]) for c, R in (w.vehicle_pose(d, 3.0) for d in w.decoys)]
        return b"".join([w.terrain.heights_m.tobytes(), w.buildings_lo_m.tobytes(), w.drone_start()[0].tobytes(),
                         np.array(poses).tobytes(), np.array([b.centre_m for b in w.layout.boulders]).tobytes()])

    for decoys in ("ambiguous", "parked"):
        cruise = snapshot("cruise", decoys)
        assert snapshot("stop_and_go", decoys) == cruise and snapshot("evasive", decoys) == cruise


def test_evasive_target_in_the_env_speeds_up_under_the_following_drone():
    reset_info, infos = _episode("evasive", SEED, 8.0)
    spec = SCENES["desert"]
    assert reset_info["target_motion"]["radius_m"] == pytest.approx(evasive_radius_m(spec.follow_altitude_agl_m,
                                                                                     EnvConfig().camera_fov_deg), 1e-3)
    positions = np.array([info["target_position_m"] for info in infos])
    speed = np.linalg.norm(np.diff(positions[:, :2], axis=0), axis=1) / FRAME_S
    assert speed.max() > SPEED_UP_FRACTION * EVASIVE_SPEED_FACTOR * spec.target_speed_mps
    assert max(info["horizontal_distance_m"] for info in infos) < reset_info["target_motion"]["radius_m"]


def test_evasive_world_time_must_not_go_back(client):
    world = _world(client, "desert", "evasive")
    world.update(1.0, np.zeros(3))
    with pytest.raises(ValueError, match="must not decrease"):
        world.update(0.5, np.zeros(3))


def test_reset_info_names_the_mode_and_cruise_is_the_default():
    assert EnvConfig().target_motion == "cruise"
    reset_info, _ = _episode("cruise", SEED, 0.1)
    assert reset_info["target_motion"] == {"mode": "cruise"}


@pytest.mark.parametrize("make", [lambda: EnvConfig(target_motion="fast"), lambda: TargetMotion("fast"),
                                  lambda: TradeFollowEnv(target_motion="fast")])
def test_bad_target_motion_raises_value_error_naming_it(make):
    with pytest.raises(ValueError, match=r"target_motion.*'fast'"):
        make()


@pytest.mark.parametrize("mode", ["stop_and_go", "evasive"])
def test_check_env_passes_with_each_target_motion(mode):
    env = TradeFollowEnv(scene="desert", perception="oracle", target_motion=mode, camera_size=64,
                         episode_duration_s=1.0)
    try:
        check_env_strict(env, skip_render_check=True)
    finally:
        env.close()
