"""Milliseconds per frame of each TRADE stage, measured in the env beside the render time.

Usage: python benchmarks/profile_trade.py [--scene desert] [--steps 300] [--camera-size 256] [--no-ground-mask]
       [--json OUT]
The scripted follower flies; the stack runs on every rendered frame (pose_source="gt"). Full TRADE (the env's
default, ground mask on) unless --no-ground-mask.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

from step_clock import StepClock  # benchmarks/ is on sys.path when this script runs

from trade_gym.agents import ScriptedFollower
from trade.pipeline import StageTimings
from trade_gym.env import TradeFollowEnv
from trade_gym.rollout import fly_episode

PERCENTILES = (50, 90, 99)


def profile(scene: str, steps: int, camera_size: int, seed: int, ground_mask: bool = True) -> dict:
    env = TradeFollowEnv(scene=scene, perception="trade", camera_size=camera_size, ground_mask=ground_mask)
    render_ms: list[float] = []
    original_render = env.camera.render

    def timed_render(T):
        start = time.perf_counter()
        frame = original_render(T)
        render_ms.append((time.perf_counter() - start) * 1e3)
        return frame

    env.camera.render = timed_render
    stages: dict[str, list[float]] = {f.name: [] for f in fields(StageTimings)}

    def read_stages(flown, obs, info) -> None:
        timings = env.perception.last.timings
        for name in stages:
            stages[name].append(getattr(timings, name))

    clock = StepClock(env)
    try:
        fly_episode(clock, ScriptedFollower(), seed, steps, on_step=read_stages)
    finally:
        env.close()
    step_ms = [1e3 * s for s in clock.step_s]
    stack = np.sum([stages[n] for n in stages], axis=0)
    table = {name: _summary(v) for name, v in stages.items()}
    table["stack_total_ms"] = _summary(stack)
    table["render_ms"] = _summary(render_ms[1:])  # the first render belongs to reset
    table["env_step_ms"] = _summary(step_ms)
    return {"scene": scene, "camera_size": camera_size, "ground_mask": ground_mask, "steps": len(step_ms),
            "ms_per_frame": table,
            "load_average_1min_at_end": round(os.getloadavg()[0], 2)}


def _summary(values) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    out = {"mean": round(float(v.mean()), 2)}
    out.update({f"p{q}": round(float(np.percentile(v, q)), 2) for q in PERCENTILES})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-ground-mask", action="store_true", help="TRADE without the ground mask")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    result = profile(args.scene, args.steps, args.camera_size, args.seed, ground_mask=not args.no_ground_mask)
    print(f"{'stage':<16}{'mean':>8}{'p50':>8}{'p90':>8}{'p99':>8}   [ms per frame]")
    for name, s in result["ms_per_frame"].items():
        print(f"{name:<16}{s['mean']:>8.2f}{s['p50']:>8.2f}{s['p90']:>8.2f}{s['p99']:>8.2f}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
