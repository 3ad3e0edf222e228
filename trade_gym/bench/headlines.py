"""The compact tables of the results summary (docs/results.md): one per headline question, each computed
from a committed run's results (or the speed benchmark's records), so no number in them is typed in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from trade_gym.bench.failures import FAIL_GROUND_RMSE_M
from trade_gym.bench.runner import RunResult
from trade_gym.bench.summary import metric_stats, metric_values, pooled_rmse, summarise
from trade_gym.bench.tables import MISSING, fmt, pooled_mean, table
from trade_gym.bench.real_flight_report import ordered_times, run_time
from trade_gym.bench.thermal_report import good_world, run_stack

Record = dict[str, Any]
# The paper's Table 1, full TRADE: pooled ground-depth RMSE [m] with (ground-truth, VIO) pose per scene.
PAPER_TABLE1_RMSE_M = {"desert": (0.13, 1.26), "city": (1.46, 3.5), "mountain": (0.55, 2.98)}
POSES = ("gt", "vio")
FOLLOWERS = ("scripted", "learned")
RATE_DIGITS = 2  # success and following rates, tracked fractions
ERROR_DIGITS = 2  # horizontal following error [m]
LATENCY_KEY = "perception_latency_ms"  # the latency suite's swept env keyword
BREADTH_AXES = ("target_motion", "appearance")  # the breadth suite's switch grid, in column order


def _unique(values: Sequence[Any]) -> list[Any]:
    return list(dict.fromkeys(values))


def _one(records: Sequence[Record], **match: Any) -> Record | None:
    """The first record whose fields equal `match` (None when there is none)."""
    return next((r for r in records if all(r[k] == v for k, v in match.items())), None)


def _rate(value_and_n: tuple[float, int]) -> str:
    """A pooled mean with the number of runs it pools, 'mean (n)'."""
    value, n = value_and_n
    return f"{fmt(value, RATE_DIGITS)} ({n})"


def _pair(records: Sequence[Record | None], metric: str, digits: int) -> str:
    """'a / b': the mean of `metric` in each record ('–' for a missing one)."""
    return " / ".join(fmt(r["metrics"][metric]["mean"], digits) if r else MISSING for r in records)


def paper_protocol_table(results: Sequence[RunResult]) -> list[str]:
    """Per scene: pooled ground-depth RMSE of full TRADE with gt and with vio pose beside the paper's, then
    the tracked fraction (mean over worlds) and decoy switches (total) of TRADE and DCF, both with vio pose."""
    summary = summarise(results)
    rows = []
    for scene in _unique([r["scene"] for r in summary]):
        trade = [_one(summary, scene=scene, perception="trade", pose_source=p) for p in POSES]
        dcf = _one(summary, scene=scene, perception="dcf", pose_source="vio")
        paper = PAPER_TABLE1_RMSE_M.get(scene, (None, None))
        rmse = [fmt(r["pooled_ground_depth_rmse_m"]) if r else MISSING for r in trade]
        switches = " / ".join(str(r["decoy_switches_total"]) if r else MISSING for r in (trade[1], dcf))
        rows.append([scene, str(trade[0]["n_runs"] if trade[0] else MISSING), rmse[0], fmt(paper[0]), rmse[1],
                     fmt(paper[1]), _pair((trade[1], dcf), "tracked_fraction", RATE_DIGITS), switches])
    return table(["scene", "worlds", "gt RMSE [m]", "paper gt", "vio RMSE [m]", "paper vio",
                  "tracked TRADE / DCF", "switches TRADE / DCF"], rows)


def _depth_row(runs: Sequence[RunResult]) -> list[str]:
    """Pooled ground-depth RMSE, per-flight median, worst flight and how many flights exceed the failure
    threshold, over `runs` (the failed ones left out)."""
    ok = [r for r in runs if r.error is None]
    rmses = metric_values(ok, "ground_depth_rmse_m")
    pooled = pooled_rmse(rmses, metric_values(ok, "ground_depth_frames"))
    scored = [(rmse, r) for rmse, r in zip(rmses, ok) if math.isfinite(rmse)]
    worst_m, worst = max(scored, key=lambda pair: pair[0], default=(math.nan, None))
    worst_text = f"{fmt(worst_m)} (world {worst.spec.seed}, {worst.spec.policy})" if worst else MISSING
    above = sum(not rmse <= FAIL_GROUND_RMSE_M for rmse in rmses)  # NaN (no ground depth) counts as above
    return [str(len(ok)), fmt(pooled), fmt(metric_stats(rmses)["median"]), worst_text, f"{above} of {len(ok)}"]


def depth_spread_table(results: Sequence[RunResult]) -> list[str]:
    """Per scene and pose source, over every flight (world x follower) of full TRADE: pooled ground-depth RMSE,
    per-flight median, the worst flight and the flights above the failure threshold."""
    trade = [r for r in results if r.spec.perception == "trade"]
    rows = []
    for scene in _unique([r.spec.scene for r in trade]):
        for pose in _unique([r.spec.pose_source for r in trade if r.spec.scene == scene]):
            runs = [r for r in trade if r.spec.scene == scene and r.spec.pose_source == pose]
            rows.append([scene, pose] + _depth_row(runs))
    return table(["scene", "pose", "flights", "pooled RMSE [m]", "median [m]", "worst [m] (world, follower)",
                  f"> {FAIL_GROUND_RMSE_M:g} m"], rows)


def follower_table(results: Sequence[RunResult]) -> list[str]:
    """Per scene and pose source: success rate, following rate and mean horizontal error [m] of the scripted
    and the learned follower (means over worlds), full TRADE."""
    summary = [r for r in summarise(results) if r["perception"] == "trade"]
    rows = []
    for scene in _unique([r["scene"] for r in summary]):
        for pose in _unique([r["pose_source"] for r in summary if r["scene"] == scene]):
            pair = [_one(summary, scene=scene, pose_source=pose, policy=p) for p in FOLLOWERS]
            worlds = " / ".join(str(r["n_runs"]) if r else MISSING for r in pair)
            rows.append([scene, pose, worlds, _pair(pair, "success", RATE_DIGITS),
                         _pair(pair, "following_rate", RATE_DIGITS),
                         _pair(pair, "mean_horizontal_error_m", ERROR_DIGITS)])
    follower_names = " / ".join(FOLLOWERS)
    return table(["scene", "pose", f"worlds ({follower_names})", "success", "following rate", "error [m]"], rows)


def breadth_success_table(results: Sequence[RunResult]) -> list[str]:
    """Per follower and perception: the success rate for each target motion and each appearance, and over all
    runs (pooled over scenes and decoy tiers); cells 'rate (runs)'."""
    records = [r for r in summarise(results) if r["kind"] == "breadth"]
    columns = [(axis, value) for axis in BREADTH_AXES for value in _unique([r["switches"][axis] for r in records])]
    rows = []
    for policy, perception in _unique([(r["policy"], r["perception"]) for r in records]):
        mine = [r for r in records if (r["policy"], r["perception"]) == (policy, perception)]
        cells = [_rate(pooled_mean([r for r in mine if r["switches"][axis] == value], "success"))
                 for axis, value in columns]
        rows.append([f"{policy} ({perception})"] + cells + [_rate(pooled_mean(mine, "success"))])
    return table(["follower (perception)"] + [f"{value}" for _, value in columns] + ["all"], rows)


def latency_table(results: Sequence[RunResult]) -> list[str]:
    """Per perception latency [ms]: each follower's mean horizontal error [m] and tracked fraction, means over
    the scenes' runs; cells 'mean (runs)'."""
    summary = summarise(results)
    policies = _unique([r["policy"] for r in summary])
    rows = []
    for latency_ms in sorted(_unique([r["switches"][LATENCY_KEY] for r in summary])):
        at = [r for r in summary if r["switches"][LATENCY_KEY] == latency_ms]
        row = [fmt(latency_ms)]
        for policy in policies:
            mine = [r for r in at if r["policy"] == policy]
            error_m, n = pooled_mean(mine, "mean_horizontal_error_m")
            row += [f"{fmt(error_m, ERROR_DIGITS)} ({n})", _rate(pooled_mean(mine, "tracked_fraction"))]
        rows.append(row)
    header = ["latency [ms]"] + [f"{p}: {what}" for p in policies for what in ("error [m]", "tracked")]
    return table(header, rows)


def thermal_table(results: Sequence[RunResult]) -> list[str]:
    """Per scene (rows) and time of day (columns), full TRADE on the thermal camera: the worlds tracked >= 0.95 with no
    decoy switch, of the worlds flown, and the mean tracked fraction; then per scene the light stack's ground RMSE
    [m] pooled over its frames."""
    ok = [r for r in results if r.error is None]
    full = [r for r in ok if run_stack(r) == "full"]
    light = [r for r in ok if run_stack(r) == "light"]
    times = ordered_times([run_time(r) for r in full])
    rows = []
    for scene in _unique([r.spec.scene for r in full]):
        row = [scene]
        for time in times:
            mine = [r for r in full if (r.spec.scene, run_time(r)) == (scene, time)]
            tracked = metric_stats(metric_values(mine, "tracked_fraction"))
            row.append(f"{sum(good_world(r.metrics) for r in mine)} of {len(mine)} ({fmt(tracked['mean'], RATE_DIGITS)})"
                       if mine else MISSING)
        mine = [r for r in light if r.spec.scene == scene]
        row.append(fmt(pooled_rmse(metric_values(mine, "ground_depth_rmse_m"),
                                   metric_values(mine, "ground_depth_frames"))) if mine else MISSING)
        rows.append(row)
    return table(["scene"] + [f"full TRADE, {t}" for t in times] + ["light stack ground RMSE [m]"], rows)


def speed_table(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """One row per `benchmarks/speed.py` record: env steps/s without rendering (oracle perception), with rendering at
    256 px and with full TRADE at 256 px (the real-time target is the camera's 30 Hz; `–` in a record made before
    speed.py measured it), with the record's date and machine (its commit is in the record)."""
    rows = [[r["scene"], f"{r['oracle_steps_per_s']:g}", f"{r['rendering_steps_per_s_256']:g}",
             f"{r['trade_steps_per_s_256']:g}" if "trade_steps_per_s_256" in r else MISSING,
             r["meta"]["date"][:len("YYYY-MM-DD")], f"{r['meta']['cpu']} ({r['meta']['cores']} cores)"]
            for r in records]
    return table(["scene", "oracle steps/s", "rendering steps/s (256 px)", "full TRADE steps/s (256 px)", "date",
                  "machine"], rows)
