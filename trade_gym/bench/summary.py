"""Aggregates runs into one summary record per configuration: mean and spread of every metric
over seeds, and depth RMSE pooled over all frames of all runs (as the paper's Tables 1 and 2 report).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from trade_gym.bench.failures import failure_cause
from trade_gym.bench.runner import RunResult
from trade_gym.bench.suites import RunSpec
from trade_gym.metrics import DEPTH_KINDS, METRIC_NAMES


UPPER_PERCENTILE = 90.0  # the "p90" of metric_stats
CONFIDENCE_Z = 1.959964  # the standard normal quantile of a two-sided 95 % interval


def metric_stats(values: Sequence[float]) -> dict[str, float | int]:
    """mean, sample std (NaN below two values), min, max, median and 90th percentile (linear
    interpolation) over the finite values, and their count n."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if not len(v):
        return {"mean": math.nan, "std": math.nan, "min": math.nan, "max": math.nan, "median": math.nan,
                "p90": math.nan, "n": 0}
    std = float(np.std(v, ddof=1)) if len(v) > 1 else math.nan
    return {"mean": float(np.mean(v)), "std": std, "min": float(np.min(v)), "max": float(np.max(v)),
            "median": float(np.median(v)), "p90": float(np.percentile(v, UPPER_PERCENTILE)), "n": len(v)}


def wilson_interval(rate: float, n: int, z: float = CONFIDENCE_Z) -> tuple[float, float]:
    """The Wilson score interval (95 % by default) of a success rate `rate` observed over `n` runs: unlike the
    normal approximation it stays inside [0, 1] and is not empty at a rate of 0 or 1; (NaN, NaN) for n = 0."""
    if n <= 0 or not math.isfinite(rate):
        return math.nan, math.nan
    z2 = z * z
    centre = (rate + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(rate * (1 - rate) / n + z2 / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def pooled_rmse(rmses: Sequence[float], frames: Sequence[float]) -> float:
    """RMSE over the union of the runs' frames: sqrt(sum_i rmse_i^2 n_i / sum_i n_i)."""
    r, n = np.asarray(rmses, dtype=np.float64), np.asarray(frames, dtype=np.float64)
    ok = np.isfinite(r) & (n > 0)
    return float(np.sqrt(np.sum(r[ok] ** 2 * n[ok]) / np.sum(n[ok]))) if ok.any() else math.nan


def spec_record(spec: RunSpec) -> dict[str, Any]:
    """The fields describing a configuration (no seed)."""
    return {"config_id": spec.config_id, "group": spec.group, "kind": spec.kind, "scene": spec.scene,
            "policy": spec.policy, "perception": spec.perception, "pose_source": spec.pose_source,
            "switches": dict(spec.switches), "depth_kind": spec.depth_kind}


def _number(value: Any) -> float:
    """A metric as a float; NaN when undefined or absent (results written before the metric existed)."""
    return math.nan if value is None else float(value)


def metric_values(runs: Sequence[RunResult], name: str) -> list[float]:
    """Metric `name` of each run as a float: counts and flags as numbers, NaN where undefined (None: `success`
    without a following rate) or absent."""
    return [_number(r.metrics.get(name)) for r in runs]


def summarise(results: Sequence[RunResult]) -> list[dict[str, Any]]:
    """One record per configuration, in first-appearance order."""
    by_config: dict[str, list[RunResult]] = {}
    for r in results:
        by_config.setdefault(r.spec.config_id, []).append(r)
    summary = []
    for runs in by_config.values():
        ok = [r for r in runs if r.error is None]
        record = spec_record(runs[0].spec) | {"n_runs": len(runs), "n_failed": len(runs) - len(ok)}
        record["metrics"] = {name: metric_stats(metric_values(ok, name)) for name in METRIC_NAMES}
        for kind in DEPTH_KINDS:
            frames = metric_values(ok, f"{kind}_depth_frames")
            record[f"pooled_{kind}_depth_rmse_m"] = pooled_rmse(metric_values(ok, f"{kind}_depth_rmse_m"), frames)
            record[f"pooled_{kind}_depth_frames"] = int(sum(frames))
        record["decoy_switches_total"] = int(sum(metric_values(ok, "decoy_switches")))
        record["crashes"] = int(sum(bool(r.metrics["crashed"]) for r in ok))
        scores_ground = runs[0].spec.perception != "oracle" and runs[0].spec.depth_kind == "ground"
        causes = [(r.spec.seed, failure_cause(r.metrics, scores_ground)) for r in ok]
        record["failed_runs"] = [{"seed": seed, "cause": cause} for seed, cause in causes if cause is not None]
        summary.append(record)
    return summary


def config_label(record: dict[str, Any]) -> str:
    """Short label of a configuration within its group and scene (for tables and plot legends)."""
    parts = [record["policy"], record["perception"], record["pose_source"]]
    parts += [f"{'+' if v else '-'}{k}" if isinstance(v, bool) else f"{k}={v}" if isinstance(v, str) else f"{k}={v:g}"
              for k, v in record["switches"].items()]
    return " ".join(parts)
