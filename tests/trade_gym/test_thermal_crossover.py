"""The named times of day of the thermal scenes: the albedos the crossover rule assumes are those of the shipped
textures and paint, the crossover's contrast is near zero where night's and day's are not, and the city's white truck
never crosses (the rule gives its closest approach)."""

from __future__ import annotations

from importlib import resources

import cv2
import numpy as np
import pytest

from trade_gym.sim.scenes import SCENES
from trade_gym.sim.thermal_crossover import (
    DAY_H, FINE_STEP_H, MORNING_SEARCH_H, NIGHT_H, TARGET_ALBEDO, TERRAIN_ALBEDO, TIMES_OF_DAY, morning_crossover,
    parked_contrast_k, time_of_day_h,
)
from trade_gym.sim.thermal_scene import albedo_from_unlit_rgb
from trade_gym.sim.vehicles import PALETTE_RGB, _PARTS  # the parts' layout: the plan view's source

ALBEDO_ROUNDING = 5e-4  # the constants are written to 3 decimals
PLAN_CELL_M = 0.01  # raster of a vehicle's plan view [m]
CROSSED_K = 0.1  # |contrast| at the crossover hour: what a 3 min step of a few K/h leaves
NIGHT_DAY_MIN_K = 1.0  # night's and day's |contrast| at least this (the parked vehicle is plainly colder / warmer)


def _texture_albedo(name: str) -> float:
    path = resources.files("trade_gym.assets").joinpath("textures", f"{name}.png")
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return float(albedo_from_unlit_rgb(np.ascontiguousarray(bgr[:, :, ::-1])).mean())


def _plan_view_albedo(kind: str) -> float:
    """Area-weighted albedo of the top face of the highest part at each point of the vehicle's plan view."""
    palette = albedo_from_unlit_rgb(np.array(PALETTE_RGB, np.uint8)[None])[0]
    corners = np.array([part[0] for part in _PARTS[kind]])
    x = np.arange(corners[:, 0].min(), corners[:, 3].max(), PLAN_CELL_M) + PLAN_CELL_M / 2
    y = np.arange(corners[:, 1].min(), corners[:, 4].max(), PLAN_CELL_M) + PLAN_CELL_M / 2
    X, Y = np.meshgrid(x, y)
    top, albedo = np.full(X.shape, -np.inf), np.full(X.shape, np.nan)
    for (x0, y0, _, x1, y1, z1), top_colour, _ in _PARTS[kind]:
        inside = (X >= min(x0, x1)) & (X < max(x0, x1)) & (Y >= min(y0, y1)) & (Y < max(y0, y1)) & (z1 > top)
        top[inside], albedo[inside] = z1, palette[top_colour]
    return float(np.nanmean(albedo))


def test_the_assumed_albedos_are_those_of_the_shipped_textures_and_vehicle_paint():
    assert set(TERRAIN_ALBEDO) == {s.ground_texture for s in SCENES.values()}
    assert set(TARGET_ALBEDO) >= {s.target_kind for s in SCENES.values()}
    for texture, albedo in TERRAIN_ALBEDO.items():
        assert _texture_albedo(texture) == pytest.approx(albedo, abs=ALBEDO_ROUNDING), texture
    for kind, albedo in TARGET_ALBEDO.items():
        assert _plan_view_albedo(kind) == pytest.approx(albedo, abs=ALBEDO_ROUNDING), kind


@pytest.mark.parametrize("scene", ["desert", "mountain"])
def test_at_the_crossover_the_contrast_is_near_zero_and_at_night_and_by_day_it_is_not(scene):
    crossover = morning_crossover(scene)
    assert crossover.crosses and MORNING_SEARCH_H[0] < crossover.time_h < MORNING_SEARCH_H[1]
    assert abs(crossover.contrast_k) < CROSSED_K
    assert crossover.contrast_k == pytest.approx(parked_contrast_k(scene, crossover.time_h))
    night, day = parked_contrast_k(scene, NIGHT_H), parked_contrast_k(scene, DAY_H)
    assert night < -NIGHT_DAY_MIN_K and day > NIGHT_DAY_MIN_K  # shell colder than the ground at night, warmer by day


def test_the_city_truck_stays_colder_than_asphalt_and_the_crossover_is_its_closest_approach():
    crossover = morning_crossover("city")
    assert not crossover.crosses and crossover.contrast_k < -NIGHT_DAY_MIN_K
    hours = np.arange(*MORNING_SEARCH_H, FINE_STEP_H)
    assert abs(crossover.contrast_k) <= min(abs(parked_contrast_k("city", h)) for h in hours) + 1e-6
    assert abs(parked_contrast_k("city", NIGHT_H)) > abs(crossover.contrast_k) < abs(parked_contrast_k("city", DAY_H))


def test_named_times_of_day_give_night_day_and_each_scene_its_own_crossover():
    assert TIMES_OF_DAY == ("night", "crossover", "day")
    for scene in SCENES:
        assert time_of_day_h(scene, "night") == NIGHT_H and time_of_day_h(scene, "day") == DAY_H
        assert time_of_day_h(scene, "crossover") == morning_crossover(scene).time_h
    assert time_of_day_h("mountain", "crossover") != time_of_day_h("desert", "crossover")
    with pytest.raises(ValueError, match="'dusk'"):
        time_of_day_h("desert", "dusk")
    with pytest.raises(ValueError, match="'moon'"):
        time_of_day_h("moon", "crossover")
