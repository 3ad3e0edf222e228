"""Render docs/img/thermal_montage.png: the reset frame of each scene's development world 3 in RGB and through the
thermal camera at night (2 h), at the morning crossover and by day (13 h), in the false colour of `render()`.

The crossover hour is computed per scene from the thermal scene's model: the morning hour at which the target's parked
twin (its material, the mean albedo of its pixels) comes closest to the terrain's temperature (its material and mean
albedo), both horizontal (a white truck never gets as warm as dark asphalt: then the closest approach).
Deterministic: re-running reproduces the same PNG. Usage: python scripts/thermal_montage.py [out.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import trade_gym  # noqa: E402, F401  (registers TradeFollow-v0)
from trade_gym.annotate import display_image  # noqa: E402
from trade_gym.sim.thermal_camera import TERRAIN_MATERIAL, UNLIT  # noqa: E402
from trade_gym.sim.thermal_scene import SurfaceModel, ThermalLook, albedo_from_unlit_rgb  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "thermal_montage.png"
SCENES = ("desert", "mountain", "city")
WORLD_SEED, RESET_SEED = 3, 1  # a development world
NIGHT_H, DAY_H = 2.0, 13.0
CROSSOVER_SEARCH_H = (5.0, 11.0)
CROSSOVER_STEP_H = 0.05
IMAGE_PX = 176
PALETTE_COLOURS = 256  # the PNG is written with a palette of this many colours (keeps it small)
LABEL_SCALE, LABEL_ORIGIN_PX = 0.42, (5, 15)
ENV = dict(perception="oracle", render_oracle_frames=True, camera_size=IMAGE_PX, world_seed=WORLD_SEED)


def crossover_h(scene: str) -> float:
    """The morning hour at which the target's parked twin and the terrain are nearest in temperature (see above)."""
    env = gym.make("TradeFollow-v0", scene=scene, **ENV)
    try:
        env.reset(seed=RESET_SEED)
        base = env.unwrapped
        frame = base.camera.render(base.true_camera_pose, UNLIT)
        world, albedo = base.world, albedo_from_unlit_rgb(frame.rgb)
        vehicle = float(albedo[frame.seg == world.target.body_id].mean())
        ground = float(albedo[np.isin(frame.seg, world.body_ids_by_role["terrain"])].mean())
        kind, terrain = world.target.kind, TERRAIN_MATERIAL[world.spec.ground_texture]
    finally:
        env.close()
    hours = np.arange(*CROSSOVER_SEARCH_H, CROSSOVER_STEP_H)
    contrast = [SurfaceModel(ThermalLook(float(h))).material_temperature_k(kind, vehicle)
                - SurfaceModel(ThermalLook(float(h))).material_temperature_k(terrain, ground) for h in hours]
    return float(hours[int(np.argmin(np.abs(contrast)))])


def frame(scene: str, time_h: float | None, label: str) -> np.ndarray:
    """(IMAGE_PX, IMAGE_PX, 3) RGB image as `render()` shows it (without boxes), labelled; RGB when time_h is None."""
    thermal = {} if time_h is None else dict(camera_modality="thermal", time_of_day_h=time_h)
    env = gym.make("TradeFollow-v0", scene=scene, **ENV, **thermal)
    try:
        env.reset(seed=RESET_SEED)
        image = display_image(env.unwrapped.camera_frame.rgb, env.unwrapped.config.camera_modality).copy()
    finally:
        env.close()
    for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):  # white on a dark outline
        cv2.putText(image, label, LABEL_ORIGIN_PX, cv2.FONT_HERSHEY_SIMPLEX, LABEL_SCALE, colour, thickness,
                    cv2.LINE_AA)
    return image


def main(out: Path) -> None:
    rows = []
    for scene in SCENES:
        dawn = crossover_h(scene)
        print(f"{scene}: crossover at {dawn:.2f} h")
        looks = ((None, f"{scene} rgb"), (NIGHT_H, f"night {NIGHT_H:.2f} h"), (dawn, f"crossover {dawn:.2f} h"),
                 (DAY_H, f"day {DAY_H:.2f} h"))
        rows.append(np.concatenate([frame(scene, t, label) for t, label in looks], axis=1))
    out.parent.mkdir(parents=True, exist_ok=True)
    montage = Image.fromarray(np.concatenate(rows, axis=0)).quantize(PALETTE_COLOURS, dither=Image.Dither.NONE)
    montage.save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
