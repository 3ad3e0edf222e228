"""Scores of one episode, as pure functions over its per-step `info` records.

Each function takes the list of info dicts an episode produced (in step order) and returns a
number; NaN where the quantity is undefined (e.g. no frame with both depths).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

Info = dict[str, Any]
TRACKED_IOU = 0.3  # a frame is tracked when IoU >= this while the target is visible


def visible_fraction(infos: Sequence[Info]) -> float:
    """Fraction of frames in which the target is visible."""
    return float(np.mean([i["target_visible"] for i in infos])) if infos else float("nan")


def tracked_fraction(infos: Sequence[Info], iou_threshold: float = TRACKED_IOU) -> float:
    """Fraction of the frames with the target visible whose estimated box has IoU >= threshold."""
    ious = np.array([i["iou"] for i in infos if i["target_visible"]], dtype=np.float64)
    return float(np.mean(ious >= iou_threshold)) if len(ious) else float("nan")


def decoy_switches(infos: Sequence[Info]) -> int:
    """Number of times the estimate lands on a decoy (rising edges of `on_decoy`)."""
    on = np.array([bool(i["on_decoy"]) for i in infos])
    if not len(on):
        return 0
    return int(on[0]) + int(np.sum(on[1:] & ~on[:-1]))


def depth_rmse(infos: Sequence[Info], kind: str) -> float:
    """RMSE [m] of `<kind>_depth_est` against `<kind>_depth_gt` (kind: "ground" or "target") over
    frames where both exist."""
    pairs = np.array([(i[f"{kind}_depth_est"], i[f"{kind}_depth_gt"]) for i in infos], dtype=np.float64)
    if not len(pairs):
        return float("nan")
    both = np.all(np.isfinite(pairs), axis=1)
    if not both.any():
        return float("nan")
    return float(np.sqrt(np.mean((pairs[both, 0] - pairs[both, 1]) ** 2)))


def depth_frames(infos: Sequence[Info], kind: str) -> int:
    """Frames where both the estimated and the true `kind` depth exist."""
    return int(sum(np.isfinite(i[f"{kind}_depth_est"]) and np.isfinite(i[f"{kind}_depth_gt"]) for i in infos))


def mean_horizontal_distance(infos: Sequence[Info]) -> float:
    """Mean horizontal distance [m] between the drone and the target."""
    return float(np.mean([i["horizontal_distance_m"] for i in infos])) if infos else float("nan")


def crashed(infos: Sequence[Info]) -> bool:
    return any(i["crashed"] for i in infos)
