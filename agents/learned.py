"""The learned follower: a trained policy shipped as ONNX and run by onnxruntime (no torch at run time).

Owns `LearnedFollower` (SB3's `predict` shape, single or batched Dict observations), its soft start, the verified
loader of the policy file and its errors (`PolicyModelError`, a subclass of `AgentError`).

Soft start and gentle acceleration before the 3D fix: `trade_gym.agents.action_shaping` (the same shaping the
training env applies). A residual policy (its file says so, `trade_gym.agents.residual`) corrects the scripted
follower's action instead of flying alone; the shaping then applies to its correction.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from trade.model_file import ModelFileError, check_sha256_format, open_verified_session
from trade_gym.action import ACTION_DIM
from trade_gym.agents.action_shaping import (MAX_ACCEL_UNFIXED_MPS2, POLICY_SPEED_SCALE_MPS, SOFT_START_S,
                                             ActionShaping, ActionShapingConfig)
from trade_gym.agents.obs_flatten import N_FEATURES, POSITION_KNOWN_INDEX, flatten_observation
from trade_gym.agents.residual import Residual
from trade_gym.agents.scripted import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.assets import ASSETS_DIR

DEFAULT_POLICY = ASSETS_DIR / "policies" / "follower_ppo.onnx"
# SHA-256 of the shipped policy, printed by `python -m trade_gym.agents.train` and recorded in follower_ppo.md
DEFAULT_POLICY_SHA256 = "71efd3165ec1d06bd22c519796d9e4a6cc47a15d74216d19eddff32f2be401f1"
__all__ = ["DEFAULT_POLICY", "DEFAULT_POLICY_SHA256", "MAX_ACCEL_UNFIXED_MPS2", "POLICY_SPEED_SCALE_MPS",
           "SOFT_START_S", "AgentError", "LearnedFollower", "PolicyModelError"]


class AgentError(Exception):
    """Base of the errors raised by the agents package."""


class PolicyModelError(AgentError, ModelFileError):
    """The policy file is missing, empty, truncated, tampered with or not a usable policy model."""


class LearnedFollower:
    """`predict(obs) -> (action, state)` from the ONNX policy at `model_path`, checked against
    `expected_sha256` on load; one intra-op thread, sequential execution (deterministic).

    The exported policy is deterministic: `predict` returns the same action for `deterministic=False`.
    The policy is memoryless; per env the follower keeps the frames since the episode's start (the soft start,
    `soft_start_s=0` turns it off) and its last action (the acceleration limit before the 3D fix,
    `max_accel_unfixed_mps2=math.inf` turns it off), both in `trade_gym.agents.action_shaping`: `episode_start` True restarts an
    episode, and the first call after construction or `reset()` counts as a start. `state` is passed through unused.
    `LearnedFollower(soft_start_s=0, max_accel_unfixed_mps2=math.inf)` runs the bare policy.

    A residual policy file (`trade_gym.agents.residual`) flies `residual.combine(scripted, shaped policy output)`:
    the scripted follower built with `base_config` (the env's camera and action scale,
    `ScriptedFollowerConfig.of(env_config, env.action_scale)`; None: the defaults) keeps its per-env state alongside.
    `residual` is the file's `Residual` (reach and axes), None for a policy that flies alone."""

    def __init__(self, model_path: str | Path = DEFAULT_POLICY, expected_sha256: str = DEFAULT_POLICY_SHA256,
                 soft_start_s: float = SOFT_START_S, max_accel_unfixed_mps2: float = MAX_ACCEL_UNFIXED_MPS2,
                 base_config: ScriptedFollowerConfig | None = None) -> None:
        check_sha256_format(expected_sha256)
        self.shaping = ActionShaping(ActionShapingConfig(soft_start_s, max_accel_unfixed_mps2))
        self.model_path = Path(model_path)
        self._session = open_verified_session(self.model_path, expected_sha256, "policy file", PolicyModelError)
        self._input_name = _check_io(self._session, self.model_path)
        try:
            residual = Residual.of_metadata(self._session.get_modelmeta().custom_metadata_map, self.model_path)
        except ValueError as exc:
            raise PolicyModelError(str(exc)) from None
        # the scripted follower a residual policy corrects, with the residual
        self._residual = None if residual is None else (ScriptedFollower(base_config), residual)

    @property
    def residual(self) -> Residual | None:
        """The file's residual, None for a policy that flies alone."""
        return None if self._residual is None else self._residual[1]

    @property
    def residual_scale(self) -> float | None:
        """The residual's reach, None for a policy that flies alone."""
        residual = self.residual
        return None if residual is None else residual.scale

    @property
    def soft_start_s(self) -> float:
        return self.shaping.config.soft_start_s

    @property
    def max_accel_unfixed_mps2(self) -> float:
        return self.shaping.config.max_accel_unfixed_mps2

    def reset(self) -> None:
        """Forget the episodes' frame counts and last actions: the next call starts new episodes."""
        self.shaping.reset()
        if self._residual is not None:
            self._residual[0].reset()

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
        action = self.shaping.shape(np.asarray(action, dtype=np.float32), features[:, POSITION_KNOWN_INDEX] > 0.0,
                                    episode_start)
        if self._residual is not None:
            scripted, residual = self._residual
            base, _ = scripted.predict(observation, episode_start=episode_start)
            action = residual.combine(np.asarray(base).reshape(action.shape), action)
        return (action if batched else action[0]), state

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
