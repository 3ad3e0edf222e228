"""Residual learned follower: a trained policy adds a correction to the scripted follower's action.

Residual policy learning (Silver et al. 2018; Johannink et al. 2019, "Residual reinforcement learning for robot
control"): the action flown is a = clip(a_scripted(obs) + scale r(x), -1, 1), with r in [-1, 1] the policy's output
on the flat features x and `scale` its reach in action units. A policy that outputs zero flies exactly as the
scripted follower does, so training starts from the scripted follower's behaviour and learns what to change in the
conditions it is trained in.

Owns the rule (`combine`) and the policy file's record of it: two ONNX metadata entries (`residual_metadata`, read
back by `residual_scale_of`); a file without them is a policy that flies alone. The training env's wrapper is
`trade_gym.agents.training_env.ResidualAction`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from trade.validation import is_positive_number, require
from trade_gym.action import ACTION_HIGH, ACTION_LOW

BASE_KEY = "residual_base"  # ONNX metadata: the controller the policy corrects
SCALE_KEY = "residual_scale"  # ONNX metadata: the policy's reach [action units per unit output]
BASE_NAME = "scripted"  # the one base there is: `trade_gym.agents.ScriptedFollower`


def check_residual_scale(scale: float, name: str = "residual_scale") -> float:
    """`scale` if it is a finite number > 0, else ValueError naming `name` and the value."""
    require(is_positive_number(scale), name, scale, "a finite number > 0")
    return float(scale)


def combine(base: np.ndarray, residual: np.ndarray, scale: float) -> np.ndarray:
    """(N, 4) or (4,) float32 actions clip(base + scale residual, -1, 1)."""
    summed = np.asarray(base, np.float64) + scale * np.asarray(residual, np.float64)
    return np.clip(summed, ACTION_LOW, ACTION_HIGH).astype(np.float32)


def residual_metadata(scale: float) -> dict[str, str]:
    """The policy file's metadata entries for a residual policy of reach `scale`."""
    return {BASE_KEY: BASE_NAME, SCALE_KEY: repr(check_residual_scale(scale))}


def residual_scale_of(metadata: Mapping[str, str], path: str | Path) -> float | None:
    """The reach of the residual policy whose file (`path`, for messages) carries `metadata`; None for a policy that
    flies alone (no residual entries). ValueError on an unknown base or a bad scale."""
    if BASE_KEY not in metadata and SCALE_KEY not in metadata:
        return None
    base, text = metadata.get(BASE_KEY), metadata.get(SCALE_KEY, "")
    if base != BASE_NAME:
        raise ValueError(f"policy file {path}: {BASE_KEY} must be {BASE_NAME!r}, got {base!r}")
    try:
        scale = float(text)
    except ValueError:
        scale = math.nan
    if not is_positive_number(scale):
        raise ValueError(f"policy file {path}: {SCALE_KEY} must be a finite number > 0, got {text!r}")
    return scale
