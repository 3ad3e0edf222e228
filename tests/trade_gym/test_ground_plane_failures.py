"""Closed-loop regressions, one per failure class that was fixed, each on worlds that showed it (slow: 300 frames
at 256 px each): a steep plane fitted to a roof edge, a perturbed initial box whose snap was rejected (development
worlds), and a roof plane the target could not stand on held by temporal fusion (training worlds of the depth
finder)."""

from __future__ import annotations

import numpy as np
import pytest

from trade_gym.agents import ScriptedFollower
from trade.planes import MultiRansacConfig
from trade_gym import metrics
from trade_gym.bench.failures import FAIL_GROUND_RMSE_M, FAIL_TRACKED_FRACTION
from trade_gym.bench.runner import fly
from trade_gym.bench.suites import UNSEEN_PROTOCOL, RunSpec
from trade_gym.env import TradeFollowEnv
from trade_gym.rollout import fly_episode

STEPS, CAMERA_PX = 300, 256
MIN_TRACKED_FRACTION = 0.99  # tracking stays as it was: every finder run was tracked throughout
MAX_GROUND_TILT_DEG = MultiRansacConfig().max_ground_tilt_deg  # the ground a vehicle can drive (30 deg)


@pytest.mark.slow
def test_city_world_101_no_steep_plane_from_a_roof_edge_and_ground_rmse_under_failure_threshold():
    """Development city world 101 (full TRADE, gt pose, clean start): the first masked points (a roof edge
    and the street) fitted a 46 deg plane that put the ground 22 m up for 80 frames and gated the street's
    points out (ground RMSE 13.8 m)."""
    env = TradeFollowEnv(scene="city", camera_size=CAMERA_PX)
    tilts = []

    class Probe(ScriptedFollower):
        def predict(self, observation, state=None, episode_start=None, deterministic=True):
            last = env.perception.last
            if last is not None and last.plane is not None:
                tilts.append(last.plane.tilt_deg)
            return super().predict(observation, state, episode_start, deterministic)

    try:
        infos = fly_episode(env, Probe(), 101, STEPS)
    finally:
        env.close()
    assert len(infos) == STEPS and tilts
    assert max(tilts) <= MAX_GROUND_TILT_DEG
    assert metrics.depth_rmse(infos, "ground") < FAIL_GROUND_RMSE_M
    assert metrics.tracked_fraction(infos) > 0.9 and np.isfinite(metrics.depth_rmse(infos, "ground"))


@pytest.mark.slow
def test_city_world_110_perturbed_initial_box_beside_a_roof_edge_is_found_and_no_decoy_is_taken():
    """Development city world 110, the unseen suite's protocol (first frame shifted, box perturbed within
    5 px and snapped), gt pose: the box was drawn half a truck's width towards a roof edge and a parked car,
    the blob there merged with them and was rejected, and the tracker learnt a template half on the street
    (initial IoU 0.26; over 450 frames tracked 0.02 with 5 decoy switches)."""
    env = TradeFollowEnv(scene="city", camera_size=CAMERA_PX, **dict(UNSEEN_PROTOCOL))
    try:
        infos = fly_episode(env, ScriptedFollower(), 110, STEPS)
    finally:
        env.close()
    assert len(infos) == STEPS
    assert metrics.initial_iou(infos) > FAIL_TRACKED_FRACTION
    assert metrics.tracked_fraction(infos) > 0.9
    assert metrics.decoy_switches(infos) == 0


# Training city worlds whose ground depth failed in the depth finder's protocol (`trade-bench --suite unseen-depth
# --tables depth_training`, worlds 10000-10039, and the same grid on worlds 10060-10099 with gt pose:
# benchmarks/results/roof_plane_city_training*.json) before a roof plane was dropped and a weak fused plane could be
# outvoted: (follower, pose source, world, ground RMSE before [m]). Each run: full TRADE, clean start, 300 frames at
# 256 px.
ROOF_PLANE_WORLDS = (
    ("learned", "gt", 10_034, 12.26),  # 6 roof points 1.7 m under the drone held the plane for 58 frames
    ("learned", "gt", 10_078, 9.99),
    ("scripted", "gt", 10_091, 17.09),
    ("learned", "vio", 10_011, 4.15),
    ("learned", "vio", 10_017, 2.52),
    ("scripted", "vio", 10_007, 2.06),
)


@pytest.mark.slow
@pytest.mark.parametrize(("policy", "pose_source", "world", "rmse_before_m"), ROOF_PLANE_WORLDS)
def test_training_city_world_that_put_the_ground_on_a_roof_keeps_its_ground_depth_under_the_failure_threshold(
        policy: str, pose_source: str, world: int, rmse_before_m: float):
    spec = RunSpec("depth_training", "unseen", "city", policy, "trade", pose_source, world, STEPS, CAMERA_PX)
    infos, _ = fly(spec)
    rmse = metrics.depth_rmse(infos, "ground")
    assert len(infos) == STEPS and rmse_before_m > FAIL_GROUND_RMSE_M
    assert rmse < FAIL_GROUND_RMSE_M, f"world {world}: ground RMSE {rmse:.2f} m (before the fix {rmse_before_m} m)"
    assert metrics.tracked_fraction(infos) >= MIN_TRACKED_FRACTION and metrics.decoy_switches(infos) == 0
