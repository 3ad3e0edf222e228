"""Bad input fails fast and clearly: actions, keyword arguments, config values and the depth model file.

Complements test_env.py (which checks the basic bad-action shapes and a few config values).
"""

from __future__ import annotations

import dataclasses
import math
import re
import time

import gymnasium as gym
import numpy as np
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade.model_file import ModelFileError
from trade.single_image_depth import DEFAULT_MODEL, DepthModelError
from trade_gym.config import EnvConfig
from trade_gym.env import TradeFollowEnv

SMALL = dict(scene="city", perception="oracle", camera_size=64)  # the city resets fastest
MAKE_TIME_LIMIT_S = 1.0
# Numeric keyword arguments and whether 0 is out of range for them (strictly positive quantities).
NUMERIC_FIELDS = {
    "camera_size": True, "camera_fov_deg": True, "camera_pitch_deg": True, "target_speed_mps": True,
    "episode_duration_s": True, "lost_timeout_s": True, "visible_fraction_threshold": False,
    "init_box_perturb_px": False, "init_frame_shift_max": False, "oracle_box_sigma_px": False,
    "oracle_depth_sigma_frac": False, "oracle_velocity_sigma_mps": False, "oracle_dropout_prob": False,
    "oracle_noise_correlation_s": False, "oracle_first_fix_delay_s": False, "world_seed": False,
    "perception_latency_ms": False, "time_of_day_h": False,
}
BOOL_FIELDS = [f.name for f in dataclasses.fields(EnvConfig) if f.type == "bool"]
BAD_NUMBERS = [math.nan, math.inf, -math.inf, -1.0]


@pytest.fixture(scope="module")
def reset_env():
    env = TradeFollowEnv(**SMALL)
    env.reset(seed=0)
    yield env
    env.close()


def _bad_config_cases():
    for name, zero_is_bad in NUMERIC_FIELDS.items():
        for value in BAD_NUMBERS + ([0.0] if zero_is_bad else []):
            yield pytest.param(name, value, id=f"{name}={value}")


def test_numeric_field_table_covers_every_numeric_config_field():
    numeric = {f.name for f in dataclasses.fields(EnvConfig)  # by the words of the type (not WaypointScale's "int")
               if {"int", "float"} & set(re.findall(r"\w+", f.type)) and f.type != "bool"}
    assert numeric == set(NUMERIC_FIELDS)


@pytest.mark.parametrize("name, value", list(_bad_config_cases()))
def test_make_non_finite_or_out_of_range_value_raises_value_error_naming_it_within_1s(name, value):
    start = time.perf_counter()
    with pytest.raises(ValueError, match=name):
        gym.make("TradeFollow-v0", **{name: value})
    assert time.perf_counter() - start < MAKE_TIME_LIMIT_S


@pytest.mark.parametrize("name", BOOL_FIELDS)
def test_make_non_bool_switch_raises_value_error_naming_it(name):
    with pytest.raises(ValueError, match=name):
        gym.make("TradeFollow-v0", **{name: 1})


@pytest.mark.parametrize("kwargs", [dict(scenery="desert"), dict(ground_masks=True), dict(seed=0)])
def test_unknown_keyword_raises_type_error_naming_it(kwargs):
    (name,) = kwargs
    with pytest.raises(TypeError, match=name):
        TradeFollowEnv(**kwargs)


@pytest.mark.parametrize("bad", [
    np.zeros(5), np.zeros((1, 4)), np.zeros((2, 2)), [], np.array(np.nan), None, "fast",
    [0.0, 0.0, -np.inf, 0.0], np.array([0, 0, 0, np.nan], np.float32),
])
def test_step_bad_action_raises_value_error(bad, reset_env):
    with pytest.raises(ValueError):
        reset_env.step(bad)
    reset_env.step(np.zeros(4, np.float32))  # the env is still usable after the rejected action


def test_action_beyond_bounds_gives_identical_obs_reward_and_info_as_clipped():
    envs = [TradeFollowEnv(**SMALL) for _ in range(2)]
    rng = np.random.default_rng(4)
    try:
        for e in envs:
            e.reset(seed=11)
        for _ in range(15):
            wild = rng.uniform(-3.0, 3.0, 4) * rng.choice([1.0, 1e6], 4)
            out_wild = envs[0].step(wild.astype(np.float32))
            out_clip = envs[1].step(np.clip(wild, -1.0, 1.0).astype(np.float32))
            assert _bytes(out_wild) == _bytes(out_clip)
    finally:
        for e in envs:
            e.close()


def _bytes(step_output) -> bytes:
    """Every value of (obs, reward, terminated, truncated, info) as bytes, keys sorted."""
    obs, reward, terminated, truncated, info = step_output
    parts = [np.asarray(obs[k]).tobytes() for k in sorted(obs)]
    parts += [np.asarray(v).tobytes() for v in (reward, terminated, truncated)]
    parts += [k.encode() + np.asarray(info[k]).tobytes() for k in sorted(info)]
    return b"".join(parts)


@pytest.mark.parametrize("damage", ["missing", "empty", "truncated", "tampered"])
def test_env_with_damaged_depth_model_raises_depth_model_error_naming_the_file(damage, tmp_path, monkeypatch):
    import trade_gym.perception.trade_stack as trade_stack

    path = tmp_path / "depth_small.onnx"
    data = DEFAULT_MODEL.read_bytes()
    if damage == "empty":
        path.write_bytes(b"")
    elif damage == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif damage == "tampered":
        path.write_bytes(data[:-1] + bytes([data[-1] ^ 0xFF]))
    original = trade_stack.SingleImageDepth
    monkeypatch.setattr(trade_stack, "SingleImageDepth", lambda: original(model_path=path))
    start = time.perf_counter()
    with pytest.raises(DepthModelError, match=str(path)) as raised:
        gym.make("TradeFollow-v0", ground_mask=True, camera_size=64)
    assert time.perf_counter() - start < MAKE_TIME_LIMIT_S
    assert isinstance(raised.value, ModelFileError)  # the one project error type for model files
