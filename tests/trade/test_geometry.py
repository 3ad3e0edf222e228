"""Tests of the camera geometry helpers that have no other home: the projected covariance
(`CameraIntrinsics.project_covariance`) and the rotation-quaternion conversions."""

from __future__ import annotations

import numpy as np

import pytest

from trade.geometry import CameraIntrinsics, Pose, matrix_to_quat_xyzw, project_world, quat_xyzw_to_matrix, rotation_z

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
