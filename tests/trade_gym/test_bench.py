"""trade-bench: suites as data, argument validation, aggregation, and one tiny
end-to-end run (oracle perception) checked for schema validity and serial/parallel equality."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import jsonschema
import numpy as np
import pytest

from trade_gym.bench import cli, failures, plots, runner
from trade_gym.bench import results as results_module
from trade_gym.bench.plots import nanmean_ragged
from trade_gym.bench.policies import (POLICY_NAMES, HoverPolicy, available_policies, learned_unavailable_reason,
                                      make_policy)
from trade_gym.bench.report import follow_pivot, machine, render_markdown, table1_pivot, tracking_pivot
from trade_gym.bench.results import (deterministic_part, load_schema, to_json_safe, vector_isa,
                                     widest_numpy_target)
from trade_gym.bench.suites import GROUP_KINDS, SUITES, RunSpec, Selection, expand_suite
from trade_gym.bench.summary import metric_stats, pooled_rmse, summarise
from trade_gym.config import PERCEPTION_MODES, POSE_SOURCES, SCENE_NAMES
from trade_gym.metrics import METRIC_NAMES

ALL = ("scripted", "learned", "hover", "random")


def _no_episodes(*args, **kwargs):
    raise AssertionError("an episode ran although the arguments were invalid")


BAD_ARGUMENTS = {
    "unknown scene": ["--scenes", "moon"],
    "unknown policy": ["--policies", "dance"],
    "seed range reversed": ["--seeds", "5", "2"],
    "unknown ablation switch": ["--ablation", "warp_drive=true"],
    "tables without suite": ["--tables", "table1"],
    "unknown suite group": ["--suite", "quick", "--tables", "table9"],
    "reference of an overridden suite": ["--suite", "quick", "--steps", "10", "--write-reference"],
    "reference check of an overridden suite": ["--suite", "quick", "--seeds", "1", "1", "--check-reference"],
    "reference check of another suite": ["--suite", "latency", "--check-reference"],
}


@pytest.mark.parametrize("name", BAD_ARGUMENTS)
def test_cli_bad_argument_exits_2_with_one_line_before_any_episode(name, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    status = cli.main(BAD_ARGUMENTS[name] + ["--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("trade-bench: error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_cli_missing_output_parent_exits_2(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    assert cli.main(["--out", str(tmp_path / "absent" / "out")]) == 2
    assert "parent folder" in capsys.readouterr().err


def test_cli_learned_policy_error_only_when_its_model_is_missing(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    status = cli.main(["--policies", "learned", "--list"])
    if learned_unavailable_reason() is None:
        assert status == 0 and "learned" in capsys.readouterr().out
    else:
        assert status == 2 and "policy 'learned' is not available" in capsys.readouterr().err
        assert "learned" not in available_policies()


def test_cli_subprocess_bad_scene_stderr_is_exactly_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "trade_gym.bench.cli", "--scenes", "moon", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [proc.stderr.strip()] and proc.stderr.startswith("trade-bench: error:")


def test_quick_suite_covers_every_scene_followers_and_perceptions():
    runs = expand_suite("quick", Selection(), ALL)
    assert {r.scene for r in runs} == set(SCENE_NAMES)
    assert {r.policy for r in runs} == set(ALL)
    assert {r.perception for r in runs} == {"oracle", "trade", "dcf"}
    assert len({r.run_id for r in runs}) == len(runs)


def test_paper_suite_follows_protocol_and_run_counts():
    runs = expand_suite("paper", Selection(), ALL)
    by_group = {g.name: [r for r in runs if r.group == g.name] for g in SUITES["paper"]}
    assert len(by_group["table1"]) == 3 * 2 * 4 * 5  # scenes x pose x (fusion x mask) x 5 runs
    assert len(by_group["table2"]) == 3 * 2 * 5  # scenes x RANSAC off/on x 5 runs
    assert len(by_group["tracking"]) == 3 * 2 * 10  # scenes x (trade, dcf) x 10 runs
    for r in runs:
        kw = r.env_kwargs()
        assert kw["init_frame_shift_max"] == 10 and kw["init_box_perturb_px"] == 5.0 and kw["snap_init_box"]
    assert all(r.env_kwargs()["single_image_depth"] for r in by_group["table2"])
    assert {r.switch_value("depth_only_ransac") for r in by_group["table2"]} == {False, True}
    assert {r.pose_source for r in by_group["tracking"]} == {"vio"}
    cli.validate_runs(runs)  # every configuration is accepted by EnvConfig and the stack's config


def test_selection_filters_axes_and_overrides_seeds_and_steps():
    sel = Selection(scenes=("city",), perceptions=("dcf",), seeds=(3, 4), steps=42)
    runs = expand_suite("quick", sel, ALL)
    assert [r.run_id for r in runs] == ["tracking/city/scripted/dcf/gt/seed3", "tracking/city/scripted/dcf/gt/seed4"]
    assert all(r.steps == 42 and r.env_kwargs()["episode_duration_s"] == pytest.approx(42 / 30) for r in runs)


def test_ablation_filter_keeps_runs_with_matching_switch_value():
    runs = expand_suite("paper", Selection(switches=(("ground_mask", (True,)),), groups=("table1",)), ALL)
    assert len(runs) == 60 and all(r.switch_value("ground_mask") for r in runs)


def test_custom_grid_without_suite_sweeps_both_switch_values():
    runs = expand_suite(None, Selection(scenes=("desert",), switches=(("imu_noise", (False, True)),)), ALL)
    assert [r.switch_value("imu_noise") for r in runs] == [False, True]


def test_unavailable_policy_dropped_from_suite_expansion():
    runs = expand_suite("quick", Selection(), ("scripted", "hover", "random"))
    assert "learned" not in {r.policy for r in runs} and runs


def test_random_policy_seeded_reproducible_and_hover_is_zero():
    a, b, c = (make_policy("random", s, 90.0) for s in (3, 3, 4))
    obs = {}
    acts = [p.predict(obs)[0] for p in (a, b, c)]
    np.testing.assert_array_equal(acts[0], acts[1])
    assert not np.array_equal(acts[0], acts[2]) and np.all(np.abs(acts[0]) <= 1.0)
    np.testing.assert_array_equal(HoverPolicy().predict(obs)[0], np.zeros(4))


def test_pooled_rmse_weights_runs_by_frame_count():
    # run 1: 1 frame at error 3 m; run 2: 3 frames at 1 m -> sqrt((9 + 3) / 4)
    assert pooled_rmse([3.0, 1.0], [1, 3]) == pytest.approx(math.sqrt(3.0))
    assert pooled_rmse([3.0, math.nan], [1, 0]) == pytest.approx(3.0)
    assert math.isnan(pooled_rmse([math.nan], [0]))


def test_metric_stats_single_value_has_undefined_spread():
    s = metric_stats([2.0, math.nan])
    assert s["mean"] == 2.0 and s["n"] == 1 and math.isnan(s["std"])
    assert metric_stats([1.0, 3.0])["std"] == pytest.approx(math.sqrt(2.0))


def test_nanmean_ragged_averages_runs_of_different_lengths():
    np.testing.assert_allclose(nanmean_ragged([[1.0, 2.0, 3.0], [3.0, np.nan]]), [2.0, 2.0, 3.0])


def _record(scene, pose, tf, gm, rmse):
    return {"scene": scene, "pose_source": pose, "switches": {"temporal_fusion": tf, "ground_mask": gm},
            "pooled_ground_depth_rmse_m": rmse, "pooled_ground_depth_frames": 100 + 10 * tf + gm}


def test_table1_pivot_cells_show_gt_then_vio_in_brackets():
    records = [_record("desert", p, tf, gm, rmse=(1.0 if p == "gt" else 2.0) + tf + 10 * gm)
               for p in ("gt", "vio") for tf in (False, True) for gm in (False, True)]
    rows = table1_pivot(records)
    assert rows[2] == "| ✗ | ✗ | 1 [100] (2 [100]) |" and rows[5] == "| ✓ | ✓ | 12 [111] (13 [111]) |"


def test_run_spec_exception_recorded_as_one_line_error(monkeypatch):
    def broken(spec, **kwargs):  # fly(spec, record_root=...)
        raise RuntimeError("the target is not in view at reset")

    monkeypatch.setattr(runner, "fly", broken)
    result = runner.run_spec(RunSpec("g", "custom", "desert", "hover", "oracle", "gt", 0, 5, 64))
    assert result.metrics == {} and result.series is None
    assert result.error.startswith("RuntimeError: the target is not in view") and "\n" not in result.error
    md = render_markdown(summarise([result]), {"commit": "c", "date_utc": "d", "cpu": "x", "cores": 1,
                                               "renderer": "r", "runs": 1, "wall_s": 1.0, "jobs": 1},
                         {}, [f"{result.spec.run_id}: {result.error}"], [])
    assert "## Failed runs" in md and "0/1" in md


def test_run_all_parallel_metrics_equal_serial_on_oracle_runs():
    specs = expand_suite(None, Selection(scenes=("desert", "city"), policies=("random",), seeds=(0, 1), steps=25), ALL)
    parallel, serial = runner.run_all(specs, jobs=2), runner.run_all(specs, jobs=1)
    assert [r.spec for r in parallel] == specs
    # NaN (undefined scores) compared as null, as results.json stores them
    assert to_json_safe([r.metrics for r in parallel]) == to_json_safe([r.metrics for r in serial])
    assert [r.trajectory_sha256 for r in parallel] == [r.trajectory_sha256 for r in serial]
    assert all(r.error is None and r.metrics["steps"] == 25 for r in parallel)
    np.testing.assert_array_equal(parallel[3].series.drone_xy_m, serial[3].series.drone_xy_m)


def test_cli_tiny_oracle_run_writes_schema_valid_outputs_with_timing_apart(tmp_path, capsys):
    args = ["--scenes", "desert", "--policies", "scripted", "hover", "--seeds", "0", "1", "--steps", "20"]
    assert cli.main(args + ["--out", str(tmp_path / "a")]) == 0
    doc = json.loads((tmp_path / "a" / "results.json").read_text())
    jsonschema.validate(doc, load_schema())
    assert len(doc["runs"]) == 4 and all(r["metrics"]["steps"] == 20 for r in doc["runs"])
    assert doc["meta"]["jobs"] == 1 and doc["meta"]["renderer"] == "TinyRenderer"
    assert doc["meta"]["cpu_vector_isa"] and set(doc["meta"]["simd_dispatch"]) == {"numpy", "opencv"}
    assert all(r["timing"]["steps_per_s"] > 0 for r in doc["runs"])
    assert all(set(r["metrics"]) == set(METRIC_NAMES) for r in doc["runs"])  # scores only, no timing
    comparable = json.dumps(deterministic_part(doc))
    assert "steps_per_s" not in comparable and "wall_s" not in comparable and doc["runs"][0]["run_id"] in comparable
    md = (tmp_path / "a" / "results.md").read_text()
    assert "| desert | hover oracle gt | 2/2 | 20 ± 0 |" in md
    assert {"custom_iou.png", "custom_paths.png"} <= set(doc["files"]["plots"])
    for name in doc["files"]["plots"]:
        assert (tmp_path / "a" / name).stat().st_size > 0
    assert "4 runs in" in capsys.readouterr().out
    # --report renders the same results.md and summary again from results.json (and series.npz beside it)
    assert cli.main(["--report", str(tmp_path / "a"), "--out", str(tmp_path / "b")]) == 0
    again = json.loads((tmp_path / "b" / "results.json").read_text())
    assert (tmp_path / "b" / "results.md").read_text() == md
    assert deterministic_part(again) == deterministic_part(doc) and again["meta"] == doc["meta"]
    assert (tmp_path / "b" / "custom_iou.png").stat().st_size > 0
    assert "Scorecard" in md and "| desert | scripted oracle gt | 1 ± 0 |" in md  # success rate 1
    # a results.json written before the scorecard existed renders, its scorecard undefined (null)
    old = json.loads((tmp_path / "a" / "results.json").read_text())
    for run in old["runs"]:
        run["metrics"] = {k: v for k, v in run["metrics"].items() if k not in SCORECARD_KEYS}
    del old["meta"]["cpu_vector_isa"], old["meta"]["simd_dispatch"]  # written before the ISA was recorded
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "results.json").write_text(json.dumps(old))
    assert cli.main(["--report", str(tmp_path / "old"), "--out", str(tmp_path / "c")]) == 0
    rendered = json.loads((tmp_path / "c" / "results.json").read_text())
    assert all(r["metrics"][k] is None for r in rendered["runs"] for k in SCORECARD_KEYS)
    assert "Scorecard" not in (tmp_path / "c" / "results.md").read_text()
    assert f"{old['meta']['cpu']} ({old['meta']['cores']} cores), renderer" in (tmp_path / "c" / "results.md").read_text()


SCORECARD_KEYS = ("success", "following_rate", "collision_rate", "nre", "dre", "adq")


@pytest.mark.parametrize("where", ["missing", "same folder"])
def test_cli_report_of_a_missing_or_same_folder_exits_2(where, tmp_path, capsys):
    source = tmp_path / "run"
    source.mkdir()
    if where == "same folder":
        (source / "results.json").write_text("{}")
    out = source if where == "same folder" else tmp_path / "out"
    assert cli.main(["--report", str(source), "--out", str(out)]) == 2
    assert capsys.readouterr().err.startswith("trade-bench: error: --")


def _unseen_result(scene: str, seed: int, rmse: float, bias: float, tracked: float) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {
        "steps": 450, "tracked_fraction": tracked, "initial_iou": 0.8, "decoy_switches": 0,
        "ground_depth_rmse_m": rmse, "ground_depth_frames": 400, "ground_depth_bias_m": bias, "crashed": False}
    spec = RunSpec("unseen", "unseen", scene, "scripted", "trade", "gt", seed, 450, 256)
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 500.0), None)


def test_unseen_report_gives_pooled_rmse_frames_spread_and_each_failed_world_with_its_cause(tmp_path):
    results = [_unseen_result("city", 7, 0.3, 0.1, 0.95), _unseen_result("city", 8, 0.5, -0.2, 0.9),
               _unseen_result("city", 9, 14.0, -13.0, 0.92)]
    summary = summarise(results)
    assert summary[0]["pooled_ground_depth_frames"] == 1200
    assert summary[0]["failed_runs"] == [{"seed": 9, "cause": failures.PLANE_ABOVE}]
    md = render_markdown(summary, {"commit": "c", "date_utc": "d", "cpu": "x", "cores": 1, "renderer": "r",
                                   "runs": 3, "wall_s": 1.0, "jobs": 1}, {}, [], [])
    pooled = math.sqrt((0.3 ** 2 + 0.5 ** 2 + 14.0 ** 2) / 3)
    assert f"| city | scripted trade gt | 3 | {pooled:.2f} | 1200 | 0.5 / 11.3 / 14 |" in md
    assert "| 1 of 3 |" in md and f"- city, scripted trade gt, world 9: {failures.PLANE_ABOVE}" in md
    assert plots.plot_strip(results, "t", tmp_path / "strip.png").stat().st_size > 0


def test_headline_keeps_tables_drops_details_and_plots():
    from trade_gym.bench.report import headline

    text = "# t\n\n## A\n\n| x |\n|---|\n| 1 |\n\n<details><summary>all</summary>\n\n| y |\n\n</details>\n\n## Plots\n\n![p](p.png)\n"
    out = headline(text)
    assert "| x |" in out and "| 1 |" in out
    assert "| y |" not in out and "p.png" not in out and "<details>" not in out


def test_cli_report_with_tables_renders_only_those_groups_and_names_the_ones_there(tmp_path, capsys):
    args = ["--suite", "quick", "--scenes", "desert", "--policies", "scripted", "--perceptions", "oracle", "dcf",
            "--steps", "10", "--out", str(tmp_path / "a")]
    assert cli.main(args) == 0
    doc = json.loads((tmp_path / "a" / "results.json").read_text())
    assert sorted(r["group"] for r in doc["runs"]) == ["follow", "tracking"]
    assert cli.main(["--report", str(tmp_path / "a"), "--tables", "tracking", "--out", str(tmp_path / "b")]) == 0
    again = json.loads((tmp_path / "b" / "results.json").read_text())
    assert [r["group"] for r in again["runs"]] == ["tracking"] and again["meta"] == doc["meta"]
    assert again["summary"] == [s for s in doc["summary"] if s["group"] == "tracking"]
    capsys.readouterr()
    assert cli.main(["--report", str(tmp_path / "a"), "--tables", "table1", "--out", str(tmp_path / "c")]) == 2
    assert capsys.readouterr().err.strip() == (f"trade-bench: error: --tables table1: not in "
                                               f"{tmp_path / 'a' / 'results.json'} (its groups: follow, tracking)")
    assert cli.main(["--report", str(tmp_path / "a"), "--scenes", "city", "--out", str(tmp_path / "d")]) == 2
    assert capsys.readouterr().err.strip() == (f"trade-bench: error: --scenes city: not in "
                                               f"{tmp_path / 'a' / 'results.json'} (its scenes: desert)")
    assert cli.main(["--report", str(tmp_path / "a"), "--scenes", "desert", "--out", str(tmp_path / "e")]) == 0
    assert json.loads((tmp_path / "e" / "results.json").read_text())["runs"] == doc["runs"]


def test_latency_suite_sweeps_five_latencies_per_scene_and_follower_on_development_worlds():
    from trade_gym.bench.splits import DEVELOPMENT
    from trade_gym.bench.suites import LATENCIES_MS

    runs = expand_suite("latency", Selection(), ALL)
    assert len(runs) == 3 * 2 * 5 and {r.scene for r in runs} == set(SCENE_NAMES)
    assert {r.policy for r in runs} == {"scripted", "learned"} and {r.perception for r in runs} == {"trade"}
    assert sorted({r.switch_value("perception_latency_ms") for r in runs}) == sorted(LATENCIES_MS)
    assert all(r.env_kwargs()["perception_latency"] == "fixed" and r.world_seed in DEVELOPMENT for r in runs)
    assert "latency/city/learned/trade/gt/perception_latency_ms=33/seed0" in {r.run_id for r in runs}
    cli.validate_runs(runs)
    cli.check_worlds("latency", runs)


def _latency_result(policy: str, latency_ms: float, error_m: float, tracked: float) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {
        "steps": 450, "tracked_fraction": tracked, "visible_fraction": 1.0, "mean_horizontal_error_m": error_m, "decoy_switches": 0,
        "ground_depth_frames": 0, "target_depth_frames": 0, "crashed": False}
    spec = RunSpec("latency", "latency", "desert", policy, "trade", "gt", 0, 450, 256,
                   (("perception_latency_ms", latency_ms),), (("perception_latency", "fixed"),))
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_latency_report_pivots_error_and_tracked_by_latency_and_plots_them(tmp_path):
    results = [_latency_result("scripted", 0.0, 0.5, 0.9), _latency_result("scripted", 100.0, 0.75, 0.6),
               _latency_result("learned", 0.0, 0.4, 0.95), _latency_result("learned", 100.0, 1.25, 0.3)]
    md = render_markdown(summarise(results), {"commit": "c", "date_utc": "d", "cpu": "x", "cores": 1,
                                              "renderer": "r", "runs": 4, "wall_s": 1.0, "jobs": 1}, {}, [], [])
    assert "| scene | follower | 0 ms: error [m] / tracked (visible) | 100 ms: error [m] / tracked (visible) |" in md
    assert "| desert | scripted | 0.5 / 0.9 (1) | 0.75 / 0.6 (1) |" in md
    assert "| desert | learned | 0.4 / 0.95 (1) | 1.25 / 0.3 (1) |" in md
    assert "scripted trade gt perception_latency_ms=100" in md  # the per-configuration table's label
    path = plots.plot_latency(results, "t", tmp_path / "latency.png")
    assert path is not None and path.stat().st_size > 0


def test_paths_plot_draws_the_runs_world_under_the_paths():
    """The top view's background is the run's own world (terrain and buildings), framed around the paths."""
    spec = RunSpec("custom", "custom", "city", "scripted", "oracle", "gt", 0, 10, 32)
    xy = np.array([[0.0, -45.0], [10.0, -35.0]])
    fig, ax = plots.plt.subplots()
    try:
        plots._draw_terrain(ax, spec, xy)
        (image,) = ax.get_images()
        x0, x1, y0, y1 = image.get_extent()
        assert x0 < 0.0 and x1 > 10.0 and y0 < -45.0 and y1 > -35.0 and x1 - x0 == pytest.approx(y1 - y0)
        assert np.ptp(np.asarray(image.get_array())) > 0  # shading and a building, not a flat fill
    finally:
        plots.plt.close(fig)


def test_tracking_pivot_puts_the_visible_fraction_beside_the_tracking_scores():
    stats = lambda v: {"mean": v, "std": float("nan"), "n": 1}  # noqa: E731
    record = {"scene": "city", "perception": "trade", "pose_source": "vio", "switches": {},
              "decoy_switches_total": 2,
              "metrics": {"visible_fraction": stats(0.8), "tracked_fraction": stats(0.9), "success_auc": stats(0.7)}}
    rows = tracking_pivot([record])
    assert rows[0] == "| scene | trade (vio) switches | trade (vio) visible | trade (vio) tracked | trade (vio) AUC |"
    assert rows[2] == "| city | 2 | 0.8 | 0.9 | 0.7 |"


def test_schema_enums_name_every_suite_group_kind_and_axis_of_the_code():
    schema = load_schema()
    meta_suite = schema["properties"]["meta"]["properties"]["suite"]["enum"]
    config = schema["$defs"]["config"]["properties"]
    assert set(meta_suite) == set(SUITES) | {None}
    assert set(config["kind"]["enum"]) == set(GROUP_KINDS)
    assert set(config["scene"]["enum"]) == set(SCENE_NAMES)
    assert set(config["policy"]["enum"]) == set(POLICY_NAMES)
    assert set(config["perception"]["enum"]) == set(PERCEPTION_MODES)
    assert set(config["pose_source"]["enum"]) == set(POSE_SOURCES)


def test_depth_finder_document_with_its_strips_is_schema_valid():
    result = _unseen_result("city", 10_034, 12.3, -5.8, 1.0)
    results = [dataclasses.replace(result, metrics=result.metrics | {"success": None, "ground_depth_off_fraction": 0.4})]
    meta = results_module.collect_meta("unseen-depth", ["--suite", "unseen-depth"], 2, len(results), 1.0)
    doc = to_json_safe(results_module.build_document(results, summarise(results), meta,
                                                     ["strips/strip_unseen_city.jpg"], None))
    jsonschema.validate(doc, load_schema())


def _follow_record(policy: str, tracked: float, success: dict) -> dict:
    stats = lambda v: {"mean": v, "std": float("nan"), "n": 1}  # noqa: E731
    return {"scene": "mountain", "policy": policy, "perception": "oracle", "pose_source": "gt", "switches": {},
            "n_runs": 1, "n_failed": 0, "crashes": 0,
            "metrics": {"mean_horizontal_error_m": stats(0.5), "following_rate": stats(0.95),
                        "visible_fraction": stats(1.0), "tracked_fraction": stats(tracked), "success": success}}


def test_follow_pivot_scores_what_the_follower_controls_and_no_box_overlap():
    rows = follow_pivot([_follow_record("scripted", 0.83, {"mean": 1.0, "std": float("nan"), "n": 1}),
                         _follow_record("random", 0.983, {"mean": float("nan"), "std": float("nan"), "n": 0})])
    assert rows[2] == ("| scene | follower | horizontal distance [m] | in follow band | target in view | success | "
                       "crashes |")
    assert rows[4] == "| mountain | scripted (oracle) | 0.5 | 0.95 | 1 | 1/1 | 0/1 |"
    assert rows[5] == "| mountain | random (oracle) | 0.5 | 0.95 | 1 | – | 0/1 |"  # success undefined (old results)
    assert "tracked" not in "\n".join(rows[2:]) and "0.83" not in "\n".join(rows)


@pytest.mark.parametrize("flags, isa", [
    (["fpu", "sse4_2", "avx", "avx2", "avx512f", "avx512bw", "avx512vl"], "AVX-512: avx512f avx512bw avx512vl"),
    (["sse4_1", "sse4_2", "avx", "avx2", "fma"], "AVX2"), (["sse4_2", "avx"], "AVX"), (["sse4_1", "sse4_2"], "SSE4.2"),
    (["fp", "asimd", "sve"], "SVE"), (["fp", "asimd"], "NEON"), (["sse2"], "unknown"), ([], "unknown")])
def test_vector_isa_names_the_widest_and_the_avx512_flags(flags, isa):
    assert vector_isa(flags) == isa


def test_widest_numpy_target_is_the_widest_current_target_of_any_loop():
    info = {"add": {"dd": {"current": "X86_V4", "available": "X86_V4 X86_V3 baseline(SSE SSE2)"}},
            "abs": {"ff": {"current": "X86_V3", "available": "X86_V3 baseline(SSE SSE2)"}},
            "cos": {"ff": {"current": "baseline(SSE SSE2)", "available": "baseline(SSE SSE2)"}}}
    assert widest_numpy_target(info) == "X86_V4"
    assert widest_numpy_target({"cos": info["cos"]}) == "baseline(SSE SSE2)" and widest_numpy_target({}) == "unknown"


def test_report_header_names_the_cpu_its_vector_isa_and_simd_paths_and_old_meta_still_renders():
    meta = {"cpu": "AMD EPYC", "cores": 2}
    assert machine(meta) == "AMD EPYC (2 cores)"
    meta |= {"cpu_vector_isa": "AVX2", "simd_dispatch": {"numpy": "X86_V3", "opencv": "AVX2"}}
    assert machine(meta) == "AMD EPYC (2 cores, AVX2; numpy X86_V3, opencv AVX2)"
