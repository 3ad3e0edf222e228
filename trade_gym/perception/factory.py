"""Builds the perception mode named by the env config."""

from __future__ import annotations

from collections.abc import Callable

from trade.geometry import CameraIntrinsics, Pose
from trade_gym.config import EnvConfig
from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import Perception
from trade_gym.perception.oracle import OraclePerception


def make_perception(config: EnvConfig, intrinsics: CameraIntrinsics, ground_truth: Callable[[], GroundTruth],
                    true_camera_pose: Callable[[], Pose]) -> Perception:
    """`ground_truth` and `true_camera_pose` (the current frame's, from the env) are handed to the oracle only
    (its noise is applied in the true camera frame); the TRADE and DCF modes see the sensors only."""
    if config.perception == "oracle":
        return OraclePerception(config.oracle, ground_truth, true_camera_pose)
    from trade_gym.perception.trade_stack import TradePerception  # the stack imports OpenCV/filterpy

    return TradePerception(config, intrinsics)
