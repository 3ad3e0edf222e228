"""The TRADE stack in the loop (perception="trade"): desert, ground-truth pose, scripted follower."""

from __future__ import annotations

import pytest

from tests.trade_gym.test_follow import fly_episode
from trade_gym import metrics

STEPS = 300
MAX_GROUND_RMSE_M = 0.5
MIN_TRACKED_FRACTION = 0.9
TRACKED_IOU = 0.3


def desert_metrics(seed: int, perception: str = "trade") -> dict[str, float]:
    infos = fly_episode("desert", seed, perception=perception, camera_size=256, pose_source="gt",
                        episode_duration_s=STEPS / 30.0)
    return {
        "steps": len(infos),
        "tracked": metrics.tracked_fraction(infos, TRACKED_IOU),
        "ground_rmse_m": metrics.depth_rmse(infos, "ground"),
        "ground_frames": metrics.depth_frames(infos, "ground"),
        "switches": metrics.decoy_switches(infos),
    }


def _check(m: dict[str, float]) -> None:
    assert m["steps"] == STEPS
    assert m["ground_frames"] >= STEPS // 2, m  # the plane exists for most of the run
    assert m["ground_rmse_m"] <= MAX_GROUND_RMSE_M, m
    assert m["tracked"] >= MIN_TRACKED_FRACTION, m
    assert m["switches"] == 0, m


def test_trade_desert_tracks_and_estimates_ground_depth_one_seed():
    _check(desert_metrics(seed=0))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_trade_desert_five_seeds(seed):
    _check(desert_metrics(seed))
