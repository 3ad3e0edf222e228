"""When a run counts as failed (ground depth off by more than 2 m, or the target tracked in under half
of its visible frames) and a first classification of why, from the run's own metrics.

The classes are coarse on purpose: they point at the stage to look at (initial box, tracker, plane),
not at the mechanism; that takes the run's frames.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from trade_gym.metrics import TRACKED_IOU

FAIL_GROUND_RMSE_M = 2.0  # a world fails when its ground-depth RMSE exceeds this [m] ...
FAIL_TRACKED_FRACTION = 0.5  # ... or the target is tracked in fewer of its visible frames than this
# A depth failure is a bias (one plane, consistently off) when |mean error| exceeds this fraction of the RMSE.
BIAS_FRACTION_OF_RMSE = 0.5

WRONG_INITIAL_BOX = "wrong initial box"
ON_DECOY = "tracked a decoy"
LOST_TRACK = "lost the target"
NO_GROUND_DEPTH = "no ground-depth estimate"
PLANE_ABOVE = "depth too short: plane above the ground (roof, mask leak)"
PLANE_BELOW = "depth too long: plane below the ground"
PLANE_UNSTABLE = "depth noisy: plane unstable"


def _value(metrics: Mapping[str, float | int | bool | None], name: str) -> float:
    value = metrics.get(name)
    return math.nan if value is None else float(value)


def tracking_cause(metrics: Mapping[str, float | int | bool | None]) -> str | None:
    """Why the track failed (None when it did not)."""
    tracked = _value(metrics, "tracked_fraction")
    if not tracked < FAIL_TRACKED_FRACTION:  # NaN (the target never visible) is no tracking failure
        return None
    if _value(metrics, "initial_iou") < TRACKED_IOU:
        return WRONG_INITIAL_BOX
    return ON_DECOY if _value(metrics, "decoy_switches") > 0 else LOST_TRACK


def depth_cause(metrics: Mapping[str, float | int | bool | None]) -> str | None:
    """Why the ground depth failed (None when it did not)."""
    rmse = _value(metrics, "ground_depth_rmse_m")
    if math.isnan(rmse):
        return NO_GROUND_DEPTH
    if rmse <= FAIL_GROUND_RMSE_M:
        return None
    bias = _value(metrics, "ground_depth_bias_m")
    if bias < -BIAS_FRACTION_OF_RMSE * rmse:
        return PLANE_ABOVE
    return PLANE_BELOW if bias > BIAS_FRACTION_OF_RMSE * rmse else PLANE_UNSTABLE


def failure_cause(metrics: Mapping[str, float | int | bool | None], scores_ground_depth: bool = True) -> str | None:
    """'; '-joined causes of a failed run, None for a run that passed. `scores_ground_depth`: whether the
    run's perception estimates ground depth at all (the oracle does not)."""
    causes = [tracking_cause(metrics), depth_cause(metrics) if scores_ground_depth else None]
    found = [c for c in causes if c is not None]
    return "; ".join(found) if found else None
