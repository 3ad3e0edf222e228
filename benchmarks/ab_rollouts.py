"""Before/after rollout identity: SHA-256 per scene and seed of closed-loop episodes (scripted follower) in a
baseline tree and in this one, each in its own subprocess: observations, rewards, flags and infos, bit for bit.

Keys only this tree has (`--new-keys`, default `estimate_age_s`: the latency observation) are left out of
both, so a speed change can be checked against a commit from before a new key.

Usage: git worktree add /tmp/base <commit>; python benchmarks/ab_rollouts.py --base /tmp/base
       [--perception oracle] [--steps 400] [--camera-size 256] [--seeds 0 7]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from ab_speed import HERE, import_root, probe_env, run_meta

SCENES = ("desert", "city", "mountain")
# Hashes every step's (obs, reward, terminated, truncated, info), keys sorted, new keys skipped; a reset seeded
# seed + RESET_SEED_OFFSET follows an episode's end. The probe runs on each tree's own code, a base from before
# trade_gym.rollout's hooks too, so it keeps its own loop (across episodes, hashing rewards and flags as well).
_PROBE = """
import hashlib, json, sys
import numpy as np
from trade_gym.agents import ScriptedFollower
from trade_gym.env import TradeFollowEnv
perception, steps, size, skip = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), set(json.loads(sys.argv[4]))
scenes, seeds, offset = json.loads(sys.argv[5]), json.loads(sys.argv[6]), int(sys.argv[7])
def feed(h, v):
    if isinstance(v, dict):
        for k in sorted(v):
            if k not in skip:
                h.update(k.encode()); feed(h, v[k])
    elif isinstance(v, (tuple, list)):
        h.update(b"(%d" % len(v))
        for x in v:
            feed(h, x)
    else:
        a = np.asarray(v); h.update(a.dtype.str.encode() + str(a.shape).encode() + a.tobytes())
out = {}
for scene in scenes:
    for seed in seeds:
        env = TradeFollowEnv(scene=scene, perception=perception, camera_size=size)
        policy, h = ScriptedFollower(), hashlib.sha256()
        obs, info = env.reset(seed=seed)
        feed(h, (obs, info))
        for k in range(steps):
            action, _ = policy.predict(obs, episode_start=np.array([k == 0]))
            step = env.step(action)
            feed(h, step)
            obs = step[0]
            if step[2] or step[3]:
                obs, info = env.reset(seed=seed + offset)
                feed(h, (obs, info))
        env.close()
        out[f"{scene}/seed{seed}"] = h.hexdigest()
print(json.dumps(out))
"""
RESET_SEED_OFFSET = 100


def digests(tree: Path, args: argparse.Namespace) -> dict[str, str]:
    argv = [args.perception, str(args.steps), str(args.camera_size), json.dumps(args.new_keys), json.dumps(SCENES),
            json.dumps(args.seeds), str(RESET_SEED_OFFSET)]
    out = subprocess.run([sys.executable, "-c", _PROBE, *argv], cwd=import_root(tree), env=probe_env(tree),
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--perception", default="oracle")
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 7])
    parser.add_argument("--new-keys", nargs="*", default=["estimate_age_s"])
    args = parser.parse_args()
    if not (args.base / "trade_gym").is_dir():
        parser.error(f"--base {args.base} holds no trade_gym package")
    base, new = digests(args.base, args), digests(HERE, args)
    differ = [run for run in base if base[run] != new[run]]
    meta = run_meta(args.base)
    print(json.dumps({"perception": args.perception, "steps": args.steps, "identical": not differ, "differ": differ,
                      "base_commit": meta["base_commit"], "new_commit": meta["new_commit"]}, indent=2))
    raise SystemExit(1 if differ else 0)


if __name__ == "__main__":
    main()
