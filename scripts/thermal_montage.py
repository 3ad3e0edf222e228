"""Render docs/img/thermal_montage.png: one frame of each scene's development world 3 as the real-flight suite's camera
sees it (45 deg pitch, the waypoint follower settled behind the target on oracle estimates, so every column flies the
same path), in RGB and through the thermal camera at the suite's times of day: night (2 h), the morning crossover and
day (13 h), in the false colour of `render()`.

The hours are the library's (`trade_gym.sim.thermal_crossover.time_of_day_h`): the crossover is the morning hour at
which the scene's target's parked twin comes closest to the terrain's temperature (a white truck never gets as warm as
dark asphalt: then the closest approach). Deterministic: re-running reproduces the same PNG.
Usage: python scripts/thermal_montage.py [out.png]
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
from trade_gym.agents import WaypointFollower, WaypointFollowerConfig  # noqa: E402
from trade_gym.annotate import display_image  # noqa: E402
from trade_gym.bench.suites import REAL_FLIGHT_ENV  # noqa: E402
from trade_gym.sim.thermal_crossover import TIMES_OF_DAY, morning_crossover, time_of_day_h  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "thermal_montage.png"
SCENES = ("desert", "mountain", "city")
WORLD_SEED, RESET_SEED = 3, 1  # a development world
IMAGE_PX = 176
PALETTE_COLOURS = 256  # the PNG is written with a palette of this many colours (keeps it small)
LABEL_SCALE, LABEL_ORIGIN_PX = 0.42, (5, 15)
# the suite's camera (pitch) and follower on a development world, rendered without running perception
ENV = dict(perception="oracle", render_oracle_frames=True, camera_size=IMAGE_PX, world_seed=WORLD_SEED,
           camera_pitch_deg=dict(REAL_FLIGHT_ENV)["camera_pitch_deg"], action_mode="waypoint")
SETTLE_STEPS = 90  # frames flown before the one shown (3 s: the follower has backed off to its place behind the target)


def frame(scene: str, time_h: float | None, label: str) -> np.ndarray:
    """(IMAGE_PX, IMAGE_PX, 3) RGB image as `render()` shows it (without boxes), labelled; RGB when time_h is None."""
    thermal = {} if time_h is None else dict(camera_modality="thermal", time_of_day_h=time_h)
    env = gym.make("TradeFollow-v0", scene=scene, **ENV, **thermal)
    try:
        obs, _ = env.reset(seed=RESET_SEED)
        follower = WaypointFollower(WaypointFollowerConfig.of(env.unwrapped.config))
        for _ in range(SETTLE_STEPS):
            obs = env.step(follower.predict(obs)[0])[0]
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
        crossover = morning_crossover(scene)
        print(f"{scene}: crossover at {crossover.time_h:.2f} h, parked target minus terrain {crossover.contrast_k:+.2f} K"
              f"{'' if crossover.crosses else ' (closest approach: they do not cross)'}")
        hours = {name: time_of_day_h(scene, name) for name in TIMES_OF_DAY}
        looks = ((None, f"{scene} rgb"), *((hour, f"{name} {hour:.2f} h") for name, hour in hours.items()))
        rows.append(np.concatenate([frame(scene, t, label) for t, label in looks], axis=1))
    out.parent.mkdir(parents=True, exist_ok=True)
    montage = Image.fromarray(np.concatenate(rows, axis=0)).quantize(PALETTE_COLOURS, dither=Image.Dither.NONE)
    montage.save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
