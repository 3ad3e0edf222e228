"""The env's reward is the following task: its terms, their shape, and what they rank on dev worlds."""

from __future__ import annotations

import numpy as np
import pytest

from trade_gym.bench.policies import make_policy
from trade_gym.bench.splits import DEVELOPMENT
from trade_gym.config import CAMERA_RATE_HZ, SCENE_NAMES, EnvConfig
from trade_gym.reward import RewardConfig, RewardInputs, compute_reward
from trade_gym.rollout import run_episode
from trade_gym.scoring import FollowBand
from trade_gym.sim.scenes import get_scene

TERMS = ("visible", "distance", "height", "effort", "crash")
HOVER_ACTION = np.zeros(4, np.float32)
RETURN_FRAMES = 300  # 10 s: the target drives 15-30 m, a few follow heights' worth of footprint
RETURN_WORLDS = DEVELOPMENT.seeds(2)
MIN_RETURN_GAIN = 0.2  # the scripted follower earns at least 20 % more than the better floor
MAX_HOVER_RETURN_SHARE = 0.5  # hovering at the start distance earns at most half the scripted follower's return


def frame_reward(follow_height_m: float, distance_m: float = 0.0, height_m: float | None = None,
                 visible: bool = True, crashed: bool = False, action=HOVER_ACTION) -> tuple[float, dict]:
    height = follow_height_m if height_m is None else height_m
    band_m = FollowBand.of(follow_height_m, EnvConfig().camera_fov_deg).max_distance_m
    return compute_reward(RewardConfig(), RewardInputs(visible, distance_m, height, follow_height_m, band_m,
                                                       np.asarray(action, np.float32), crashed))


@pytest.mark.parametrize("scene", SCENE_NAMES)
def test_standing_further_off_the_target_earns_strictly_less(scene):
    h = get_scene(scene).follow_altitude_agl_m
    rewards = [frame_reward(h, distance_m=d)[0] for d in (0.0, 2.0, 5.0, 10.0)]
    assert all(a > b for a, b in zip(rewards, rewards[1:])), rewards


@pytest.mark.parametrize("scene", SCENE_NAMES)
def test_distance_is_measured_in_following_band_distances_and_saturates_at_the_band_edge(scene):
    h = get_scene(scene).follow_altitude_agl_m
    band_m = FollowBand.of(h, EnvConfig().camera_fov_deg).max_distance_m
    share = RewardConfig().band_distance_share
    for d in (band_m / 2, band_m, 2 * band_m, h, 3 * h):
        expected = share * min(d / band_m, 1.0) + (1.0 - share) * min(d / h, 1.0)
        assert frame_reward(h, distance_m=d)[1]["distance"] == pytest.approx(-expected)
    assert frame_reward(h, distance_m=h)[1]["distance"] == pytest.approx(-1.0)  # both parts saturated


@pytest.mark.parametrize("scene", SCENE_NAMES)
def test_climbing_above_the_follow_height_earns_less_than_holding_it(scene):
    h = get_scene(scene).follow_altitude_agl_m
    assert frame_reward(h, height_m=h + 5.0)[0] < frame_reward(h, height_m=h)[0]
    assert frame_reward(h, height_m=h - 5.0)[0] < frame_reward(h, height_m=h)[0]


def test_terms_sum_to_the_reward_and_each_term_has_its_sign():
    total, terms = frame_reward(30.0, distance_m=4.0, height_m=33.0, crashed=True, action=[0.5, -0.5, 0.2, 0.0])
    assert set(terms) == set(TERMS) and total == pytest.approx(sum(terms.values()))
    assert terms["visible"] > 0 and all(terms[t] < 0 for t in ("distance", "height", "effort", "crash"))
    assert frame_reward(30.0, visible=False)[1]["visible"] == 0.0


def test_a_crash_never_pays_against_flying_on_until_the_lost_timeout():
    """The worst frame without a crash, repeated until the lost-target timeout ends the episode, loses less
    than the crash penalty."""
    config, env = RewardConfig(), EnvConfig()
    timeout_frames = env.lost_timeout_s * CAMERA_RATE_HZ
    assert config.crash_penalty >= config.worst_frame_loss() * timeout_frames
    worst, _ = frame_reward(30.0, distance_m=1e3, height_m=1e3, visible=False, action=np.ones(4))
    assert worst == pytest.approx(-config.worst_frame_loss())


@pytest.mark.parametrize("bad", [{"crash_penalty": -1.0}, {"distance_weight": float("nan")},
                                 {"visible_bonus": True}, {"band_distance_share": 1.5}])
def test_bad_reward_weight_raises_naming_it(bad):
    name = next(iter(bad))
    with pytest.raises(ValueError, match=f"RewardConfig.{name}"):
        RewardConfig(**bad)


def test_gym_make_takes_reward_weights_as_a_config_or_a_mapping():
    assert EnvConfig(reward={"distance_weight": 2.0}).reward == RewardConfig(distance_weight=2.0)
    with pytest.raises(ValueError, match="reward must be"):
        EnvConfig(reward=3)
    with pytest.raises(TypeError, match="centering_weight"):
        EnvConfig(reward={"centering_weight": 1.0})


def episode_return(policy_name: str, scene: str, seed: int) -> float:
    policy = make_policy(policy_name, seed, EnvConfig().camera_pitch_deg)
    infos = run_episode(policy, seed, RETURN_FRAMES, scene=scene, perception="oracle")
    return sum(info["reward_" + t] for info in infos for t in TERMS)


@pytest.mark.parametrize("scene", SCENE_NAMES)
def test_following_earns_clearly_more_than_hovering_or_random_actions(scene):
    """Over dev worlds (oracle), the scripted follower's return beats the better of hover and random by 20 %, and
    hovering at the start distance earns at most half of it: watching the target drive off is not following."""
    mean = {name: np.mean([episode_return(name, scene, s) for s in RETURN_WORLDS])
            for name in ("scripted", "hover", "random")}
    floor = max(mean["hover"], mean["random"])
    assert mean["scripted"] >= floor + MIN_RETURN_GAIN * abs(floor), mean
    assert mean["hover"] <= MAX_HOVER_RETURN_SHARE * mean["scripted"], mean
