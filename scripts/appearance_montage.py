"""Render docs/img/appearance_randomized.png: each scene's development world 3 as "fixed" and under four seeds'
`appearance="randomized"`, after half a second of yawing (so the motion blur shows), 256 px, one row per scene.

Deterministic: re-running reproduces the same PNG. Usage: python scripts/appearance_montage.py [out.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import trade_gym  # noqa: E402, F401  (registers TradeFollow-v0)

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "appearance_randomized.png"
SCENES = ("desert", "city", "mountain")
WORLD_SEED = 3  # a development world
SEEDS = (1, 2, 3, 4)  # reset seeds of the randomized columns (the fixed column uses the first)
IMAGE_PX = 256
YAW_STEPS = 15  # frames of yawing before the picture
YAW_ACTION = np.array([0.0, 0.0, 0.0, 0.6], np.float32)
LABEL_SCALE, LABEL_ORIGIN_PX = 0.5, (6, 18)


def frame(scene: str, appearance: str, seed: int) -> np.ndarray:
    """(IMAGE_PX, IMAGE_PX, 3) BGR camera image, labelled."""
    env = gym.make("TradeFollow-v0", scene=scene, perception="oracle", render_oracle_frames=True,
                   camera_size=IMAGE_PX, appearance=appearance, world_seed=WORLD_SEED)
    try:
        env.reset(seed=seed)
        for _ in range(YAW_STEPS):
            env.step(YAW_ACTION)
        image = np.ascontiguousarray(env.unwrapped.camera_frame.rgb[:, :, ::-1])
    finally:
        env.close()
    label = f"{scene} fixed" if appearance == "fixed" else f"{scene} seed {seed}"
    for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):  # white on a dark outline
        cv2.putText(image, label, LABEL_ORIGIN_PX, cv2.FONT_HERSHEY_SIMPLEX, LABEL_SCALE, colour, thickness,
                    cv2.LINE_AA)
    return image


def main(out: Path) -> None:
    looks = [("fixed", SEEDS[0])] + [("randomized", seed) for seed in SEEDS]
    rows = [np.concatenate([frame(scene, mode, seed) for mode, seed in looks], axis=1) for scene in SCENES]
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), np.concatenate(rows, axis=0), [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"could not write {out}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
