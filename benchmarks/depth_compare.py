"""Compare the ground depth of two trade-bench runs world by world (before and after a change).

Per cell (group, scene, follower, pose source): pooled ground RMSE, the worst world, how many worlds exceed 1 and
2 m, the mean fraction of frames whose plane is off by more than 1 m, tracking, and which worlds moved (ground
RMSE changed by more than --moved-m, or the tracked fraction by more than 0.01). Runs are matched by their id
without the group name, so a custom grid compares with a suite's group.

    python benchmarks/depth_compare.py --before OLD/results.json --after NEW/results.json --out x.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from trade_gym.bench.summary import metric_stats, pooled_rmse

MOVED_TRACKED = 0.01  # a change of the tracked fraction above this counts as moved
THRESHOLDS_M = (1.0, 2.0)  # worlds above these ground RMSEs are counted


def _runs(paths: list[Path]) -> tuple[dict[str, dict], dict]:
    """The runs of one or more results.json, keyed by run id without the group; the first file's meta."""
    runs, metas = {}, []
    for path in paths:
        doc = json.loads(path.read_text())
        metas.append(doc["meta"])
        for r in doc["runs"]:
            if not r.get("error"):
                runs["/".join(r["run_id"].split("/")[1:])] = r
    return runs, metas[0]


def _value(run: dict, name: str) -> float:
    value = run["metrics"].get(name)
    return math.nan if value is None else float(value)


def cell_figures(runs: list[dict]) -> dict:
    rmse = [_value(r, "ground_depth_rmse_m") for r in runs]
    frames = [_value(r, "ground_depth_frames") for r in runs]
    stats = metric_stats(rmse)
    finite = [e for e in rmse if math.isfinite(e)]
    tracked = metric_stats([_value(r, "tracked_fraction") for r in runs])
    return {
        "worlds": len(runs),
        "pooled_ground_rmse_m": pooled_rmse(rmse, frames),
        "ground_frames": int(sum(n for e, n in zip(rmse, frames) if math.isfinite(e))),
        "worst_ground_rmse_m": stats["max"],
        "median_ground_rmse_m": stats["median"],
        **{f"worlds_above_{t:g}m": sum(e > t for e in finite) for t in THRESHOLDS_M},
        "worlds_without_ground_depth": len(rmse) - len(finite),
        "mean_plane_off_fraction": metric_stats([_value(r, "ground_depth_off_fraction") for r in runs])["mean"],
        "min_tracked_fraction": tracked["min"],
        "mean_tracked_fraction": tracked["mean"],
        "decoy_switches": int(sum(_value(r, "decoy_switches") for r in runs)),
    }


def _cell(run: dict) -> str:
    return f"{run['group']}/{run['scene']}/{run['policy']}/{run['pose_source']}"


def compare(before: dict[str, dict], after: dict[str, dict], moved_m: float) -> dict:
    common = [k for k in after if k in before]
    cells: dict[str, list[str]] = {}
    for key in common:
        cells.setdefault(_cell(after[key]), []).append(key)
    record = {}
    for cell, keys in cells.items():
        moved = []
        for key in keys:
            b, a = before[key], after[key]
            db = _value(a, "ground_depth_rmse_m") - _value(b, "ground_depth_rmse_m")
            dt = _value(a, "tracked_fraction") - _value(b, "tracked_fraction")
            if not (abs(db) <= moved_m) or abs(dt) > MOVED_TRACKED:  # NaN on either side counts as moved
                moved.append({"world": a["seed"], "ground_rmse_m": [_value(b, "ground_depth_rmse_m"),
                                                                    _value(a, "ground_depth_rmse_m")],
                              "tracked": [_value(b, "tracked_fraction"), _value(a, "tracked_fraction")]})
        record[cell] = {"before": cell_figures([before[k] for k in keys]),
                        "after": cell_figures([after[k] for k in keys]), "moved_worlds": moved}
    return record


def _line(cell: str, fig: dict) -> str:
    return (f"{cell:45s} pooled {fig['pooled_ground_rmse_m']:6.3f} m  worst {fig['worst_ground_rmse_m']:6.2f}  "
            f">1 m {fig['worlds_above_1m']:2d}  >2 m {fig['worlds_above_2m']:2d}  off {fig['mean_plane_off_fraction']:.3f}"
            f"  tracked min {fig['min_tracked_fraction']:.3f}  switches {fig['decoy_switches']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, nargs="+", required=True, help="results.json of the runs before")
    parser.add_argument("--after", type=Path, nargs="+", required=True, help="results.json of the runs after")
    parser.add_argument("--moved-m", type=float, default=0.1, help="ground RMSE change that counts as moved [m]")
    parser.add_argument("--out", type=Path, help="write the comparison as JSON here")
    args = parser.parse_args()
    (before, meta_before), (after, meta_after) = _runs(args.before), _runs(args.after)
    record = compare(before, after, args.moved_m)
    for cell, entry in record.items():
        print(_line(cell + " before", entry["before"]))
        print(_line(cell + " after", entry["after"]))
        print(f"{'':45s} moved: {len(entry['moved_worlds'])} of {entry['after']['worlds']} worlds: "
              + ", ".join(f"{m['world']} {m['ground_rmse_m'][0]:.2f}->{m['ground_rmse_m'][1]:.2f}"
                          for m in entry["moved_worlds"]))
    if args.out is not None:
        doc = {"command": "python benchmarks/depth_compare.py --before " + " ".join(map(str, args.before))
               + " --after " + " ".join(map(str, args.after)),
               "before": {k: meta_before.get(k) for k in ("commit", "date_utc", "cpu", "argv")},
               "after": {k: meta_after.get(k) for k in ("commit", "date_utc", "cpu", "argv")},
               "moved_m": args.moved_m, "cells": record}
        args.out.write_text(json.dumps(doc, indent=1, allow_nan=True) + "\n")


if __name__ == "__main__":
    main()
