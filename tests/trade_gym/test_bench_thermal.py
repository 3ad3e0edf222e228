"""trade-bench's thermal suite: its grid (full TRADE on the thermal camera at three times of day in every scene and the
light stack at night and by day in desert and mountain, scripted follower, gt pose, every evaluation world), the
same envs as benchmarks/thermal_tracking.py flies on development worlds, and its report (gates and per-world
failure classes)."""

from __future__ import annotations

import json
import sys

from trade_gym.bench import cli, headlines, runner
from trade_gym.bench.plots import plot_suite
from trade_gym.bench.report import render_markdown
from trade_gym.bench.results import load_results
from trade_gym.bench.splits import DEVELOPMENT, EVALUATION
from trade_gym.bench.suites import SUITE_JOBS, RunSpec, Selection, expand_suite
from trade_gym.bench.summary import summarise
from trade_gym.bench.thermal_report import BELOW_GOOD, DECOY_SWITCH, thermal_failure_classes
from trade_gym.config import SCENE_NAMES, EnvConfig
from trade_gym.metrics import METRIC_NAMES
from trade_gym.sim.thermal_crossover import DAY_H, NIGHT_H, TIMES_OF_DAY, morning_crossover

from tests.trade_gym.test_bench_real_flight import ALL, ROOT, SMOKE_PX, SMOKE_STEPS, SMOKE_WORLD
from tests.trade_gym.test_bench_real_flight import META as REAL_FLIGHT_META
from tests.trade_gym.test_results_doc import render_page_of

META = REAL_FLIGHT_META | {"suite": "thermal"}


def _configs(runs):
    return [(r.group, EnvConfig(**r.env_kwargs())) for r in runs]


def test_thermal_suite_is_full_trade_at_three_times_everywhere_and_the_light_stack_at_night_and_day():
    runs = expand_suite("thermal", Selection(), ALL)
    full = [r for r in runs if r.group == "thermal"]
    light = [r for r in runs if r.group == "thermal_light"]
    assert len(full) == len(SCENE_NAMES) * len(TIMES_OF_DAY) * len(EVALUATION) == 180
    assert len(light) == 2 * 2 * len(EVALUATION) == 80 and len(runs) == 260
    assert {r.scene for r in light} == {"desert", "mountain"}
    assert {r.switch_value("time_of_day") for r in light} == {"night", "day"}
    assert {(r.policy, r.perception, r.pose_source, r.steps, r.camera_size) for r in runs} == \
        {("scripted", "trade", "gt", 450, 256)}
    assert sorted({r.world_seed for r in runs}) == list(EVALUATION.seeds())
    hours = {"night": NIGHT_H, "day": DAY_H}
    for group, config in _configs(runs):
        assert config.camera_modality == "thermal" and config.camera_pitch_deg == EnvConfig().camera_pitch_deg
        assert config.stack == ("light" if group == "thermal_light" else "full")
        assert config.action_mode == "velocity" and config.init_box_perturb_px > 0  # the paper's start protocol
    for run in runs:
        time = run.switch_value("time_of_day")
        assert run.env_kwargs()["time_of_day_h"] == hours.get(time, morning_crossover(run.scene).time_h)
    cli.validate_runs(runs)
    cli.check_worlds("thermal", runs)
    assert SUITE_JOBS["thermal"] == 2 and "thermal" in cli.EVALUATION_SUITES


def test_thermal_tuning_suite_flies_what_the_thermal_benchmark_flies_on_development_worlds():
    tuning = expand_suite("thermal-tuning", Selection(), ALL)
    assert all(r.world_seed in DEVELOPMENT for r in tuning) and len(tuning) == 260
    cli.check_worlds("thermal-tuning", tuning)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from thermal_tracking import spec
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    looks = {"night": f"{NIGHT_H:g}", "day": f"{DAY_H:g}"}
    for run in tuning:
        time = run.switch_value("time_of_day")
        look = looks.get(time, f"{morning_crossover(run.scene).time_h:g}")
        stack = "light" if run.group == "thermal_light" else "full"
        benchmark = spec(run.scene, look, run.seed, stack, "gt", run.steps)
        assert EnvConfig(**benchmark.env_kwargs()) == EnvConfig(**run.env_kwargs()), run.run_id


def _result(group: str, scene: str, time: str, seed: int, tracked: float, switches: int = 0,
            rmse_m: float = 0.5, frames: int = 400) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {
        "steps": 450, "tracked_fraction": tracked, "visible_fraction": 1.0, "success": True, "crashed": False,
        "initial_iou": 0.8, "ground_depth_rmse_m": rmse_m, "ground_depth_frames": frames, "target_depth_frames": 0,
        "decoy_switches": switches}
    spec = next(r for r in expand_suite("thermal", Selection(scenes=(scene,), groups=(group,)), ALL)
                if r.switch_value("time_of_day") == time)
    spec = RunSpec(spec.group, spec.kind, scene, spec.policy, spec.perception, spec.pose_source, seed, spec.steps,
                   spec.camera_size, spec.switches, spec.extra, spec.depth_kind)
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_report_gives_the_good_world_gate_the_light_stacks_pooled_rmse_and_failures_per_world(tmp_path):
    # desert night: 19 of 20 good worlds (met); mountain day: 1 of 2 (not met)
    full = [_result("thermal", "desert", "night", seed, 1.0) for seed in range(19)]
    full += [_result("thermal", "desert", "night", 19, 0.99, switches=1),
             _result("thermal", "mountain", "day", 1, 0.97), _result("thermal", "mountain", "day", 2, 0.6),
             _result("thermal", "desert", "crossover", 1, 1.0), _result("thermal", "city", "night", 1, 0.3)]
    light = [_result("thermal_light", "desert", "night", 1, 0.97, rmse_m=0.6, frames=300),
             _result("thermal_light", "mountain", "day", 1, 0.97, rmse_m=1.2, frames=100)]
    results = full + light
    md = render_markdown(summarise(results), META, {}, [], [], results)
    assert "| time of day | scene | tracked | worst world | decoy switches | ground RMSE [m] | worlds |" in md
    assert "| night | desert | 1 ± 0 | 0.99 | 1 | 0.5 [8000] | 20 |" in md
    assert "| desert | night | 19 of 20 | met |" in md and "| mountain | day | 1 of 2 | not met |" in md
    # sqrt((0.36 * 300 + 1.44 * 100) / 400) = 0.794
    assert "light stack: ground RMSE (gt pose) <= 1 m pooled over every frame at night and day in desert and " \
        "mountain: 0.794 m over 2 worlds, met." in md
    assert f"| desert | night | 19 | 0.99 | 1 | 0.5 | {DECOY_SWITCH} |" in md  # a world under the bar
    assert f"| mountain | day | 2 | 0.6 | 0 | 0.5 | {BELOW_GOOD} |" in md
    assert "| desert | crossover | 1 | 1 | 0 | 0.5 | – |" in md  # the crossover, reported though it passed
    assert "| city | night | 1 | 0.3 | 0 | 0.5 | lost the target |" in md
    assert "| desert | night | 3 |" not in md  # a good world in a gated cell is not listed
    assert [p.name for p in plot_suite(results, tmp_path)] == ["thermal_by_time_of_day.png"]


def test_thermal_failure_classes_name_a_switch_a_low_track_depth_and_an_error():
    good = {"tracked_fraction": 0.96, "initial_iou": 0.8, "ground_depth_rmse_m": 0.4, "decoy_switches": 0}
    assert thermal_failure_classes(good) == []
    assert thermal_failure_classes(good | {"decoy_switches": 2}) == [DECOY_SWITCH]
    assert thermal_failure_classes(good | {"tracked_fraction": 0.9}) == [BELOW_GOOD]
    assert thermal_failure_classes(good | {"tracked_fraction": 0.2, "decoy_switches": 1}) == \
        ["tracked a decoy", DECOY_SWITCH]
    assert thermal_failure_classes(good | {"ground_depth_rmse_m": 3.0, "ground_depth_bias_m": -3.0}) == \
        ["depth too short: plane above the ground (roof, mask leak)"]
    assert thermal_failure_classes({}, "RuntimeError: boom") == ["run error: RuntimeError: boom"]


def test_a_tiny_thermal_run_of_both_stacks_writes_results_that_reload_and_render_a_results_page(tmp_path,
                                                                                                  monkeypatch):
    out = tmp_path / "thermal"
    argv = ["--suite", "thermal", "--scenes", "mountain", "--ablation", "time_of_day=night", "--seeds",
            str(SMOKE_WORLD), str(SMOKE_WORLD), "--steps", str(SMOKE_STEPS), "--camera-size", str(SMOKE_PX),
            "--jobs", "1", "--out", str(out)]
    assert cli.main(argv) == 0
    doc = json.loads((out / "results.json").read_text())
    assert [(r["group"], r["error"]) for r in doc["runs"]] == [("thermal", None), ("thermal_light", None)]
    assert [r["env_kwargs"].get("stack", "full") for r in doc["runs"]] == ["full", "light"]
    assert all(r["env_kwargs"]["time_of_day_h"] == NIGHT_H for r in doc["runs"])
    results, _ = load_results(out / "results.json")
    assert [r.spec.group for r in results] == ["thermal", "thermal_light"]
    assert (out / "thermal_by_time_of_day.png").is_file() and (out / "thermal_per_world.png").is_file()
    title, page = render_page_of(tmp_path, "thermal", monkeypatch)
    assert page.startswith(f"# {title}") and f"Command: `trade-bench {' '.join(argv)}`" in page
    assert "Acceptance (issue 45), full TRADE" in page and "Acceptance (issue 45), light stack" in page


def test_summary_table_counts_good_worlds_per_scene_and_time_and_pools_the_light_stacks_rmse():
    results = [_result("thermal", "desert", "night", 1, 1.0), _result("thermal", "desert", "night", 2, 0.9),
               _result("thermal", "desert", "day", 1, 0.99, switches=1),
               _result("thermal_light", "desert", "night", 1, 0.97, rmse_m=0.6, frames=300),
               _result("thermal_light", "desert", "day", 1, 0.97, rmse_m=1.2, frames=100)]
    lines = headlines.thermal_table(results)
    assert lines[0] == "| scene | full TRADE, night | full TRADE, day | light stack ground RMSE [m] |"
    assert lines[2] == "| desert | 1 of 2 (0.95) | 0 of 1 (0.99) | 0.794 |"
