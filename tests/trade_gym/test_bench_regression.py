"""Regression guard: a fixed-seed slice of the quick suite must stay within tolerance of the committed
reference (trade_gym/bench/quick_reference.json). Regenerate after an intended change with
`trade-bench --suite quick --out /tmp/quick --write-reference` and commit the file."""

from __future__ import annotations

import dataclasses

import pytest

from trade_gym.bench import reference
from trade_gym.bench.policies import available_policies
from trade_gym.bench.runner import run_all
from trade_gym.bench.suites import Selection, expand_suite

# Oracle runs are cheap (~1-3 ms/step); one rendered TRADE run (128 px, 150 steps) covers the stack.
GUARD_RUN_IDS = (
    "follow/desert/scripted/oracle/gt/seed0",
    "follow/city/scripted/oracle/gt/seed0",
    "follow/mountain/scripted/oracle/gt/seed0",
    "follow/desert/random/oracle/gt/seed0",
    "tracking/desert/scripted/trade/gt/seed0",
)


@pytest.fixture(scope="module")
def guard_results():
    specs = {s.run_id: s for s in expand_suite("quick", Selection(), available_policies())}
    return run_all([specs[run_id] for run_id in GUARD_RUN_IDS], jobs=1)


def test_quick_slice_within_tolerance_of_committed_reference(guard_results):
    problems, compared = reference.check_against_reference(guard_results, reference.load_reference())
    assert compared == len(GUARD_RUN_IDS), "reference lacks some guard runs: regenerate it"
    assert problems == [], "\n".join(problems + [f"regenerate if intended: {reference.REGENERATE_COMMAND}"])


def test_guard_trade_run_tracks_and_estimates_ground_depth(guard_results):
    trade = guard_results[-1].metrics
    assert trade["tracked_fraction"] >= 0.9 and trade["ground_depth_frames"] > 0


def test_guard_flags_degraded_tracking_and_depth(guard_results):
    run = guard_results[-1]
    worse = dict(run.metrics, tracked_fraction=run.metrics["tracked_fraction"] - 0.2,
                 ground_depth_rmse_m=2.0 * run.metrics["ground_depth_rmse_m"] + 1.0)
    problems, _ = reference.check_against_reference([dataclasses.replace(run, metrics=worse)],
                                                    reference.load_reference())
    assert [p.split(" ")[1] for p in problems] == ["tracked_fraction", "ground_depth_rmse_m"]
