"""Full (or light) TRADE on the thermal camera against the same runs in RGB, on development worlds, one run at a time:
tracked fraction, decoy switches, success, ground RMSE per run, and optionally a per-frame trace of chosen runs.

Each run is the tuning suite's (`trade-bench --suite tuning`): scripted follower, `perception="trade"`, 450 frames at
256 px, the unseen protocol (initial box perturbed within 5 px and snapped, first frame shifted within 10), reset seed
= world seed; a cell adds `camera_modality="thermal"` and `time_of_day_h`, or flies RGB ("rgb").

Usage: python benchmarks/thermal_tracking.py --scenes desert mountain --looks 2 13 rgb --seeds 100 109
       [--stack light] [--pose-source gt] [--trace 103 107 --trace-json TRACES] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from trade_gym import metrics
from trade_gym.bench.runner import fly, trajectory_sha256
from trade_gym.bench.splits import EVALUATION
from trade_gym.bench.suites import PAPER_CAMERA_PX, PAPER_STEPS, UNSEEN_PROTOCOL, RunSpec
from trade.types import iou
from trade_gym.provenance import cpu_model, git_commit

# The per-run scores kept (`trade_gym.metrics.episode_metrics` names).
SCORES = ("tracked_fraction", "decoy_switches", "success", "success_auc", "visible_fraction",
          "longest_lost_streak_s", "ground_depth_rmse_m", "crashed")


def spec(scene: str, look: str, seed: int, stack: str, pose_source: str, steps: int) -> RunSpec:
    """The tuning suite's run of `seed` in `scene`; look "rgb", or a time of day [h] for the thermal camera."""
    if EVALUATION.first <= seed <= EVALUATION.last:
        raise ValueError(f"seed {seed} is an evaluation world: this benchmark flies development worlds only")
    extra = UNSEEN_PROTOCOL + ((("stack", stack),) if stack != "full" else ())  # full: the tuning suite's kwargs
    if look != "rgb":
        extra += (("camera_modality", "thermal"), ("time_of_day_h", float(look)))
    return RunSpec("thermal", "custom", scene, "scripted", "trade", pose_source, seed, steps, PAPER_CAMERA_PX,
                   (), extra)


class Tracer:
    """Per-frame record of a run: truth and estimate boxes, IoU, the stack's peak score, tracked flag and the colour
    refiner's verdicts on the frame (every `refine` call: output box, re-detection checks)."""

    def __init__(self) -> None:
        self.frames: list[dict[str, Any]] = []
        self._verdicts: list[str] = []
        self._estimate: Any = None

    def _wrap(self, pipeline: Any) -> None:
        """Record every verdict of the refiner and the estimate of every pipeline step."""
        refiner, step = pipeline.tracking.refiner, pipeline.step
        refine = refiner.refine

        def traced_refine(*args: Any, **kwargs: Any) -> Any:
            result = refine(*args, **kwargs)
            reference = kwargs.get("size_reference")
            fill = np.nan if result is None or reference is None else result.area_px / (reference.w_px * reference.h_px)
            self._verdicts.append(None if result is None else
                                  (result.rejection or "ok", round(float(result.contrast), 2), round(float(fill), 2),
                                   result.box.as_array()))
            return result

        def traced_step(*args: Any, **kwargs: Any) -> Any:
            self._estimate = step(*args, **kwargs)
            return self._estimate

        refiner.refine, pipeline.step = traced_refine, traced_step

    def __call__(self, env: Any, obs: dict, info: dict) -> None:
        pipeline = env.unwrapped.perception.pipeline
        if not self.frames:  # after the reset: the initial estimate
            self._wrap(pipeline)
            self._estimate = pipeline._last
        est = self._estimate
        gt = np.asarray(info.get("gt_bbox", [np.nan] * 4), dtype=np.float64)
        verdicts = [v if v is None else [v[0], v[1], v[2], round(iou(v[3], gt), 2) if np.all(np.isfinite(gt)) else None]
                    for v in self._verdicts]
        dcf = pipeline.tracking.dcf.box
        self.frames.append({
            "gt_bbox": [round(float(v), 1) for v in info.get("gt_bbox", [np.nan] * 4)],
            "est_bbox": [round(float(v), 1) for v in info.get("est_bbox", [np.nan] * 4)],
            "iou": round(float(info.get("iou", np.nan)), 3),
            "visible": bool(info.get("target_visible", False)),
            "on_decoy": bool(info.get("on_decoy", False)),
            "tracked": bool(est.tracked), "peak": round(float(est.peak_score), 3),
            "coast": est.coast_reason, "refiner": verdicts,
            "dcf_wh": [round(dcf.w_px, 1), round(dcf.h_px, 1)],
        })
        self._verdicts = []


def run(scene: str, look: str, seed: int, stack: str, pose_source: str, steps: int, trace: bool) -> dict[str, Any]:
    run_spec = spec(scene, look, seed, stack, pose_source, steps)
    tracer = Tracer() if trace else None
    start = time.process_time()
    infos, timing = fly(run_spec, on_frame=tracer)
    scores = metrics.episode_metrics(infos)
    row: dict[str, Any] = {"scene": scene, "look": look, "seed": seed, "stack": stack, "pose_source": pose_source,
                           "steps": len(infos), **{k: scores.get(k) for k in SCORES},
                           "cpu_s": round(time.process_time() - start, 1), "wall_s": round(timing.wall_s, 1),
                           "trajectory_sha256": trajectory_sha256(infos)}
    if tracer is not None:
        row["trace"] = tracer.frames
    return row


def cell_summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (scene, look, stack): runs, mean tracked fraction, runs tracked >= 0.95 without a switch, switches."""
    cells: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        cells.setdefault((r["scene"], r["look"], r["stack"]), []).append(r)
    out = []
    for (scene, look, stack), rs in cells.items():
        rmse = [r["ground_depth_rmse_m"] for r in rs if r["ground_depth_rmse_m"] is not None]
        out.append({"scene": scene, "look": look, "stack": stack, "n": len(rs),
                    "tracked_mean": round(float(np.mean([r["tracked_fraction"] for r in rs])), 3),
                    "good_runs": sum(r["tracked_fraction"] >= 0.95 and r["decoy_switches"] == 0 for r in rs),
                    "switches": sum(r["decoy_switches"] for r in rs),
                    "success": sum(bool(r["success"]) for r in rs),
                    "ground_rmse_median_m": round(float(np.median(rmse)), 2) if rmse else None})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["desert", "mountain"])
    parser.add_argument("--looks", nargs="+", default=["2", "13", "rgb"], help="time of day [h] (thermal) or rgb")
    parser.add_argument("--seeds", type=int, nargs=2, default=[100, 109], metavar=("FIRST", "LAST"))
    parser.add_argument("--stack", default="full", choices=["full", "light"])
    parser.add_argument("--pose-source", default="gt", choices=["gt", "vio"])
    parser.add_argument("--steps", type=int, default=PAPER_STEPS)
    parser.add_argument("--trace", type=int, nargs="*", default=[], help="seeds to record per frame")
    parser.add_argument("--trace-json", type=Path, default=None, help="where the per-frame records go")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    traces: dict[str, list[dict[str, Any]]] = {}
    record: dict[str, Any] = {
        "command": "python benchmarks/thermal_tracking.py " + " ".join(sys.argv[1:]),
        "commit": git_commit(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": f"{cpu_model()}, {os.cpu_count()} cores, {platform.platform()}", "rows": []}
    for scene in args.scenes:
        for look in args.looks:
            for seed in range(args.seeds[0], args.seeds[1] + 1):
                row = run(scene, look, seed, args.stack, args.pose_source, args.steps, seed in args.trace)
                if "trace" in row:
                    traces[f"{scene}/{look}/{args.stack}/{seed}"] = row.pop("trace")
                record["rows"].append(row)
                print(f"{scene:8s} {look:>4s} {seed} tracked {row['tracked_fraction']:.3f} "
                      f"switches {row['decoy_switches']} success {row['success']} "
                      f"ground {row['ground_depth_rmse_m']} cpu {row['cpu_s']} s", flush=True)
                record["cells"] = cell_summary(record["rows"])
                record["load_average_1min"] = round(os.getloadavg()[0], 2)
                if args.json:
                    args.json.write_text(json.dumps(record, indent=1))
                if args.trace_json and traces:
                    args.trace_json.write_text(json.dumps(traces))
    for cell in record.get("cells", []):
        print(cell)


if __name__ == "__main__":
    main()
