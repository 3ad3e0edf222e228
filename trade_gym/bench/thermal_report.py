"""The thermal suite's tables: per time of day x scene the tracked fraction, decoy switches and pooled ground-depth
RMSE; issue 45's gates (full TRADE: tracked >= 0.95 with no decoy switch on at least 19 of 20 worlds at night and by
day in desert and mountain; the light stack: ground RMSE <= 1 m pooled over those cells); and per world, for the
crossover, the city and every world that misses the gate, each run's scores and its failure classes.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from trade_gym.bench.failures import failure_cause
from trade_gym.bench.real_flight_report import (NO_FAILURE, PER_WORLD_SCENE, PER_WORLD_TIME, hours_flown,
                                                ordered_times, run_time, switches_time)
from trade_gym.bench.summary import metric_values, pooled_rmse
from trade_gym.bench.tables import MISSING, fmt, mean_pm, table, with_frames
from trade_gym.bench.suites import THERMAL_GATE_SCENES, THERMAL_GATE_TIMES

if TYPE_CHECKING:
    from trade_gym.bench.runner import RunResult

Record = dict[str, Any]
# Issue 45's acceptance: "thermal night and day, desert and mountain: full TRADE tracked >= 0.95 with no switch on at
# least 19 of 20 worlds; light stack ground RMSE (gt pose) <= 1 m pooled; the crossover and the city reported per
# world (not gated), with the failure classes named" (the gated cells: suites.THERMAL_GATE_SCENES / _TIMES)
GOOD_TRACKED_FRACTION = 0.95  # a world passes with at least this tracked fraction ...
GOOD_MAX_SWITCHES = 0  # ... and no more decoy switches
GATE_GOOD_WORLD_FRACTION = 19 / 20  # a cell passes when at least this fraction of its worlds do
GATE_LIGHT_GROUND_RMSE_M = 1.0  # the light stack's ground RMSE, pooled over every gated cell's frames
RATE_DIGITS = 2
BELOW_GOOD = f"tracked < {GOOD_TRACKED_FRACTION:g}"
DECOY_SWITCH = "switched to a decoy"


def run_stack(run: RunResult) -> str:
    """The TRADE preset a run flew (`stack`; "full" when its env took the default)."""
    return str(run.spec.env_kwargs().get("stack", "full"))


def good_world(metrics: Mapping[str, Any]) -> bool:
    """Whether a run meets the per-world bar: tracked >= 0.95 and no decoy switch."""
    tracked, switches = metrics.get("tracked_fraction"), metrics.get("decoy_switches")
    return (tracked is not None and float(tracked) >= GOOD_TRACKED_FRACTION and switches is not None
            and float(switches) <= GOOD_MAX_SWITCHES)


def thermal_failure_classes(metrics: Mapping[str, Any], error: str | None = None) -> list[str]:
    """Why a run missed the per-world bar or failed (`failures.failure_cause`'s classes, a decoy switch, tracked
    under the bar); [] for a run that met it."""
    if error is not None:
        return [f"run error: {error}"]
    found = [c for c in (failure_cause(metrics) or "").split("; ") if c]
    if float(metrics.get("decoy_switches") or 0) > GOOD_MAX_SWITCHES:
        found.append(DECOY_SWITCH)
    tracked = metrics.get("tracked_fraction")
    if tracked is not None and float(tracked) < GOOD_TRACKED_FRACTION and not found:
        found.append(BELOW_GOOD)
    return found


def thermal_pivot(records: Sequence[Record]) -> list[str]:
    """Rows time of day x scene: tracked fraction (mean ± std, worst world), decoy switches (total) and ground-depth
    RMSE pooled over every frame of every world."""
    rows = []
    for time in ordered_times([switches_time(r["switches"]) for r in records]):
        for r in (r for r in records if switches_time(r["switches"]) == time):
            tracked = r["metrics"]["tracked_fraction"]
            rows.append([time, r["scene"], mean_pm(tracked, RATE_DIGITS),
                         fmt(tracked["min"], RATE_DIGITS) if tracked["n"] else MISSING,
                         str(r["decoy_switches_total"]),
                         with_frames(r["pooled_ground_depth_rmse_m"], r["pooled_ground_depth_frames"]),
                         f"{r['n_runs'] - r['n_failed']}"])
    caption = ("Tracked: the fraction of visible frames with IoU >= 0.3, mean ± std over worlds, and the worst world; "
               "decoy switches summed over worlds; ground-depth RMSE [m] pooled over every frame of every world "
               "[frames].")
    return [caption, ""] + table(["time of day", "scene", "tracked", "worst world", "decoy switches",
                                  "ground RMSE [m]", "worlds"], rows)


def gate_tables(runs: Sequence[RunResult]) -> list[str]:
    """Issue 45's gates on the gated cells present: full TRADE's good worlds per cell; the light stack's ground RMSE
    per cell and pooled over them."""
    gated = [r for r in runs
             if r.error is None and r.spec.scene in THERMAL_GATE_SCENES and run_time(r) in THERMAL_GATE_TIMES]
    lines = []
    full = [r for r in gated if run_stack(r) == "full"]
    if full:
        rows = []
        for scene in THERMAL_GATE_SCENES:
            for time in THERMAL_GATE_TIMES:
                mine = [r for r in full if (r.spec.scene, run_time(r)) == (scene, time)]
                if mine:
                    good = sum(good_world(r.metrics) for r in mine)
                    met = good >= GATE_GOOD_WORLD_FRACTION * len(mine)
                    rows.append([scene, time, f"{good} of {len(mine)}", "met" if met else "not met"])
        lines += [f"Acceptance (issue 45), full TRADE: tracked >= {GOOD_TRACKED_FRACTION:g} with no decoy switch on at "
                  f"least {GATE_GOOD_WORLD_FRACTION:.0%} of the worlds (19 of 20) of each cell.", ""]
        lines += table(["scene", "time of day", "worlds tracked >= 0.95, no switch", "gate"], rows) + [""]
    light = [r for r in gated if run_stack(r) == "light"]
    if light:
        rmse = pooled_rmse(metric_values(light, "ground_depth_rmse_m"), metric_values(light, "ground_depth_frames"))
        met = math.isfinite(rmse) and rmse <= GATE_LIGHT_GROUND_RMSE_M
        lines += [f"Acceptance (issue 45), light stack: ground RMSE (gt pose) <= {GATE_LIGHT_GROUND_RMSE_M:g} m pooled "
                  f"over every frame at {' and '.join(THERMAL_GATE_TIMES)} in {' and '.join(THERMAL_GATE_SCENES)}: "
                  f"{fmt(rmse)} m over {len(light)} worlds, {'met' if met else 'not met'}.", ""]
    return lines


def _world_row(run: RunResult) -> list[str]:
    m = run.metrics
    tracked, switches, rmse = (m.get(k) for k in ("tracked_fraction", "decoy_switches", "ground_depth_rmse_m"))
    return [run.spec.scene, run_time(run), str(run.spec.seed),
            MISSING if tracked is None else fmt(float(tracked), RATE_DIGITS),
            MISSING if switches is None else str(int(switches)), MISSING if rmse is None else fmt(float(rmse)),
            "; ".join(thermal_failure_classes(m, run.error)) or NO_FAILURE]


def thermal_worlds(runs: Sequence[RunResult]) -> list[str]:
    """The gates, the hours flown, the failure classes counted per cell of the crossover, the city and the gated
    cells, and a row per world for the crossover, the city and every world that misses the bar."""
    lines = gate_tables(runs) + hours_flown(runs)
    shown = [r for r in runs if run_time(r) == PER_WORLD_TIME or r.spec.scene == PER_WORLD_SCENE
             or thermal_failure_classes(r.metrics, r.error)]
    if not shown:
        return lines
    counts = []
    for scene, time in dict.fromkeys((r.spec.scene, run_time(r)) for r in shown):
        classes = Counter(c for r in runs if (r.spec.scene, run_time(r)) == (scene, time)
                          for c in thermal_failure_classes(r.metrics, r.error))
        counts.append([scene, time, ", ".join(f"{c} {n}" for c, n in classes.most_common()) or NO_FAILURE])
    lines += [f"Failure classes per cell: the {PER_WORLD_TIME} in every scene, the {PER_WORLD_SCENE} at every time "
              "(reported, not gated), and the cells of worlds that miss the bar (tracked >= "
              f"{GOOD_TRACKED_FRACTION:g}, no switch; or a failed run); runs per class (a run may have several).", ""]
    lines += table(["scene", "time of day", "failure classes"], counts)
    lines += ["", "<details><summary>per world</summary>", ""]
    lines += table(["scene", "time of day", "world", "tracked", "decoy switches", "ground RMSE [m]",
                    "failure classes"], [_world_row(r) for r in shown])
    return lines + ["</details>", ""]
