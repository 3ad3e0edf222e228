"""Before/after instructions per oracle step under valgrind's cachegrind: deterministic where step rates on a
shared host swing by +-20 %. Each tree runs the same probe twice (N steps and 0 steps); the difference over N
is the per-step count (the scripted follower's predict plus `env.step`; imports, reset and a warm-up step cancel out).

Usage: git worktree add /tmp/base <commit>; python benchmarks/oracle_instructions.py --base /tmp/base
       [--scene desert] [--steps 300] [--json OUT]     (needs valgrind; ~1 min per run)
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

from ab_speed import HERE, import_root, probe_env, run_meta

# The probe: reset, then `steps` steps of the scripted follower in oracle mode. It runs on each tree's own code, a
# base from before trade_gym.rollout's hooks too, so it keeps its own loop (and counts the same instructions).
_PROBE = """
import sys
from trade_gym.agents import ScriptedFollower
from trade_gym.env import TradeFollowEnv
env = TradeFollowEnv(scene=sys.argv[1], perception="oracle")
policy = ScriptedFollower()
obs, _ = env.reset(seed=0)
for _ in range(WARM_UP_STEPS + int(sys.argv[2])):
    obs, *_ = env.step(policy.predict(obs)[0])
env.close()
"""
_TOTAL = re.compile(r"I\s+refs:\s+([\d,]+)")
# steps both runs take first: one-time costs of a process's first step (the flight kernel's load from numba's cache)
# cancel out like imports and reset
WARM_UP_STEPS = 1


def _instructions(tree: Path, scene: str, steps: int) -> int:
    """Instructions the probe executes in `tree` (cachegrind's I refs, no cache simulation)."""
    probe = f"WARM_UP_STEPS = {WARM_UP_STEPS}\n{_PROBE}"
    out = subprocess.run(["valgrind", "--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null",
                          sys.executable, "-c", probe, scene, str(steps)], cwd=import_root(tree), env=probe_env(tree),
                         capture_output=True, text=True, check=True).stderr
    match = _TOTAL.search(out)
    if match is None:
        raise RuntimeError(f"no instruction count in cachegrind's output for {tree}: {out[-500:]}")
    return int(match.group(1).replace(",", ""))


def per_step(tree: Path, scene: str, steps: int) -> float:
    _instructions(tree, scene, 0)  # fills numba's cache (the flight kernel), so neither measured run compiles
    return (_instructions(tree, scene, steps) - _instructions(tree, scene, 0)) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if not (args.base / "trade_gym").is_dir():
        parser.error(f"--base {args.base} holds no trade_gym package")
    if shutil.which("valgrind") is None:
        parser.error("valgrind is not installed (apt-get install valgrind)")
    base, new = per_step(args.base, args.scene, args.steps), per_step(HERE, args.scene, args.steps)
    result = {"scene": args.scene, "steps": args.steps, "base_instructions_per_step": round(base),
              "new_instructions_per_step": round(new), "instruction_ratio_base_over_new": round(base / new, 4),
              **run_meta(args.base)}
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
