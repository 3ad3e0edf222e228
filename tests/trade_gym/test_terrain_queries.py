"""The step loop's compiled terrain queries equal the vectorised ones they stand in for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym.sim.terrain import Heightfield
from trade_gym.sim.vehicle_poses import terrain_pose as scalar_terrain_pose
from trade_gym.sim.vehicles import terrain_pose

N_POINTS = 2000
SPACING_M = 2.0
HALF_EXTENTS_M = (2.3, 0.95, 0.75)
POSE_TOL = 1e-12


@pytest.fixture(scope="module")
def field() -> Heightfield:
    rng = np.random.default_rng(7)
    return Heightfield.centred(3.0 * rng.normal(size=(40, 50)).astype(np.float32), SPACING_M)


def test_height_at_equals_height_m_bit_for_bit_inside_and_beyond_the_grid(field):
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-70.0, 70.0, N_POINTS), rng.uniform(-60.0, 60.0, N_POINTS)  # the grid spans +-49 x +-39 m
    scalar = np.array([field.height_at(a, b) for a, b in zip(x.tolist(), y.tolist())])
    assert np.array_equal(scalar, field.height_m(x, y))
    assert math.isnan(field.height_at(math.nan, 0.0)) and math.isnan(field.height_at(0.0, math.nan))


def test_compiled_vehicle_pose_equals_the_vectorised_terrain_pose_to_rounding(field):
    rng = np.random.default_rng(2)
    xy, heading = rng.uniform(-40.0, 40.0, (200, 2)), rng.uniform(-math.pi, math.pi, 200)
    centres, rotations = terrain_pose(field, xy, heading, HALF_EXTENTS_M)
    for i in range(len(heading)):
        c, s = math.cos(heading[i]), math.sin(heading[i])
        pose = scalar_terrain_pose(field.grid, float(xy[i, 0]), float(xy[i, 1]), c, s, *HALF_EXTENTS_M)
        # numpy's vectorised cos/sin and norms round in other places than the scalar code: 1 ulp seen
        np.testing.assert_allclose(pose[:3], centres[i], rtol=0, atol=POSE_TOL)
        np.testing.assert_allclose(pose[3:], rotations[i].ravel(), rtol=0, atol=POSE_TOL)


def test_gradient_at_equals_gradient_bit_for_bit_inside_and_beyond_the_grid(field):
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-70.0, 70.0, N_POINTS), rng.uniform(-60.0, 60.0, N_POINTS)
    scalar = np.array([field.gradient_at(a, b) for a, b in zip(x.tolist(), y.tolist())])
    assert np.array_equal(scalar, field.gradient(x, y))
    assert all(math.isnan(g) for g in field.gradient_at(math.nan, 0.0))
