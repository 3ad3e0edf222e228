"""Cost of recording an episode (trade_gym.recording.RecordSequence) per frame, beside the env step it records,
in one run: RGB only, and RGB with the depth and instance-id layers; plus the per-episode cost of closing a
sequence (meta.json and the rename).

Only the wrapper's own work is timed (building the frame record, the PNG/npz writes and the frames.jsonl line);
the env step is timed in the same loop, so the ratio is measured on the same machine at the same moment.
Usage: python benchmarks/record_speed.py [--scene desert] [--camera-size 256] [--steps 150] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from trade_gym.agents import ScriptedFollower
from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.env import TradeFollowEnv
from trade_gym.provenance import cpu_model, git_commit
from trade_gym.recording import RecordSequence
from trade_gym.rollout import fly_episode

LAYERS = {"rgb": {}, "rgb+depth+seg": {"depth": True, "seg": True}}
SEED = 0  # development world 0


class TimedRecord(RecordSequence):
    """RecordSequence timing its own per-frame work, the env steps below it and the closing of sequences [s]."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.write_s: list[float] = []
        self.step_s: list[float] = []
        self.finish_s: list[float] = []

    def _write(self, info: dict[str, Any]) -> None:
        start = time.perf_counter()
        super()._write(info)
        self.write_s.append(time.perf_counter() - start)

    def step(self, action):
        start = time.perf_counter()
        out = self.env.step(action)
        self.step_s.append(time.perf_counter() - start)
        self._write(out[-1])
        if out[2] or out[3]:
            self._timed_finish()
        return out

    def _timed_finish(self) -> None:
        start = time.perf_counter()
        self._finish()
        self.finish_s.append(time.perf_counter() - start)


def measure(scene: str, camera_size: int, steps: int, root: Path, layers: dict[str, bool]) -> dict[str, float]:
    env = TimedRecord(TradeFollowEnv(scene=scene, camera_size=camera_size, episode_duration_s=steps / CAMERA_RATE_HZ), root,
                      **layers)
    try:
        fly_episode(env, ScriptedFollower(), SEED, steps)
    finally:
        env.close()
    sequence = env.written[0]
    size = sum(f.stat().st_size for f in sequence.rglob("*") if f.is_file())
    write_ms = 1e3 * statistics.median(env.write_s)
    step_ms = 1e3 * statistics.median(env.step_s)
    return {"frames": len(env.write_s), "write_ms_median": write_ms, "write_ms_mean": 1e3 * statistics.mean(env.write_s),
            "step_ms_median": step_ms, "write_over_step": write_ms / step_ms,
            "finish_ms": 1e3 * env.finish_s[0] if env.finish_s else float("nan"),
            "bytes_per_frame": size / len(env.write_s)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="desert")
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--steps", type=int, default=150)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, layers in LAYERS.items():
            results[name] = measure(args.scene, args.camera_size, args.steps, Path(tmp) / name, layers)
            r = results[name]
            print(f"{name}: {r['write_ms_median']:.2f} ms per frame (mean {r['write_ms_mean']:.2f}) beside a "
                  f"{r['step_ms_median']:.1f} ms env step ({100 * r['write_over_step']:.1f} %), "
                  f"{r['bytes_per_frame'] / 1024:.0f} kB per frame, closing {r['finish_ms']:.1f} ms", flush=True)
    document = {"scene": args.scene, "camera_size": args.camera_size, "perception": "trade", "seed": SEED,
                "results": results, "commit": git_commit(), "cpu": cpu_model(), "cores": os.cpu_count(),
                "load_average_1min": round(os.getloadavg()[0], 2),
                "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    if args.json is not None:
        args.json.write_text(json.dumps(document, indent=1) + "\n")


if __name__ == "__main__":
    main()
