"""The real-flight suite's tables: per time of day x scene x perception the tracked fraction, success and collision
rates with their 95 % Wilson interval; issue 45's acceptance gate (desert and mountain at night); the hours flown; and
per world, for the crossover and the city (reported, not gated), each run's scores and its failure classes.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from trade_gym.bench.failures import failure_cause
from trade_gym.bench.suites import NAMED_AXES, TIME_OF_DAY_AXIS
from trade_gym.bench.tables import MISSING, fmt, mean_pm, rate_cell, table
from trade_gym.sim.thermal_crossover import TIMES_OF_DAY

if TYPE_CHECKING:
    from trade_gym.bench.runner import RunResult

Record = dict[str, Any]
HOUR_KEY = NAMED_AXES[TIME_OF_DAY_AXIS].keyword  # the env keyword the time of day sets (time_of_day_h)
# Issue 45's acceptance: "the waypoint follower keeps the target tracked >= 0.9 in desert and mountain at night, with
# no collision" (tracked fraction: the mean over the group's worlds; no collision: none in any world), and "the
# crossover and the city reported per world (not gated)"
GATE_TRACKED_FRACTION = 0.9
GATE_SCENES = ("desert", "mountain")
GATE_TIME = "night"
PER_WORLD_TIME = "crossover"  # reported per world in every scene ...
PER_WORLD_SCENE = "city"  # ... and this scene at every time
RATE_DIGITS = 2
COLLISION = "collision"  # a failure class beside `trade_gym.bench.failures`' (which score perception only)
OFF_BAND = "out of the following band"  # no other class, but success failed: the follower lagged the target
NO_FAILURE = "–"


def switches_time(record_or_switches: Mapping[str, Any]) -> str:
    """The time of day by name in a run's switches (or a summary record's `switches`)."""
    return str(record_or_switches.get(TIME_OF_DAY_AXIS))


def run_time(run: RunResult) -> str:
    """A run's time of day by name (`RunSpec.switch_value` of the named axis)."""
    return str(run.spec.switch_value(TIME_OF_DAY_AXIS))


def ordered_times(values: Sequence[str]) -> list[str]:
    present = set(values)
    return [t for t in TIMES_OF_DAY if t in present]


def _rate(record: Record, metric: str) -> str:
    stats = record["metrics"][metric]
    return rate_cell(stats["mean"], stats["n"])


def real_flight_pivot(records: Sequence[Record]) -> list[str]:
    """Rows time of day x scene; per perception: tracked fraction (mean ± std over worlds), success and collision
    rates [95 % Wilson interval] (runs); then the acceptance gate."""
    perceptions = list(dict.fromkeys(r["perception"] for r in records))
    scenes = list(dict.fromkeys(r["scene"] for r in records))
    rows = []
    for time in ordered_times([switches_time(r["switches"]) for r in records]):
        for scene in scenes:
            row = [time, scene]
            for perception in perceptions:
                r = next((r for r in records if (r["scene"], r["perception"], switches_time(r["switches"])) ==
                          (scene, perception, time)), None)
                row += [mean_pm(r["metrics"]["tracked_fraction"], RATE_DIGITS), _rate(r, "success"),
                        _rate(r, "collision_rate")] if r else [MISSING] * 3
            rows.append(row)
    header = ["time of day", "scene"] + [f"{p} {what}" for p in perceptions
                                         for what in ("tracked", "success", "collision")]
    caption = ("Tracked: the fraction of visible frames with IoU >= 0.3, mean ± std over worlds; success (no "
               "collision, in the following band on >= 90 % of frames) and collision rates with their 95 % Wilson "
               "interval and (runs). At 45 deg pitch the band is centred one follow height behind the target, "
               "where the camera centres it (`trade_gym.scoring.FollowBand`).")
    gate = gate_table(records)
    return [caption, ""] + table(header, rows) + ([""] + gate if gate else [])


def gate_table(records: Sequence[Record]) -> list[str]:
    """Issue 45's gate per gated scene and perception at night: tracked fraction (mean, worst world), collisions and
    whether both hold."""
    rows = []
    for r in records:
        if r["scene"] in GATE_SCENES and switches_time(r["switches"]) == GATE_TIME:
            tracked, runs = r["metrics"]["tracked_fraction"], r["n_runs"] - r["n_failed"]
            met = tracked["n"] > 0 and tracked["mean"] >= GATE_TRACKED_FRACTION and r["crashes"] == 0 and runs > 0
            rows.append([r["scene"], r["perception"], fmt(tracked["mean"], RATE_DIGITS),
                         fmt(tracked["min"], RATE_DIGITS), f"{r['crashes']} of {runs}", "met" if met else "not met"])
    if not rows:
        return []
    return [f"Acceptance (issue 45): at {GATE_TIME}, in {' and '.join(GATE_SCENES)}, the target tracked >= "
            f"{GATE_TRACKED_FRACTION:g} (mean over worlds) with no collision in any world; the crossover and the "
            "city are reported per world below, not gated.", ""] + \
        table(["scene", "perception", "tracked (mean)", "tracked (worst world)", "collisions", "gate"], rows)


def failure_classes(metrics: Mapping[str, Any], error: str | None = None) -> list[str]:
    """The named reasons a run failed: its error, `failures.failure_cause`'s classes (tracking, ground depth), a
    collision, or else, when it did not succeed, leaving the following band; [] for a run that passed."""
    if error is not None:
        return [f"run error: {error}"]
    found = [c for c in (failure_cause(metrics) or "").split("; ") if c]
    found += [COLLISION] if metrics.get("crashed") else []
    success = metrics.get("success")
    return found or ([OFF_BAND] if success is not None and not success else [])


def _per_world(run: RunResult | None) -> list[str]:
    if run is None:
        return [MISSING] * 3
    m = run.metrics
    tracked = m.get("tracked_fraction")
    success = m.get("success")
    return [fmt(math.nan if tracked is None else float(tracked), RATE_DIGITS),
            MISSING if success is None else ("✓" if success else "✗"),
            "; ".join(failure_classes(m, run.error)) or NO_FAILURE]


def hours_flown(runs: Sequence[RunResult]) -> list[str]:
    """'Hours flown [h, solar time]: ' per scene, each time of day's hour."""
    hours = {(r.spec.scene, run_time(r)): r.spec.env_kwargs()[HOUR_KEY] for r in runs}
    scenes = list(dict.fromkeys(r.spec.scene for r in runs))
    times = ordered_times([t for _, t in hours])
    return ["Hours flown [h, solar time]: " + "; ".join(
        f"{scene} " + ", ".join(f"{t} {hours[scene, t]:g}" for t in times if (scene, t) in hours) for scene in scenes)
        + " (the crossover: `trade_gym.sim.thermal_crossover.morning_crossover`).", ""]


def real_flight_worlds(runs: Sequence[RunResult]) -> list[str]:
    """The hours flown per scene, the failure classes counted per scene, time and perception for the crossover and
    the city, and a row per world of those (tracked fraction, success, failure classes per perception)."""
    lines = hours_flown(runs)
    perceptions = list(dict.fromkeys(r.spec.perception for r in runs))
    shown = [r for r in runs if run_time(r) == PER_WORLD_TIME or r.spec.scene == PER_WORLD_SCENE]
    cells = list(dict.fromkeys((r.spec.scene, run_time(r)) for r in shown))
    by_key = {(r.spec.scene, run_time(r), r.spec.perception, r.spec.seed): r for r in shown}
    counts, worlds = [], []
    for scene, time in cells:
        mine = [r for r in shown if (r.spec.scene, run_time(r)) == (scene, time)]
        row = [scene, time]
        for perception in perceptions:
            classes = Counter(c for r in mine if r.spec.perception == perception
                              for c in failure_classes(r.metrics, r.error))
            row.append(", ".join(f"{c} {n}" for c, n in classes.most_common()) or NO_FAILURE)
        counts.append(row)
        for seed in dict.fromkeys(r.spec.seed for r in mine):
            worlds.append([scene, time, str(seed)] + [cell for p in perceptions
                                                      for cell in _per_world(by_key.get((scene, time, p, seed)))])
    if not counts:
        return lines
    lines += [f"Failure classes ({PER_WORLD_TIME} in every scene, and the {PER_WORLD_SCENE} at every time; not gated): "
              "runs per class (a run may have several).", ""]
    lines += table(["scene", "time of day"] + list(perceptions), counts)
    lines += ["", "<details><summary>per world</summary>", ""]
    lines += table(["scene", "time of day", "world"] + [f"{p} {what}" for p in perceptions
                                                        for what in ("tracked", "success", "failure classes")], worlds)
    return lines + ["</details>", ""]
