"""Optional video of one benchmark run: the env's annotated frames (truth and estimate boxes,
trajectory, features) written as mp4 (OpenCV) or, when no mp4 encoder is available, as a GIF.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

from trade_gym.bench.runner import fly
from trade_gym.bench.suites import RunSpec
from trade_gym.config import CAMERA_RATE_HZ

MP4_FOURCC = "mp4v"
GIF_FRAME_STRIDE = 3  # GIF fallback keeps every 3rd frame (10 fps) to stay small
GIF_FRAME_MS = int(1000 * GIF_FRAME_STRIDE / CAMERA_RATE_HZ)


def record_video(spec: RunSpec, out_stem: Path) -> Path:
    """Fly `spec` again with rendering on and write its frames to `<out_stem>.mp4` (or `.gif`).

    A separate episode from the scored one: turning rendering on changes how an oracle run finds
    its ground truth, so the benchmark's metrics never come from this pass."""
    frames: list[np.ndarray] = []

    def grab(env: gym.Env, obs: dict, info: dict) -> None:
        frames.append(env.render())

    fly(spec, on_frame=grab, render=True)
    return write_video(frames, out_stem)


def write_video(frames: list[np.ndarray], out_stem: Path, rate_hz: float = CAMERA_RATE_HZ) -> Path:
    """Write RGB frames (H, W, 3) uint8 at `rate_hz` to `<out_stem>.mp4`, or to `<out_stem>.gif` (every
    GIF_FRAME_STRIDE-th frame) when OpenCV has no mp4 encoder; returns the file written."""
    if not frames:
        raise ValueError(f"{out_stem}: no frames to write")
    mp4 = out_stem.with_suffix(".mp4")
    if _write_mp4(mp4, frames, rate_hz):
        return mp4
    gif = out_stem.with_suffix(".gif")
    _write_gif(gif, frames[::GIF_FRAME_STRIDE], int(1000 * GIF_FRAME_STRIDE / rate_hz))
    return gif


def _write_mp4(path: Path, frames: list[np.ndarray], rate_hz: float) -> bool:
    """True when OpenCV's mp4 writer accepted every frame (RGB in, BGR to the codec)."""
    if not frames:
        return False
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*MP4_FOURCC), float(rate_hz), (w, h))
    if not writer.isOpened():
        return False
    try:
        for f in frames:
            writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    return path.exists() and path.stat().st_size > 0


def _write_gif(path: Path, frames: list[np.ndarray], frame_ms: int = GIF_FRAME_MS) -> None:
    from PIL import Image  # Pillow comes with matplotlib

    images = [Image.fromarray(f) for f in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=frame_ms, loop=0)
