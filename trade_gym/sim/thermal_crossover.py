"""The named times of day of a thermal scene (night, the morning crossover, day) and the rule that finds a scene's
crossover hour from the thermal model of its target's material and its terrain's.

Owns `NIGHT_H`, `DAY_H`, `TIMES_OF_DAY`, the albedos the rule assumes (`TERRAIN_ALBEDO`, `TARGET_ALBEDO`),
`parked_contrast_k`, `Crossover`, `morning_crossover` and `time_of_day_h` (a named time for one scene).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from trade_gym.sim.scenes import get_scene
from trade_gym.sim.thermal_camera import DEFAULT_TIME_OF_DAY_H, TERRAIN_MATERIAL
from trade_gym.sim.thermal_scene import SOLAR_NOON_H, SurfaceModel, ThermalLook

# Night: the small hours, 8 h after the equinox sunset (18 h): the thin vehicle shells have long radiated down to the
# sky while the heavy ground still gives back the day's heat (the night contrast of tests/trade_gym/test_thermal_scene)
NIGHT_H = 2.0
DAY_H = DEFAULT_TIME_OF_DAY_H  # 13 h: early afternoon, the thermal camera's default (its sun near the RGB scenes')
TIMES_OF_DAY = ("night", "crossover", "day")  # in the order of the day: deep night, after sunrise, early afternoon
# The morning crossover is searched from an hour before the equinox sunrise (6 h) to solar noon (the afternoon one,
# after 15 h, is the other crossing of the day), first on a coarse grid, then finely around its best hour
MORNING_SEARCH_H = (5.0, SOLAR_NOON_H)
COARSE_STEP_H = 0.5
FINE_STEP_H = 0.05  # 3 min: the hour's resolution

# The albedos the rule assumes (the thermal camera reads each pixel's albedo off the unlit render; the rule needs one
# number per surface). Terrain: the mean of `albedo_from_unlit_rgb` over every pixel of the shipped texture
# (assets/textures/<name>.png; mean albedo, not the albedo of the mean colour, since temperature is linear in it).
# Target: the vehicle's plan view, the area-weighted albedo of the top face of its highest part at each point
# (`vehicles._PARTS`' top colours in `vehicles.PALETTE_RGB`): what a camera above sees, with appearance="fixed".
# tests/trade_gym/test_thermal_crossover.py recomputes both from the shipped files.
TERRAIN_ALBEDO = MappingProxyType({"desert_ground": 0.307, "city_ground": 0.107, "mountain_ground": 0.177})
TARGET_ALBEDO = MappingProxyType({"car": 0.090, "truck": 0.825, "tank": 0.113})


def parked_contrast_k(scene: str, time_h: float) -> float:
    """Temperature of the scene's target's parked twin minus its terrain's [K] at solar time `time_h`, both
    horizontal, under the default thermal look (`ThermalLook`: a mild clear day): the target kind's material with
    `TARGET_ALBEDO`, the terrain texture's material with `TERRAIN_ALBEDO`. Parked: a driving target adds its running
    heat (`thermal_camera.RUNNING_BODY_EXCESS_K` and more on its engine and exhaust) on top."""
    spec = get_scene(scene)
    model = SurfaceModel(ThermalLook(float(time_h)))
    target = model.material_temperature_k(spec.target_kind, TARGET_ALBEDO[spec.target_kind])
    ground = TERRAIN_MATERIAL[spec.ground_texture]
    return target - model.material_temperature_k(ground, TERRAIN_ALBEDO[spec.ground_texture])


@dataclass(frozen=True)
class Crossover:
    """A scene's morning crossover: the hour [h, solar time] at which its target's parked twin comes nearest the
    terrain's temperature, the contrast left there [K] (target minus terrain), and whether the two cross at all in
    the morning (False: the hour is the closest approach, e.g. the city's white truck stays colder than asphalt)."""

    time_h: float
    contrast_k: float
    crosses: bool


@functools.cache
def morning_crossover(scene: str) -> Crossover:
    """The scene's `Crossover`: the hour of least |`parked_contrast_k`| between `MORNING_SEARCH_H`, found on a
    `COARSE_STEP_H` grid and refined to `FINE_STEP_H` around its best hour (computed once per scene and process)."""
    first_h, last_h = MORNING_SEARCH_H
    coarse = np.arange(first_h, last_h + COARSE_STEP_H / 2, COARSE_STEP_H)
    contrast = np.array([parked_contrast_k(scene, h) for h in coarse])
    best = coarse[int(np.argmin(np.abs(contrast)))]
    fine = np.arange(max(best - COARSE_STEP_H, first_h), min(best + COARSE_STEP_H, last_h) + FINE_STEP_H / 2,
                     FINE_STEP_H)
    fine_contrast = np.array([parked_contrast_k(scene, h) for h in fine])
    i = int(np.argmin(np.abs(fine_contrast)))
    crosses = bool(np.any(np.sign(contrast[1:]) != np.sign(contrast[:-1])))
    return Crossover(round(float(fine[i]), 2), float(fine_contrast[i]), crosses)


def time_of_day_h(scene: str, name: str) -> float:
    """The hour [h, solar time] of the named time of day (`TIMES_OF_DAY`) in `scene`: `NIGHT_H`, `DAY_H`, or the
    scene's `morning_crossover`; ValueError naming an unknown name (or scene)."""
    if name == "night":
        return NIGHT_H
    if name == "day":
        return DAY_H
    if name == "crossover":
        return morning_crossover(scene).time_h
    raise ValueError(f"time of day must be one of {TIMES_OF_DAY}, got {name!r}")
