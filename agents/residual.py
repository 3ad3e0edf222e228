"""Residual learned follower: a trained policy adds a correction to the scripted follower's action.

Residual policy learning (Silver et al. 2018; Johannink et al. 2019, "Residual reinforcement learning for robot
control"): the action flown is a = clip(a_scripted(obs) + scale m * r(x), -1, 1), with r in [-1, 1] the policy's
output on the flat features x, `scale` its reach in action units and m the mask of the axes it may correct
(`Residual.axes`). A policy that outputs zero flies exactly as the scripted follower does, so training starts from
the scripted follower's behaviour and learns what to change in the conditions it is trained in.

Owns the rule (`Residual.combine`) and the policy file's record of it: ONNX metadata entries
(`Residual.metadata`, read back by `Residual.of_metadata`); a file without them is a policy that flies alone. The
training env's wrapper is `trade_gym.agents.training_env.ResidualAction`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trade.validation import is_positive_number, require
from trade_gym.action import ACTION_HIGH, ACTION_LOW, ACTION_NAMES

BASE_KEY = "residual_base"  # ONNX metadata: the controller the policy corrects
SCALE_KEY = "residual_scale"  # ONNX metadata: the policy's reach [action units per unit output]
AXES_KEY = "residual_axes"  # ONNX metadata: the action axes the policy corrects, comma-separated
BASE_NAME = "scripted"  # the one base there is: `trade_gym.agents.ScriptedFollower`
# the axes a policy outputs (yaw is never commanded); a residual file without AXES_KEY corrects all of them
POLICY_AXES = ACTION_NAMES[:ACTION_NAMES.index("yaw_rate")]
# The recipe's axes: the horizontal ones. The height stays the scripted follower's, which holds the following band's
# height: a residual of all three axes, trained on the oracle, commanded climbs of 0.3-0.5 of full scale under full
# TRADE where the scripted follower held, and left the band's height (desert training world 10202, breadth-tuning).
HORIZONTAL_AXES = ("forward", "left")


def check_residual_scale(scale: float, name: str = "residual_scale") -> float:
    """`scale` if it is a finite number > 0, else ValueError naming `name` and the value."""
    require(is_positive_number(scale), name, scale, "a finite number > 0")
    return float(scale)


def check_residual_axes(axes: Sequence[str], name: str = "residual_axes") -> tuple[str, ...]:
    """`axes` as a tuple if they are distinct names of POLICY_AXES, at least one, else ValueError naming `name`."""
    ok = (not isinstance(axes, str) and len(axes) > 0 and all(a in POLICY_AXES for a in axes)
          and len(set(axes)) == len(axes))
    require(ok, name, axes, f"distinct names of {POLICY_AXES}, at least one")
    return tuple(axes)


@dataclass(frozen=True)
class Residual:
    """A residual policy's reach `scale` and the action `axes` it corrects (the others are the scripted follower's)."""

    scale: float
    axes: tuple[str, ...] = POLICY_AXES

    def __post_init__(self) -> None:
        check_residual_scale(self.scale)
        object.__setattr__(self, "axes", check_residual_axes(self.axes))

    @property
    def mask(self) -> np.ndarray:
        """(ACTION_DIM,) 1.0 on the corrected axes, 0.0 elsewhere."""
        return np.array([float(name in self.axes) for name in ACTION_NAMES])

    def combine(self, base: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """(N, 4) or (4,) float32 actions clip(base + scale mask residual, -1, 1)."""
        summed = np.asarray(base, np.float64) + self.scale * self.mask * np.asarray(residual, np.float64)
        return np.clip(summed, ACTION_LOW, ACTION_HIGH).astype(np.float32)

    def metadata(self) -> dict[str, str]:
        """The policy file's metadata entries."""
        return {BASE_KEY: BASE_NAME, SCALE_KEY: repr(float(self.scale)), AXES_KEY: ",".join(self.axes)}

    @classmethod
    def of_metadata(cls, metadata: Mapping[str, str], path: str | Path) -> Residual | None:
        """The residual of the policy file (`path`, for messages) that carries `metadata`; None for a policy that
        flies alone (no residual entries). ValueError naming the file and the value on a bad entry."""
        if not any(key in metadata for key in (BASE_KEY, SCALE_KEY, AXES_KEY)):
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
        axes_text = metadata.get(AXES_KEY)
        axes = POLICY_AXES if axes_text is None else tuple(axes_text.split(","))
        try:
            return cls(scale, axes)
        except ValueError:
            raise ValueError(f"policy file {path}: {AXES_KEY} must be comma-separated distinct names of "
                             f"{POLICY_AXES}, got {axes_text!r}") from None
