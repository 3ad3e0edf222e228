"""The TRADE stack in the loop (perception="trade"): desert, ground-truth pose, scripted follower."""

from __future__ import annotations

import numpy as np
import pytest

from tests.trade_gym.test_follow import fly_episode

STEPS = 300
MAX_GROUND_RMSE_M = 0.5
MIN_TRACKED_FRACTION = 0.9
TRACKED_IOU = 0.3


def desert_metrics(seed: int, perception: str = "trade") -> dict[str, float]:
    infos = fly_episode("desert", seed, perception=perception, camera_size=256, pose_source="gt",
                        episode_duration_s=STEPS / 30.0)
    ious = np.array([i["iou"] for i in infos])
    visible = np.array([i["target_visible"] for i in infos])
    ground = np.array([(i["ground_depth_est"], i["ground_depth_gt"]) for i in infos])
    both = np.all(np.isfinite(ground), axis=1)
    on_decoy = np.array([i["on_decoy"] for i in infos])
    return {
        "steps": len(infos),
        "tracked": float(np.mean(ious[visible] >= TRACKED_IOU)),
        "ground_rmse_m": float(np.sqrt(np.mean((ground[both, 0] - ground[both, 1]) ** 2))),
        "ground_frames": int(both.sum()),
        "switches": int(on_decoy[0] + np.sum(on_decoy[1:] & ~on_decoy[:-1])),
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
