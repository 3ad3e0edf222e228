"""Failed-run classification of trade-bench: the thresholds' edges and each cause."""

from __future__ import annotations

import math

import pytest

from trade_gym.bench import failures as f

PASSING = {"tracked_fraction": 0.9, "initial_iou": 0.8, "decoy_switches": 0, "ground_depth_rmse_m": 0.3,
           "ground_depth_bias_m": -0.1}


def test_passing_run_has_no_cause_and_the_thresholds_are_inclusive():
    assert f.failure_cause(PASSING) is None
    edge = PASSING | {"tracked_fraction": f.FAIL_TRACKED_FRACTION, "ground_depth_rmse_m": f.FAIL_GROUND_RMSE_M}
    assert f.failure_cause(edge) is None


@pytest.mark.parametrize("change, cause", [
    ({"tracked_fraction": 0.2, "initial_iou": 0.1}, f.WRONG_INITIAL_BOX),
    ({"tracked_fraction": 0.2, "decoy_switches": 2}, f.ON_DECOY),
    ({"tracked_fraction": 0.2}, f.LOST_TRACK),
    ({"ground_depth_rmse_m": 12.0, "ground_depth_bias_m": -11.0}, f.PLANE_ABOVE),
    ({"ground_depth_rmse_m": 5.0, "ground_depth_bias_m": 4.0}, f.PLANE_BELOW),
    ({"ground_depth_rmse_m": 5.0, "ground_depth_bias_m": 0.5}, f.PLANE_UNSTABLE),
    ({"ground_depth_rmse_m": None}, f.NO_GROUND_DEPTH),
])
def test_each_cause_is_named(change, cause):
    assert f.failure_cause(PASSING | change) == cause


def test_both_stages_failing_lists_both_and_oracle_runs_skip_depth():
    metrics = PASSING | {"tracked_fraction": 0.1, "ground_depth_rmse_m": 9.0, "ground_depth_bias_m": -8.0}
    assert f.failure_cause(metrics) == f"{f.LOST_TRACK}; {f.PLANE_ABOVE}"
    assert f.failure_cause(PASSING | {"ground_depth_rmse_m": math.nan}, scores_ground_depth=False) is None
