"""Before/after cost of the TRADE tracker stage on tracked and on lost frames, the base tree's and this
tree's alternated in subprocesses in one run, so both see the same machine load.

The sequence is the synthetic planar world of the tests (128 px): a target driving under a following
camera, hidden by a grey patch for 30 frames after 60 tracked ones (re-detection runs on every hidden
frame), then 15 frames back in view. Per frame the pipeline's own tracker-stage time (wall clock) is read;
the median over tracked and over lost frames is kept per round, then the median over rounds.

Usage: git worktree add /tmp/base <commit>; python benchmarks/redetect_speed.py --base /tmp/base
       [--rounds 5] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from ab_speed import import_root, median_ratio, probe_env, run_meta  # benchmarks/ is on sys.path when this script runs

HERE = Path(__file__).resolve().parents[1]

_PROBE = """
import json, statistics, numpy as np
from tests.trade.planar_scene import PlanarScene
from trade.pipeline import PipelineConfig, TradePipeline
from trade.types import BBox
FPS, ALTITUDE_M, SPEED_MPS, TRACKED, HIDDEN, AFTER = 30.0, 15.0, 2.2, 60, 30, 15
scene = PlanarScene.make(size_px=128, fov_deg=90.0, seed=0)
pipeline = TradePipeline(PipelineConfig(object_height_m=0.0), scene.intrinsics, np.random.default_rng(0))
tracked_ms, lost_ms = [], []
for k in range(TRACKED + HIDDEN + AFTER):
    t_s = k / FPS
    target = np.array([SPEED_MPS * t_s, 0.0])
    cam = np.array([target[0], target[1], ALTITUDE_M])
    image, pose, gt = scene.render(cam, target), scene.camera_pose(cam), scene.target_box(cam, target)
    if TRACKED <= k < TRACKED + HIDDEN:
        lo = np.floor(gt[:2] - gt[2:] / 4).astype(int)
        hi = np.ceil(gt[:2] + 1.25 * gt[2:]).astype(int)
        image[lo[1]:hi[1], lo[0]:hi[0]] = 128
    if k == 0:
        pipeline.initialise(image, BBox.from_array(gt), pose, t_s)
        continue
    est = pipeline.step(image, pose, t_s)
    (tracked_ms if est.tracked else lost_ms).append(est.timings.tracker_ms)
print(json.dumps({"tracked_ms": statistics.median(tracked_ms), "lost_ms": statistics.median(lost_ms),
                  "tracked_frames": len(tracked_ms), "lost_frames": len(lost_ms)}))
"""


def _measure(tree: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE], cwd=import_root(tree), env=probe_env(tree),
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, required=True, help="source tree of the base commit")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if not (args.base / "trade" / "pipeline.py").is_file():
        parser.error(f"--base {args.base} holds no trade package")
    trees = {"base": args.base.resolve(), "new": HERE}
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    for _ in range(args.rounds):
        for name, tree in trees.items():
            runs[name].append(_measure(tree))
    counts = {key: runs["new"][-1][key] for key in ("tracked_frames", "lost_frames")}
    result: dict = {"what": __doc__.splitlines()[0], "rounds": args.rounds, "frames": counts}
    for kind in ("tracked_ms", "lost_ms"):
        base, new, ratio = median_ratio([r[kind] for r in runs["base"]], [r[kind] for r in runs["new"]])
        result[kind] = {"base": round(base, 3), "new": round(new, 3), "ratio_new_over_base": round(ratio, 3)}
        print(f"{kind.removesuffix('_ms')} frames: base {base:.2f} ms, new {new:.2f} ms, new/base {ratio:.2f}")
    result.update(run_meta(args.base))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
