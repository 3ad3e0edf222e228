"""Optional video of one benchmark run: the annotated onboard view beside a top view, over a strip of IoU
and depth error (`trade_gym.bench.dashboard`), written as mp4 (OpenCV) or, without an mp4 encoder, as a GIF.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np

from trade_gym.bench.dashboard import Dashboard
from trade_gym.bench.runner import fly
from trade_gym.bench.suites import RunSpec
from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.env import TradeFollowEnv

MP4_FOURCC = "mp4v"
VIDEO_PANEL_PX = 512  # onboard view and top view side; the video is twice as wide
GIF_FRAME_STRIDE = 3  # GIF fallback keeps every 3rd frame (10 fps) to stay small
GIF_FRAME_MS = int(1000 * GIF_FRAME_STRIDE / CAMERA_RATE_HZ)


def record_video(spec: RunSpec, out_stem: Path) -> Path:
    """Fly `spec` again with rendering on, at a camera of at least VIDEO_PANEL_PX, and write its dashboard
    frames (`trade_gym.bench.dashboard`) to `<out_stem>.mp4` (or `.gif`).

    A separate episode from the scored one (rendering on, and the camera may be larger), so the benchmark's
    metrics never come from this pass."""
    frames: list[np.ndarray] = []
    board: list[Dashboard] = []

    def grab(env: gym.Env, obs: dict, info: dict) -> None:
        base, image = env.unwrapped, env.render()
        if not isinstance(base, TradeFollowEnv) or not isinstance(image, np.ndarray):  # as `fly` builds it
            raise TypeError(f"record_video needs a TradeFollow-v0 env rendering rgb_array, got {type(base).__name__}")
        if not board:  # the reset: the world exists now
            board.append(Dashboard(base.world, VIDEO_PANEL_PX, spec.steps * base.config.frame_dt_s))
        frames.append(board[0].frame(image, info, base.estimate.position_world_m))

    fly(dataclasses.replace(spec, camera_size=max(spec.camera_size, VIDEO_PANEL_PX)), on_frame=grab, render=True)
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
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*MP4_FOURCC), float(rate_hz), (w, h))
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
