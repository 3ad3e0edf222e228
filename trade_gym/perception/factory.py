"""Builds the perception mode named by the env config."""

from __future__ import annotations

from collections.abc import Callable

from trade.geometry import CameraIntrinsics, Pose
from trade_gym.config import EnvConfig
from trade_gym.perception.base import Perception
from trade_gym.perception.oracle import OracleConfig, OraclePerception


def make_perception(config: EnvConfig, intrinsics: CameraIntrinsics,
                    true_camera_pose: Callable[[], Pose]) -> Perception:
    """`true_camera_pose` is consumed by the oracle only (its noise is applied in the camera frame)."""
    if config.perception == "oracle":
        return OraclePerception(
            OracleConfig(
                box_sigma_px=config.oracle_box_sigma_px,
                depth_sigma_frac=config.oracle_depth_sigma_frac,
                velocity_sigma_mps=config.oracle_velocity_sigma_mps,
                dropout_prob=config.oracle_dropout_prob,
                noise_correlation_s=config.oracle_noise_correlation_s,
                first_fix_delay_s=config.oracle_first_fix_delay_s,
            ),
            true_camera_pose,
        )
    from trade_gym.perception.trade_stack import TradePerception  # the stack imports OpenCV/filterpy

    return TradePerception(config, intrinsics)
