"""Episode metrics on hand-made info sequences with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym import metrics

GT_BOX = (100.0, 100.0, 20.0, 10.0)
NO_BOX = (math.nan, math.nan, math.nan, math.nan)


def info(iou=1.0, visible=True, on_decoy=False, g=(10.0, 10.0), t=(9.0, 9.0), dist=1.0, crash=False,
         gt=GT_BOX, est=GT_BOX):
    return {"iou": iou, "target_visible": visible, "on_decoy": on_decoy, "ground_depth_est": g[0],
            "ground_depth_gt": g[1], "target_depth_est": t[0], "target_depth_gt": t[1],
            "horizontal_distance_m": dist, "crashed": crash, "gt_bbox": np.array(gt), "est_bbox": np.array(est),
            "est_valid": est is not NO_BOX, "following": True}


def shifted(dx_px: float) -> tuple[float, float, float, float]:
    return (GT_BOX[0] + dx_px, GT_BOX[1], GT_BOX[2], GT_BOX[3])


def test_perfect_track_scores_full_marks():
    infos = [info() for _ in range(10)]
    assert metrics.tracked_fraction(infos) == 1.0
    assert metrics.decoy_switches(infos) == 0
    assert metrics.depth_rmse(infos, "ground") == 0.0
    assert not metrics.crashed(infos)
    assert metrics.precision_at(infos) == 1.0
    assert metrics.longest_lost_streak_s(infos) == 0.0
    # OTB convention: success counts IoU > tau, so IoU = 1 fails only tau = 1 (20 of 21 thresholds).
    assert metrics.success_auc(infos) == pytest.approx(20 / 21)


def test_switch_onto_decoy_counted_once_per_rising_edge():
    flags = [False, True, True, False, True, False]
    infos = [info(on_decoy=f, iou=0.0 if f else 0.9) for f in flags]
    assert metrics.decoy_switches(infos) == 2
    assert metrics.tracked_fraction(infos) == 0.5


def test_decoy_switch_episode_starting_on_decoy_counts_first_frame():
    infos = [info(on_decoy=True, iou=0.0), info(on_decoy=True, iou=0.0), info()]
    assert metrics.decoy_switches(infos) == 1


def test_gap_frames_where_target_hidden_are_not_scored_for_tracking():
    infos = [info(iou=0.8), info(iou=0.0, visible=False, gt=NO_BOX, est=NO_BOX), info(iou=0.1)]
    assert metrics.visible_fraction(infos) == 2 / 3
    assert metrics.tracked_fraction(infos) == 0.5
    assert metrics.precision_at(infos) == 1.0  # both visible frames have their centre on the truth


def test_lost_streak_gap_of_hidden_and_untracked_frames_measured_in_seconds():
    ious = [1.0, 0.0, 0.0, 1.0, 0.1, 0.2, 0.0, 1.0]
    visible = [True, False, False, True, True, True, False, True]
    infos = [info(iou=i, visible=v) for i, v in zip(ious, visible)]
    # Longest lost run: frames 4..6 (two low-IoU frames and one hidden frame) = 3 frames.
    assert metrics.longest_lost_streak_s(infos, frame_dt_s=0.5) == pytest.approx(1.5)
    assert metrics.longest_lost_streak_s(infos) == pytest.approx(3 / 30)


def test_longest_run_edge_cases_counts_runs_touching_both_ends():
    assert metrics.longest_run([]) == 0
    assert metrics.longest_run([False, False]) == 0
    assert metrics.longest_run([True, True, False, True]) == 2
    assert metrics.longest_run([False, True, True, True]) == 3


def test_success_auc_constant_iou_counts_thresholds_below_it():
    # IoU 0.5 exceeds tau = 0, 0.05, ..., 0.45: 10 of 21 thresholds.
    infos = [info(iou=0.5) for _ in range(4)]
    assert metrics.success_auc(infos) == pytest.approx(10 / 21)
    # Half the frames at IoU 0 (never > tau): the AUC halves.
    infos += [info(iou=0.0) for _ in range(4)]
    assert metrics.success_auc(infos) == pytest.approx(5 / 21)


def test_precision_centre_error_threshold_is_inclusive_and_missing_estimate_fails():
    infos = [info(est=shifted(20.0)), info(est=shifted(20.5)), info(est=NO_BOX), info(est=shifted(3.0))]
    assert metrics.precision_at(infos) == 0.5
    err = metrics.centre_errors_px(infos)
    np.testing.assert_allclose(err[[0, 1, 3]], [20.0, 20.5, 3.0])
    assert err[2] == np.inf
    assert metrics.precision_at(infos, threshold_px=25.0) == 0.75


def test_depth_rmse_ignores_frames_missing_either_depth():
    infos = [info(g=(11.0, 10.0)), info(g=(math.nan, 10.0)), info(g=(7.0, 10.0))]
    assert math.isclose(metrics.depth_rmse(infos, "ground"), math.sqrt((1 + 9) / 2))
    assert metrics.depth_frames(infos, "ground") == 2
    np.testing.assert_array_equal(metrics.depth_errors_m(infos, "ground"), [1.0, math.nan, -3.0])


def test_ground_off_fraction_counts_frames_beyond_the_threshold_among_those_with_both_depths():
    infos = [info(g=(10.5, 10.0)), info(g=(math.nan, 10.0)), info(g=(7.0, 10.0)), info(g=(11.2, 10.0))]
    assert metrics.depth_off_fraction(infos, "ground") == pytest.approx(2 / 3)  # 1 m: -3 and +1.2 are off
    assert metrics.depth_off_fraction(infos, "ground", threshold_m=2.0) == pytest.approx(1 / 3)
    assert math.isnan(metrics.depth_off_fraction([info(g=(math.nan, 10.0))], "ground"))
    assert metrics.episode_metrics(infos)["ground_depth_off_fraction"] == pytest.approx(2 / 3)


def test_depth_rmse_unknown_kind_raises_value_error():
    with pytest.raises(ValueError, match="kind"):
        metrics.depth_rmse([info()], "sky")


def test_horizontal_error_and_crash_flag_over_episode():
    infos = [info(dist=1.0), info(dist=3.0), info(dist=5.0, crash=True)]
    assert metrics.mean_horizontal_distance(infos) == 3.0
    assert metrics.crashed(infos)


def test_empty_track_gives_nan_not_errors():
    assert math.isnan(metrics.tracked_fraction([]))
    assert math.isnan(metrics.depth_rmse([], "target"))
    assert metrics.decoy_switches([]) == 0
    scores = metrics.episode_metrics([])
    assert scores["steps"] == 0 and scores["decoy_switches"] == 0 and scores["crashed"] is False
    for name in ("visible_fraction", "success_auc", "precision_20px", "longest_lost_streak_s",
                 "ground_depth_rmse_m", "mean_horizontal_error_m"):
        assert math.isnan(scores[name]), name


def test_empty_estimate_track_scores_zero_and_whole_episode_lost():
    infos = [info(iou=0.0, est=NO_BOX, g=(math.nan, 10.0), t=(math.nan, 9.0)) for _ in range(6)]
    scores = metrics.episode_metrics(infos)
    assert scores["tracked_fraction"] == 0.0
    assert scores["success_auc"] == 0.0
    assert scores["precision_20px"] == 0.0
    assert scores["longest_lost_streak_s"] == pytest.approx(6 / 30)
    assert math.isnan(scores["ground_depth_rmse_m"]) and scores["ground_depth_frames"] == 0


def test_initial_iou_is_the_first_arriving_estimates_also_when_a_latency_holds_it_back():
    assert metrics.initial_iou([info(iou=0.7), info(iou=0.2)]) == 0.7
    late = [info(iou=0.0, est=NO_BOX), info(iou=0.0, est=NO_BOX), info(iou=0.8), info(iou=0.1)]
    assert metrics.initial_iou(late) == 0.8  # not the 0 of the first steps, which held no estimate yet
    assert math.isnan(metrics.initial_iou([info(iou=0.0, est=NO_BOX)]))


def test_episode_metrics_keys_match_metric_names():
    assert tuple(metrics.episode_metrics([info()])) == metrics.METRIC_NAMES


def test_steps_per_second_zero_time_is_nan():
    assert metrics.steps_per_second(300, 2.0) == 150.0
    assert math.isnan(metrics.steps_per_second(300, 0.0))
