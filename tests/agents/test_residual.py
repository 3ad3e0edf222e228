"""Residual learned follower: the rule, the policy file's metadata, the training env's wrapper and LearnedFollower
flying a residual file (a zero residual flies exactly the scripted follower)."""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from trade_gym.action import ACTION_DIM
from trade_gym.agents.learned import LearnedFollower, PolicyModelError
from trade_gym.agents.obs_flatten import N_FEATURES
from trade_gym.agents.residual import AXES_KEY, BASE_KEY, POLICY_AXES, SCALE_KEY, Residual
from trade_gym.agents.scripted import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.agents.train import TrainConfig, _parser, config_from_args, train
from trade_gym.agents.training_env import ResidualAction
from trade_gym.agents.warm_start import WarmStartConfig
from trade_gym.agents.zoo import RESIDUAL_ACTION, env_wrappers
from trade_gym.env import TradeFollowEnv

STEPS = 60  # past the oracle's first fix (first_fix_delay_s 1 s = 30 frames): both of the scripted laws run
ENV = {"scene": "desert", "perception": "oracle", "oracle_first_fix_delay_s": 1.0, "camera_fov_deg": 90.0}


def constant_policy(path, action: list[float], metadata: dict[str, str] | None) -> str:
    """An ONNX policy features (N, F) -> action (N, 4) that outputs `action` for every input (0 x features + action),
    with `metadata`; returns its SHA-256."""
    weight = numpy_helper.from_array(np.zeros((N_FEATURES, ACTION_DIM), np.float32), "weight")
    bias = numpy_helper.from_array(np.asarray(action, np.float32), "bias")
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["features", "weight"], ["product"]),
         helper.make_node("Add", ["product", "bias"], ["action"])],
        "constant", [helper.make_tensor_value_info("features", TensorProto.FLOAT, ["batch", N_FEATURES])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", ACTION_DIM])], [weight, bias])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if metadata:
        helper.set_model_props(model, metadata)
    onnx.save(model, str(path))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_combine_adds_the_scaled_residual_on_its_axes_and_clips():
    base = np.array([0.5, -0.9, 0.3, 0.0])
    residual = np.array([1.0, -1.0, 0.5, 0.7])  # the yaw entry is never added: a policy does not command yaw
    out = Residual(0.4).combine(base, residual)
    np.testing.assert_allclose(out, [0.9, -1.0, 0.5, 0.0], atol=1e-7)
    assert out.dtype == np.float32
    horizontal = Residual(0.4, ("forward", "left")).combine(np.stack([base, base]), np.stack([residual, residual]))
    np.testing.assert_allclose(horizontal, [[0.9, -1.0, 0.3, 0.0]] * 2, atol=1e-7)  # the height is the base's


def test_metadata_round_trip_and_a_plain_file_has_no_residual():
    for residual in (Residual(0.35), Residual(0.35, ("left", "forward")), Residual(0.2, ("up",))):
        assert Residual.of_metadata(residual.metadata(), "p.onnx") == residual
    assert Residual.of_metadata({}, "p.onnx") is None
    # a file from before the axes entry: its residual corrects every axis the policy outputs
    assert Residual.of_metadata({BASE_KEY: "scripted", SCALE_KEY: "0.5"}, "p.onnx") == Residual(0.5, POLICY_AXES)


@pytest.mark.parametrize("metadata, words", [
    ({BASE_KEY: "waypoint", SCALE_KEY: "0.5"}, "'waypoint'"),
    ({BASE_KEY: "scripted", SCALE_KEY: "wide"}, "'wide'"),
    ({BASE_KEY: "scripted", SCALE_KEY: "-1"}, "'-1'"),
    ({SCALE_KEY: "0.5"}, "None"),
    ({AXES_KEY: "forward"}, "None"),
    ({BASE_KEY: "scripted", SCALE_KEY: "0.5", AXES_KEY: "forward,yaw_rate"}, "'forward,yaw_rate'"),
    ({BASE_KEY: "scripted", SCALE_KEY: "0.5", AXES_KEY: "left,left"}, "'left,left'"),
    ({BASE_KEY: "scripted", SCALE_KEY: "0.5", AXES_KEY: ""}, "''"),
])
def test_bad_metadata_raises_value_error_naming_file_and_value(metadata, words):
    with pytest.raises(ValueError, match=f"p.onnx.*{words}"):
        Residual.of_metadata(metadata, "p.onnx")


@pytest.mark.parametrize("bad", [0.0, -0.5, float("nan"), float("inf")])
def test_bad_scale_raises_value_error_naming_it(bad):
    with pytest.raises(ValueError, match="residual_scale"):
        Residual(bad)
    with pytest.raises(ValueError, match="TrainConfig.residual_scale"):
        TrainConfig(residual_scale=bad, warm_start=None)


@pytest.mark.parametrize("bad", [(), ("yaw_rate",), ("forward", "forward"), "forward", ("Forward",)])
def test_bad_axes_raise_value_error_naming_them(bad):
    with pytest.raises(ValueError, match="residual_axes"):
        Residual(0.5, bad)
    for scale in (0.5, None):
        with pytest.raises(ValueError, match="TrainConfig.residual_axes"):
            TrainConfig(residual_scale=scale, residual_axes=bad, warm_start=None)


def test_residual_refuses_a_warm_start():
    with pytest.raises(ValueError, match="residual_scale needs warm_start=None"):
        TrainConfig(residual_scale=0.5, warm_start=WarmStartConfig())


def test_zoo_file_wraps_the_residual_inside_the_shaping():
    wrappers = env_wrappers(TrainConfig(residual_scale=0.5, warm_start=None))
    assert wrappers[1] == {RESIDUAL_ACTION: {"scale": 0.5, "axes": ["forward", "left"]}}
    assert RESIDUAL_ACTION not in str(env_wrappers(TrainConfig()))


def test_zero_residual_flies_the_scripted_follower_step_for_step():
    """ResidualAction with a zero action gives the env exactly the scripted follower's actions (same observations,
    rewards); a second episode restarts the scripted follower's state."""
    plain, wrapped = TradeFollowEnv(**ENV), ResidualAction(TradeFollowEnv(**ENV), 0.5)
    try:
        for seed in (3, 4):
            follower = ScriptedFollower(ScriptedFollowerConfig.of(plain.config, plain.action_scale))
            obs_a, _ = plain.reset(seed=seed)
            obs_b, _ = wrapped.reset(seed=seed)
            for _ in range(STEPS):
                action, _ = follower.predict(obs_a)
                obs_a, reward_a, *_ = plain.step(action)
                obs_b, reward_b, *_ = wrapped.step(np.zeros(ACTION_DIM, np.float32))
                assert reward_a == reward_b
                for key in obs_a:
                    np.testing.assert_array_equal(obs_a[key], obs_b[key])
    finally:
        plain.close()
        wrapped.close()


def test_learned_follower_on_a_residual_file_adds_the_shaped_residual_to_the_scripted_follower(tmp_path):
    """A constant residual r on the horizontal axes, its shaping off: LearnedFollower's action is
    Residual(0.5, horizontal).combine(scripted, r) for single and batched observations; a zero residual (shaped or
    not) is the scripted follower itself."""
    residual = [0.2, -0.1, 0.05, 0.0]
    rule = Residual(0.5, ("forward", "left"))
    path = tmp_path / "residual.onnx"
    sha = constant_policy(path, residual, rule.metadata())
    zero_path = tmp_path / "zero.onnx"
    zero_sha = constant_policy(zero_path, [0.0] * ACTION_DIM, Residual(0.5).metadata())
    env = TradeFollowEnv(**ENV)
    config = ScriptedFollowerConfig.of(env.config, env.action_scale)
    learned = LearnedFollower(path, sha, soft_start_s=0.0, max_accel_unfixed_mps2=math.inf, base_config=config)
    zero = LearnedFollower(zero_path, zero_sha, base_config=config)
    scripted, reference = ScriptedFollower(config), ScriptedFollower(config)
    assert learned.residual == rule and learned.residual_scale == 0.5
    try:
        obs, _ = env.reset(seed=5)
        for _ in range(STEPS):
            expected, _ = scripted.predict(obs)
            action, _ = learned.predict(obs)
            np.testing.assert_allclose(action, rule.combine(expected, np.array(residual)), atol=1e-6)
            assert action[2] == expected[2]  # the height is the scripted follower's
            zero_action, _ = zero.predict(obs)
            np.testing.assert_array_equal(zero_action, reference.predict(obs)[0])
            obs, *_ = env.step(action)
    finally:
        env.close()
    # a batch of two copies of the last frame: each env's first frame, as a single observation's is
    batch = {k: np.stack([v, v]) for k, v in obs.items()}
    first, _ = ScriptedFollower(config).predict(obs)
    batched = LearnedFollower(path, sha, soft_start_s=0.0, max_accel_unfixed_mps2=math.inf, base_config=config)
    np.testing.assert_allclose(batched.predict(batch)[0], np.stack([rule.combine(first, np.array(residual))] * 2),
                               atol=1e-6)


def test_a_plain_file_flies_alone_and_bad_metadata_is_a_policy_model_error(tmp_path):
    path = tmp_path / "plain.onnx"
    assert LearnedFollower(path, constant_policy(path, [0.1, 0.0, 0.0, 0.0], None)).residual_scale is None
    bad = tmp_path / "bad.onnx"
    sha = constant_policy(bad, [0.0] * ACTION_DIM, {BASE_KEY: "scripted", SCALE_KEY: "0"})
    with pytest.raises(PolicyModelError, match="bad.onnx.*'0'"):
        LearnedFollower(bad, sha)


def test_training_a_residual_writes_a_residual_policy_file(tmp_path):
    """`--residual-scale` with `--from-scratch`: a short PPO run on the residual env exports a file that
    LearnedFollower flies as a residual of that reach (before and after the fine-tune)."""
    args = _parser().parse_args(["--out", str(tmp_path), "--from-scratch", "--residual-scale", "0.4", "--steps", "256",
                                 "--n-envs", "1", "--finetune-steps", "64", "--no-progress", "--checkpoint-every", "0"])
    config = replace(config_from_args(args), n_steps_per_env=64, batch_size=32, n_epochs=1, scenes=("desert",),
                     episode_duration_s=2.0, finetune_env_kwargs=(("camera_size", 64),))
    assert config.residual_scale == 0.4
    record = train(config, tmp_path)
    assert record["max_abs_onnx_minus_sb3"] <= 1e-5
    for name, sha in (("policy.onnx", record["onnx_sha256"]),
                      ("policy_before_finetune.onnx", record["finetune"]["onnx_sha256_before"])):
        assert LearnedFollower(tmp_path / name, sha).residual == Residual(0.4, ("forward", "left"))
