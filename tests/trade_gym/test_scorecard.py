"""The scorecard: EVT-style success, following and collision rates; VOTS-style NRE, DRE and ADQ."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym import metrics
from trade_gym.reward import RewardInputs
from trade_gym.scoring import FOLLOW_BAND_HEIGHT_FRACTION, FollowBand

H, FOV = 30.0, 110.0


def frame(visible=True, reported=True, iou=0.8, following=True, crashed=False) -> dict:
    return {"target_visible": visible, "est_valid": reported, "iou": iou, "following": following, "crashed": crashed}


def test_each_vots_class_from_visibility_report_and_overlap():
    infos = [frame(), frame(iou=0.0), frame(reported=False), frame(visible=False, iou=math.nan),
             frame(visible=False, reported=False, iou=math.nan)]
    assert metrics.vots_classes(infos) == {"tracked": 1, "failure": 1, "miss": 1, "hallucination": 1, "notice": 1}
    assert metrics.not_reported_error(infos) == pytest.approx(1 / 3)
    assert metrics.drift_rate_error(infos) == pytest.approx(1 / 3)


def test_adq_needs_more_than_ten_absent_frames():
    absent = [frame(visible=False, reported=False, iou=math.nan)] * metrics.ADQ_MIN_ABSENT_FRAMES
    assert math.isnan(metrics.absence_detection_quality(absent))
    more = absent + [frame(visible=False, reported=True, iou=math.nan)]
    assert metrics.absence_detection_quality(more) == pytest.approx(10 / 11)
    assert math.isnan(metrics.not_reported_error(absent))  # no visible frame: undefined, not 0


def test_success_needs_no_crash_and_the_band_on_ninety_percent_of_frames():
    n_in = int(metrics.SUCCESS_FOLLOWING_RATE * 100)
    edge = [frame()] * n_in + [frame(following=False)] * (100 - n_in)
    assert metrics.following_rate(edge) == pytest.approx(metrics.SUCCESS_FOLLOWING_RATE) and metrics.success(edge)
    below = [frame()] * (n_in - 1) + [frame(following=False)] * (101 - n_in)
    assert not metrics.success(below)
    crashed = [frame()] * 99 + [frame(crashed=True)]
    assert not metrics.success(crashed)
    assert metrics.success([]) is None and metrics.success([{k: v for k, v in frame().items() if k != 'following'}]) is None


def band_inputs(distance_m: float, height_m: float, visible: bool = True) -> RewardInputs:
    return RewardInputs(visible, distance_m, height_m, H, FollowBand.of(H, FOV).max_distance_m, np.zeros(4), False)


def test_follow_band_edges_follow_the_geometry():
    band = FollowBand.of(H, FOV)
    half_width = H * math.tan(math.radians(FOV) / 2)
    assert band.max_distance_m == pytest.approx(half_width / 4)
    assert band.holds(band_inputs(band.max_distance_m, H))
    assert not band.holds(band_inputs(band.max_distance_m * 1.01, H))
    tol = FOLLOW_BAND_HEIGHT_FRACTION * H
    assert band.holds(band_inputs(0.0, H + tol)) and not band.holds(band_inputs(0.0, H + tol * 1.01))
    assert not band.holds(band_inputs(0.0, H, visible=False))


def test_episode_metrics_carry_every_scorecard_key_from_an_env_episode():
    from trade_gym.bench.policies import make_policy
    from trade_gym.rollout import run_episode

    infos = run_episode(make_policy("scripted", 0, 90.0), 0, 60, scene="desert", perception="oracle")
    scores = metrics.episode_metrics(infos)
    for key in ("success", "following_rate", "collision_rate", "nre", "dre", "adq"):
        assert key in scores
    assert scores["following_rate"] > 0.5 and scores["collision_rate"] == 0.0 and math.isnan(scores["adq"])


def test_an_occlusion_gives_absent_frames_that_adq_scores():
    """A 1 s overpass over the path hides the target (absent frames); the stack should not report a box there."""
    import gymnasium as gym

    from trade_gym.agents import ScriptedFollower
    from trade_gym.faults import Fault, FaultSchedule, SensorFaults
    from trade_gym.rollout import fly_episode

    schedule = FaultSchedule((Fault("occlusion", start_frame=20, duration_frames=30),))
    env = SensorFaults(gym.make("TradeFollow-v0", scene="desert", camera_size=128), schedule)
    try:
        infos = fly_episode(env, ScriptedFollower(), 0, 70)
    finally:
        env.close()
    classes = metrics.vots_classes(infos)
    absent = classes["hallucination"] + classes["notice"]
    assert absent > metrics.ADQ_MIN_ABSENT_FRAMES, classes
    adq = metrics.absence_detection_quality(infos)
    assert 0.0 <= adq <= 1.0 and classes["tracked"] > 0, classes


def test_a_pitched_camera_moves_the_band_to_its_standoff():
    """With the camera pitched 45 deg the target is centred one follow height behind it: the band is centred on that
    standoff (a drone right above the target is out of it), and the reward's distance error is measured from it; a
    downward camera's standoff is exactly 0 (the band as before)."""
    assert FollowBand.of(H, FOV).standoff_m == 0.0
    band = FollowBand.of(H, FOV, 45.0)
    assert band.standoff_m == pytest.approx(H) and band.max_distance_m == FollowBand.of(H, FOV).max_distance_m

    def inputs(distance_m: float) -> RewardInputs:
        return RewardInputs(True, distance_m, H, H, band.max_distance_m, np.zeros(4), False, band.standoff_m)
    assert band.holds(inputs(H)) and band.holds(inputs(H + 0.9 * band.max_distance_m))
    assert not band.holds(inputs(0.0)) and not band.holds(inputs(H + 1.1 * band.max_distance_m))
    assert inputs(H).follow_error_m == pytest.approx(0.0, abs=1e-9) and inputs(0.0).follow_error_m == pytest.approx(H)
