"""Regression guard: the quick suite's fixed-seed metrics, committed as a reference, and the
tolerances within which a new run may be worse than it.

Regenerate (after an intended change, on a quiet machine):
    trade-bench --suite quick --out /tmp/quick --write-reference
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import Any

from trade_gym.bench.results import git_commit, to_json_safe
from trade_gym.bench.runner import RunResult

REFERENCE_FILE = "quick_reference.json"
REGENERATE_COMMAND = "trade-bench --suite quick --out /tmp/quick --write-reference"


@dataclass(frozen=True)
class Tolerance:
    """A metric may be worse than the reference by abs_tol + rel_tol * |reference|; `higher_is_better`
    says which way is worse. Improvements never fail."""

    higher_is_better: bool
    abs_tol: float
    rel_tol: float = 0.0

    def worse_by(self, reference: float, value: float) -> float:
        """How far `value` is on the bad side of `reference` beyond the tolerance (> 0 fails)."""
        worse = reference - value if self.higher_is_better else value - reference
        return worse - (self.abs_tol + self.rel_tol * abs(reference))


# Same-machine runs are bit-identical; these margins absorb float drift across CPUs and libraries
# (a closed loop amplifies it) and harmless refactors, yet fail a lost target (5 % of the frames is
# 7 frames of a 150-frame run), a new decoy switch, or depth error grown by a quarter.
TOLERANCES: dict[str, Tolerance] = {
    "steps": Tolerance(True, 0.0),  # an earlier termination (target lost, crash) always fails
    "visible_fraction": Tolerance(True, 0.05),
    "tracked_fraction": Tolerance(True, 0.05),
    "success_auc": Tolerance(True, 0.05),
    "precision_20px": Tolerance(True, 0.05),
    "longest_lost_streak_s": Tolerance(False, 0.5),
    "decoy_switches": Tolerance(False, 0.0),
    "ground_depth_rmse_m": Tolerance(False, 0.05, 0.25),
    "target_depth_rmse_m": Tolerance(False, 0.05, 0.25),
    "ground_depth_frames": Tolerance(True, 0.0, 0.2),
    "target_depth_frames": Tolerance(True, 0.0, 0.2),
    "mean_horizontal_error_m": Tolerance(False, 0.25, 0.25),
    "crashed": Tolerance(False, 0.0),
}


def reference_path() -> Path:
    """The committed reference (package data next to this module)."""
    return Path(str(resources.files("trade_gym.bench").joinpath(REFERENCE_FILE)))


def reference_document(results: Sequence[RunResult]) -> dict[str, Any]:
    return {
        "about": "trade-bench quick-suite metrics for fixed seeds (regression guard); regenerate with: "
                 + REGENERATE_COMMAND,
        "commit": git_commit(Path(__file__).resolve().parent),
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "runs": {r.spec.run_id: {"steps_requested": r.spec.steps, "camera_size": r.spec.camera_size,
                                 "metrics": dict(r.metrics)} for r in results if r.error is None},
    }


def write_reference(results: Sequence[RunResult], path: Path) -> None:
    path.write_text(json.dumps(to_json_safe(reference_document(results)), indent=1, allow_nan=False) + "\n")


def load_reference(path: Path | None = None) -> dict[str, Any]:
    return json.loads((path or reference_path()).read_text())


def _as_float(value: Any) -> float:
    return math.nan if value is None else float(value)


def compare_run(run_id: str, metrics: dict[str, Any], reference: dict[str, Any]) -> list[str]:
    """One line per metric of `metrics` that is worse than `reference` beyond its tolerance; a metric
    defined in the reference but undefined now (NaN) is worse."""
    problems = []
    for name, tol in TOLERANCES.items():
        ref, value = _as_float(reference.get(name)), _as_float(metrics.get(name))
        if math.isnan(ref):
            continue
        if math.isnan(value):
            problems.append(f"{run_id}: {name} is undefined, reference {ref:.4g}")
        elif tol.worse_by(ref, value) > 0.0:
            direction = "lower" if tol.higher_is_better else "higher"
            problems.append(f"{run_id}: {name} = {value:.4g}, reference {ref:.4g} "
                            f"(allowed {tol.abs_tol:g} + {tol.rel_tol:g} x |ref| {direction})")
    return problems


def check_against_reference(results: Sequence[RunResult], reference: dict[str, Any]) -> tuple[list[str], int]:
    """(regressions, runs compared): runs whose id, length and camera match a reference entry."""
    problems, compared = [], 0
    for r in results:
        entry = reference["runs"].get(r.spec.run_id)
        if entry is None or entry["steps_requested"] != r.spec.steps or entry["camera_size"] != r.spec.camera_size:
            continue
        compared += 1
        if r.error is not None:
            problems.append(f"{r.spec.run_id}: failed: {r.error}")
            continue
        problems += compare_run(r.spec.run_id, r.metrics, entry["metrics"])
    return problems, compared
