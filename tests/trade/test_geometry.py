"""Tests of the camera geometry helpers that have no other home: the projected covariance
(`CameraIntrinsics.project_covariance`), the rotation-quaternion conversions and the rotation warp."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trade.geometry import (CameraIntrinsics, Pose, RotationWarp, matrix_to_quat_xyzw, project_world,
                            quat_xyzw_to_matrix, rotation_z)

SAMPLES = 200_000
N_ROTATIONS = 20
# a half turn about x, y, z: trace -1, each branch of Shepperd's method past the trace one
HALF_TURNS = (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]))


def _project_covariance(K: CameraIntrinsics, T_world_cam: Pose, point_world: np.ndarray,
                        C_world: np.ndarray) -> np.ndarray:
    """The image covariance of a world point: its camera-frame point and covariance through K."""
    T_cam_world = T_world_cam.inverse()
    return K.project_covariance(T_cam_world.apply(point_world)[0], T_cam_world.R @ C_world @ T_cam_world.R.T)


def test_project_covariance_matches_the_spread_of_projected_samples() -> None:
    """For a small world covariance the first-order image covariance equals the sample covariance of the
    projected points (a tilted, yawed camera 20 m up; a point off the optical axis)."""
    K = CameraIntrinsics.from_fov(160, 120, 70.0)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(2.8), -np.sin(2.8)], [0.0, np.sin(2.8), np.cos(2.8)]])
    T_world_cam = Pose(rotation_z(0.6) @ tilt, np.array([3.0, -2.0, 20.0]))
    point = np.array([6.0, 1.0, 0.5])
    C = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.005], [0.0, 0.005, 0.02]])
    rng = np.random.default_rng(0)
    pixels = project_world(K, T_world_cam, rng.multivariate_normal(point, C, SAMPLES))
    assert np.isfinite(pixels).all()  # every sample in front of the camera
    np.testing.assert_allclose(_project_covariance(K, T_world_cam, point, C), np.cov(pixels.T), rtol=0.03)


def test_project_covariance_is_nan_behind_the_camera() -> None:
    K = CameraIntrinsics.from_fov(64, 64, 90.0)
    T_world_cam = Pose(np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 10.0]))  # looking down
    assert np.isnan(_project_covariance(K, T_world_cam, np.array([0.0, 0.0, 12.0]), np.eye(3))).all()
    assert np.isfinite(_project_covariance(K, T_world_cam, np.zeros(3), np.eye(3))).all()


def _random_rotations(seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(N_ROTATIONS):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        out.append(q * np.sign(np.linalg.det(q)))
    return out


@pytest.mark.parametrize("R", [*_random_rotations(3), *HALF_TURNS, np.eye(3)])
def test_matrix_to_quat_round_trip_recovers_rotation_and_unit_norm(R) -> None:
    q = matrix_to_quat_xyzw(R.ravel())
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    np.testing.assert_allclose(quat_xyzw_to_matrix(q), R, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_quat_to_matrix_round_trip_recovers_quaternion_up_to_sign(seed) -> None:
    for q in np.random.default_rng(seed).normal(size=(N_ROTATIONS, 4)):
        q /= np.linalg.norm(q)
        back = np.array(matrix_to_quat_xyzw(quat_xyzw_to_matrix(q).ravel()))
        np.testing.assert_allclose(back * np.sign(back @ q), q, atol=1e-12)  # q and -q are one rotation


@pytest.mark.parametrize("seed", range(5))
def test_rotation_warp_maps_a_points_pixel_to_where_the_turned_camera_sees_it(seed) -> None:
    """Two cameras at one position, the second turned by up to 0.2 rad about a random axis: the warp takes each point's
    pixel in the first image to its pixel in the second, at any depth; a ray turned behind the second camera is NaN."""
    rng = np.random.default_rng(seed)
    K = CameraIntrinsics.from_fov(256, 256, 60.0)
    T_first = Pose(_random_rotations(seed)[0], rng.normal(size=3))
    axis = rng.normal(size=3)
    turn, _ = cv2.Rodrigues(0.2 * rng.uniform() * axis / np.linalg.norm(axis))
    T_second = Pose(T_first.R @ turn, T_first.t)
    pixels = rng.uniform(0, 255, size=(20, 2))
    points = T_first.apply(K.backproject(pixels, rng.uniform(5.0, 500.0, size=20)))
    expected = project_world(K, T_second, points)
    warp = RotationWarp.between(K, T_first, T_second)
    np.testing.assert_allclose([warp.apply(p) for p in pixels], expected, atol=1e-6)
    assert np.all(np.isnan(RotationWarp.between(K, T_first, Pose(T_first.R @ np.diag([1.0, -1.0, -1.0]),
                                                                   T_first.t)).apply(pixels[0])))
    np.testing.assert_allclose(RotationWarp.identity().apply(pixels[0]), pixels[0])


def test_rotation_warp_moves_a_box_by_its_centre_and_keeps_its_size():
    K = CameraIntrinsics.from_fov(256, 256, 60.0)
    T_first = Pose.identity()
    turn, _ = cv2.Rodrigues(np.array([0.05, -0.03, 0.1]))
    warp = RotationWarp.between(K, T_first, Pose(turn, np.zeros(3)))
    box = np.array([100.0, 60.0, 12.0, 20.0])
    moved = warp.apply_box(box)
    np.testing.assert_allclose(moved[:2] + moved[2:] / 2.0, warp.apply(box[:2] + box[2:] / 2.0))
    np.testing.assert_array_equal(moved[2:], box[2:])
    np.testing.assert_allclose(RotationWarp.identity().apply_box(box), box)
    missing = np.full(4, np.nan)
    assert np.all(np.isnan(warp.apply_box(missing)))
    behind = RotationWarp.between(K, T_first, Pose(np.diag([1.0, -1.0, -1.0]), np.zeros(3)))
    np.testing.assert_array_equal(behind.apply_box(box), box)  # its centre's ray turned behind: kept
