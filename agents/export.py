"""Export of a trained stable-baselines3 follower (PPO or SAC) to ONNX for `LearnedFollower`.

The graph maps features (N, N_FEATURES) float32 to actions (N, 4) float32: the deterministic action
(PPO: the Gaussian mean clipped to [-1, 1]; SAC: tanh of the mean), with a zero yaw rate appended when
the policy was trained on the 3-D (forward, left, up) action. A residual policy's file carries its metadata
(`trade_gym.agents.residual.Residual.metadata`). Training extras only: imports torch.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.sac.policies import SACPolicy

from trade_gym.action import ACTION_DIM
from trade_gym.agents.obs_flatten import N_FEATURES
from trade_gym.agents.residual import POLICY_AXES, Residual

OPSET = 17  # supported by the venv's onnxruntime (1.17+ runs opset <= 20)
INPUT_NAME = "features"
OUTPUT_NAME = "action"
VERIFY_SAMPLES = 256
VERIFY_FEATURE_STD = 2.0  # random verification features ~ N(0, 2^2), inside the +-10 feature clip


class DeterministicActor(torch.nn.Module):
    """features (N, F) -> deterministic env action (N, 4), as SB3's `predict(deterministic=True)`."""

    # the buffers registered in __init__ (torch types a module's attributes only as tensor or module)
    embed: torch.Tensor
    low: torch.Tensor
    high: torch.Tensor

    def __init__(self, model: BaseAlgorithm) -> None:
        super().__init__()
        policy, space = model.policy, model.action_space
        if not isinstance(policy, (ActorCriticPolicy, SACPolicy)) or not isinstance(space, spaces.Box):
            raise TypeError(f"export needs a PPO or SAC policy on a Box action space, got {type(policy).__name__} "
                            f"on {space}")
        self.policy = policy
        self.pad = ACTION_DIM - int(space.shape[0])
        if self.pad < 0:
            raise ValueError(f"policy action dim {space.shape[0]} exceeds the env's {ACTION_DIM}")
        self.register_buffer("embed", torch.eye(ACTION_DIM - self.pad, ACTION_DIM))
        self.register_buffer("low", torch.as_tensor(space.low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(space.high, dtype=torch.float32))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        policy = self.policy
        if isinstance(policy, ActorCriticPolicy):
            # a = clip(W_a h(x) + b_a, low, high), h = the actor MLP on the flattened features (the actor's own
            # features where the policy keeps separate actor and critic extractors)
            extracted = policy.extract_features(features)
            latent = policy.mlp_extractor.forward_actor(extracted[0] if isinstance(extracted, tuple) else extracted)
            action = torch.clamp(policy.action_net(latent), self.low, self.high)
        else:
            # SAC: a = tanh(mu(x)) rescaled from [-1, 1] to [low, high]
            mean, _, _ = policy.actor.get_action_dist_params(features)
            squashed = torch.tanh(mean)
            action = self.low + (squashed + 1.0) * 0.5 * (self.high - self.low)
        if self.pad:
            action = action @ self.embed  # a_env = a E, E = [I | 0]: zero yaw rate, exact, static width
        return action


def export_onnx(model: BaseAlgorithm, path: str | Path, metadata: dict[str, str] | None = None) -> str:
    """Write the deterministic actor of `model` to `path` (dynamic batch) with the model `metadata` entries (e.g.
    `Residual.metadata`); returns the file's SHA-256."""
    if model.observation_space.shape != (N_FEATURES,):
        raise ValueError(f"model observes {model.observation_space.shape}, expected ({N_FEATURES},) features")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    actor = DeterministicActor(model).eval()
    # The TorchScript exporter (dynamo=False): the torch.export one needs onnxscript, which the train extra
    # does not carry; torch flags the old one as deprecated, which says nothing about this graph.
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(actor, (torch.zeros(1, N_FEATURES),), str(path), opset_version=OPSET, dynamo=False,
                          input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
                          dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}})
    if metadata:
        import onnx

        graph = onnx.load(str(path))
        onnx.helper.set_model_props(graph, metadata)
        onnx.save(graph, str(path))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def sb3_actions(model: BaseAlgorithm, features: np.ndarray) -> np.ndarray:
    """SB3's own deterministic actions (N, 4) for features (N, F), yaw padded like the export."""
    action, _ = model.predict(np.asarray(features, np.float32), deterministic=True)
    action = np.asarray(action, np.float32).reshape(len(features), -1)
    pad = ACTION_DIM - action.shape[1]
    return np.concatenate([action, np.zeros((len(action), pad), np.float32)], axis=1)


def max_export_error(model: BaseAlgorithm, path: str | Path, rng: np.random.Generator) -> float:
    """max |onnxruntime(path) - SB3 predict| over random features (the export's self-check)."""
    import onnxruntime as ort

    features = (rng.standard_normal((VERIFY_SAMPLES, N_FEATURES)) * VERIFY_FEATURE_STD).astype(np.float32)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (onnx_action,) = session.run(None, {INPUT_NAME: features})
    return float(np.max(np.abs(onnx_action - sb3_actions(model, features))))


def main() -> None:
    import argparse

    from stable_baselines3 import PPO, SAC

    parser = argparse.ArgumentParser(description="Export a saved SB3 follower (.zip) to ONNX.")
    parser.add_argument("model", type=Path, help="SB3 .zip saved by trade_gym.agents.train")
    parser.add_argument("out", type=Path, help="ONNX file to write")
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo")
    parser.add_argument("--residual-scale", type=float, default=None,
                        help="the model was trained as a residual of the scripted follower with this reach")
    parser.add_argument("--residual-axes", nargs="+", default=list(POLICY_AXES), choices=POLICY_AXES, metavar="AXIS",
                        help="the action axes the residual corrects (TrainConfig.residual_axes)")
    args = parser.parse_args()
    model = (PPO if args.algo == "ppo" else SAC).load(args.model, device="cpu")
    metadata = None if args.residual_scale is None else Residual(args.residual_scale, tuple(args.residual_axes)).metadata()
    digest = export_onnx(model, args.out, metadata)
    error = max_export_error(model, args.out, np.random.default_rng(0))
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes), SHA-256 {digest}, max |onnx - sb3| = {error:.2e}")


if __name__ == "__main__":
    main()
