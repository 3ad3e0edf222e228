"""Episode metrics on hand-made info sequences with known answers."""

from __future__ import annotations

import math

from trade_gym import metrics


def info(iou=1.0, visible=True, on_decoy=False, g=(10.0, 10.0), t=(9.0, 9.0), dist=1.0, crash=False):
    return {"iou": iou, "target_visible": visible, "on_decoy": on_decoy, "ground_depth_est": g[0],
            "ground_depth_gt": g[1], "target_depth_est": t[0], "target_depth_gt": t[1],
            "horizontal_distance_m": dist, "crashed": crash}


def test_perfect_track_scores_full_marks():
    infos = [info() for _ in range(10)]
    assert metrics.tracked_fraction(infos) == 1.0
    assert metrics.decoy_switches(infos) == 0
    assert metrics.depth_rmse(infos, "ground") == 0.0
    assert not metrics.crashed(infos)


def test_switch_onto_decoy_counted_once_per_rising_edge():
    flags = [False, True, True, False, True, False]
    infos = [info(on_decoy=f, iou=0.0 if f else 0.9) for f in flags]
    assert metrics.decoy_switches(infos) == 2
    assert metrics.tracked_fraction(infos) == 0.5


def test_gap_frames_where_target_hidden_are_not_scored_for_tracking():
    infos = [info(iou=0.8), info(iou=0.0, visible=False), info(iou=0.1)]
    assert metrics.visible_fraction(infos) == 2 / 3
    assert metrics.tracked_fraction(infos) == 0.5


def test_depth_rmse_ignores_frames_missing_either_depth():
    infos = [info(g=(11.0, 10.0)), info(g=(math.nan, 10.0)), info(g=(7.0, 10.0))]
    assert math.isclose(metrics.depth_rmse(infos, "ground"), math.sqrt((1 + 9) / 2))
    assert metrics.depth_frames(infos, "ground") == 2


def test_empty_track_gives_nan_not_errors():
    assert math.isnan(metrics.tracked_fraction([]))
    assert math.isnan(metrics.depth_rmse([], "target"))
    assert metrics.decoy_switches([]) == 0
