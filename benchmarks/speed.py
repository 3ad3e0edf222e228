"""Env speed in one run: oracle steps/s (no rendering), rendering steps/s at 256x256, the pybullet render alone,
and the full loop (full TRADE perception, the default, at 256x256), so the ratios are measured on the same machine
at the same moment.

Usage: python benchmarks/speed.py [--steps N] [--scene desert] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from step_clock import StepClock  # benchmarks/ is on sys.path when this script runs

from trade_gym.agents import ScriptedFollower
from trade_gym.bench.policies import HoverPolicy
from trade_gym.env import TradeFollowEnv
from trade_gym.provenance import git_commit
from trade_gym.rollout import fly_episode


def _steps_per_s(env: TradeFollowEnv, n_steps: int, seed: int,
                 policy_name: str = "scripted") -> tuple[float, float, float]:
    """(env.step calls per wall-clock second, per CPU second of this process, mean reset time [ms])
    under the named policy (hover: the zero action, the target soon leaves the view); with the scripted
    follower episodes run their full length, the k-th reset seeded seed + k; only the time inside step()
    and reset() is counted. CPU time excludes the VM's steal time, which makes wall-clock rates vary by
    +-30 % on a shared host."""
    policy = ScriptedFollower() if policy_name == "scripted" else HoverPolicy()
    clock = StepClock(env)
    while len(clock.step_s) < n_steps:
        fly_episode(clock, policy, seed + len(clock.reset_s), n_steps - len(clock.step_s))
    return n_steps / sum(clock.step_s), n_steps / sum(clock.step_cpu_s), float(np.mean(clock.reset_s)) * 1e3


def _render_ms(env: TradeFollowEnv, n_frames: int, seed: int) -> float:
    env.reset(seed=seed)
    T = env._true_camera_pose()
    start = time.perf_counter()
    for _ in range(n_frames):
        env.camera.render(T)
    return (time.perf_counter() - start) / n_frames * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--render-steps", type=int, default=100)
    parser.add_argument("--trade-steps", type=int, default=300, help="steps of the full TRADE loop at 256 px")
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--policy", choices=("scripted", "hover"), default="scripted")
    args = parser.parse_args()

    oracle = TradeFollowEnv(scene=args.scene, perception="oracle", camera_size=256)
    rendering = TradeFollowEnv(scene=args.scene, perception="oracle", camera_size=256, render_mode="rgb_array")
    trade = TradeFollowEnv(scene=args.scene, perception="trade", camera_size=256)
    try:
        oracle_sps, oracle_cpu_sps, reset_ms = _steps_per_s(oracle, args.steps, seed=0, policy_name=args.policy)
        render_sps, _, _ = _steps_per_s(rendering, args.render_steps, seed=0)
        render_ms = _render_ms(rendering, args.render_steps, seed=0)
        trade_sps, trade_cpu_sps, _ = _steps_per_s(trade, args.trade_steps, seed=0)
    finally:
        oracle.close()
        rendering.close()
        trade.close()
    result = {
        "scene": args.scene,
        "policy": args.policy,
        "oracle_steps_per_s": round(oracle_sps, 1),
        "oracle_steps_per_cpu_s": round(oracle_cpu_sps, 1),
        "reset_ms": round(reset_ms, 1),
        "rendering_steps_per_s_256": round(render_sps, 2),
        "render_only_ms_256": round(render_ms, 2),
        "rendering_step_ms_256": round(1e3 / render_sps, 2),
        "render_share_of_rendering_step": round(render_ms / (1e3 / render_sps), 3),
        "oracle_over_rendering_speed_ratio": round(oracle_sps / render_sps, 1),
        "trade_steps_per_s_256": round(trade_sps, 2),  # full TRADE perception, the scripted follower, one process
        "trade_steps_per_cpu_s_256": round(trade_cpu_sps, 2),
        "meta": {
            "commit": git_commit(),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "cpu": platform.processor() or platform.machine(),
            "python": platform.python_version(),
            "load_average_1min_at_end": round(os.getloadavg()[0], 2),
            "cores": os.cpu_count(),
        },
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
