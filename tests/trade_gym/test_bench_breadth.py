"""trade-bench's scenario breadth: the suite's grid and its tuning twin, the success table's cells and intervals, the
breadth report, plot and document."""

from __future__ import annotations

import collections
import math

import jsonschema
import pytest

from trade_gym.bench import cli, plots, runner
from trade_gym.bench import results as results_module
from trade_gym.bench.report import render_markdown
from trade_gym.bench.results import load_schema, to_json_safe
from trade_gym.bench.suites import RunSpec, Selection, expand_suite
from trade_gym.bench.summary import summarise
from trade_gym.metrics import METRIC_NAMES

ALL = ("scripted", "learned", "hover", "random")


def test_breadth_suite_is_every_tier_motion_appearance_follower_and_perception_on_evaluation_worlds():
    from trade_gym.bench.splits import EVALUATION
    from trade_gym.bench.suites import BREADTH_TIERS

    runs = expand_suite("breadth", Selection(), ALL)
    # tiers x scenes x worlds x followers x perceptions x motions x appearances
    assert len(runs) == 3 * 3 * 5 * 2 * 2 * 3 * 2
    assert len({r.world_seed for r in runs}) >= 5
    assert {r.switch_value("decoys") for r in runs} == set(BREADTH_TIERS)
    assert {r.switch_value("target_motion") for r in runs} == {"cruise", "stop_and_go", "evasive"}
    assert {r.switch_value("appearance") for r in runs} == {"fixed", "randomized"}
    assert {(r.policy, r.perception) for r in runs} == {(p, q) for p in ("scripted", "learned") for q in ("trade", "dcf")}
    assert all(r.world_seed in EVALUATION for r in runs)
    assert "breadth_parked/city/learned/dcf/vio/target_motion=evasive,appearance=randomized/seed5000" in \
        {r.run_id for r in runs}
    cli.validate_runs(runs)
    cli.check_worlds("breadth", runs)
    with pytest.raises(cli.UsageError):  # its evaluation worlds belong to evaluation suites only
        cli.check_worlds(None, runs[:1])


MIN_SUCCESS_CELL_RUNS = 30  # issue 41: every cell of the breadth success table holds at least this many runs


def test_every_cell_of_the_breadth_success_table_holds_at_least_30_runs():
    """A cell: follower, perception, target motion and appearance, runs pooled over scenes, worlds and tiers."""
    runs = expand_suite("breadth", Selection(), ALL)
    cells = collections.Counter((r.policy, r.perception, r.switch_value("target_motion"), r.switch_value("appearance"))
                                for r in runs)
    assert len(cells) == 2 * 2 * 3 * 2 and min(cells.values()) >= MIN_SUCCESS_CELL_RUNS, cells


def test_breadth_tuning_suite_is_the_breadth_grid_on_training_worlds():
    from trade_gym.bench.splits import TRAINING

    tuning, evaluation = expand_suite("breadth-tuning", Selection(), ALL), expand_suite("breadth", Selection(), ALL)
    assert len(tuning) == len(evaluation) and all(r.world_seed in TRAINING for r in tuning)
    cli.check_worlds("breadth-tuning", tuning)
    assert {r.run_id.rsplit("/", 1)[0] for r in tuning} == {r.run_id.rsplit("/", 1)[0] for r in evaluation}


def test_wilson_interval_matches_the_textbook_values_and_stays_in_the_unit_interval():
    from trade_gym.bench.summary import wilson_interval

    assert wilson_interval(0.5, 18) == pytest.approx((0.2903, 0.7097), abs=1e-4)
    assert wilson_interval(1.0, 45) == pytest.approx((0.9213, 1.0), abs=1e-4)
    low, high = wilson_interval(0.0, 30)
    assert low == 0.0 and high == pytest.approx(0.1135, abs=1e-4)
    assert all(math.isnan(v) for v in wilson_interval(0.5, 0))


def _breadth_result(tier: str, policy: str, perception: str, motion: str, success: bool) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {
        "steps": 450, "success": success, "following_rate": 0.95 if success else 0.2, "collision_rate": 0.0,
        "ground_depth_frames": 0, "target_depth_frames": 0, "decoy_switches": 0, "crashed": False}
    spec = RunSpec(f"breadth_{tier}", "breadth", "desert", policy, perception, "vio", 5000, 450, 256,
                   (("target_motion", motion), ("appearance", "fixed")), (("decoys", tier),))
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 20.0), None)


def test_breadth_report_gives_success_per_tier_and_motion_and_plots_it(tmp_path):
    results = [_breadth_result(tier, "scripted", perception, motion, success)
               for tier, perception, motion, success in [
                   ("none", "trade", "cruise", True), ("none", "trade", "evasive", True),
                   ("none", "dcf", "cruise", True), ("none", "dcf", "evasive", False),
                   ("ambiguous", "trade", "cruise", True), ("ambiguous", "trade", "evasive", False),
                   ("ambiguous", "dcf", "cruise", False), ("ambiguous", "dcf", "evasive", False)]]
    md = render_markdown(summarise(results), {"commit": "c", "date_utc": "d", "cpu": "x", "cores": 1,
                                              "renderer": "r", "runs": 8, "wall_s": 1.0, "jobs": 1}, {}, [], [])
    assert "| tier | scripted (trade) | scripted (dcf) |" in md
    assert "| breadth_none | 1 [0.34, 1] (2) | 0.5 [0.09, 0.91] (2) |" in md
    assert "| breadth_ambiguous | 0.5 [0.09, 0.91] (2) | 0 [0, 0.66] (2) |" in md
    # the success table: motion x appearance, pooled over tiers
    assert "| follower (perception) | cruise, fixed | evasive, fixed |" in md
    assert "| scripted (trade) | 1 [0.34, 1] (2) | 0.5 [0.09, 0.91] (2) |" in md
    assert "| follower | cruise, fixed | evasive, fixed | success | following | collision |" in md
    assert "| scripted (dcf) | 1 [0.21, 1] (1) | 0 [0, 0.79] (1) | 0.5 [0.09, 0.91] (2) | 0.57 (2) | 0 (2) |" in md
    written = plots.plot_suite(results, tmp_path)
    assert [p.name for p in written] == ["breadth_success.png"] and written[0].stat().st_size > 0
    assert plots.plot_suite(results[:0], tmp_path) == []


def test_breadth_suite_document_is_schema_valid():
    results = [_breadth_result(tier, "learned", "trade", "stop_and_go", tier == "none") for tier in ("none", "parked")]
    meta = results_module.collect_meta("breadth", ["--suite", "breadth"], 2, len(results), 1.0)
    doc = to_json_safe(results_module.build_document(results, summarise(results), meta, [], None))
    jsonschema.validate(doc, load_schema())
