"""Benchmark figures (matplotlib, Agg): per-frame IoU and per-frame depth error averaged over runs
(the paper's Figures 7 and 6), and a top view of the target's and the drone's paths, per group.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the headless backend)
import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402

from trade_gym.bench.failures import FAIL_GROUND_RMSE_M, FAIL_TRACKED_FRACTION  # noqa: E402
from trade_gym.bench.real_flight_report import GATE_TRACKED_FRACTION  # noqa: E402
from trade_gym.bench.thermal_report import GOOD_TRACKED_FRACTION, run_stack  # noqa: E402
from trade_gym.bench.runner import RunResult, RunSeries  # noqa: E402
from trade_gym.bench.suites import TIME_OF_DAY_AXIS, RunSpec  # noqa: E402
from trade_gym.bench.summary import config_label, metric_values, spec_record  # noqa: E402
from trade_gym.config import CAMERA_RATE_HZ  # noqa: E402
from trade_gym.sim.thermal_crossover import TIMES_OF_DAY  # noqa: E402

TERRAIN_MARGIN_M = 5.0  # terrain shown around the paths [m]
TERRAIN_IMAGE_PX = 400
PANEL_SIZE_IN = (8.5, 3.2)  # one scene per panel, legend on the right [inch]
DPI = 110
LEGEND_FONT_SIZE = 7


def nanmean_ragged(series: Sequence[npt.NDArray[np.float64]]) -> npt.NDArray[np.float64]:
    """Per-frame mean over runs of different lengths, ignoring NaN: (max T,) with NaN where no run has
    a value."""
    length = max((len(s) for s in series), default=0)
    stack = np.full((len(series), length), np.nan)
    for row, s in zip(stack, series):
        row[: len(s)] = s
    counts = np.sum(np.isfinite(stack), axis=0)
    sums = np.nansum(stack, axis=0)
    return np.divide(sums, counts, out=np.full(length, np.nan), where=counts > 0)


def _series(run: RunResult) -> RunSeries:
    """The run's per-frame series; `_by_scene_and_config` keeps only the runs that have one."""
    if run.series is None:
        raise ValueError(f"run {run.spec.run_id} has no per-frame series")
    return run.series


def _by_scene_and_config(results: Sequence[RunResult]) -> dict[str, dict[str, list[RunResult]]]:
    out: dict[str, dict[str, list[RunResult]]] = {}
    for r in results:
        if r.series is not None:
            out.setdefault(r.spec.scene, {}).setdefault(config_label(spec_record(r.spec)), []).append(r)
    return out


def _panels(n: int) -> tuple[plt.Figure, np.ndarray]:
    fig, axes = plt.subplots(n, 1, figsize=(PANEL_SIZE_IN[0], PANEL_SIZE_IN[1] * n), squeeze=False)
    return fig, axes[:, 0]


def _legend_right(ax: plt.Axes) -> None:
    ax.legend(fontsize=LEGEND_FONT_SIZE, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, bbox_inches="tight")  # keeps the legends outside the axes
    plt.close(fig)
    return path


def plot_per_frame(results: Sequence[RunResult], quantity: str, ylabel: str, title: str, path: Path) -> Path | None:
    """Per-frame mean over runs of `RunSeries.<quantity>` (absolute value), one line per configuration,
    one panel per scene; None when no run has a finite value."""
    grouped = _by_scene_and_config(results)
    curves = {scene: {label: nanmean_ragged([np.abs(getattr(r.series, quantity)) for r in runs])
                      for label, runs in configs.items()} for scene, configs in grouped.items()}
    if not any(np.isfinite(c).any() for configs in curves.values() for c in configs.values()):
        return None
    fig, axes = _panels(len(curves))
    for ax, (scene, configs) in zip(axes, curves.items()):
        for label, curve in configs.items():
            n_runs = len(grouped[scene][label])
            ax.plot(np.arange(len(curve)) / CAMERA_RATE_HZ, curve, label=f"{label} (n={n_runs})", lw=1.0)
        ax.set(title=f"{title}: {scene}", xlabel="time [s]", ylabel=ylabel)
        ax.grid(alpha=0.3)
        _legend_right(ax)
    return _save(fig, path)


def plot_paths(results: Sequence[RunResult], title: str, path: Path) -> Path | None:
    """Top view (world x east, y north [m]): the target's path and, per configuration, the drone's path
    of its first run (starts circled), one panel per scene."""
    grouped = _by_scene_and_config(results)
    if not grouped:
        return None
    fig, axes = _panels(len(grouped))
    for ax, (scene, configs) in zip(axes, grouped.items()):
        first_runs = [runs[0] for runs in configs.values()]
        longest = max(first_runs, key=lambda r: len(_series(r).target_xy_m))
        target = _series(longest).target_xy_m
        _draw_terrain(ax, longest.spec, np.vstack([target] + [_series(r).drone_xy_m for r in first_runs]))
        ax.plot(target[:, 0], target[:, 1], "k-", lw=2.0, label="target")
        for label, run in zip(configs, first_runs):
            xy = _series(run).drone_xy_m
            short = label.split("/", 1)[1] if "/" in label else label  # the group name is in the title
            line, = ax.plot(xy[:, 0], xy[:, 1], lw=1.0, label=short.replace("/", " "))
            if len(xy):
                ax.plot(*xy[0], "o", color=line.get_color(), mfc="none")  # start (hover stays there)
        if len(target):
            ax.plot(*target[0], "ko")
        ax.set(title=f"{title}: {scene}, world of seed {longest.spec.seed}", xlabel="x east [m]", ylabel="y north [m]",
               aspect="equal")
        ax.grid(alpha=0.3)
        _legend_right(ax)
    return _save(fig, path)


def _draw_terrain(ax: plt.Axes, spec: RunSpec, xy_m: npt.NDArray[np.float64]) -> None:
    """The run's world under the paths: hill-shaded terrain and building footprints (`bench.dashboard`), in a
    square around the points; the world is rebuilt from the run's seed (a reset, no rendering)."""
    from trade_gym.bench.dashboard import ViewBox, terrain_image
    from trade_gym.env import TradeFollowEnv

    finite = xy_m[np.all(np.isfinite(xy_m), axis=1)]
    if not len(finite):
        return
    box = ViewBox.around(finite, TERRAIN_MARGIN_M, TERRAIN_IMAGE_PX)
    side = box.side_m
    env = TradeFollowEnv(**(spec.env_kwargs() | {"perception": "oracle", "render_mode": None}))
    try:
        env.reset(seed=spec.seed)
        image = terrain_image(env.world, box)
    finally:
        env.close()
    ax.imshow(image, extent=(box.x0_m, box.x0_m + side, box.y0_m, box.y0_m + side), origin="upper", zorder=0)
    ax.set(xlim=(box.x0_m, box.x0_m + side), ylim=(box.y0_m, box.y0_m + side))


STRIP_PANEL_IN = (4.2, 5.0)  # one metric per panel [inch]
STRIP_JITTER = 0.12  # half-width of the horizontal spread of a category's dots [category widths]
MIN_LOG_RMSE_M = 0.01  # floor of the log-scaled RMSE axis [m]
# (metric, axis label, failure threshold, log scale) of the strip plot's panels
STRIP_METRICS = (("ground_depth_rmse_m", "ground-depth RMSE per world [m]", FAIL_GROUND_RMSE_M, True),
                 ("tracked_fraction", "tracked fraction per world", FAIL_TRACKED_FRACTION, False))


def plot_strip(results: Sequence[RunResult], title: str, path: Path) -> Path | None:
    """Per-run values (one dot per world) of each `STRIP_METRICS` entry for every scene x configuration,
    with the failure threshold dashed."""
    categories: dict[str, list[RunResult]] = {}
    for r in results:
        if r.error is None:
            categories.setdefault(f"{r.spec.scene}\n{config_label(spec_record(r.spec))}", []).append(r)
    if not categories:
        return None
    fig, axes = plt.subplots(1, len(STRIP_METRICS), figsize=(STRIP_PANEL_IN[0] * len(STRIP_METRICS),
                                                             STRIP_PANEL_IN[1]), squeeze=False)
    offsets = np.random.default_rng(0)  # a fixed jitter: the same results draw the same figure
    for ax, (name, label, threshold, log) in zip(axes[0], STRIP_METRICS):
        for k, runs in enumerate(categories.values()):
            values = np.array(metric_values(runs, name), dtype=np.float64)
            values = np.maximum(values, MIN_LOG_RMSE_M) if log else values
            x = k + offsets.uniform(-STRIP_JITTER, STRIP_JITTER, len(values))
            ax.plot(x, values, "o", ms=4, alpha=0.7, color=f"C{k % 10}")
        ax.axhline(threshold, color="k", ls="--", lw=0.8, label=f"failure threshold ({threshold:g})")
        ax.set_xticks(range(len(categories)), list(categories), rotation=90, fontsize=LEGEND_FONT_SIZE)
        ax.set(ylabel=label, yscale="log" if log else "linear", title=title)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=LEGEND_FONT_SIZE, loc="upper left", bbox_to_anchor=(0.0, -0.45))
    return _save(fig, path)


LATENCY_KEY = "perception_latency_ms"  # the latency suite's swept env keyword
LINE_STYLES = ("-", "--", ":", "-.")  # one per follower in the latency plot
# (metric, axis label) of the latency plot's panels
LATENCY_METRICS = (("mean_horizontal_error_m", "mean horizontal following error [m]"),
                   ("tracked_fraction", "tracked fraction (IoU >= 0.3 while visible)"))


def plot_latency(results: Sequence[RunResult], title: str, path: Path) -> Path | None:
    """Each `LATENCY_METRICS` entry against the perception latency [ms]: one line per scene (colour) x follower
    (line style), the mean over its runs with bars of one sample std when there are several; a panel per metric."""
    curves: dict[tuple[str, str], dict[float, list[RunResult]]] = {}
    for r in results:
        if r.error is None:
            by_latency = curves.setdefault((r.spec.scene, r.spec.policy), {})
            by_latency.setdefault(float(r.spec.switch_value(LATENCY_KEY)), []).append(r)
    if not curves:
        return None
    scenes = list(dict.fromkeys(scene for scene, _ in curves))
    policies = list(dict.fromkeys(policy for _, policy in curves))
    fig, axes = plt.subplots(1, len(LATENCY_METRICS), figsize=(PANEL_SIZE_IN[0], PANEL_SIZE_IN[1] * 1.3),
                             squeeze=False)
    for ax, (name, label) in zip(axes[0], LATENCY_METRICS):
        for (scene, policy), by_latency in curves.items():
            latencies = sorted(by_latency)
            values = [np.array(metric_values(by_latency[v], name), dtype=np.float64) for v in latencies]
            mean = [float(np.mean(v[np.isfinite(v)])) if np.isfinite(v).any() else np.nan for v in values]
            std = [float(np.std(v[np.isfinite(v)], ddof=1)) if np.isfinite(v).sum() > 1 else 0.0 for v in values]
            ax.errorbar(latencies, mean, yerr=std, marker="o", ms=3, lw=1.0, capsize=2,
                        color=f"C{scenes.index(scene) % 10}",
                        ls=LINE_STYLES[policies.index(policy) % len(LINE_STYLES)], label=f"{scene}: {policy}")
        ax.set(xlabel="perception latency [ms]", ylabel=label, title=title)
        ax.grid(alpha=0.3)
    _legend_right(axes[0][-1])
    return _save(fig, path)


def plot_group(results: Sequence[RunResult], group: str, depth_kind: str, out: Path) -> list[Path]:
    """All figures of one group, written into `out`; returns the files written."""
    depth = f"{depth_kind}_depth_error_m"
    kind = results[0].spec.kind if results else None
    strip = [plot_strip(results, f"{group}: one dot per world", out / f"{group}_per_world.png")] \
        if kind in ("unseen", "real_flight", "thermal") else []
    strip += [plot_latency(results, f"{group}: metric against latency", out / f"{group}_vs_latency.png")] \
        if kind == "latency" else []
    written = strip + [
        plot_per_frame(results, "iou", "IoU (mean over runs)", f"{group} IoU per frame", out / f"{group}_iou.png"),
        plot_per_frame(results, depth, f"|{depth_kind} depth error| [m]", f"{group} {depth_kind} depth error",
                       out / f"{group}_{depth_kind}_depth_error.png"),
        plot_paths(results, f"{group} paths", out / f"{group}_paths.png"),
    ]
    return [p for p in written if p is not None]


BREADTH_MOTION_KEY, BREADTH_TIER_KEY = "target_motion", "decoys"  # the breadth suite's axes (env keywords)


def plot_breadth(results: Sequence[RunResult], path: Path) -> Path | None:
    """Success rate by decoy tier (bars) and target motion (groups of bars), one panel per follower x perception,
    pooled over scenes and appearances; None without breadth runs."""
    runs = [r for r in results if r.spec.kind == "breadth" and r.error is None and r.metrics.get("success") is not None]
    if not runs:
        return None
    panels = list(dict.fromkeys((r.spec.policy, r.spec.perception) for r in runs))
    tiers = list(dict.fromkeys(r.spec.switch_value(BREADTH_TIER_KEY) for r in runs))
    motions = list(dict.fromkeys(r.spec.switch_value(BREADTH_MOTION_KEY) for r in runs))
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.2), squeeze=False, sharey=True)
    width = 0.8 / len(tiers)
    for ax, (policy, perception) in zip(axes[0], panels):
        for i, tier in enumerate(tiers):
            rates = []
            for motion in motions:
                hits = [bool(r.metrics["success"]) for r in runs if (r.spec.policy, r.spec.perception) == (policy, perception)
                        and r.spec.switch_value(BREADTH_TIER_KEY) == tier
                        and r.spec.switch_value(BREADTH_MOTION_KEY) == motion]
                rates.append(np.mean(hits) if hits else np.nan)
            ax.bar(np.arange(len(motions)) + (i - (len(tiers) - 1) / 2) * width, rates, width, label=tier,
                   color=f"C{i}")
        ax.set_xticks(np.arange(len(motions)), motions, fontsize=8)
        ax.set(title=f"{policy}, {perception}", ylim=(0, 1.05))
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("success rate")
    axes[0][-1].legend(title="decoys", fontsize=LEGEND_FONT_SIZE)
    return _save(fig, path)


BAR_WIDTH = 0.38  # of one time of day's slot, per perception (two side by side)


def _plot_by_time_of_day(runs: Sequence[RunResult], path: Path, series: Callable[[RunResult], str],
                         gate: float) -> Path:
    """Tracked fraction by time of day, one panel per scene: a bar per series (the mean over worlds), a dot per
    world, the gate dashed."""
    scenes = list(dict.fromkeys(r.spec.scene for r in runs))
    names = list(dict.fromkeys(series(r) for r in runs))
    present = {r.spec.switch_value(TIME_OF_DAY_AXIS) for r in runs}
    times = [t for t in TIMES_OF_DAY if t in present]
    fig, axes = plt.subplots(1, len(scenes), figsize=(3.2 * len(scenes), 3.2), squeeze=False, sharey=True)
    jitter = np.random.default_rng(0)  # a fixed jitter: the same results draw the same figure
    for ax, scene in zip(axes[0], scenes):
        for i, name in enumerate(names):
            x = np.arange(len(times)) + (i - (len(names) - 1) / 2) * BAR_WIDTH
            values = [np.array(metric_values([r for r in runs if (r.spec.scene, series(r)) == (scene, name)
                                              and r.spec.switch_value(TIME_OF_DAY_AXIS) == t], "tracked_fraction"))
                      for t in times]
            means = [float(np.nanmean(v)) if np.isfinite(v).any() else np.nan for v in values]
            ax.bar(x, means, BAR_WIDTH, color=f"C{i}", alpha=0.6, label=name)
            for xi, v in zip(x, values):
                ax.plot(xi + jitter.uniform(-STRIP_JITTER, STRIP_JITTER, len(v)) * BAR_WIDTH, v, ".", ms=3,
                        color=f"C{i}")
        ax.axhline(gate, color="k", ls="--", lw=0.8)
        ax.set_xticks(np.arange(len(times)), times, fontsize=8)
        ax.set(title=scene, ylim=(0, 1.05))
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel(f"tracked fraction (gate {gate:g} dashed)")
    axes[0][-1].legend(fontsize=LEGEND_FONT_SIZE)
    return _save(fig, path)


def plot_real_flight(results: Sequence[RunResult], path: Path) -> Path | None:
    """The real-flight suite's tracked fraction by time of day, a bar per perception; None without its runs."""
    runs = [r for r in results if r.spec.kind == "real_flight" and r.error is None]
    return _plot_by_time_of_day(runs, path, lambda r: r.spec.perception, GATE_TRACKED_FRACTION) if runs else None


def plot_thermal(results: Sequence[RunResult], path: Path) -> Path | None:
    """The thermal suite's tracked fraction by time of day, a bar per stack (full, light); None without its runs."""
    runs = [r for r in results if r.spec.kind == "thermal" and r.error is None]
    return _plot_by_time_of_day(runs, path, lambda r: f"{run_stack(r)} stack",
                                GOOD_TRACKED_FRACTION) if runs else None


def plot_suite(results: Sequence[RunResult], out: Path) -> list[Path]:
    """The figures across a suite's groups (the breadth suite's success rate by tier and motion, the real-flight and
    thermal suites' tracked fraction by time of day)."""
    figures = (plot_breadth(results, out / "breadth_success.png"),
               plot_real_flight(results, out / "real_flight_by_time_of_day.png"),
               plot_thermal(results, out / "thermal_by_time_of_day.png"))
    return [p for p in figures if p is not None]
