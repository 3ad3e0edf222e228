"""`make demo`: fly the scripted follower in each scene headless, print a score table and
write an annotated GIF per scene.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from agents import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.config import SCENE_NAMES

GIF_FRAME_STRIDE = 3  # keep every 3rd frame: 10 fps at a 30 Hz camera
GIF_FRAME_MS = 100


@dataclass(frozen=True)
class DemoScore:
    scene: str
    steps: int
    visible_fraction: float
    mean_distance_error_m: float
    crashed: bool
    wall_s: float


def fly(scene: str, seed: int, duration_s: float, perception: str, camera_size: int,
        gif_path: Path | None) -> DemoScore:
    env = gym.make("TradeFollow-v0", scene=scene, perception=perception, camera_size=camera_size,
                   episode_duration_s=duration_s, render_mode="rgb_array" if gif_path else None)
    policy = ScriptedFollower(ScriptedFollowerConfig(camera_pitch_deg=env.unwrapped.config.camera_pitch_deg))
    frames, visible, distance = [], [], []
    crashed = False
    start = time.perf_counter()
    try:
        obs, info = env.reset(seed=seed)
        episode_start = True
        done = False
        while not done:
            action, _ = policy.predict(obs, episode_start=np.array([episode_start]))
            episode_start = False
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            visible.append(info["target_visible"])
            distance.append(info["horizontal_distance_m"])
            crashed = crashed or info["crashed"]
            if gif_path is not None and len(visible) % GIF_FRAME_STRIDE == 0:
                frames.append(env.render())
    finally:
        env.close()
    if gif_path is not None and frames:
        _write_gif(gif_path, frames)
    return DemoScore(scene, len(visible), float(np.mean(visible)), float(np.mean(distance)), crashed,
                     time.perf_counter() - start)


def _write_gif(path: Path, frames: list[np.ndarray]) -> None:
    from PIL import Image  # Pillow comes with matplotlib

    images = [Image.fromarray(f) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=GIF_FRAME_MS, loop=0)


def format_table(scores: list[DemoScore]) -> str:
    lines = ["| scene | steps | visible fraction | mean distance error [m] | crashed | wall [s] |",
             "|---|---|---|---|---|---|"]
    for s in scores:
        lines.append(f"| {s.scene} | {s.steps} | {s.visible_fraction:.3f} | {s.mean_distance_error_m:.2f} | "
                     f"{s.crashed} | {s.wall_s:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("demo_out"), help="folder for GIFs and the table")
    parser.add_argument("--scenes", nargs="+", default=list(SCENE_NAMES), choices=SCENE_NAMES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--perception", default="trade", choices=("oracle", "trade", "dcf"))
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--no-gif", action="store_true")
    args = parser.parse_args(argv)
    if not args.out.parent.exists():
        parser.error(f"--out parent folder does not exist: {args.out.parent}")
    args.out.mkdir(exist_ok=True)
    scores = []
    for scene in args.scenes:
        gif = None if args.no_gif else args.out / f"{scene}.gif"
        scores.append(fly(scene, args.seed, args.duration_s, args.perception, args.camera_size, gif))
        print(f"{scene}: done in {scores[-1].wall_s:.1f} s", file=sys.stderr)
    table = format_table(scores)
    (args.out / "scores.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
