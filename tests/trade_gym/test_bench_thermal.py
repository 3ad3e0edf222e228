"""trade-bench's thermal suite: its grid (full TRADE on the thermal camera at three times of day in every scene and the
light stack at night and by day in desert and mountain, scripted follower, gt pose, every evaluation world), the
same envs as benchmarks/thermal_tracking.py flies on development worlds, and its report (gates and per-world
failure classes)."""

from __future__ import annotations

import sys
from pathlib import Path

from trade_gym.bench import cli
from trade_gym.bench.splits import DEVELOPMENT, EVALUATION
from trade_gym.bench.suites import SUITE_JOBS, Selection, expand_suite
from trade_gym.config import SCENE_NAMES, EnvConfig
from trade_gym.sim.thermal_crossover import DAY_H, NIGHT_H, TIMES_OF_DAY, morning_crossover

ROOT = Path(__file__).resolve().parents[2]
ALL = ("scripted", "learned", "waypoint", "hover", "random")


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
