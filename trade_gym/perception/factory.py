"""Builds the perception mode named by the env config."""

from __future__ import annotations

from collections.abc import Callable

from trade.geometry import CameraIntrinsics, Pose
from trade_gym.config import EnvConfig
from trade_gym.perception.base import Perception
from trade_gym.perception.oracle import OraclePerception


def make_perception(config: EnvConfig, intrinsics: CameraIntrinsics,
                    true_camera_pose: Callable[[], Pose]) -> Perception:
    """`true_camera_pose` is consumed by the oracle only (its noise is applied in the camera frame)."""
    if config.perception == "oracle":
        return OraclePerception(config.oracle, true_camera_pose)
    from trade_gym.perception.trade_stack import TradePerception  # the stack imports OpenCV/filterpy

    return TradePerception(config, intrinsics)
