"""results.md: the benchmark's tables for a person to read: one generic table per group plus the
paper-shaped pivot of its kind (Table 1, Table 2, the tracking comparison, the follower comparison).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from trade_gym.bench.failures import FAIL_GROUND_RMSE_M, FAIL_TRACKED_FRACTION
from trade_gym.bench.real_flight_report import real_flight_pivot, real_flight_worlds
from trade_gym.bench.thermal_report import thermal_pivot, thermal_worlds
from trade_gym.bench.summary import config_label
from trade_gym.bench.tables import MISSING, fmt, mean_pm, pooled_mean, rate_cell, table, with_frames
from trade_gym.metrics import GROUND_OFF_M

if TYPE_CHECKING:
    from trade_gym.bench.runner import RunResult

Record = dict[str, Any]


def generic_table(records: Sequence[Record]) -> list[str]:
    header = ["scene", "configuration", "runs", "steps", "visible", "tracked", "AUC", "P@20px", "lost max [s]",
              "switches", "ground RMSE [m] [frames]", "target RMSE [m] [frames]", "horiz. error [m]", "crashes"]
    rows = []
    for r in records:
        m = r["metrics"]
        rows.append([r["scene"], config_label(r), f"{r['n_runs'] - r['n_failed']}/{r['n_runs']}",
                     mean_pm(m["steps"], 4), mean_pm(m["visible_fraction"]), mean_pm(m["tracked_fraction"]),
                     mean_pm(m["success_auc"]), mean_pm(m["precision_20px"]), fmt(m["longest_lost_streak_s"]["max"]),
                     str(r["decoy_switches_total"]), _depth(r, "ground"), _depth(r, "target"),
                     mean_pm(m["mean_horizontal_error_m"]), str(r["crashes"])])
    return table(header, rows)


def _depth(record: Record, kind: str) -> str:
    return with_frames(record[f"pooled_{kind}_depth_rmse_m"], record[f"pooled_{kind}_depth_frames"])


# The scorecard's columns: EVT-Bench style per episode, VOTS style per frame (`trade_gym.metrics`).
SCORECARD = (("success", "success rate"), ("following_rate", "following rate"), ("collision_rate", "collision rate"),
             ("nre", "NRE"), ("dre", "DRE"), ("adq", "ADQ"))


def scorecard_table(records: Sequence[Record]) -> list[str]:
    """Success, following and collision rates and NRE / DRE / ADQ per configuration; nothing for results
    written before the scorecard existed."""
    if not any(r["metrics"].get("success", {}).get("n", 0) for r in records):
        return []
    rows = [[r["scene"], config_label(r)] + [mean_pm(r["metrics"][key]) for key, _ in SCORECARD] for r in records]
    return ["Scorecard: success (no crash, in the following band on >= 90 % of frames), following and collision "
            "rates; VOTS not-reported and drift-rate errors, absence-detection quality (> 10 absent frames).", ""] + \
        table(["scene", "configuration"] + [label for _, label in SCORECARD], rows) + [""]


def _scenes(records: Sequence[Record]) -> list[str]:
    return list(dict.fromkeys(r["scene"] for r in records))


def _find(records: Sequence[Record], **match: Any) -> Record | None:
    return next((r for r in records if all(r.get(k) == v or r["switches"].get(k) == v for k, v in match.items())),
                None)


def table1_pivot(records: Sequence[Record]) -> list[str]:
    """Pooled ground-depth RMSE [m] [frames]: rows temporal fusion x ground mask, cells 'gt (vio)' per scene."""
    scenes = _scenes(records)
    rows = []
    for tf in (False, True):
        for gm in (False, True):
            cells = []
            for scene in scenes:
                gt, vio = (_find(records, scene=scene, pose_source=p, temporal_fusion=tf, ground_mask=gm)
                           for p in ("gt", "vio"))
                cell = _depth(gt, "ground") if gt else MISSING
                cells.append(cell + (f" ({_depth(vio, 'ground')})" if vio else ""))
            rows.append(["✓" if tf else "✗", "✓" if gm else "✗"] + cells)
    return table(["temporal fusion", "ground mask"] + scenes, rows)


def table2_pivot(records: Sequence[Record]) -> list[str]:
    """Pooled target-depth RMSE [m] [frames] of single-image depth, RANSAC off/on per scene."""
    scenes = _scenes(records)
    rows = []
    for ransac in (False, True):
        cells = [_find(records, scene=s, depth_only_ransac=ransac) for s in scenes]
        rmses = [_depth(c, "target") if c else MISSING for c in cells]
        rows.append(["✓" if ransac else "✗"] + rmses)
    return table(["RANSAC"] + scenes, rows)


def tracking_pivot(records: Sequence[Record]) -> list[str]:
    """Per scene and perception: decoy switches (total), visible and tracked fraction and success AUC (mean ±
    std); tracking scores are over the visible frames, so the visible fraction says how many there were."""
    columns = list(dict.fromkeys((r["perception"], r["pose_source"]) for r in records))
    header = ["scene"] + [f"{p} ({pose}) {what}" for p, pose in columns
                          for what in ("switches", "visible", "tracked", "AUC")]
    rows = []
    for scene in _scenes(records):
        row = [scene]
        for perception, pose in columns:
            r = _find(records, scene=scene, perception=perception, pose_source=pose)
            row += [str(r["decoy_switches_total"]), mean_pm(r["metrics"]["visible_fraction"]),
                    mean_pm(r["metrics"]["tracked_fraction"]), mean_pm(r["metrics"]["success_auc"])] if r \
                else [MISSING] * 4
        rows.append(row)
    return table(header, rows)


FOLLOW_CAPTION = ("What the follower controls: the mean horizontal distance it kept to the target (0 = straight above "
                  "it), the fraction of frames in the following band and with the target in view, and its runs that "
                  "succeeded and crashed. How well the estimated box overlaps the target is perception's score: it is "
                  "in the tracking tables and in each group's details in results.md.")


def _of_runs(count: float, runs: int) -> str:
    """'count/runs' ('–' without runs)."""
    return f"{round(count)}/{runs}" if runs else MISSING


def follow_pivot(records: Sequence[Record]) -> list[str]:
    """Per scene and follower (perception, and pose when the group has several), what the follower controls: mean
    horizontal distance to the target [m], following rate (frames in the band), target-in-view fraction (mean ±
    std over runs), successes and crashes of its runs; no box-overlap score, which only perception moves."""
    configs = list(dict.fromkeys((r["policy"], r["perception"], r["pose_source"]) for r in records))
    several_poses = len({pose for _, _, pose in configs}) > 1
    rows = []
    for scene in _scenes(records):
        for policy, perception, pose in configs:
            r = _find(records, scene=scene, policy=policy, perception=perception, pose_source=pose)
            if r is None:
                continue
            m, success = r["metrics"], r["metrics"]["success"]
            rows.append([scene, f"{policy} ({perception}{', ' + pose if several_poses else ''})",
                         mean_pm(m["mean_horizontal_error_m"], 2), mean_pm(m["following_rate"]),
                         mean_pm(m["visible_fraction"]), _of_runs(success["mean"] * success["n"], success["n"]),
                         _of_runs(r["crashes"], r["n_runs"] - r["n_failed"])])
    header = ["scene", "follower", "horizontal distance [m]", "in follow band", "target in view", "success",
              "crashes"]
    return [FOLLOW_CAPTION, ""] + table(header, rows)


def unseen_pivot(records: Sequence[Record]) -> list[str]:
    """Per scene and configuration: pooled ground-depth RMSE with its frame count, the per-world median,
    90th percentile and worst RMSE, tracking, and how many worlds failed; then each failed world's cause."""
    header = ["scene", "configuration", "worlds", "ground RMSE pooled [m]", "frames", "per-world median / p90 / "
              "worst [m]", f"plane off > {GROUND_OFF_M:g} m (mean / worst)", "visible (mean)",
              "tracked (mean, median)", "switches", "failed worlds"]
    rows, failed = [], []
    for r in records:
        m, rmse = r["metrics"], r["metrics"]["ground_depth_rmse_m"]
        off = m.get("ground_depth_off_fraction", {"n": 0})
        rows.append([r["scene"], config_label(r), str(r["n_runs"] - r["n_failed"]),
                     fmt(r["pooled_ground_depth_rmse_m"]), str(r["pooled_ground_depth_frames"]),
                     " / ".join(fmt(rmse[k]) for k in ("median", "p90", "max")),
                     f"{fmt(off['mean'])} / {fmt(off['max'])}" if off["n"] else MISSING,
                     fmt(m["visible_fraction"]["mean"]),
                     f"{fmt(m['tracked_fraction']['mean'])}, {fmt(m['tracked_fraction']['median'])}",
                     str(r["decoy_switches_total"]), f"{len(r['failed_runs'])} of {r['n_runs']}"])
        failed += [f"- {r['scene']}, {config_label(r)}, world {f['seed']}: {f['cause']}" for f in r["failed_runs"]]
    lines = table(header, rows)
    lines += ["", f"A world fails when its ground-depth RMSE exceeds {FAIL_GROUND_RMSE_M:g} m (or it has no ground "
              f"depth) or the target is tracked in fewer than {FAIL_TRACKED_FRACTION:g} of its visible frames; "
              "the cause is classified from the run's metrics (`trade_gym.bench.failures`). Plane off: the fraction "
              f"of a world's frames whose ground estimate misses the true ground by more than {GROUND_OFF_M:g} m "
              "on the true box's ray.", ""]
    return lines + (["Failed worlds:", ""] + failed if failed else ["No world failed."])


LATENCY_KEY = "perception_latency_ms"  # the latency suite's swept env keyword


def latency_pivot(records: Sequence[Record]) -> list[str]:
    """Per scene and follower: mean horizontal following error [m] / tracked fraction (visible fraction) at each
    latency [ms]."""
    latencies = sorted(dict.fromkeys(r["switches"][LATENCY_KEY] for r in records))
    rows = []
    for scene in _scenes(records):
        for policy in dict.fromkeys(r["policy"] for r in records if r["scene"] == scene):
            row = [scene, policy]
            for latency in latencies:
                r = _find(records, scene=scene, policy=policy, **{LATENCY_KEY: latency})
                m = r["metrics"] if r else None
                row.append(f"{mean_pm(m['mean_horizontal_error_m'], 2)} / {mean_pm(m['tracked_fraction'])} "
                           f"({mean_pm(m['visible_fraction'])})" if m else MISSING)
            rows.append(row)
    return table(["scene", "follower"] + [f"{fmt(v)} ms: error [m] / tracked (visible)" for v in latencies], rows)


BREADTH_AXES = ("target_motion", "appearance")  # the breadth groups' switch grid


def _breadth_cell(records: Sequence[Record], cell: tuple[str, ...]) -> list[Record]:
    return [r for r in records if tuple(r["switches"][a] for a in BREADTH_AXES) == cell]


def breadth_pivot(records: Sequence[Record]) -> list[str]:
    """One decoy tier: per follower and perception, the success rate for each target motion x appearance (pooled
    over scenes), then success, following and collision rates over all its runs; success cells with their 95 %
    interval."""
    cells = list(dict.fromkeys(tuple(r["switches"][a] for a in BREADTH_AXES) for r in records))
    rows = []
    for policy, perception in dict.fromkeys((r["policy"], r["perception"]) for r in records):
        mine = [r for r in records if r["policy"] == policy and r["perception"] == perception]
        row = [f"{policy} ({perception})"] + [rate_cell(*pooled_mean(_breadth_cell(mine, c), "success")) for c in cells]
        row.append(rate_cell(*pooled_mean(mine, "success")))
        for metric in ("following_rate", "collision_rate"):
            rate, n = pooled_mean(mine, metric)
            row.append(f"{fmt(rate, 2)} ({n})")
        rows.append(row)
    header = ["follower"] + [f"{motion}, {look}" for motion, look in cells] + ["success", "following", "collision"]
    return ["Success rate per target motion and appearance (runs pooled over scenes) [95 % Wilson interval], then "
            "all runs' success, following and collision rates; (n) = runs with the score defined.", ""] + \
        table(header, rows)


def breadth_headline(summary: Sequence[Record]) -> list[str]:
    """Across the breadth groups: the success table (per follower and perception, the success rate of each target
    motion x appearance, runs pooled over scenes, worlds and decoy tiers, with its 95 % interval), then the
    success rate per decoy tier; nothing without breadth records."""
    records = [r for r in summary if r["kind"] == "breadth"]
    if not records:
        return []
    columns = list(dict.fromkeys((r["policy"], r["perception"]) for r in records))
    cells = list(dict.fromkeys(tuple(r["switches"][a] for a in BREADTH_AXES) for r in records))
    success = []
    for policy, perception in columns:
        mine = [r for r in records if (r["policy"], r["perception"]) == (policy, perception)]
        success.append([f"{policy} ({perception})"]
                       + [rate_cell(*pooled_mean(_breadth_cell(mine, c), "success")) for c in cells])
    tiers = []
    for group in dict.fromkeys(r["group"] for r in records):
        mine = [r for r in records if r["group"] == group]
        tiers.append([group] + [rate_cell(*pooled_mean([r for r in mine if (r["policy"], r["perception"]) == c],
                                                       "success")) for c in columns])
    return (["## Breadth headline: success rate per target motion and appearance", "",
             "Runs pooled over scenes, worlds and decoy tiers; [95 % Wilson interval] (runs).", ""]
            + table(["follower (perception)"] + [f"{motion}, {look}" for motion, look in cells], success)
            + ["", "## Breadth headline: success rate per decoy tier", ""]
            + table(["tier"] + [f"{p} ({q})" for p, q in columns], tiers) + [""])


PIVOTS = {"table1": table1_pivot, "table2": table2_pivot, "tracking": tracking_pivot, "follow": follow_pivot,
          "unseen": unseen_pivot, "latency": latency_pivot, "breadth": breadth_pivot, "real_flight": real_flight_pivot,
          "thermal": thermal_pivot}
# Tables of a kind made from its runs rather than its summary records (per world, and what each run was flown with)
RUN_TABLES: dict[str, Callable[[Sequence[RunResult]], list[str]]] = {"real_flight": real_flight_worlds,
                                                                     "thermal": thermal_worlds}


def machine(meta: Record) -> str:
    """'CPU (cores, vector ISA; the SIMD paths numpy and OpenCV take)'; results.json written before the ISA was
    recorded give 'CPU (cores)'."""
    isa = f", {meta['cpu_vector_isa']}" if "cpu_vector_isa" in meta else ""
    paths = ", ".join(f"{lib} {path}" for lib, path in meta.get("simd_dispatch", {}).items())
    return f"{meta['cpu']} ({meta['cores']} cores{isa}{'; ' + paths if paths else ''})"


def render_markdown(summary: Sequence[Record], meta: Record, titles: dict[str, str], failures: Sequence[str],
                    plots: Sequence[str], runs: Sequence[RunResult] = ()) -> str:
    """The whole results.md; `runs` (the summarised runs) adds the tables some kinds make from runs (`RUN_TABLES`)."""
    lines = [f"# trade-bench results{' — suite ' + meta['suite'] if meta.get('suite') else ''}", "",
             f"commit `{meta['commit']}`, {meta['date_utc']}, {machine(meta)}, "
             f"renderer {meta['renderer']}, {meta['runs']} runs in {meta['wall_s']:.0f} s with {meta['jobs']} jobs.",
             "", "Means ± sample std over seeds; depth RMSE pooled over all frames of all runs; "
             "[n] after a depth RMSE: the frames it pools; tracking scores over frames with the target visible "
             "(the visible fraction beside them); `–` = undefined (no such frame).", ""]
    lines += breadth_headline(summary)
    for group in dict.fromkeys(r["group"] for r in summary):
        records = [r for r in summary if r["group"] == group]
        lines += [f"## {titles.get(group, group)}", ""]
        pivot = PIVOTS.get(records[0]["kind"])
        if pivot is None:
            lines += generic_table(records) + [""] + scorecard_table(records)
        else:
            lines += pivot(records) + [""]
            group_runs = [r for r in runs if r.spec.group == group]
            if records[0]["kind"] in RUN_TABLES and group_runs:
                lines += RUN_TABLES[records[0]["kind"]](group_runs)
            lines += ["<details><summary>all configurations</summary>", ""]
            lines += generic_table(records) + [""] + scorecard_table(records) + ["</details>", ""]
    if failures:
        lines += ["## Failed runs", ""] + [f"- {f}" for f in failures] + [""]
    if plots:
        lines += ["## Plots", ""] + [f"![{p}]({p})" for p in plots] + [""]
    return "\n".join(lines)


def headline(markdown: str) -> str:
    """The score tables of a results.md for the terminal: without the collapsed per-configuration details
    and the plot links."""
    lines, hidden = [], False
    for line in markdown.splitlines():
        if line.startswith("<details>"):
            hidden = True
        elif line.startswith("</details>"):
            hidden = False
        elif line.startswith("## Plots"):
            break
        elif not hidden:
            lines.append(line)
    return "\n".join(lines).strip() + "\n"
