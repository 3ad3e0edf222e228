"""Env speed in one run: oracle steps/s (no rendering), rendering steps/s at 256x256, and the
pybullet render alone, so the ratios are measured on the same machine at the same moment.

Usage: python benchmarks/speed.py [--steps N] [--scene desert] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from trade_gym.env import TradeFollowEnv


def _steps_per_s(env: TradeFollowEnv, n_steps: int, seed: int) -> float:
    env.reset(seed=seed)
    action = np.zeros(4, np.float32)
    start = time.perf_counter()
    done_steps = 0
    while done_steps < n_steps:
        _, _, terminated, truncated, _ = env.step(action)
        done_steps += 1
        if terminated or truncated:
            env.reset(seed=seed)
    return done_steps / (time.perf_counter() - start)


def _render_ms(env: TradeFollowEnv, n_frames: int, seed: int) -> float:
    env.reset(seed=seed)
    T = env.unwrapped._true_camera_pose()
    start = time.perf_counter()
    for _ in range(n_frames):
        env.camera.render(T)
    return (time.perf_counter() - start) / n_frames * 1e3


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--render-steps", type=int, default=100)
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()

    oracle = TradeFollowEnv(scene=args.scene, perception="oracle", camera_size=256)
    rendering = TradeFollowEnv(scene=args.scene, perception="oracle", camera_size=256, render_mode="rgb_array")
    try:
        oracle_sps = _steps_per_s(oracle, args.steps, seed=0)
        render_sps = _steps_per_s(rendering, args.render_steps, seed=0)
        render_ms = _render_ms(rendering, args.render_steps, seed=0)
    finally:
        oracle.close()
        rendering.close()
    result = {
        "scene": args.scene,
        "oracle_steps_per_s": round(oracle_sps, 1),
        "rendering_steps_per_s_256": round(render_sps, 2),
        "render_only_ms_256": round(render_ms, 2),
        "rendering_step_ms_256": round(1e3 / render_sps, 2),
        "render_share_of_rendering_step": round(render_ms / (1e3 / render_sps), 3),
        "oracle_over_rendering_speed_ratio": round(oracle_sps / render_sps, 1),
        "meta": {
            "commit": _commit(),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "cpu": platform.processor() or platform.machine(),
            "python": platform.python_version(),
        },
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
