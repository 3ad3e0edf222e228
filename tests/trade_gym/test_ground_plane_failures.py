"""Closed-loop regressions, one per failure class of the unseen-world suite that was fixed, each on a
development world that showed it (slow: 300 frames at 256 px each)."""

from __future__ import annotations

import numpy as np
import pytest

from agents import ScriptedFollower
from trade.planes import MultiRansacConfig
from trade_gym import metrics
from trade_gym.bench.failures import FAIL_GROUND_RMSE_M
from trade_gym.env import TradeFollowEnv
from trade_gym.rollout import fly_episode

STEPS, CAMERA_PX = 300, 256
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
