"""Camera projection and depth, IMU sampling and noise, and pose sources (gt / vio)."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from trade.geometry import CameraIntrinsics, Pose, matrix_to_quat_xyzw, project_world, rotation_z
from trade.camera_pitch import mount_rotation
from trade_gym.sim.camera import Camera, CameraConfig
from trade_gym.sim.imu import Imu, ImuConfig
from trade_gym.sim.pose_source import VioConfig, VioPoseSource, make_pose_source

PHYSICS_DT_S = 1.0 / 240.0
STEPS_PER_FRAME = 8


@pytest.fixture()
def client():
    """A DIRECT client with a ground plane (body 0) and three coloured boxes of different heights."""
    cid = p.connect(p.DIRECT)
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
    p.createMultiBody(0, plane, -1, [0, 0, 0], physicsClientId=cid)
    for (x, y, half_height), rgba in zip(
        [(3.0, 2.0, 1.0), (-4.0, 1.0, 2.5), (1.0, -5.0, 0.5)], [(1, 0, 0, 1), (0, 1, 0, 1), (0, 0, 1, 1)]
    ):
        half = [1.0, 1.5, half_height]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=rgba, physicsClientId=cid)
        p.createMultiBody(0, col, vis, [x, y, half_height], physicsClientId=cid)
    yield cid
    p.disconnect(physicsClientId=cid)


# ------------------------------------------------------------------------------------------ camera
def test_camera_mount_pitch90_looks_down_with_image_top_forward():
    R = mount_rotation(90.0)
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-12)  # optical axis = -z_body
    np.testing.assert_allclose(R[:, 0], [0, -1, 0], atol=1e-12)  # x_cam = -y_body
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    K = CameraIntrinsics.from_fov(64, 64, 110.0)
    T = Pose(np.eye(3), [0, 0, 10]).compose(Pose(R, np.zeros(3)))
    ahead, left = project_world(K, T, np.array([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]]))
    assert ahead[1] < K.cy_px and ahead[0] == pytest.approx(K.cx_px)  # forward is image up
    assert left[0] < K.cx_px and left[1] == pytest.approx(K.cy_px)  # left is image left


def test_camera_mount_pitch45_axis_halfway_between_forward_and_down():
    R = mount_rotation(45.0)
    np.testing.assert_allclose(R[:, 2], [math.sqrt(0.5), 0, -math.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("pitch_deg,width_px,height_px", [(90.0, 256, 256), (45.0, 256, 256), (90.0, 161, 120)])
def test_camera_render_marker_centroid_within_half_px_of_intrinsics_projection(
    client, pitch_deg, width_px, height_px
):
    cam = Camera(client, CameraConfig(width_px=width_px, height_px=height_px, pitch_deg=pitch_deg))
    K = cam.intrinsics
    T_world_cam = cam.pose(rotation_z(0.4), [0.3, -0.2, 20.0])
    rng = np.random.default_rng(3)
    # six markers on a 3 x 2 grid of image cells (no overlap), jittered by sub-pixel amounts
    cells = np.stack(np.meshgrid([0.2, 0.5, 0.8], [0.3, 0.7]), axis=-1).reshape(-1, 2)
    pixels = cells * [K.width_px, K.height_px] + rng.uniform(-5.0, 5.0, (6, 2))
    depths_m = rng.uniform(4.0, 9.0, 6)
    centres = T_world_cam.apply(K.backproject(pixels, depths_m))
    radius_px = 10.0
    ids = []
    for centre, depth in zip(centres, depths_m):
        # a thin disc facing the camera: its image is a disc centred on the projection of its centre
        vis = p.createVisualShape(p.GEOM_CYLINDER, radius=radius_px * depth / K.fx_px, length=0.005,
                                  rgbaColor=[1, 1, 1, 1], physicsClientId=client)
        ids.append(p.createMultiBody(0, -1, vis, centre.tolist(), matrix_to_quat_xyzw(T_world_cam.R.ravel()),
                                     physicsClientId=client))
    frame = cam.render(T_world_cam)
    assert frame.rgb.shape == (height_px, width_px, 3) and frame.rgb.dtype == np.uint8
    assert frame.seg.shape == (height_px, width_px) and frame.seg.dtype == np.int32
    predicted = project_world(K, T_world_cam, centres)
    for body, uv in zip(ids, predicted):
        rows, cols = np.nonzero(frame.seg == body)
        assert len(rows) > 0.8 * math.pi * radius_px**2
        error_px = np.hypot(cols.mean() - uv[0], rows.mean() - uv[1])
        assert error_px < 0.5, f"marker {body}: centroid off by {error_px:.3f} px"


@pytest.mark.parametrize("pitch_deg", [90.0, 45.0])
def test_camera_depth_is_camera_z_matching_raytest_within_1pct(client, pitch_deg):
    cam = Camera(client, CameraConfig(width_px=128, height_px=128, pitch_deg=pitch_deg, far_m=500.0))
    K = cam.intrinsics
    T_world_cam = cam.pose(rotation_z(0.3), [0.5, -1.0, 12.0])
    frame = cam.render(T_world_cam)
    assert frame.depth_m.dtype == np.float32
    grid = np.arange(4, K.width_px, 8, dtype=np.float64)
    pixels = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)
    rays_world = K.rays(pixels) @ T_world_cam.R.T  # z_cam = 1 per ray
    starts = np.repeat(T_world_cam.t[None], len(pixels), axis=0)
    hits = p.rayTestBatch(starts.tolist(), (starts + cam.config.far_m * rays_world).tolist(),
                          physicsClientId=client)
    hit_ids = np.array([h[0] for h in hits])
    z_ray = np.array([h[2] for h in hits]) * cam.config.far_m  # hit fraction of a ray reaching z = far
    cols, rows = pixels[:, 0].astype(int), pixels[:, 1].astype(int)
    same = hit_ids == frame.seg[rows, cols]
    assert same.mean() > 0.9
    hit = same & (hit_ids >= 0)
    assert hit.sum() > 100
    np.testing.assert_allclose(frame.depth_m[rows, cols][hit], z_ray[hit], rtol=0.01)
    # off-axis pixels: range exceeds z by > 10 %, so the check above distinguishes z from range
    assert np.max(np.linalg.norm(rays_world[hit], axis=1)) > 1.1
    np.testing.assert_allclose(frame.depth_m[rows, cols][same & (hit_ids < 0)], cam.config.far_m, rtol=0.01)


def test_camera_config_invalid_pitch_raises_naming_field():
    with pytest.raises(ValueError, match="pitch_deg"):
        CameraConfig(pitch_deg=120.0)
    with pytest.raises(ValueError, match="renderer"):
        CameraConfig(renderer="vulkan")


# --------------------------------------------------------------------------------------------- imu
def _feed_constant(imu: Imu, seconds: float, accel, gyro) -> list:
    """Feed constant truth at 240 Hz, reading once per 8 steps; returns the batches."""
    batches = []
    for step in range(1, int(round(seconds / PHYSICS_DT_S)) + 1):
        imu.add_truth(step * PHYSICS_DT_S, accel, gyro)
        if step % STEPS_PER_FRAME == 0:
            batches.append(imu.read())
    return batches


def test_imu_delivers_200hz_six_or_seven_samples_per_frame():
    imu = Imu(ImuConfig(), np.random.default_rng(0))
    batches = _feed_constant(imu, 3.0, [0, 0, 9.81], [0, 0, 0])
    counts = [len(b.t_s) for b in batches]
    assert set(counts) == {6, 7}
    t = np.concatenate([b.t_s for b in batches])
    np.testing.assert_allclose(np.diff(t), 1.0 / 200.0, atol=1e-12)
    assert np.sum((t > 0.0) & (t <= 1.0 + 1e-12)) == 200
    assert len(t) == 600


def test_imu_noise_disabled_interpolates_truth_linearly():
    imu = Imu(ImuConfig(noise=False), np.random.default_rng(0))
    slope, offset = np.array([1.0, -2.0, 0.5, 0.1, 0.2, -0.3]), np.array([0.0, 0.0, 9.81, 0.0, 0.0, 0.0])
    samples = []
    for step in range(1, 49):
        t = step * PHYSICS_DT_S
        truth = offset + slope * t
        imu.add_truth(t, truth[:3], truth[3:])
        if step % STEPS_PER_FRAME == 0:
            samples.append(imu.read())
    t = np.concatenate([b.t_s for b in samples])
    got = np.hstack([np.concatenate([b.accel_mps2 for b in samples]),
                     np.concatenate([b.gyro_radps for b in samples])])
    np.testing.assert_allclose(got, offset + slope * t[:, None], atol=1e-12)


def test_imu_white_noise_std_matches_density_times_sqrt_rate_within_10pct():
    config = ImuConfig(accel_bias_random_walk_mps3_per_rthz=0.0, gyro_bias_random_walk_radps2_per_rthz=0.0,
                       accel_initial_bias_sigma_mps2=0.0, gyro_initial_bias_sigma_radps=0.0)
    imu = Imu(config, np.random.default_rng(1))
    accel_truth, gyro_truth = np.array([0.3, -0.2, 9.81]), np.array([0.05, 0.0, -0.1])
    batches = _feed_constant(imu, 20.0, accel_truth, gyro_truth)
    accel_noise = np.concatenate([b.accel_mps2 for b in batches]) - accel_truth
    gyro_noise = np.concatenate([b.gyro_radps for b in batches]) - gyro_truth
    np.testing.assert_allclose(accel_noise.std(axis=0), 2.94e-3 * math.sqrt(200.0), rtol=0.1)
    np.testing.assert_allclose(gyro_noise.std(axis=0), 1.75e-4 * math.sqrt(200.0), rtol=0.1)
    assert np.all(np.abs(accel_noise.mean(axis=0)) < 0.01)


def test_imu_bias_random_walk_step_std_matches_density_times_sqrt_period():
    config = ImuConfig(accel_noise_density_mps2_per_rthz=0.0, gyro_noise_density_radps_per_rthz=0.0,
                       accel_bias_random_walk_mps3_per_rthz=0.02, gyro_bias_random_walk_radps2_per_rthz=0.001)
    imu = Imu(config, np.random.default_rng(2))
    batches = _feed_constant(imu, 20.0, [0, 0, 9.81], [0, 0, 0])
    accel = np.concatenate([b.accel_mps2 for b in batches])
    gyro = np.concatenate([b.gyro_radps for b in batches])
    np.testing.assert_allclose(np.diff(accel, axis=0).std(axis=0), 0.02 * math.sqrt(1 / 200.0), rtol=0.1)
    np.testing.assert_allclose(np.diff(gyro, axis=0).std(axis=0), 0.001 * math.sqrt(1 / 200.0), rtol=0.1)
    np.testing.assert_allclose(imu.accel_bias_mps2, accel[-1] - [0, 0, 9.81], atol=1e-12)


def test_imu_same_seed_same_samples_other_seed_differs():
    def run(seed: int) -> np.ndarray:
        imu = Imu(ImuConfig(), np.random.default_rng(seed))
        return np.concatenate([b.accel_mps2 for b in _feed_constant(imu, 0.5, [0, 0, 9.81], [0, 0, 0])])

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.allclose(run(7), run(8))


def test_imu_config_negative_density_raises_naming_field():
    with pytest.raises(ValueError, match="gyro_noise_density_radps_per_rthz"):
        ImuConfig(gyro_noise_density_radps_per_rthz=-1.0)


# ------------------------------------------------------------------------------------- pose source
def _pose(x_m: float) -> Pose:
    return Pose(rotation_z(0.2) @ mount_rotation(90.0), [x_m, 1.0, 20.0])


def test_pose_source_gt_returns_exact_pose():
    source = make_pose_source("gt", np.random.default_rng(0))
    for x in (0.0, 10.0, 100.0):
        estimate = source.estimate(_pose(x), x)
        np.testing.assert_array_equal(estimate.R, _pose(x).R)
        np.testing.assert_array_equal(estimate.t, _pose(x).t)


def test_pose_source_vio_error_grows_with_distance_as_sqrt():
    config = VioConfig()
    position_err, yaw_err = {10: [], 100: []}, {10: [], 100: []}
    for seed in range(300):
        source = make_pose_source("vio", np.random.default_rng(seed), config)
        for d in range(2, 101, 2):
            est = source.estimate(_pose(float(d)), float(d))
            if d in position_err:
                position_err[d].append(est.t - _pose(float(d)).t)
                R_err = est.R @ _pose(float(d)).R.T  # = Rz(yaw error)
                yaw_err[d].append(math.atan2(R_err[1, 0], R_err[0, 0]))
                np.testing.assert_allclose(R_err[2], [0, 0, 1], atol=1e-12)  # yaw only
    rms_p = {d: float(np.sqrt(np.mean(np.square(e)))) for d, e in position_err.items()}
    rms_y = {d: float(np.sqrt(np.mean(np.square(e)))) for d, e in yaw_err.items()}
    assert rms_p[100] == pytest.approx(config.position_drift_sigma_m_per_sqrt_m * 10.0, rel=0.15)
    assert rms_y[100] == pytest.approx(config.yaw_drift_sigma_rad_per_sqrt_m * 10.0, rel=0.15)
    assert rms_p[100] > 2.0 * rms_p[10] and rms_y[100] > 2.0 * rms_y[10]


def test_pose_source_vio_same_seed_same_drift_no_motion_no_drift():
    def drift(seed: int) -> np.ndarray:
        source = VioPoseSource(VioConfig(), np.random.default_rng(seed))
        return np.array([source.estimate(_pose(d), d).t for d in np.linspace(0.0, 50.0, 20)])

    np.testing.assert_array_equal(drift(4), drift(4))
    assert not np.allclose(drift(4), drift(5))
    source = VioPoseSource(VioConfig(), np.random.default_rng(0))
    first = source.estimate(_pose(5.0), 5.0)
    again = source.estimate(_pose(5.0), 5.0)
    np.testing.assert_array_equal(first.t, again.t)
    with pytest.raises(ValueError, match="distance_flown_m"):
        source.estimate(_pose(5.0), 4.0)


def test_make_pose_source_unknown_name_raises_listing_valid_names():
    with pytest.raises(ValueError, match=r"'slam'.*gt.*vio"):
        make_pose_source("slam", np.random.default_rng(0))


FRAME_S = 1.0 / 30.0


def test_pose_source_gt_velocity_is_the_true_velocity():
    source = make_pose_source("gt", np.random.default_rng(0))
    v = np.array([1.0, -2.0, 0.5])
    np.testing.assert_array_equal(source.velocity(v, 0.0), v)


def test_pose_source_vio_velocity_error_starts_at_zero_and_stays_bounded_near_its_sigma():
    config = VioConfig(velocity_error_sigma_mps=0.05, velocity_error_correlation_s=2.0)
    source = VioPoseSource(config, np.random.default_rng(1))
    v = np.array([3.0, 0.0, 0.0])
    np.testing.assert_array_equal(source.velocity(v, 0.0), v)  # no time has passed, no drift flown
    errors = np.array([source.velocity(v, k * FRAME_S) - v for k in range(1, 30_001)])
    steady = errors[3000:]  # after 50 correlation times
    assert np.all(np.abs(steady.std(axis=0) / config.velocity_error_sigma_mps - 1.0) < 0.2)
    assert np.abs(errors).max() < 6 * config.velocity_error_sigma_mps


def test_pose_source_vio_velocity_turns_with_the_yaw_drift_like_the_pose():
    source = VioPoseSource(VioConfig(position_drift_sigma_m_per_sqrt_m=0.0, velocity_error_sigma_mps=0.0),
                           np.random.default_rng(2))
    T = Pose(np.eye(3), np.zeros(3))
    drifted = source.estimate(T, 400.0)  # 400 m flown: a yaw drift of ~2.3 deg
    v = np.array([2.0, 1.0, -0.5])
    assert source.yaw_error_rad != 0.0
    np.testing.assert_allclose(source.velocity(v, FRAME_S), drifted.R @ v, atol=1e-12)


def test_pose_source_vio_velocity_time_going_back_raises_naming_it():
    source = VioPoseSource(VioConfig(), np.random.default_rng(3))
    source.velocity(np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="t_s"):
        source.velocity(np.zeros(3), 0.5)


def test_observed_drone_velocity_comes_from_the_pose_source():
    """Same seed, zero actions (the pose source does not touch the physics): with gt the observed velocity is
    the true one; with vio it differs by the VIO's bounded velocity error, and by nothing with a zero drift."""
    from trade_gym.env import TradeFollowEnv

    def velocities(**kwargs) -> np.ndarray:
        env = TradeFollowEnv(scene="desert", perception="oracle", **kwargs)
        try:
            env.reset(seed=0)
            return np.array([env.step(np.zeros(4, np.float32))[0]["drone_vel_mps"] for _ in range(60)])
        finally:
            env.close()

    gt, vio = velocities(pose_source="gt"), velocities(pose_source="vio")
    exact = velocities(pose_source="vio", vio={"position_drift_sigma_m_per_sqrt_m": 0.0,
                                                "yaw_drift_sigma_rad_per_sqrt_m": 0.0, "velocity_error_sigma_mps": 0.0})
    np.testing.assert_allclose(exact, gt, atol=1e-6)
    error = np.abs(vio - gt)
    assert error.max() > 1e-3 and error.max() < 6 * VioConfig().velocity_error_sigma_mps


def test_pose_source_vio_velocity_error_leaves_the_pose_drift_as_it_was():
    """The velocity error draws from a child stream: the pose drift is the same with or without velocity calls."""
    T = Pose(np.eye(3), np.zeros(3))

    def drift(with_velocity: bool) -> list[np.ndarray]:
        source = VioPoseSource(VioConfig(), np.random.default_rng(4))
        out = []
        for k in range(1, 50):
            out.append(source.estimate(T, 0.1 * k).t)
            if with_velocity:
                source.velocity(np.ones(3), k * FRAME_S)
        return out

    np.testing.assert_array_equal(drift(True), drift(False))
