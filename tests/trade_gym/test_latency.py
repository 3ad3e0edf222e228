"""Perception latency: "fixed" delivers frame k's estimate at the first frame j with t_j >= t_k + latency, holds
the newest arrived until then; 0 ms equals "none" exactly; "measured" delays by the compute time; bad input fails.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.utils.passive_env_checker import data_shares_objects

from trade_gym.agents import ScriptedFollower
from tests.trade_gym.test_determinism import single_digest
from trade.geometry import RotationWarp
from trade_gym.config import CAMERA_RATE_HZ, EnvConfig
from trade_gym.env import TradeFollowEnv
from trade_gym.latency import ARRIVAL_TOLERANCE_S, EstimateDelay
from trade_gym.perception.base import PerceptionOutput

ORACLE = dict(scene="city", perception="oracle", camera_size=64)  # the city resets fastest
TRADE = dict(scene="city", perception="trade", camera_size=64)
STEPS = 60
TRADE_STEPS = 12
FRAME_S = 1.0 / CAMERA_RATE_HZ
# 50 ms falls between frames (arrives 2 frames later), 100 ms exactly on the third frame after (the tolerance)
LATENCIES_MS = (50.0, 100.0)
SEED = 3


def _open_loop_run(seed: int, steps: int, poses: bool = False, **kwargs) -> list[dict]:
    """Infos of a reset and `steps` steps under a fixed sequence of actions (the same in every env, so the
    drone flies the same path whatever the observation holds); with `poses` each also holds the camera pose
    perception received ("pose")."""
    actions = np.random.default_rng(seed).uniform(-0.5, 0.5, (steps, 4)).astype(np.float32)
    env = TradeFollowEnv(**kwargs)
    extra = (lambda: {"pose": env.delivered_sensors.T_world_cam}) if poses else dict
    try:
        obs, info = env.reset(seed=seed)
        records = [info | {"obs": obs} | extra()]
        for action in actions:
            obs, _, terminated, truncated, info = env.step(action)
            records.append(info | {"obs": obs} | extra())
            assert not (terminated or truncated)
    finally:
        env.close()
    return records


def _same(a, b) -> bool:
    return np.array_equal(np.asarray(a, np.float64), np.asarray(b, np.float64), equal_nan=True)


@pytest.mark.parametrize("latency_ms", LATENCIES_MS)
def test_fixed_latency_delivers_frame_k_at_first_frame_past_its_latency_frame_by_frame(latency_ms):
    undelayed = _open_loop_run(SEED, STEPS, **ORACLE)
    delayed = _open_loop_run(SEED, STEPS, **ORACLE, perception_latency="fixed", perception_latency_ms=latency_ms)
    times = [r["t_s"] for r in undelayed]
    latency_s = latency_ms / 1000.0
    for j, record in enumerate(delayed):
        assert record["t_s"] == times[j]
        arrived = [k for k in range(j + 1) if times[j] >= times[k] + latency_s - ARRIVAL_TOLERANCE_S]
        if not arrived:  # nothing has arrived yet: a missing estimate, dated at the reset frame
            assert np.all(np.isnan(record["est_bbox"])) and not record["est_valid"]
            assert record["obs"]["track_valid"][0] == 0.0
            assert record["estimate_age_s"] == pytest.approx(times[j] - times[0], abs=1e-12)
            continue
        k = max(arrived)
        source = undelayed[k]
        assert record["estimate_age_s"] == pytest.approx(times[j] - times[k], abs=1e-12)
        assert record["obs"]["estimate_age_s"][0] == np.float32(record["estimate_age_s"])
        for key in ("est_bbox", "target_depth_est", "ground_depth_est", "est_valid"):
            assert _same(record[key], source[key]), (j, k, key)
        for key in ("bbox_norm", "target_depth_m", "track_valid", "time_lost_s"):
            assert _same(record["obs"][key], source["obs"][key]), (j, k, key)
        # the truth and the drone's own entries stay this frame's
        assert _same(record["gt_bbox"], undelayed[j]["gt_bbox"])
        assert _same(record["obs"]["drone_vel_mps"], undelayed[j]["obs"]["drone_vel_mps"])
    lag = [round(r["estimate_age_s"] / FRAME_S) for r in delayed[-5:]]
    assert lag == [math.ceil(latency_ms / 1000.0 / FRAME_S - 1e-6)] * 5


def test_latency_compensation_carries_the_held_box_by_the_cameras_rotation_since_its_frame():
    """Open loop (the same path either way), oracle at 100 ms: with compensation each held box is the uncompensated
    one warped by the rotation between the poses perception received at its frame and now; nothing else differs."""
    kwargs = ORACLE | dict(perception_latency="fixed", perception_latency_ms=100.0)
    raw = _open_loop_run(SEED, STEPS, **kwargs)
    carried = _open_loop_run(SEED, STEPS, **kwargs, latency_compensation=True, poses=True)
    env = TradeFollowEnv(**ORACLE)
    K = env.camera.intrinsics
    env.close()
    moved = 0
    for j, (a, b) in enumerate(zip(raw, carried)):
        assert a["t_s"] == b["t_s"] and _same(a["gt_bbox"], b["gt_bbox"])
        assert _same(a["target_depth_est"], b["target_depth_est"]) and a["est_valid"] == b["est_valid"]
        k = j - round(a["estimate_age_s"] / FRAME_S)
        if a["estimate_age_s"] == 0.0 or not np.all(np.isfinite(a["est_bbox"])):
            assert _same(a["est_bbox"], b["est_bbox"])
            continue
        warp = RotationWarp.between(K, carried[k]["pose"], b["pose"])
        np.testing.assert_allclose(b["est_bbox"], warp.apply_box(a["est_bbox"]), atol=1e-9)
        moved += not _same(a["est_bbox"], b["est_bbox"])
    assert moved > STEPS // 2


def test_only_the_light_stack_compensates_latency_by_default():
    assert EnvConfig(stack="light").latency_compensation and not EnvConfig().latency_compensation
    assert not EnvConfig(stack="light", latency_compensation=False).latency_compensation
    with pytest.raises(ValueError, match="latency_compensation"):
        EnvConfig(latency_compensation="yes")


def test_held_estimate_is_not_shared_between_steps():
    # 400 ms: the missing estimate is held for the first 12 frames; a user keeping every step's info or observation
    # must not see one change when another is modified (gymnasium's passive checker warns on shared arrays)
    records = _open_loop_run(SEED, 15, **ORACLE, perception_latency="fixed", perception_latency_ms=400.0)
    for before, after in zip(records, records[1:]):
        shared = [key for key in before.keys() & after.keys() if data_shares_objects(before[key], after[key])]
        assert not shared, (after["t_s"], shared)
    records[1]["est_bbox"][:] = 0.0
    assert np.all(np.isnan(records[2]["est_bbox"]))


def test_fixed_zero_latency_equals_none_exactly_oracle_closed_loop():
    none = single_digest(SEED, STEPS, **ORACLE)
    assert single_digest(SEED, STEPS, **ORACLE, perception_latency="fixed", perception_latency_ms=0.0) == none
    assert single_digest(SEED, STEPS, **ORACLE, perception_latency="fixed", perception_latency_ms=1.0) != none


def test_fixed_zero_latency_equals_none_exactly_trade_closed_loop():
    none = single_digest(SEED, TRADE_STEPS, **TRADE)
    assert single_digest(SEED, TRADE_STEPS, **TRADE, perception_latency="fixed", perception_latency_ms=0.0) == none


def test_none_observation_estimate_age_is_zero_every_frame():
    records = _open_loop_run(SEED, 10, **ORACLE)
    assert all(r["estimate_age_s"] == 0.0 and r["obs"]["estimate_age_s"][0] == 0.0 for r in records)


def test_measured_latency_delays_every_estimate_by_whole_frames():
    env = TradeFollowEnv(**ORACLE, perception_latency="measured")
    policy = ScriptedFollower()
    try:
        obs, info = env.reset(seed=SEED)
        assert info["estimate_age_s"] == 0.0 and not info["est_valid"]  # the reset estimate is still on its way
        ages = []
        for _ in range(20):
            obs, _, _, _, info = env.step(policy.predict(obs)[0])
            ages.append(info["estimate_age_s"] / FRAME_S)
    finally:
        env.close()
    # any compute time > 0 misses its own frame; the oracle's ~0.1 ms arrives by a later one
    assert all(age >= 1.0 - 1e-6 and abs(age - round(age)) < 1e-6 for age in ages)


def test_delay_keeps_the_newest_arrived_estimate_when_arrivals_overtake():
    delay = EstimateDelay(0.0, PerceptionOutput.missing())
    slow, fast = (PerceptionOutput.missing() for _ in range(2))
    delay.push(slow, 0.0, 0.3)  # frame 0 takes 300 ms
    delay.push(fast, 0.1, 0.05)  # frame 1 takes 50 ms: arrives first
    assert delay.deliver(0.1).frame_t_s == 0.0  # nothing arrived yet: the reset placeholder
    assert delay.deliver(0.15).estimate is fast
    assert delay.deliver(0.3).estimate is fast  # frame 0's arrives after a newer one: dropped


@pytest.mark.parametrize("kwargs, named", [
    (dict(perception_latency="slow"), "'slow'"),
    (dict(perception_latency="fixed", perception_latency_ms=-5.0), "-5.0"),
    (dict(perception_latency="fixed", perception_latency_ms=math.nan), "nan"),
    (dict(perception_latency="fixed"), "perception_latency_ms"),
    (dict(perception_latency_ms=33.0), "33.0"),
    (dict(perception_latency="measured", perception_latency_ms=33.0), "33.0"),
])
def test_bad_latency_arguments_raise_value_error_naming_the_value(kwargs, named):
    with pytest.raises(ValueError, match=named.replace(".", r"\.")):
        TradeFollowEnv(**ORACLE, **kwargs)
