"""TRADE against its DCF baseline (no trajectory guidance) with the scripted follower:
tracked fraction, decoy switches, ground- and target-depth RMSE per seed, in one run.

Usage: python benchmarks/tracking_compare.py --scene desert --seeds 0 1 2 3 4 --steps 300 [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from trade_gym.agents import ScriptedFollower
from trade_gym import metrics
from trade_gym.rollout import run_episode


def score(scene: str, perception: str, seed: int, steps: int, pose_source: str) -> dict:
    infos = run_episode(ScriptedFollower(), seed, max_steps=steps, scene=scene, perception=perception,
                        camera_size=256, pose_source=pose_source)
    return {
        "perception": perception, "seed": seed, "steps": len(infos),
        "tracked_fraction": metrics.tracked_fraction(infos),
        "switches": metrics.decoy_switches(infos),
        "ground_depth_rmse_m": metrics.depth_rmse(infos, "ground"),
        "target_depth_rmse_m": metrics.depth_rmse(infos, "target"),
        "crashed": metrics.crashed(infos),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--pose-source", default="gt")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    rows = [score(args.scene, mode, seed, args.steps, args.pose_source)
            for mode in ("trade", "dcf") for seed in args.seeds]
    print("| perception | seed | steps | tracked | switches | ground RMSE [m] | target RMSE [m] |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['perception']} | {r['seed']} | {r['steps']} | {r['tracked_fraction']:.3f} | {r['switches']} | "
              f"{r['ground_depth_rmse_m']:.2f} | {r['target_depth_rmse_m']:.2f} |")
    for mode in ("trade", "dcf"):
        sel = [r for r in rows if r["perception"] == mode]
        print(f"{mode}: mean tracked {np.mean([r['tracked_fraction'] for r in sel]):.3f}, "
              f"switches {sum(r['switches'] for r in sel)}, "
              f"ground RMSE {np.mean([r['ground_depth_rmse_m'] for r in sel]):.2f} m")
    if args.json:
        args.json.write_text(json.dumps({"scene": args.scene, "rows": rows,
                                         "load_average_1min_at_end": round(os.getloadavg()[0], 2)}, indent=2))


if __name__ == "__main__":
    main()
