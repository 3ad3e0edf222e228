"""The TRADE stack in the loop (perception="trade"): desert, ground-truth pose, scripted follower."""

from __future__ import annotations

import gymnasium as gym
import pytest

from tests.trade_gym.test_follow import fly_episode
from trade_gym import metrics
from trade_gym.bench.policies import make_policy
from trade_gym.config import EnvConfig

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


PITCHED_CAMERA_DEG = 45.0  # the paper's real flight
PITCHED_WORLD = 1  # a development world (desert)
MAX_FIRST_FIX_FRAME = 200
MAX_FIRST_FIX_ERROR = 0.15  # of the true target depth (8 % at the time of writing)


def test_trade_pitched_camera_gets_a_3d_fix_within_200_frames():
    """45 deg camera, full stack, waypoint follower: a target depth within 200 frames (frame 136, 8 % off, at the time of
    writing). Before the rules of trade/camera_pitch.py no frame of
    450 had one (the ground mask labelled no track ground; the ROI tracks left it with too little parallax)."""
    kw = dict(scene="desert", perception="trade", camera_pitch_deg=PITCHED_CAMERA_DEG, camera_size=256,
              world_seed=PITCHED_WORLD, action_mode="waypoint")
    env = gym.make("TradeFollow-v0", **kw)
    policy = make_policy("waypoint", PITCHED_WORLD, PITCHED_CAMERA_DEG, env_config=EnvConfig(**kw))
    obs, info = env.reset(seed=PITCHED_WORLD)
    try:
        for frame in range(MAX_FIRST_FIX_FRAME):
            obs, _, terminated, truncated, info = env.step(policy.predict(obs)[0])
            assert not (terminated or truncated)
            if info["target_depth_est"] is not None:
                break
        assert info["target_depth_est"] is not None, f"no 3D fix in {MAX_FIRST_FIX_FRAME} frames"
        error = abs(info["target_depth_est"] - info["target_depth_gt"]) / info["target_depth_gt"]
        assert error < MAX_FIRST_FIX_ERROR, (frame, info["target_depth_est"], info["target_depth_gt"])
    finally:
        env.close()
