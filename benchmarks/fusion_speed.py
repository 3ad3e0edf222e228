"""Before/after cost of one temporal-fusion update, the base tree's and this tree's alternated in one run.

Both trade/temporal_fusion.py versions run over the same synthetic frames, so both see the same machine load.

Frames: a target driving 0.1 m per frame over gently sloping ground, its ROI points within 5 m of it
(0.15 m depth noise); 8 points per frame (the city at 256 px) and 100 (the desert).

Usage: git worktree add /tmp/base <commit>; python benchmarks/fusion_speed.py --base /tmp/base
       [--rounds 5] [--json OUT]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np
from ab_speed import median_ratio, run_meta  # benchmarks/ is on sys.path when this script runs


HERE = Path(__file__).resolve().parents[1]
N_FRAMES = 450  # the paper's 15 s at 30 Hz
STEP_M = 0.1  # target travel per frame
ROI_HALF_LENGTH_M, ROI_HALF_WIDTH_M = 5.0, 4.0
GROUND_SLOPE = 0.01
DEPTH_NOISE_M = 0.15
POINTS_PER_FRAME = {"city-like": 8, "desert-like": 100}
MIN_POINTS = 6  # the masked-plane minimum the pipeline passes to the fusion


def _load(root: Path, name: str) -> ModuleType:
    """trade/temporal_fusion.py of `root` as module `name` (its imports resolve to this tree's trade)."""
    spec = importlib.util.spec_from_file_location(name, root / "trade" / "temporal_fusion.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _frames(points_per_frame: int, rng: np.random.Generator) -> list[np.ndarray]:
    frames = []
    for k in range(N_FRAMES):
        centre = k * STEP_M
        xy = np.c_[rng.uniform(centre - ROI_HALF_LENGTH_M, centre + ROI_HALF_LENGTH_M, points_per_frame),
                   rng.uniform(-ROI_HALF_WIDTH_M, ROI_HALF_WIDTH_M, points_per_frame)]
        frames.append(np.c_[xy, GROUND_SLOPE * xy[:, 0] + rng.normal(0.0, DEPTH_NOISE_M, points_per_frame)])
    return frames


def _ms_per_update(module: ModuleType, frames: list[np.ndarray]) -> float:
    fusion = module.TemporalPlaneFusion(module.TemporalFusionConfig(min_points=MIN_POINTS), np.random.default_rng(1))
    start = time.process_time()
    for points in frames:
        fusion.update(points)
    return (time.process_time() - start) / len(frames) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, required=True, help="source tree of the base commit")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    sys.path.insert(0, str(HERE))
    trees = {"base": _load(args.base, "fusion_base"), "new": _load(HERE, "fusion_new")}
    result: dict = {"what": __doc__.splitlines()[0], "rounds": args.rounds, "cases": {}}
    for case, n in POINTS_PER_FRAME.items():
        frames = _frames(n, np.random.default_rng(0))
        times: dict[str, list[float]] = {name: [] for name in trees}
        for _ in range(args.rounds):
            for name, module in trees.items():
                times[name].append(_ms_per_update(module, frames))
        base, new, ratio = median_ratio(times["base"], times["new"])
        result["cases"][case] = {"points_per_frame": n, "base_ms": round(base, 3), "new_ms": round(new, 3),
                                 "ratio_new_over_base": round(ratio, 3)}
        print(f"{case} ({n} points/frame): base {base:.3f} ms, new {new:.3f} ms per update, new/base {ratio:.2f}")
    result.update(run_meta(args.base))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
