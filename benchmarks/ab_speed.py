"""Before/after oracle step rate in one run: alternate subprocesses on a baseline source tree and on
this tree, so both see the same machine load, and report the ratio of their CPU-time rates.

With --rendered, the env also renders its camera every step (oracle perception with `render_oracle_frames`,
256 px unless --camera-size): the step rate of an image-based env without perception's own cost.

Usage: git worktree add /tmp/base <commit>; python benchmarks/ab_speed.py --base /tmp/base
       [--scene desert] [--steps 1500] [--rounds 3] [--rendered [--camera-size 256]] [--json OUT]
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import statistics
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path

from trade_gym.provenance import git_commit

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
from install_layout import import_root  # noqa: E402  (scripts/install_layout.py: one definition for both folders)

HERE = Path(__file__).resolve().parents[1]

# One measurement: oracle mode, scripted follower, the CPU time spent inside env.step only. The probe runs on each
# tree's own code, a base from before trade_gym.rollout's hooks too, so it keeps its own loop.
_PROBE = """
import json, sys, time, numpy as np
from trade_gym.agents import ScriptedFollower
from trade_gym.env import TradeFollowEnv
scene, steps, camera_px = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
kwargs = dict(render_oracle_frames=True, camera_size=camera_px) if camera_px > 0 else {}
env = TradeFollowEnv(scene=scene, perception="oracle", **kwargs)
policy = ScriptedFollower()
obs, _ = env.reset(seed=0)
cpu = wall = 0.0
episode = 0
for _ in range(steps):
    action, _ = policy.predict(obs)
    c, w = time.process_time(), time.perf_counter()
    obs, _, terminated, truncated, _ = env.step(action)
    cpu += time.process_time() - c
    wall += time.perf_counter() - w
    if terminated or truncated:
        episode += 1
        obs, _ = env.reset(seed=episode)
env.close()
print(json.dumps({"cpu_steps_per_s": steps / cpu, "wall_steps_per_s": steps / wall}))
"""


@functools.cache
def probe_env(tree: Path) -> dict[str, str]:
    """The environment of a probe process that runs `tree`'s code (run it with cwd=import_root(tree))."""
    return dict(os.environ, PYTHONPATH=str(import_root(tree)))


def _measure(tree: Path, scene: str, steps: int, camera_px: int = 0) -> dict:
    """One probe run on `tree`; `camera_px` > 0 renders the camera at that size every step."""
    out = subprocess.run([sys.executable, "-c", _PROBE, scene, str(steps), str(camera_px)], cwd=import_root(tree),
                         env=probe_env(tree), capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def median_ratio(base: list[float], new: list[float]) -> tuple[float, float, float]:
    """Median of the base tree's and of this tree's measurements, and new / base of the medians."""
    base_median, new_median = statistics.median(base), statistics.median(new)
    return base_median, new_median, new_median / base_median


def run_meta(base: Path) -> dict:
    """What a before/after benchmark records beside its numbers: both commits, date, CPU, cores, load."""
    return dict(base_commit=git_commit(base), new_commit=git_commit(HERE), date=datetime.now(timezone.utc).isoformat(),
                cpu=platform.processor() or platform.machine(), cores=os.cpu_count(),
                load_average_1min_at_end=round(os.getloadavg()[0], 2))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--base", type=Path, required=True, help="source tree of the baseline")
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--rendered", action="store_true", help="render the camera every step")
    parser.add_argument("--camera-size", type=int, default=256, help="with --rendered: image side [px]")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    camera_px = args.camera_size if args.rendered else 0
    if not (args.base / "trade_gym").is_dir():
        parser.error(f"--base {args.base} holds no trade_gym package")
    base, new = [], []
    for _ in range(args.rounds):
        base.append(_measure(args.base, args.scene, args.steps, camera_px))
        new.append(_measure(HERE, args.scene, args.steps, camera_px))
    ratios = [n["cpu_steps_per_s"] / b["cpu_steps_per_s"] for b, n in zip(base, new)]
    meta = run_meta(args.base)  # both commits, date, CPU, cores, load
    result = {
        "scene": args.scene,
        "steps_per_round": args.steps,
        "rendered_camera_px": camera_px or None,
        "base_commit": meta["base_commit"],
        "new_commit": meta["new_commit"],
        "cpu": meta["cpu"],
        "cores": meta["cores"],
        "base_cpu_steps_per_s": [round(b["cpu_steps_per_s"], 1) for b in base],
        "new_cpu_steps_per_s": [round(n["cpu_steps_per_s"], 1) for n in new],
        "base_wall_steps_per_s": [round(b["wall_steps_per_s"], 1) for b in base],
        "new_wall_steps_per_s": [round(n["wall_steps_per_s"], 1) for n in new],
        "speedup_cpu_median": round(statistics.median(ratios), 3),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
