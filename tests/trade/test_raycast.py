"""Spec tests for trade.raycast: lifted-plane raycasting and the multi-plane depth Gaussian."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.geometry import CameraIntrinsics, Pose, project_world
from trade.planes import Plane
from trade.raycast import LIFT_FRACTION_OF_HEIGHT, RaycastConfig, depth_uncertainty, raycast_plane

K = CameraIntrinsics.from_fov(320, 240, 90.0)
CENTRE_PX = np.array([K.cx_px, K.cy_px])
R_NADIR = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # cam z -> world -z
ALTITUDE_M = 20.0


def nadir_pose(x: float = 0.0, y: float = 0.0) -> Pose:
    return Pose(R_NADIR, np.array([x, y, ALTITUDE_M]))


def tilted_about_y(tilt_deg: float, offset_m: float = 0.0) -> Plane:
    """z = x tan(tilt) - offset/cos: normal (-sin, 0, cos)."""
    t = math.radians(tilt_deg)
    return Plane(np.array([-math.sin(t), 0.0, math.cos(t)]), offset_m)


def oblique_pose() -> Pose:
    """Camera 45 deg off nadir, pitched towards +y (north), yawed a little."""
    a, yaw = math.radians(45.0), math.radians(10.0)
    pitch = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
    Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return Pose(Rz @ pitch @ R_NADIR, np.array([3.0, -4.0, ALTITUDE_M]))


@pytest.mark.parametrize("height_m", [0.0, 1.6, 4.0])
def test_raycast_nadir_centre_ray_on_tilted_plane_matches_closed_form(height_m: float) -> None:
    """Vertical ray x = y = 0 meets n·x = h/2 with n = (-sin t, 0, cos t) at z = h / (2 cos t)."""
    tilt = math.radians(25.0)
    res = raycast_plane(K, nadir_pose(), CENTRE_PX, tilted_about_y(25.0), object_height_m=height_m)
    z_hit = LIFT_FRACTION_OF_HEIGHT * height_m / math.cos(tilt)
    assert res.valid
    np.testing.assert_allclose(res.point_world, [0.0, 0.0, z_hit], atol=1e-9)
    assert res.depth_m == pytest.approx(ALTITUDE_M - z_hit)


def test_raycast_oblique_camera_recovers_point_on_lifted_plane_and_its_camera_z() -> None:
    plane, height_m, pose = tilted_about_y(15.0, offset_m=-1.0), 2.0, oblique_pose()
    lifted = plane.lifted(LIFT_FRACTION_OF_HEIGHT * height_m)
    target = np.array([2.0, 12.0, 0.0])
    target[2] = lifted.height_at(target[:2])  # a point on the lifted plane, in view
    pixel = project_world(K, pose, target[None, :])[0]
    res = raycast_plane(K, pose, pixel, plane, object_height_m=height_m)
    assert res.valid
    np.testing.assert_allclose(res.point_world, target, atol=1e-9)
    assert res.depth_m == pytest.approx(pose.inverse().apply(target)[0, 2])
    assert abs(plane.signed_distance(res.point_world)[0] - 1.0) < 1e-9  # lifted by half of 2 m


def test_raycast_ray_parallel_to_plane_is_invalid() -> None:
    looking_north = Pose(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]), [0.0, 0.0, 5.0])
    res = raycast_plane(K, looking_north, CENTRE_PX, Plane(np.array([0.0, 0.0, 1.0]), 0.0))
    assert not res.valid and math.isnan(res.depth_m) and np.all(np.isnan(res.point_world))


@pytest.mark.parametrize("ground_z_m", [ALTITUDE_M + 5.0, ALTITUDE_M])
def test_raycast_plane_behind_camera_or_through_it_is_invalid(ground_z_m: float) -> None:
    res = raycast_plane(K, nadir_pose(), CENTRE_PX, Plane(np.array([0.0, 0.0, 1.0]), -ground_z_m))
    assert not res.valid and math.isnan(res.depth_m)


def test_raycast_camera_looking_up_at_ground_below_is_invalid() -> None:
    looking_up = Pose(np.eye(3), np.array([0.0, 0.0, 5.0]))  # camera z = world z: optical axis up
    res = raycast_plane(K, looking_up, CENTRE_PX, Plane(np.array([0.0, 0.0, 1.0]), 0.0))
    assert not res.valid


def test_raycast_negative_object_height_raises() -> None:
    with pytest.raises(ValueError, match="object_height_m"):
        raycast_plane(K, nadir_pose(), CENTRE_PX, Plane(np.array([0.0, 0.0, 1.0]), 0.0), object_height_m=-1.0)


def test_depth_uncertainty_two_ground_planes_gives_their_mean_and_half_spread() -> None:
    planes = [Plane(np.array([0.0, 0.0, 1.0]), -z) for z in (2.0, 6.0)]  # depths 18 m and 14 m
    g = depth_uncertainty(K, nadir_pose(), CENTRE_PX, planes, object_height_m=2.0)  # lift 1 m: 17, 13
    assert g.valid and g.n_valid == 2
    assert g.mean_m == pytest.approx(15.0) and g.sigma_m == pytest.approx(2.0)


def test_depth_uncertainty_single_plane_sigma_is_the_configured_floor() -> None:
    cfg = RaycastConfig(min_depth_sigma_m=0.4)
    g = depth_uncertainty(K, nadir_pose(), CENTRE_PX, [tilted_about_y(10.0)], config=cfg)
    assert g.mean_m == pytest.approx(ALTITUDE_M) and g.sigma_m == pytest.approx(0.4)


def test_depth_uncertainty_ignores_planes_behind_camera_and_reports_none_valid() -> None:
    ground, above = Plane(np.array([0.0, 0.0, 1.0]), 0.0), Plane(np.array([0.0, 0.0, 1.0]), -30.0)
    g = depth_uncertainty(K, nadir_pose(), CENTRE_PX, [ground, above])
    assert g.n_valid == 1 and g.mean_m == pytest.approx(ALTITUDE_M)
    none = depth_uncertainty(K, nadir_pose(), CENTRE_PX, [above])
    assert not none.valid and math.isnan(none.mean_m)
    assert not depth_uncertainty(K, nadir_pose(), CENTRE_PX, []).valid


def test_raycast_config_bad_field_raises_naming_it() -> None:
    with pytest.raises(ValueError, match="min_depth_sigma_m"):
        RaycastConfig(min_depth_sigma_m=0.0)
