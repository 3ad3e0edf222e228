"""Before/after training speed in one run: alternate short `python -m trade_gym.agents.train` runs (PPO from scratch,
the shipped hyperparameters, no fine-tune) on a baseline source tree and on this tree, so both see the same machine
load. Reports steps/s of each, their ratio, and whether both trained the same policy (the ONNX's SHA-256): a change
that is only faster must give the same one.

Usage: git worktree add /tmp/base <commit>; python benchmarks/ab_train.py --base /tmp/base [--steps 98304]
       [--rounds 2] [--n-envs N] [--json OUT]
(--n-envs: both trees train with that many envs, each in its own way of running them: the same transitions.)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from ab_speed import HERE, median_ratio, probe_env, run_meta  # noqa: E402  (benchmarks/ is the script's folder)
from install_layout import import_root  # noqa: E402  (on sys.path through ab_speed)

# 12 PPO rollouts of the shipped 2 x 4096 steps: enough resets (episodes of 450 steps) to weigh as in a full run
DEFAULT_STEPS = 12 * 2 * 4096


def _train(tree: Path, steps: int, n_envs: int | None) -> dict:
    """One short training run on `tree`'s code: its wall steps/s and the exported policy's hash."""
    envs = [] if n_envs is None else ["--n-envs", str(n_envs)]
    with tempfile.TemporaryDirectory(prefix="ab_train_") as out:
        subprocess.run([sys.executable, "-m", "trade_gym.agents.train", "--from-scratch", "--steps", str(steps),
                        "--finetune-steps", "0", "--checkpoint-every", "0", "--no-progress", "--out", out, *envs],
                       cwd=import_root(tree), env=probe_env(tree), capture_output=True, text=True, check=True)
        record = json.loads((Path(out) / "train_record.json").read_text())
    return {"steps_per_s": record["steps_per_s"], "onnx_sha256": record["onnx_sha256"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--steps", type=int, default=DEFAULT_STEPS)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--n-envs", type=int, default=None, help="training envs (default: the hyperparameter file's)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if not (args.base / "trade_gym").is_dir():
        parser.error(f"--base {args.base} holds no trade_gym package")
    base, new = [], []
    for _ in range(args.rounds):
        base.append(_train(args.base, args.steps, args.n_envs))
        new.append(_train(HERE, args.steps, args.n_envs))
    base_median, new_median, ratio = median_ratio([b["steps_per_s"] for b in base], [n["steps_per_s"] for n in new])
    result = {
        "what": "training steps/s (PPO from scratch, shipped hyperparameters, no fine-tune), base and new alternated",
        "command": f"python benchmarks/ab_train.py --base <tree of base_commit> --steps {args.steps} "
                   f"--rounds {args.rounds}" + ("" if args.n_envs is None else f" --n-envs {args.n_envs}"),
        **run_meta(args.base),
        "steps_per_run": args.steps,
        "n_envs": args.n_envs or "the hyperparameter file's",
        "base_steps_per_s": [b["steps_per_s"] for b in base],
        "new_steps_per_s": [n["steps_per_s"] for n in new],
        "speedup_median": round(ratio, 3),
        "base_median_steps_per_s": base_median,
        "new_median_steps_per_s": new_median,
        "same_policy": len({r["onnx_sha256"] for r in base + new}) == 1,
        "onnx_sha256": sorted({r["onnx_sha256"] for r in base + new}),
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
