"""Before/after per-stage cost of the TRADE stack: profile_trade.py alternated in subprocesses on a baseline
source tree and on this tree in one run (ABBA order per round), with and without the ground mask, so both
trees see the same machine load; per stage the median over rounds of each run's mean, and new / base.

This tree's profile_trade.py runs on both (the code under test is the tree on PYTHONPATH), so a base from
before its --no-ground-mask flag is measured the same way.

Usage: git worktree add --detach /tmp/base <commit>; python benchmarks/profile_trade_ab.py --base /tmp/base
       [--scene desert] [--steps 300] [--camera-size 256] [--rounds 2] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from ab_speed import import_root, probe_env, run_meta  # benchmarks/ is on sys.path when this script runs

HERE = Path(__file__).resolve().parents[1]
PROFILE = Path(__file__).resolve().parent / "profile_trade.py"
MODES = {"ground_mask": [], "no_ground_mask": ["--no-ground-mask"]}  # full TRADE (env default), no mask
RATIO_DIGITS = 3
MS_DIGITS = 2


def _profile(tree: Path, args: argparse.Namespace, mode_flags: list[str]) -> dict[str, float]:
    """Mean ms per frame of each stage (profile_trade's ms_per_frame.<stage>.mean) of one run on `tree`."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "profile.json"
        subprocess.run([sys.executable, str(PROFILE), "--scene", args.scene, "--steps", str(args.steps),
                        "--camera-size", str(args.camera_size), "--json", str(out), *mode_flags], cwd=import_root(tree),
                       env=probe_env(tree), check=True, capture_output=True, text=True)
        table = json.loads(out.read_text())["ms_per_frame"]
    return {stage: summary["mean"] for stage, summary in table.items()}


def _loaded_from(tree: Path) -> str:
    """Where `trade` is imported from in a probe of `tree` (checks that the run measures that tree)."""
    code = "import os, trade; print(os.path.realpath(trade.__file__))"
    return subprocess.run([sys.executable, "-c", code], env=probe_env(tree), cwd=import_root(tree),
                          check=True, capture_output=True, text=True).stdout.strip()


def _compare(base_runs: list[dict], new_runs: list[dict]) -> dict:
    """Per stage: median of the base runs' means, of this tree's, and new / base."""
    table = {}
    for stage in base_runs[0]:
        base = statistics.median(r[stage] for r in base_runs)
        new = statistics.median(r[stage] for r in new_runs)
        table[stage] = {"base_ms": round(base, MS_DIGITS), "new_ms": round(new, MS_DIGITS),
                        "ratio": round(new / base, RATIO_DIGITS) if base > 0 else None}  # a stage that never ran
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    base_tree = args.base.resolve()
    if not (base_tree / "trade" / "__init__.py").is_file():
        parser.error(f"--base {args.base} holds no trade package")
    modes = {}
    for mode, flags in MODES.items():
        runs: dict[str, list[dict]] = {"base": [], "new": []}
        for k in range(args.rounds):
            order = [("base", base_tree), ("new", HERE)]
            for name, tree in order if k % 2 == 0 else order[::-1]:
                runs[name].append(_profile(tree, args, flags))
        modes[mode] = {"stages": _compare(runs["base"], runs["new"]), "runs": runs}
        print(mode)
        for stage, row in modes[mode]["stages"].items():
            print(f"  {stage:<16}{row['base_ms']:>8.2f}{row['new_ms']:>8.2f}   x{row['ratio']}")
    result = {"command": " ".join([Path(sys.executable).name, *sys.argv]), "scene": args.scene,
              "steps": args.steps, "camera_size": args.camera_size, "rounds": args.rounds,
              "trade_loaded_from": {"base": _loaded_from(base_tree), "new": _loaded_from(HERE)},
              **run_meta(base_tree), "modes": modes}
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
