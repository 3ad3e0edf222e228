"""The env's public contract: registration, spaces, check_env, determinism, bad input, lifecycle."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.env import TradeFollowEnv
from tests.trade_gym.env_checks import check_env_strict

SMALL = dict(camera_size=64)
INFO_KEYS = (
    "gt_bbox", "est_bbox", "iou", "target_visible", "on_decoy", "target_depth_gt",
    "target_depth_est", "ground_depth_gt", "ground_depth_est", "crashed",
)


def _rollout(env, seed: int, n_steps: int, render: bool = False):
    obs, info = env.reset(seed=seed)
    action_rng = np.random.default_rng(123)
    records = [(obs, info, None)]
    for _ in range(n_steps):
        action = action_rng.uniform(-0.3, 0.3, 4).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        frame = env.render() if render else None
        records.append((obs, info, reward, frame))
        if terminated or truncated:
            break
    return records


def _assert_same(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for k in a:
            _assert_same(a[k], b[k])
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape
        assert a.tobytes() == b.tobytes()
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b)
    else:
        assert a == b


def test_import_registers_env_and_module_prefix_works():
    env = gym.make("trade_gym:TradeFollow-v0", perception="oracle", **SMALL)
    try:
        assert env.spec.id == "TradeFollow-v0"
        assert env.spec.max_episode_steps == 900
    finally:
        env.close()


@pytest.mark.parametrize("scene", ["desert", "city", "mountain"])
def test_check_env_passes_with_warnings_as_errors(scene):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("TradeFollow-v0", scene=scene, perception="oracle", **SMALL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
            sb3_check_env(env.unwrapped, warn=True)
    finally:
        env.close()


def test_info_has_ground_truth_and_reward_terms_sum_to_reward():
    env = TradeFollowEnv(perception="oracle", **SMALL)
    try:
        env.reset(seed=3)
        for _ in range(5):
            _, reward, _, _, info = env.step(np.zeros(4, np.float32))
            for key in INFO_KEYS:
                assert key in info
            terms = [v for k, v in info.items() if k.startswith("reward_")]
            assert len(terms) >= 4
            assert np.isclose(sum(terms), reward)
            assert info["gt_bbox"].shape == (4,) and info["est_bbox"].shape == (4,)
    finally:
        env.close()


def test_same_seed_same_actions_identical_for_200_steps_with_frames():
    envs = [TradeFollowEnv(perception="oracle", render_mode="rgb_array", **SMALL) for _ in range(2)]
    try:
        a, b = (_rollout(e, seed=7, n_steps=200, render=True) for e in envs)
        assert len(a) == len(b) > 100
        _assert_same(a, b)
    finally:
        for e in envs:
            e.close()


def test_different_seeds_give_different_worlds():
    env = TradeFollowEnv(perception="oracle", **SMALL)
    try:
        obs0, info0 = env.reset(seed=0)
        obs1, info1 = env.reset(seed=1)
        assert not np.array_equal(info0["target_position_m"], info1["target_position_m"])
        assert not np.array_equal(obs0["target_pos_rel_m"], obs1["target_pos_rel_m"])
    finally:
        env.close()


@pytest.mark.parametrize("bad", [np.zeros(3), np.zeros((4, 1)), 0.5, [np.nan, 0, 0, 0], [0, np.inf, 0, 0]])
def test_bad_action_raises_value_error_naming_shape(bad):
    env = TradeFollowEnv(perception="oracle", **SMALL)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"\(4,\)"):
            env.step(bad)
    finally:
        env.close()


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(scene="moon"), "scene"),
        (dict(camera_size=0), "camera_size"),
        (dict(camera_size=-64), "camera_size"),
        (dict(perception="dimp"), "perception"),
        (dict(pose_source="slam"), "pose_source"),
        (dict(camera_fov_deg=float("nan")), "camera_fov_deg"),
        (dict(episode_duration_s=0.0), "episode_duration_s"),
    ],
)
def test_bad_config_raises_value_error_at_make(kwargs, field):
    with pytest.raises(ValueError, match=field):
        gym.make("TradeFollow-v0", **kwargs)


def test_unknown_keyword_raises_type_error():
    with pytest.raises(TypeError):
        gym.make("TradeFollow-v0", scenery="desert")


def test_close_twice_is_safe_and_step_after_close_raises():
    env = TradeFollowEnv(perception="oracle", **SMALL)
    env.reset(seed=0)
    env.close()
    env.close()
    with pytest.raises(RuntimeError, match="close"):
        env.step(np.zeros(4, np.float32))


def test_render_returns_annotated_frame():
    env = TradeFollowEnv(perception="oracle", render_mode="rgb_array", camera_size=96)
    try:
        env.reset(seed=0)
        env.step(np.zeros(4, np.float32))
        frame = env.render()
        assert frame.shape == (96, 96, 3) and frame.dtype == np.uint8
        # The ground-truth box is drawn in pure green somewhere in the frame.
        green = (frame[..., 0] == 0) & (frame[..., 1] == 255) & (frame[..., 2] == 0)
        assert green.sum() > 10
    finally:
        env.close()


def test_action_beyond_bounds_acts_like_the_bound():
    envs = [TradeFollowEnv(perception="oracle", **SMALL) for _ in range(2)]
    try:
        for e in envs:
            e.reset(seed=5)
        for _ in range(10):
            oa = envs[0].step(np.array([5.0, -3.0, 2.0, -9.0], np.float32))[0]
            ob = envs[1].step(np.array([1.0, -1.0, 1.0, -1.0], np.float32))[0]
            _assert_same(oa, ob)
    finally:
        for e in envs:
            e.close()


def test_default_env_is_full_trade_with_ground_mask_and_temporal_fusion():
    env = gym.make("TradeFollow-v0")
    try:
        perception = env.unwrapped.perception
        stack = perception.pipeline_config
        assert env.unwrapped.config.perception == "trade"
        assert stack.ground_mask and stack.temporal_fusion and stack.tracker.trajectory_guidance
        assert not stack.single_image_depth and perception.depth_model is not None
    finally:
        env.close()


def test_depth_only_mode_needs_the_ground_mask_turned_off_explicitly():
    with pytest.raises(ValueError, match="single_image_depth.*ground_mask"):
        gym.make("TradeFollow-v0", single_image_depth=True)
    gym.make("TradeFollow-v0", single_image_depth=True, ground_mask=False, camera_size=32).close()


def test_making_and_stepping_prints_nothing_and_agents_lists_its_lazy_names():
    """In a fresh interpreter (pybullet not yet imported): gym.make, reset, step and close write nothing to
    stdout or stderr (pybullet's C import prints a build-time banner on fd 2), and dir(trade_gym.agents) lists
    the names that load lazily."""
    import subprocess
    import sys

    code = ("import gymnasium as gym, trade_gym\nfrom trade_gym import agents\n"
            "env = gym.make('TradeFollow-v0', perception='oracle')\n"
            "env.reset(seed=0); env.step(env.action_space.sample()); env.close()\n"
            "assert {'LearnedFollower', 'PolicyModelError', 'ScriptedFollower'} <= set(dir(agents)), dir(agents)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == "", (done.stdout, done.stderr)


@pytest.mark.parametrize("perception", ["trade", "dcf"])
def test_check_env_passes_for_the_image_perceptions_with_missing_depths_as_none(perception):
    """check_env steps two envs with one seed and compares their infos: a depth that does not exist yet is
    None (NaN would differ from itself)."""
    env = gym.make("TradeFollow-v0", scene="desert", perception=perception, **SMALL)
    try:
        check_env_strict(env)
        _, info = env.reset(seed=0)
        assert info["ground_depth_est"] is None or math.isfinite(info["ground_depth_est"])
    finally:
        env.close()


def test_gymnasium_record_video_writes_an_episode(tmp_path):
    """gymnasium's RecordVideo (MoviePy, the `video` extra) records the env's rgb_array frames as an mp4."""
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(gym.make("TradeFollow-v0", perception="oracle", render_mode="rgb_array", **SMALL),
                      str(tmp_path / "videos"), episode_trigger=lambda episode: True, disable_logger=True)
    try:
        env.reset(seed=0)
        for _ in range(10):
            env.step(env.action_space.sample())
    finally:
        env.close()
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0, list((tmp_path / "videos").iterdir())
