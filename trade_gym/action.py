"""The action of TradeFollow-v0, published once for the env and its followers: modes, size, bounds and scale.

`action_mode="velocity"` (default): the env maps a = (forward, left, up, yaw rate) in [ACTION_LOW, ACTION_HIGH]^ACTION_DIM
to the setpoint a * scale (velocity in the drone's heading frame [m/s], yaw rate [rad/s]); the scale is the
quadrotor's setpoint limits (`ActionScale.of(QuadrotorConfig)`), DEFAULT_ACTION_SCALE unless `gym.make(...,
quadrotor=...)` sets them. `action_mode="waypoint"`: a = (forward, left, up, yaw) is a position and heading offset
a * scale from the drone (`WaypointScale`, [m] and [rad]), turned into the world setpoint the quadrotor's position
controller holds (`waypoint_setpoint`), as a companion computer turns its offsets into PX4 offboard setpoints.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from trade.validation import is_positive_number, require
from trade_gym.sim.quadrotor import QuadrotorConfig

ACTION_MODES = ("velocity", "waypoint")
ACTION_NAMES = ("forward", "left", "up", "yaw_rate")  # velocity mode
WAYPOINT_ACTION_NAMES = ("forward", "left", "up", "yaw")  # waypoint mode: offsets from the drone
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


@dataclass(frozen=True)
class WaypointScale:
    """Offset per unit action in waypoint mode: horizontal (forward and left) and vertical position [m], heading [rad].

    Defaults: 20 m reaches the position controller's full horizontal speed (gain 0.5/s: 10 m/s, clipped to 8), 5 m
    its full vertical speed (0.75/s: 3.75 m/s, clipped to 3); a quarter turn of heading per setpoint. The heading
    offset stays within half a turn, where its sense is unambiguous.
    """

    max_offset_horizontal_m: float = 20.0
    max_offset_vertical_m: float = 5.0
    max_yaw_offset_rad: float = math.pi / 2.0

    def __post_init__(self) -> None:
        for name in ("max_offset_horizontal_m", "max_offset_vertical_m"):
            require(is_positive_number(getattr(self, name)), f"WaypointScale.{name}", getattr(self, name),
                    "a finite number > 0 [m]")
        require(is_positive_number(self.max_yaw_offset_rad) and self.max_yaw_offset_rad <= math.pi,
                "WaypointScale.max_yaw_offset_rad", self.max_yaw_offset_rad, "in (0, pi] [rad]")

    def per_component(self) -> tuple[float, float, float, float]:
        """(forward, left, up, yaw) per unit action, in WAYPOINT_ACTION_NAMES order."""
        return (self.max_offset_horizontal_m, self.max_offset_horizontal_m, self.max_offset_vertical_m,
                self.max_yaw_offset_rad)


DEFAULT_WAYPOINT_SCALE = WaypointScale()


def waypoint_setpoint(offset: Sequence[float], position_m: Sequence[float],
                      yaw_rad: float) -> tuple[tuple[float, float, float], float]:
    """The world setpoint of a waypoint action: `offset` = (forward, left, up [m], yaw [rad]) from the drone at
    `position_m` (3,) world [m] with heading `yaw_rad`, in its heading frame at that moment; returns
    (p + Rz(yaw) (forward, left, up), yaw + yaw offset), the absolute position and heading PX4 holds."""
    forward, left, up, yaw_offset = offset
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    x, y, z = position_m
    return (x + c * forward - s * left, y + s * forward + c * left, z + up), yaw_rad + yaw_offset


def action_space(dim: int = ACTION_DIM) -> spaces.Box:
    """Box(ACTION_LOW, ACTION_HIGH, (dim,), float32): the env's (dim = ACTION_DIM) or a follower's first `dim`."""
    return spaces.Box(ACTION_LOW, ACTION_HIGH, (dim,), np.float32)


def clip_action(action: object) -> list[float]:
    """The action as ACTION_DIM floats clipped to [ACTION_LOW, ACTION_HIGH]; ValueError for a wrong shape or a
    non-finite value. (Plain floats: the env step's scalar maths is cheaper on them than on arrays.)"""
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (ACTION_DIM,):
        raise ValueError(f"action must have shape ({ACTION_DIM},), got shape {a.shape}: {action!r}")
    values = a.tolist()
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"action of shape ({ACTION_DIM},) must be finite, got {values}")
    return [min(max(v, ACTION_LOW), ACTION_HIGH) for v in values]
