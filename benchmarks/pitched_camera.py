"""Before/after on a pitched camera: TRADE with the waypoint follower, per run the tracked fraction, the frames with a
target depth, the first of them, the target-depth RMSE and the horizontal distance (mean and last), on source trees
run each in its own subprocess (the base's code, then this tree's, or any trees named with --tree).

Usage: git worktree add /tmp/base <commit>; python benchmarks/pitched_camera.py --base /tmp/base
       [--tree name=path ...] [--pitch 45] [--scenes desert mountain] [--worlds 10000 10001] [--poses gt vio]
       [--stacks full light] [--steps 300] [--camera-size 256] [--out benchmarks/results/pitched_camera.json]
Training worlds only (10000+): nothing here is tuned on evaluation worlds.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from ab_speed import HERE, import_root, probe_env, run_meta

# One episode per call, on the probing tree's own code: gym.make with the waypoint follower of trade-bench.
_PROBE = """
import json, sys, numpy as np, gymnasium as gym
import trade_gym
from trade_gym.bench.policies import make_policy
from trade_gym.config import EnvConfig
from trade_gym.metrics import episode_metrics
kw = json.loads(sys.argv[1]); steps = int(sys.argv[2]); seed = kw["world_seed"]
env = gym.make("TradeFollow-v0", **kw)
policy = make_policy("waypoint", seed, kw["camera_pitch_deg"], env_config=EnvConfig(**kw))
obs, info = env.reset(seed=seed)
infos = []
for _ in range(steps):
    action, _ = policy.predict(obs)
    obs, _, terminated, truncated, info = env.step(action)
    infos.append(info)
    if terminated or truncated:
        break
env.close()
m = episode_metrics(infos)
depth = [i["target_depth_est"] is not None for i in infos]
out = {k: m[k] for k in ("steps", "tracked_fraction", "target_depth_frames", "target_depth_rmse_m",
                         "mean_horizontal_error_m", "crashed")}
out["first_depth_frame"] = depth.index(True) if any(depth) else None
out["last_horizontal_distance_m"] = infos[-1]["horizontal_distance_m"]
print(json.dumps(out))
"""


def run(tree: Path, kwargs: dict, steps: int) -> dict:
    """One episode on `tree`'s code; its metrics."""
    out = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(kwargs), str(steps)], cwd=import_root(tree),
                         env=probe_env(tree), capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--tree", action="append", default=[], metavar="NAME=PATH", help="more trees to run")
    parser.add_argument("--pitch", type=float, default=45.0)
    parser.add_argument("--scenes", nargs="+", default=["desert", "mountain"])
    parser.add_argument("--worlds", nargs="+", type=int, default=[10000, 10001, 10002])
    parser.add_argument("--poses", nargs="+", default=["gt", "vio"])
    parser.add_argument("--stacks", nargs="+", default=["full"])
    parser.add_argument("--modality", default="rgb")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if min(args.worlds) < 10000:
        parser.error("--worlds: training worlds (10000+) only")
    trees = {"base": args.base, **{t.split("=", 1)[0]: Path(t.split("=", 1)[1]) for t in args.tree}, "new": HERE}
    runs = []
    for stack in args.stacks:
        for scene in args.scenes:
            for world in args.worlds:
                for pose in args.poses:
                    kw = dict(scene=scene, world_seed=world, pose_source=pose, stack=stack, perception="trade",
                              camera_pitch_deg=args.pitch, camera_size=args.camera_size, action_mode="waypoint",
                              camera_modality=args.modality)
                    row = {"stack": stack, "scene": scene, "world": world, "pose": pose}
                    for name, tree in trees.items():
                        row[name] = run(tree, kw, args.steps)
                    print(json.dumps(row), flush=True)
                    runs.append(row)
    record = {"command": "python " + " ".join(sys.argv), "what": __doc__.split("\n\n")[0],
              "meta": run_meta(args.base), "trees": {k: str(v) for k, v in trees.items()}, "runs": runs}
    if args.out:
        args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
