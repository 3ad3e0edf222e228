"""The training env's breadth: per-episode scene and scenario options of the env, their draws, and the action shaping
the policy trains under (the same as `LearnedFollower` flies with)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym.agents.action_shaping import ActionShaping, ActionShapingConfig, ShapedAction
from trade_gym.agents.learned import LearnedFollower
from trade_gym.agents.obs_flatten import flatten_observation
from trade_gym.agents.train import TrainConfig, train
from trade_gym.agents.training_env import EpisodeDraws, ScenarioDraws, SceneRandomizedEnv
from trade_gym.config import SCENE_NAMES
from trade_gym.env import TradeFollowEnv
from trade_gym.sim.appearance import APPEARANCE_MODES
from trade_gym.sim.scenes import DECOY_TIERS
from trade_gym.sim.target_motion import TARGET_MOTIONS

ORACLE = {"perception": "oracle", "episode_duration_s": 0.2}


def test_reset_options_set_the_scenario_for_that_episode_only():
    env = TradeFollowEnv(scene="desert", **ORACLE)
    try:
        _, info = env.reset(seed=3, options={"target_motion": "evasive", "decoys": "none"})
        assert info["target_motion"]["mode"] == "evasive" and env.world.decoys == ()
        _, info = env.reset(seed=3)
        assert info["target_motion"]["mode"] == "cruise" and len(env.world.decoys) > 0
        assert env.config.target_motion == "cruise" and env.config.decoys == "ambiguous"
    finally:
        env.close()


def test_reset_option_equals_making_the_env_with_that_argument():
    def first_steps(env: TradeFollowEnv, **reset_kwargs) -> list[np.ndarray]:
        try:
            obs, _ = env.reset(seed=5, **reset_kwargs)
            return [obs["target_pos_rel_m"]] + [env.step(np.zeros(4, np.float32))[0]["target_pos_rel_m"]
                                                for _ in range(5)]
        finally:
            env.close()

    made = first_steps(TradeFollowEnv(scene="city", target_motion="stop_and_go", decoys="parked", **ORACLE))
    option = first_steps(TradeFollowEnv(scene="desert", **ORACLE),
                         options={"scene": "city", "target_motion": "stop_and_go", "decoys": "parked"})
    for a, b in zip(made, option, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("options, words", [({"world_seed": 3}, "'world_seed'"), ({"scene": "forest"}, "forest"),
                                            ({"target_motion": "teleport"}, "teleport"),
                                            ({"appearance": "sepia"}, "sepia")])
def test_bad_reset_option_raises_value_error_naming_it(options, words):
    env = TradeFollowEnv(scene="desert", **ORACLE)
    try:
        with pytest.raises(ValueError, match=words):
            env.reset(seed=0, options=options)
    finally:
        env.close()


def test_scenario_draws_cover_every_choice_and_a_single_choice_draws_nothing():
    rng = np.random.default_rng(0)
    draws = [ScenarioDraws(("cruise", "evasive"), ("none", "parked", "ambiguous"), ("fixed",)).draw(rng)
             for _ in range(60)]
    assert {d["target_motion"] for d in draws} == {"cruise", "evasive"}
    assert {d["decoys"] for d in draws} == {"none", "parked", "ambiguous"} and {d["appearance"] for d in draws} == {
        "fixed"}
    rng, untouched = np.random.default_rng(1), np.random.default_rng(1)
    assert ScenarioDraws().draw(rng) == {"target_motion": "cruise", "decoys": "ambiguous", "appearance": "fixed"}
    assert rng.integers(1 << 30) == untouched.integers(1 << 30)
    with pytest.raises(ValueError, match="target_motions"):
        ScenarioDraws(target_motions=("teleport",))


def test_scene_randomized_env_draws_scenarios_per_episode_into_the_env():
    env = SceneRandomizedEnv(("desert",), ScenarioDraws(("cruise", "evasive"), ("none", "ambiguous")), **ORACLE)
    try:
        seen = set()
        for k in range(12):
            _, info = env.reset(seed=k)
            seen.add((info["target_motion"]["mode"], len(env.unwrapped.world.decoys) > 0))
        assert seen == {("cruise", False), ("cruise", True), ("evasive", False), ("evasive", True)}
    finally:
        env.close()


def test_one_env_for_every_scene_flies_the_episodes_of_an_env_made_for_each():
    """SceneRandomizedEnv resets one env on each episode's drawn scene, world and scenario; an env made for that
    scene and reset on the same world seed and scenario flies the same episode."""
    scenarios = ScenarioDraws(TARGET_MOTIONS, DECOY_TIERS, APPEARANCE_MODES)
    env = SceneRandomizedEnv(SCENE_NAMES, scenarios, **ORACLE)
    actions = np.random.default_rng(4).uniform(-1.0, 1.0, (4, 4)).astype(np.float32)
    scenes = set()
    try:
        for k in range(6):
            obs, info = env.reset(seed=11) if k == 0 else env.reset()
            episode = env.unwrapped.episode_config
            scenes.add(info["scene"])
            flown = [obs] + [env.step(a)[0] for a in actions]
            alone = TradeFollowEnv(scene=info["scene"], **ORACLE)
            try:
                options = {o: getattr(episode, o) for o in ("decoys", "target_motion", "appearance")}
                again = [alone.reset(seed=info["world_seed"], options=options)[0]] + [alone.step(a)[0]
                                                                                      for a in actions]
            finally:
                alone.close()
            for a, b in zip(flown, again, strict=True):
                for key in a:
                    np.testing.assert_array_equal(a[key], b[key])
        assert len(scenes) > 1
    finally:
        env.close()


def test_episode_draws_refuse_an_unknown_scene_naming_it():
    env = TradeFollowEnv(**ORACLE)
    try:
        with pytest.raises(ValueError, match="scenes.*forest"):
            EpisodeDraws(env, scenes=["desert", "forest"])
        with pytest.raises(ValueError, match="decoy_tiers"):
            EpisodeDraws(env, decoy_tiers=[])
    finally:
        env.close()


def test_shaped_action_gives_the_env_what_learned_follower_flies():
    """The same policy outputs through the training wrapper and through LearnedFollower's shaping reach the env
    identically, episode starts and the 3D-fix flag included."""
    rng = np.random.default_rng(2)
    outputs = rng.uniform(-1.0, 1.0, (80, 4)).astype(np.float32)
    received: list[np.ndarray] = []
    env = SceneRandomizedEnv(("desert",), **ORACLE, oracle_first_fix_delay_s=0.5)
    wrapped = ShapedAction(env)
    original_step = env.step
    env.step = lambda action: (received.append(np.array(action)), original_step(action))[1]  # type: ignore
    reference, expected = ActionShaping(), []
    try:
        obs, _ = wrapped.reset(seed=0)
        start = True
        for output in outputs:
            known = flatten_observation(obs)[0][:, -1] > 0.0
            expected.append(reference.shape(output[None], known, np.array([start]))[0])
            obs, _, terminated, truncated, _ = wrapped.step(output)
            start = terminated or truncated
            if start:
                obs, _ = wrapped.reset()
        np.testing.assert_array_equal(np.array(received), np.array(expected))
        assert np.abs(received[0]).max() == 0.0  # the soft start's first frame
    finally:
        wrapped.close()


def test_learned_follower_shaping_is_action_shaping():
    follower = LearnedFollower(soft_start_s=0.5, max_accel_unfixed_mps2=3.0)
    assert follower.shaping.config == ActionShapingConfig(0.5, 3.0)
    with pytest.raises(ValueError, match="max_accel_unfixed_mps2"):
        ActionShapingConfig(max_accel_unfixed_mps2=-1.0)
    assert ActionShapingConfig(max_accel_unfixed_mps2=math.inf).max_step == math.inf


def test_finetune_continues_training_on_its_own_env_kwargs(tmp_path):
    """A small PPO run whose fine-tune flies the TRADE stack at a 32 px camera; the record holds both stages."""
    config = TrainConfig(total_steps=128, n_envs=1, n_steps_per_env=64, batch_size=64, n_epochs=1,
                         scenes=("desert",), episode_duration_s=1.0, progress_bar=False, warm_start=None,
                         critic_warmup_steps=0, checkpoint_every_steps=0, finetune_steps=128,
                         finetune_env_kwargs=(("perception", "trade"), ("camera_size", 32)))
    record = train(config, tmp_path)
    assert record["steps"] >= 256 and record["finetune"]["steps"] >= 128
    assert (tmp_path / "policy_before_finetune.onnx").is_file()
    assert record["finetune"]["onnx_sha256_before"] != record["onnx_sha256"]
