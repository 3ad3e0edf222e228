"""The thermal scene's physics, as properties: the sun's path, the air's day, night and day contrasts, the crossover,
sun-facing surfaces warmer, normals from depth, driving vehicles' heat."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.geometry import CameraIntrinsics
from trade_gym.sim.thermal_camera import normals_from_points
from trade_gym.sim.thermal_scene import (
    LATITUDE_DEG, MATERIALS, SurfaceModel, ThermalLook, air_temperature_k, albedo_from_unlit_rgb, draw_thermal_look,
    sun_direction,
)

NIGHT_H, DAY_H = 2.0, 13.0
# Albedos of the shipped colours (`albedo_from_unlit_rgb` of the textures' means and the paint cells): sand, soil,
# asphalt; a red car, an olive tank
GROUND = {"sand": 0.28, "soil": 0.15, "pavement": 0.12}
PAINT = {"car": 0.12, "tank": 0.11}
SOUTH_SLOPE = (0.0, -math.sin(math.radians(30.0)), math.cos(math.radians(30.0)))
NORTH_SLOPE = (0.0, math.sin(math.radians(30.0)), math.cos(math.radians(30.0)))


def _t(model: SurfaceModel, material: str, albedo: float, normal=(0.0, 0.0, 1.0)) -> float:
    return model.material_temperature_k(material, albedo, normal)


def test_sun_rises_in_the_east_stands_south_at_noon_and_sets_in_the_west():
    east, north, up = sun_direction(6.0)
    assert east == pytest.approx(1.0) and abs(north) < 1e-9 and abs(up) < 1e-9
    _, north, up = sun_direction(12.0)
    assert north < 0.0 and math.degrees(math.asin(up)) == pytest.approx(90.0 - LATITUDE_DEG)
    assert sun_direction(18.0)[0] == pytest.approx(-1.0)
    assert sun_direction(0.0)[2] < 0.0


def test_air_is_coldest_before_dawn_and_warmest_in_the_afternoon():
    look = ThermalLook(0.0)
    hours = np.arange(0.0, 24.0, 0.25)
    air = [air_temperature_k(look, h) for h in hours]
    assert 14.0 <= hours[int(np.argmax(air))] <= 16.0 and hours[int(np.argmin(air))] <= 4.0
    assert max(air) - min(air) == pytest.approx(2.0 * look.air_amplitude_k)


@pytest.mark.parametrize("ground, vehicle", [("sand", "car"), ("pavement", "car"), ("soil", "tank")])
def test_parked_vehicles_are_colder_than_the_ground_at_night_warmer_by_day_and_cross_over_at_dawn_and_dusk(
        ground, vehicle):
    def contrast(hour: float) -> float:
        model = SurfaceModel(ThermalLook(hour))
        return _t(model, vehicle, PAINT[vehicle]) - _t(model, ground, GROUND[ground])

    assert contrast(NIGHT_H) < -1.0 and contrast(DAY_H) > 3.0
    hours = np.arange(4.0, 21.0, 0.25)
    signs = np.sign([contrast(h) for h in hours])
    crossings = hours[1:][signs[1:] != signs[:-1]]
    assert len(crossings) == 2  # once after sunrise, once in the late afternoon (pavement stores more): crossovers
    assert 6.0 < crossings[0] < 10.0 and 15.0 < crossings[1] < 20.0


def test_surfaces_facing_the_sun_and_darker_ones_are_warmer_by_day_only():
    day, night = SurfaceModel(ThermalLook(DAY_H)), SurfaceModel(ThermalLook(NIGHT_H))
    assert _t(day, "soil", 0.15, SOUTH_SLOPE) > _t(day, "soil", 0.15) + 2.0 > _t(day, "soil", 0.15, NORTH_SLOPE) + 4.0
    assert _t(day, "sand", 0.1) > _t(day, "sand", 0.5) + 5.0
    assert abs(_t(night, "soil", 0.15, SOUTH_SLOPE) - _t(night, "soil", 0.15, NORTH_SLOPE)) < 0.1


def test_roofs_warm_with_the_sun_and_walls_facing_it_warm_more_than_walls_in_shade():
    hours = (4.0, 8.0, 11.0, 13.0)
    roofs = [_t(SurfaceModel(ThermalLook(h)), "concrete", 0.3) for h in hours]
    assert np.all(np.diff(roofs) > 0.0)
    afternoon = SurfaceModel(ThermalLook(15.0))  # sun in the south-west
    assert _t(afternoon, "concrete", 0.3, (-1.0, 0.0, 0.0)) > _t(afternoon, "concrete", 0.3, (1.0, 0.0, 0.0)) + 5.0


def test_heavy_materials_lag_the_sun_more_than_thin_shells():
    def hottest_hour(material: str) -> float:
        hours = np.arange(10.0, 18.0, 0.25)
        return float(hours[np.argmax([_t(SurfaceModel(ThermalLook(h)), material, 0.2) for h in hours])])

    assert hottest_hour("car") <= 13.0 < hottest_hour("rock")
    assert hottest_hour("car") < hottest_hour("tank")  # 25 mm armour stores more than 1 mm sheet


def test_randomized_look_draws_time_air_wind_and_emissivity_within_their_ranges_and_keeps_a_given_time():
    looks = [draw_thermal_look(np.random.default_rng(seed), None) for seed in range(20)]
    assert len({look.time_of_day_h for look in looks}) == 20
    for look in looks:
        for value, material in zip(look.emissivity, MATERIALS.values()):
            assert material.emissivity_range[0] <= value <= material.emissivity_range[1]
    given = draw_thermal_look(np.random.default_rng(0), 5.5)
    assert given.time_of_day_h == 5.5 and given.air_mean_k == looks[0].air_mean_k  # the same draws otherwise


def test_albedo_is_the_linear_luminance_of_the_unlit_colour():
    rgb = np.array([[[0, 0, 0], [255, 255, 255], [188, 188, 188], [255, 0, 0]]], np.uint8)
    np.testing.assert_allclose(albedo_from_unlit_rgb(rgb)[0], [0.0, 1.0, 0.5029, 0.2126], atol=1e-3)


def test_normals_from_depth_of_a_tilted_plane_and_at_an_object_edge():
    K = CameraIntrinsics.from_fov(32, 32, 90.0)
    u, v = np.meshgrid((np.arange(32) - K.cx_px) / K.fx_px, (np.arange(32) - K.cy_px) / K.fy_px)
    rays = np.stack([u, v, np.ones_like(u)], axis=-1).astype(np.float32)
    # the plane z = 10 + 0.5 x (camera frame): normal (0.5, 0, -1) / |.| facing the camera
    depth = (10.0 / (1.0 - 0.5 * u)).astype(np.float32)
    depth[:, 20:] = 5.0  # a box face nearer the camera on the right
    normals = normals_from_points(depth[:, :, None] * rays)
    expected = np.array([0.5, 0.0, -1.0]) / math.hypot(0.5, 1.0)
    np.testing.assert_allclose(normals[:, :20].reshape(-1, 3), np.tile(expected, (32 * 20, 1)), atol=1e-4)
    np.testing.assert_allclose(normals[:, 20:].reshape(-1, 3), np.tile([0.0, 0.0, -1.0], (32 * 12, 1)), atol=1e-4)
