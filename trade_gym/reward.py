"""Reward of TradeFollow-v0 as named terms computed from ground truth; they sum to the reward.

Terms: `visible` (+1 while the target is visible), `centering` (minus the target's distance
from the image centre, in half-image units), `altitude` (minus the relative error of the
height above the target), `effort` (minus the mean squared action) and `crash`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trade_gym.perception.base import FloatArray


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the reward terms (dimensionless)."""

    visible_weight: float = 1.0
    centering_weight: float = 0.5
    altitude_weight: float = 0.5
    effort_weight: float = 0.05
    crash_penalty: float = 10.0


def compute_reward(
    config: RewardConfig,
    target_visible: bool,
    target_pixel: FloatArray,
    image_size_px: int,
    height_above_target_m: float,
    nominal_height_m: float,
    action: FloatArray,
    crashed: bool,
) -> tuple[float, dict[str, float]]:
    """(total, terms). target_pixel: (2,) projected target centre [px], NaN when behind the camera."""
    half = image_size_px / 2.0
    u, v = float(target_pixel[0]), float(target_pixel[1])
    if target_visible and math.isfinite(u) and math.isfinite(v):
        # distance from the principal point (half - 0.5, half - 0.5) in half-image units
        offset = math.hypot(u - (half - 0.5), v - (half - 0.5)) / half
        centering = -min(offset, 1.0)
    else:
        centering = -1.0
    altitude_error = abs(height_above_target_m - nominal_height_m) / nominal_height_m
    terms = {
        "visible": config.visible_weight * float(target_visible),
        "centering": config.centering_weight * centering,
        "altitude": -config.altitude_weight * min(altitude_error, 1.0),
        "effort": -config.effort_weight * sum(float(a) * float(a) for a in action) / len(action),
        "crash": -config.crash_penalty * float(crashed),
    }
    return float(sum(terms.values())), terms
