"""The action of TradeFollow-v0, published once for the env and its followers: size, bounds and scale.

The env maps a = (forward, left, up, yaw rate) in [ACTION_LOW, ACTION_HIGH]^ACTION_DIM to the setpoint
a * scale (velocity in the drone's heading frame [m/s], yaw rate [rad/s]); the scale is the quadrotor's setpoint
limits (`ActionScale.of(QuadrotorConfig)`), DEFAULT_ACTION_SCALE unless `gym.make(..., quadrotor=...)` sets them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from trade_gym.sim.quadrotor import QuadrotorConfig

ACTION_NAMES = ("forward", "left", "up", "yaw_rate")
ACTION_DIM = len(ACTION_NAMES)
ACTION_LOW, ACTION_HIGH = -1.0, 1.0


@dataclass(frozen=True)
class ActionScale:
    """Setpoint per unit action: horizontal speed (forward and left) and vertical speed [m/s], yaw rate [rad/s]."""

    horizontal_mps: float
    vertical_mps: float
    yaw_rate_radps: float

    @classmethod
    def of(cls, quadrotor: QuadrotorConfig) -> ActionScale:
        """The scale of an env flying `quadrotor`: its setpoint limits."""
        return cls(quadrotor.max_speed_horizontal_mps, quadrotor.max_speed_vertical_mps, quadrotor.max_yaw_rate_radps)

    def per_component(self) -> tuple[float, float, float, float]:
        """(forward, left, up, yaw rate) per unit action, in ACTION_NAMES order."""
        return (self.horizontal_mps, self.horizontal_mps, self.vertical_mps, self.yaw_rate_radps)


DEFAULT_ACTION_SCALE = ActionScale.of(QuadrotorConfig())


def action_space(dim: int = ACTION_DIM) -> spaces.Box:
    """Box(ACTION_LOW, ACTION_HIGH, (dim,), float32): the env's (dim = ACTION_DIM) or a follower's first `dim`."""
    return spaces.Box(ACTION_LOW, ACTION_HIGH, (dim,), np.float32)


def validate_action(action) -> list[float]:
    """The action as ACTION_DIM floats clipped to [ACTION_LOW, ACTION_HIGH]; ValueError for a wrong shape or a
    non-finite value. (Plain floats: the env step's scalar maths is cheaper on them than on arrays.)"""
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (ACTION_DIM,):
        raise ValueError(f"action must have shape ({ACTION_DIM},), got shape {a.shape}: {action!r}")
    values = a.tolist()
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"action of shape ({ACTION_DIM},) must be finite, got {values}")
    return [min(max(v, ACTION_LOW), ACTION_HIGH) for v in values]
