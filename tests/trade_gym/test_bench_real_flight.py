"""trade-bench's real-flight suite: its grid (thermal, 45 deg, light stack, waypoint follower, vio, TRADE and DCF, each
time of day with the scene's own hour, every evaluation world), --list and --ablation of the time of day, its report
(tables, gate, per-world failure classes) and results page, and a tiny run through the CLI for both perceptions."""

from __future__ import annotations

import json
from pathlib import Path

from trade_gym.bench import cli, runner
from trade_gym.bench.real_flight_report import COLLISION, OFF_BAND, failure_classes
from trade_gym.bench.report import render_markdown
from trade_gym.bench.results import load_results
from trade_gym.bench.splits import EVALUATION, TRAINING
from trade_gym.bench.suites import SUITE_JOBS, RunSpec, Selection, expand_suite
from trade_gym.bench.summary import summarise
from trade_gym.config import SCENE_NAMES, EnvConfig
from trade_gym.metrics import METRIC_NAMES
from trade_gym.sim.thermal_crossover import DAY_H, NIGHT_H, TIMES_OF_DAY, morning_crossover

from tests.trade_gym.test_results_doc import render_page_of

ROOT = Path(__file__).resolve().parents[2]
ALL = ("scripted", "learned", "waypoint", "hover", "random")
SMOKE_STEPS, SMOKE_PX = 6, 48  # a tiny run: a few frames at a small camera
SMOKE_WORLD = TRAINING.first  # tests never fly evaluation worlds; the suite also allows training ones
META = {"commit": "c", "date_utc": "d", "cpu": "x", "cores": 1, "renderer": "r", "runs": 1, "wall_s": 1.0, "jobs": 1,
        "suite": "real-flight"}


def test_real_flight_suite_is_both_perceptions_at_three_times_on_every_evaluation_world_of_each_scene():
    runs = expand_suite("real-flight", Selection(), ALL)
    assert len(runs) == len(SCENE_NAMES) * 2 * len(TIMES_OF_DAY) * len(EVALUATION) == 360
    assert {(r.policy, r.pose_source) for r in runs} == {("waypoint", "vio")}
    assert {r.perception for r in runs} == {"trade", "dcf"} and {r.scene for r in runs} == set(SCENE_NAMES)
    assert sorted({r.world_seed for r in runs}) == list(EVALUATION.seeds())
    assert {(r.steps, r.camera_size) for r in runs} == {(450, 256)}  # as the unseen suite's
    hours = {"night": NIGHT_H, "day": DAY_H}
    for run in runs:
        kwargs = run.env_kwargs()
        config = EnvConfig(**kwargs)
        assert (config.camera_modality, config.camera_pitch_deg, config.stack, config.action_mode) == \
            ("thermal", 45.0, "light", "waypoint")
        time = run.switch_value("time_of_day")
        assert kwargs["time_of_day_h"] == hours.get(time, morning_crossover(run.scene).time_h)
        assert "time_of_day" not in kwargs and config.init_box_perturb_px > 0  # the paper's start protocol
    ids = {r.run_id for r in runs}
    assert f"real_flight/desert/waypoint/trade/vio/time_of_day=night/seed{EVALUATION.first}" in ids
    assert f"real_flight/city/waypoint/dcf/vio/time_of_day=crossover/seed{EVALUATION.last}" in ids
    assert len(ids) == len(runs)
    cli.validate_runs(runs)
    cli.check_worlds("real-flight", runs)
    assert SUITE_JOBS["real-flight"] == 2 and "real-flight" in cli.EVALUATION_SUITES


def test_real_flight_tuning_suite_is_the_real_flight_grid_on_ten_training_worlds_per_scene():
    tuning, evaluation = expand_suite("real-flight-tuning", Selection(), ALL), expand_suite("real-flight", Selection(), ALL)
    assert len(tuning) == len(evaluation) // 2 and all(r.world_seed in TRAINING for r in tuning)
    assert len({r.world_seed for r in tuning}) == 10
    cli.check_worlds("real-flight-tuning", tuning)
    assert {r.run_id.rsplit("/", 1)[0] for r in tuning} == {r.run_id.rsplit("/", 1)[0] for r in evaluation}
    assert {tuple(sorted(r.env_kwargs().items())) for r in tuning} == \
        {tuple(sorted(r.env_kwargs().items())) for r in evaluation}  # the same envs; only the worlds differ


def test_cli_lists_the_suites_runs_with_each_runs_hour(capsys):
    assert cli.main(["--suite", "real-flight", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 360
    hour = morning_crossover("mountain").time_h
    assert (f"real_flight/mountain/waypoint/dcf/vio/time_of_day=crossover/seed{EVALUATION.first} "
            f"(450 steps, 256 px, time_of_day_h={hour:g})") in lines
    assert "real-flight" in cli.build_parser().format_help()


def test_cli_ablation_picks_times_of_day_and_refuses_an_unknown_one(capsys):
    argv = ["--suite", "real-flight", "--list", "--scenes", "city", "--ablation", "time_of_day=crossover,night"]
    assert cli.main(argv) == 0
    times = {line.split("time_of_day=")[1].split("/")[0] for line in capsys.readouterr().out.splitlines()}
    assert times == {"crossover", "night"}
    assert cli.main(["--suite", "real-flight", "--list", "--ablation", "time_of_day=dusk"]) == 2
    assert "'dusk'" in capsys.readouterr().err
    assert cli.main(["--suite", "unseen", "--list", "--ablation", "time_of_day=night"]) == 2  # no such axis there


def _result(scene: str, perception: str, time: str, seed: int, tracked: float, crashed: bool = False,
            following: float = 0.0, initial_iou: float = 0.8) -> runner.RunResult:
    success = not crashed and following >= 0.9
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {
        "steps": 450, "tracked_fraction": tracked, "visible_fraction": 1.0, "success": success, "crashed": crashed,
        "collision_rate": float(crashed), "following_rate": following, "initial_iou": initial_iou,
        "ground_depth_rmse_m": 0.5, "ground_depth_frames": 400, "target_depth_frames": 0, "decoy_switches": 0}
    spec = next(r for r in expand_suite("real-flight", Selection(scenes=(scene,), perceptions=(perception,)), ALL)
                if r.switch_value("time_of_day") == time)
    spec = RunSpec(spec.group, spec.kind, scene, spec.policy, perception, spec.pose_source, seed, spec.steps,
                   spec.camera_size, spec.switches, spec.extra, spec.depth_kind)
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_report_gives_rates_with_intervals_the_night_gate_and_the_crossover_and_city_per_world():
    results = [_result("desert", "trade", "night", 1, 0.95), _result("desert", "trade", "night", 2, 0.92),
               _result("desert", "dcf", "night", 1, 0.97, crashed=True), _result("desert", "dcf", "night", 2, 0.99),
               _result("desert", "trade", "crossover", 1, 0.2), _result("desert", "dcf", "crossover", 1, 0.8),
               _result("city", "trade", "day", 1, 0.99, following=0.95)]
    md = render_markdown(summarise(results), META, {}, [], [], results)
    assert "| time of day | scene | trade tracked | trade success | trade collision | dcf tracked |" in md
    assert "| night | desert | 0.94 ± 0.02 | 0 [0, 0.66] (2) | 0 [0, 0.66] (2) | 0.98 ± 0.01 |" in md
    assert "| desert | trade | 0.94 | 0.92 | 0 of 2 | met |" in md
    assert "| desert | dcf | 0.98 | 0.97 | 1 of 2 | not met |" in md  # tracked, but a collision
    assert "Hours flown [h, solar time]: desert night 2, crossover " in md
    assert "| desert | crossover | lost the target 1 | out of the following band 1 |" in md
    assert "| city | day | – |" in md  # the city at every time, the desert only at the crossover
    assert "| desert | crossover | 1 | 0.2 | ✗ | lost the target | 0.8 | ✗ | out of the following band |" in md
    assert "| desert | night | 1 |" not in md


def test_failure_classes_name_tracking_depth_collision_and_lag_and_an_error():
    passed = {"tracked_fraction": 0.9, "initial_iou": 0.8, "ground_depth_rmse_m": 0.4, "success": True}
    assert failure_classes(passed) == []
    assert failure_classes(passed | {"success": False}) == [OFF_BAND]
    assert failure_classes(passed | {"crashed": True, "success": False}) == [COLLISION]
    assert failure_classes(passed | {"tracked_fraction": 0.1, "initial_iou": 0.0}) == ["wrong initial box"]
    assert failure_classes({}, "RuntimeError: boom") == ["run error: RuntimeError: boom"]


def test_a_tiny_real_flight_run_of_both_perceptions_writes_results_that_reload_and_render_a_results_page(
        tmp_path, monkeypatch):
    out = tmp_path / "real_flight"
    argv = ["--suite", "real-flight", "--scenes", "desert", "--ablation", "time_of_day=night,crossover", "--seeds",
            str(SMOKE_WORLD), str(SMOKE_WORLD), "--steps", str(SMOKE_STEPS), "--camera-size", str(SMOKE_PX),
            "--jobs", "1", "--out", str(out)]
    assert cli.main(argv) == 0  # the runs go through run_all; the document is checked against the schema
    doc = json.loads((out / "results.json").read_text())
    assert [(r["perception"], r["switches"]["time_of_day"], r["error"]) for r in doc["runs"]] == \
        [(p, t, None) for p in ("trade", "dcf") for t in ("night", "crossover")]
    for run in doc["runs"]:
        assert run["metrics"]["steps"] == SMOKE_STEPS and run["env_kwargs"]["camera_modality"] == "thermal"
        assert run["env_kwargs"]["time_of_day_h"] in (NIGHT_H, morning_crossover("desert").time_h)
    results, _ = load_results(out / "results.json")
    flown = {r["run_id"]: r["env_kwargs"] for r in doc["runs"]}
    assert all(r.spec.env_kwargs() == flown[r.spec.run_id] for r in results)  # the hours flown come back
    assert (out / "real_flight_by_time_of_day.png").is_file() and (out / "real_flight_per_world.png").is_file()
    title, page = render_page_of(tmp_path, "real_flight", monkeypatch)
    assert page.startswith(f"# {title}") and f"Command: `trade-bench {' '.join(argv)}`" in page
    assert "| time of day | scene | trade tracked |" in page and "Acceptance (issue 45)" in page
    assert "![real_flight_by_time_of_day.png](real_flight/real_flight_by_time_of_day.png)" in page
