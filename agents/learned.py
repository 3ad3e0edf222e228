"""The learned follower: a trained policy shipped as ONNX and run by onnxruntime (no torch at run time).

Owns `LearnedFollower` (SB3's `predict` shape, single or batched Dict observations), its soft start, the verified
loader of the policy file and its errors (`PolicyModelError`, a subclass of `AgentError`).

Soft start: for the first `soft_start_s` of an episode the policy's action is scaled by the fraction of that time
elapsed (0 on the episode's first frame, 1 from `soft_start_s` on). The camera is fixed to the drone's body, so a
sudden command tilts the drone and moves the image by tens of pixels within a few frames, and a correlation-filter
tracker initialised on the first frame, before its first 3D fix (no trajectory guidance yet), loses a target moved
that far. The policy was trained on oracle perception, which never loses a target for moving fast in the image, so
nothing taught it to start gently. The scripted follower starts gently by its image-servo gain.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from agents.obs_flatten import N_FEATURES, flatten_observation
from trade.model_file import ModelFileError, check_sha256_format, open_verified_session
from assets import ASSETS_DIR
from trade.validation import is_finite_number, require
from trade_gym.action import ACTION_DIM
from trade_gym.config import CAMERA_RATE_HZ

DEFAULT_POLICY = ASSETS_DIR / "policies" / "follower_ppo.onnx"
# SHA-256 of the shipped policy, printed by `python -m agents.train` and recorded in follower_ppo.md
DEFAULT_POLICY_SHA256 = "71efd3165ec1d06bd22c519796d9e4a6cc47a15d74216d19eddff32f2be401f1"
# Length of the soft start [s] (module docstring); set on development worlds 100-119 of the city, where the policy
# without it lost the target in its first frames on 6 of 20 worlds under full TRADE (the model card).
SOFT_START_S = 1.0


class AgentError(Exception):
    """Base of the errors raised by the agents package."""


class PolicyModelError(AgentError, ModelFileError):
    """The policy file is missing, empty, truncated, tampered with or not a usable policy model."""


class LearnedFollower:
    """`predict(obs) -> (action, state)` from the ONNX policy at `model_path`, checked against
    `expected_sha256` on load; one intra-op thread, sequential execution (deterministic).

    The exported policy is deterministic: `predict` returns the same action for `deterministic=False`.
    The policy is memoryless; the follower counts the frames since each episode's start for the soft start (module
    docstring; `soft_start_s=0` turns it off): `episode_start` True restarts an episode's count, and the first call
    after construction or `reset()` counts as a start. `state` is passed through unused."""

    def __init__(self, model_path: str | Path = DEFAULT_POLICY, expected_sha256: str = DEFAULT_POLICY_SHA256,
                 soft_start_s: float = SOFT_START_S) -> None:
        check_sha256_format(expected_sha256)
        require(is_finite_number(soft_start_s) and soft_start_s >= 0.0, "LearnedFollower soft_start_s", soft_start_s,
                ">= 0")
        self.model_path = Path(model_path)
        self.soft_start_s = float(soft_start_s)
        self._session = open_verified_session(self.model_path, expected_sha256, "policy file", PolicyModelError)
        self._input_name = _check_io(self._session, self.model_path)
        self._frames: np.ndarray | None = None  # (N,) frames since each episode's start

    def reset(self) -> None:
        """Forget the episodes' frame counts: the next call starts new episodes."""
        self._frames = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """observation: Dict with (k,) values or a batch of (N, k) values -> action (4,) or (N, 4) float32."""
        features, batched = flatten_observation(observation)
        (action,) = self._session.run(None, {self._input_name: features})
        action = np.asarray(action, dtype=np.float32) * self._soft_start_scale(len(features), episode_start)[:, None]
        return (action if batched else action[0]), state

    def _soft_start_scale(self, n: int, episode_start: np.ndarray | None) -> np.ndarray:
        """(n,) float32 action scale of this frame per env, then one frame more counted."""
        if self._frames is None or len(self._frames) != n:
            self._frames = np.zeros(n, dtype=np.int64)
        if episode_start is not None:
            self._frames[np.asarray(episode_start, dtype=bool).reshape(-1)] = 0
        ramp_frames = self.soft_start_s * CAMERA_RATE_HZ
        scale = np.ones(n) if ramp_frames == 0 else np.minimum(1.0, self._frames / ramp_frames)
        self._frames += 1
        return scale.astype(np.float32)


def _check_io(session: ort.InferenceSession, path: Path) -> str:
    """Name of the single (N, N_FEATURES) float input; PolicyModelError unless the output is (N, 4) float."""
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(outputs) != 1:
        raise PolicyModelError(f"policy file {path} must have one input and one output, "
                               f"got {len(inputs)} and {len(outputs)}")
    in_shape, out_shape = list(inputs[0].shape), list(outputs[0].shape)
    if len(in_shape) != 2 or inputs[0].type != "tensor(float)" or in_shape[1] != N_FEATURES:
        raise PolicyModelError(f"policy file {path} expects input {inputs[0].type} {in_shape}, "
                               f"not float (N, {N_FEATURES}) features")
    if len(out_shape) != 2 or outputs[0].type != "tensor(float)" or out_shape[1] != ACTION_DIM:
        raise PolicyModelError(f"policy file {path} returns {outputs[0].type} {out_shape}, "
                               f"not float (N, {ACTION_DIM}) actions")
    return inputs[0].name
