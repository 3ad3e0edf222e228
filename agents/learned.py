"""The learned follower: a trained policy shipped as ONNX and run by onnxruntime (no torch at run time).

Owns `LearnedFollower` (SB3's `predict` shape, single or batched Dict observations), its soft start, the verified
loader of the policy file and its errors (`PolicyModelError`, a subclass of `AgentError`).

Soft start: for the first `soft_start_s` of an episode the policy's action is scaled by the fraction of that time
elapsed (0 on the episode's first frame, 1 from `soft_start_s` on). The camera is fixed to the drone's body, so a
sudden command tilts the drone and moves the image by tens of pixels within a few frames, and a correlation-filter
tracker initialised on the first frame, before its first 3D fix (no trajectory guidance yet), loses a target moved
that far. The policy was trained on oracle perception, which never loses a target for moving fast in the image, so
nothing taught it to start gently. The scripted follower starts gently by its image-servo gain.

Gentle acceleration before the 3D fix: until the observation holds the target's 3D position, the horizontal
setpoint (forward, left) may change by at most `max_accel_unfixed_mps2` per second from the last frame's (zero on
an episode's first frame). Until that fix TRADE's tracker has no trajectory prediction and searches where constant
image velocity puts the target; the camera turns with the drone's tilt, so a hard brake or swerve (the policy flies
up to 7 m/s towards a target seen 7 m away, then brakes within a few frames) turns the image faster than that guess
follows and the target leaves the search window. After the fix the trajectory prediction guides the window and the
policy flies unlimited: limiting it all the time made it lag behind the target (module constant below).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from trade.model_file import ModelFileError, check_sha256_format, open_verified_session
from trade.validation import is_finite_number, is_positive_number, require
from trade_gym.action import ACTION_DIM, DEFAULT_ACTION_SCALE
from trade_gym.agents.obs_flatten import N_FEATURES, POSITION_KNOWN_INDEX, flatten_observation
from trade_gym.assets import ASSETS_DIR
from trade_gym.config import CAMERA_RATE_HZ

DEFAULT_POLICY = ASSETS_DIR / "policies" / "follower_ppo.onnx"
# SHA-256 of the shipped policy, printed by `python -m trade_gym.agents.train` and recorded in follower_ppo.md
DEFAULT_POLICY_SHA256 = "71efd3165ec1d06bd22c519796d9e4a6cc47a15d74216d19eddff32f2be401f1"
# Length of the soft start [s] (module docstring); set on development worlds 100-119 of the city, where the policy
# without it lost the target in its first frames on 6 of 20 worlds under full TRADE (the model card).
SOFT_START_S = 1.0
# Limit on the horizontal setpoint's change before the 3D fix [m/s^2] (module docstring); set on development worlds
# 100-119 of the city and the mountain (the model card): with it the city's early losses went away and the mountain
# was unchanged; the same limit held for the whole episode made the follower lag (mountain tracked 0.998 -> 0.905).
MAX_ACCEL_UNFIXED_MPS2 = 6.0
# The setpoint per unit action the policy was trained with [m/s] (the env's default quadrotor)
POLICY_SPEED_SCALE_MPS = DEFAULT_ACTION_SCALE.horizontal_mps
HORIZONTAL = slice(0, 2)  # forward, left in the action


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
    `max_accel_unfixed_mps2=math.inf` turns it off), both in the module docstring: `episode_start` True restarts an
    episode, and the first call after construction or `reset()` counts as a start. `state` is passed through unused.
    `LearnedFollower(soft_start_s=0, max_accel_unfixed_mps2=math.inf)` runs the bare policy."""

    def __init__(self, model_path: str | Path = DEFAULT_POLICY, expected_sha256: str = DEFAULT_POLICY_SHA256,
                 soft_start_s: float = SOFT_START_S, max_accel_unfixed_mps2: float = MAX_ACCEL_UNFIXED_MPS2) -> None:
        check_sha256_format(expected_sha256)
        require(is_finite_number(soft_start_s) and soft_start_s >= 0.0, "LearnedFollower soft_start_s", soft_start_s,
                ">= 0")
        require(max_accel_unfixed_mps2 == math.inf or is_positive_number(max_accel_unfixed_mps2),
                "LearnedFollower max_accel_unfixed_mps2", max_accel_unfixed_mps2, "> 0 (math.inf: no limit)")
        self.model_path = Path(model_path)
        self.soft_start_s = float(soft_start_s)
        self.max_accel_unfixed_mps2 = float(max_accel_unfixed_mps2)
        # the limit as a step of the horizontal action per frame [action units]
        self._max_step = self.max_accel_unfixed_mps2 / CAMERA_RATE_HZ / POLICY_SPEED_SCALE_MPS
        self._session = open_verified_session(self.model_path, expected_sha256, "policy file", PolicyModelError)
        self._input_name = _check_io(self._session, self.model_path)
        self._frames: np.ndarray | None = None  # (N,) frames since each episode's start
        self._last_action: np.ndarray | None = None  # (N, ACTION_DIM) the action returned on the last frame

    def reset(self) -> None:
        """Forget the episodes' frame counts and last actions: the next call starts new episodes."""
        self._frames = None
        self._last_action = None

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
        frames, last_action = self._start_episodes(len(features), episode_start)
        action = np.asarray(action, dtype=np.float32) * self._soft_start_scale(frames)[:, None]
        action = self._limit_unfixed_accel(action, last_action, features[:, POSITION_KNOWN_INDEX] > 0.0)
        return (action if batched else action[0]), state

    def _start_episodes(self, n: int, episode_start: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Restart the per-env state of the envs starting an episode (all of them on a first call or a new N);
        that state: the (n,) frame counts and (n, ACTION_DIM) last actions, kept by the follower."""
        frames, last_action = self._frames, self._last_action
        if frames is None or last_action is None or len(frames) != n:
            frames = self._frames = np.zeros(n, dtype=np.int64)
            last_action = self._last_action = np.zeros((n, ACTION_DIM), dtype=np.float32)
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            frames[starts] = 0
            last_action[starts] = 0.0
        return frames, last_action

    def _limit_unfixed_accel(self, action: np.ndarray, last_action: np.ndarray,
                             position_known: np.ndarray) -> np.ndarray:
        """(n, ACTION_DIM) actions whose horizontal setpoint, where the 3D position is not known yet, moved from the
        `last_action`'s by at most max_accel_unfixed_mps2 / CAMERA_RATE_HZ [m/s]; remembered as the last actions."""
        step = action[:, HORIZONTAL] - last_action[:, HORIZONTAL]
        norm = np.linalg.norm(step, axis=1)
        over = ~position_known & (norm > self._max_step)  # the envs whose step is cut to _max_step (same direction)
        limited = action.copy()
        limited[over, HORIZONTAL] = (last_action[over, HORIZONTAL]
                                     + step[over] * (self._max_step / norm[over])[:, None])
        self._last_action = limited
        return limited.copy()

    def _soft_start_scale(self, frames: np.ndarray) -> np.ndarray:
        """(n,) float32 action scale of this frame per env from its `frames` count, then one frame more counted
        (in place)."""
        ramp_frames = self.soft_start_s * CAMERA_RATE_HZ
        scale = np.ones(len(frames)) if ramp_frames == 0 else np.minimum(1.0, frames / ramp_frames)
        frames += 1
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
