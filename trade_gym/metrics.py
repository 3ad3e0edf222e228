"""Scores of one episode, as pure functions over its per-step `info` records.

Each function takes the list of info dicts an episode produced (in step order) and returns a
number; NaN where the quantity is undefined (e.g. no frame with both depths, no visible frame).
Tracking scores (tracked fraction, success AUC, precision) count only frames with the target visible.
"""

from __future__ import annotations

import math

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from trade.types import iou
from trade_gym.config import CAMERA_RATE_HZ

Info = dict[str, Any]
FloatArray = npt.NDArray[np.float64]

TRACKED_IOU = 0.3  # a frame is tracked when IoU >= this while the target is visible
# OTB / UAV123 success plot: IoU thresholds 0, 0.05, ..., 1; a frame succeeds when IoU > threshold.
SUCCESS_IOU_THRESHOLDS = np.linspace(0.0, 1.0, 21)
PRECISION_CENTRE_PX = 20.0  # OTB precision: centre error <= 20 px
FRAME_DT_S = 1.0 / CAMERA_RATE_HZ  # one env step = one camera frame
DEPTH_KINDS = ("ground", "target")
# A frame's ground estimate is off when its depth on the true box ray misses the true ground by more than this [m]:
# twice the MSAC inlier threshold (0.5 m), so a plane off by it is not the ground the fit's inliers lie on.
GROUND_OFF_M = 1.0

# Names of the scores `episode_metrics` returns (deterministic: no timing in here).
METRIC_NAMES = (
    "steps", "visible_fraction", "tracked_fraction", "success_auc", "precision_20px",
    "longest_lost_streak_s", "decoy_switches", "ground_depth_rmse_m", "ground_depth_frames",
    "target_depth_rmse_m", "target_depth_frames", "mean_horizontal_error_m", "crashed",
    "ground_depth_bias_m", "ground_depth_off_fraction", "initial_iou",
    "success", "following_rate", "collision_rate", "nre", "dre", "adq",
)
# EVT-Bench style: an episode succeeds without a crash and with the drone in the following band (`info["following"]`,
# `trade_gym.scoring.FollowBand`) on at least this fraction of its frames.
SUCCESS_FOLLOWING_RATE = 0.9
# VOTS: absence-detection quality needs more absent frames than this to be defined.
ADQ_MIN_ABSENT_FRAMES = 10


def on_decoy(est_bbox: Sequence[float], est_iou: float, decoy_bboxes: Sequence[Sequence[float]]) -> bool:
    """Whether the estimated box (x, y, w, h) [px] overlaps some decoy's box in view more than the target's
    (its IoU with the target: `est_iou`); the per-frame `info["on_decoy"]`."""
    best = max((iou(d, est_bbox) for d in decoy_bboxes), default=0.0)
    return bool(best > est_iou and best > 0.0)


def _column(infos: Sequence[Info], key: str, dtype: type = np.float64) -> np.ndarray:
    """(T,) array of `info[key]` over the episode."""
    return np.array([i[key] for i in infos], dtype=dtype)


def _visible(infos: Sequence[Info]) -> npt.NDArray[np.bool_]:
    return _column(infos, "target_visible", bool) if infos else np.zeros(0, bool)


def visible_fraction(infos: Sequence[Info]) -> float:
    """Fraction of frames in which the target is visible."""
    return float(np.mean(_visible(infos))) if infos else float("nan")


def tracked_fraction(infos: Sequence[Info], iou_threshold: float = TRACKED_IOU) -> float:
    """Fraction of the frames with the target visible whose estimated box has IoU >= threshold."""
    ious = np.array([i["iou"] for i in infos if i["target_visible"]], dtype=np.float64)
    return float(np.mean(ious >= iou_threshold)) if len(ious) else float("nan")


def success_auc(infos: Sequence[Info], thresholds: FloatArray = SUCCESS_IOU_THRESHOLDS) -> float:
    """Area under the OTB success curve over the visible frames.

    success(tau) = #{frames: IoU > tau} / #frames for tau in `thresholds`; AUC = mean_tau success(tau).
    As in the OTB/UAV123 toolkits a perfect track scores 20/21 (IoU > 1 never holds)."""
    ious = np.array([i["iou"] for i in infos if i["target_visible"]], dtype=np.float64)
    if not len(ious):
        return float("nan")
    success = np.mean(ious[None, :] > np.asarray(thresholds)[:, None], axis=1)  # (K,)
    return float(np.mean(success))


def centre_errors_px(infos: Sequence[Info]) -> FloatArray:
    """(T,) distance [px] between the estimated and true box centres; inf where the estimate is
    missing, NaN where the true box is."""
    if not infos:
        return np.zeros(0)
    gt = np.array([i["gt_bbox"] for i in infos], dtype=np.float64).reshape(-1, 4)
    est = np.array([i["est_bbox"] for i in infos], dtype=np.float64).reshape(-1, 4)
    # centre = (x + w/2, y + h/2)
    d = np.linalg.norm((est[:, :2] + est[:, 2:] / 2.0) - (gt[:, :2] + gt[:, 2:] / 2.0), axis=1)
    d[~np.all(np.isfinite(est), axis=1)] = np.inf
    d[~np.all(np.isfinite(gt), axis=1)] = np.nan
    return d


def precision_at(infos: Sequence[Info], threshold_px: float = PRECISION_CENTRE_PX) -> float:
    """OTB precision: fraction of visible frames (with a true box) whose centre error <= threshold."""
    err = centre_errors_px(infos)
    scored = _visible(infos) & ~np.isnan(err)
    return float(np.mean(err[scored] <= threshold_px)) if scored.any() else float("nan")


def longest_run(flags: npt.ArrayLike) -> int:
    """Length of the longest run of consecutive True values."""
    f = np.concatenate([[False], np.asarray(flags, bool), [False]]).astype(np.int8)
    edges = np.diff(f)
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return int(np.max(ends - starts)) if len(starts) else 0


def longest_lost_streak_s(infos: Sequence[Info], frame_dt_s: float = FRAME_DT_S,
                          iou_threshold: float = TRACKED_IOU) -> float:
    """Longest stretch [s] of consecutive frames in which the target is not tracked: hidden from the
    camera, or visible with IoU < threshold (streak frames x frame period)."""
    if not infos:
        return float("nan")
    tracked = _visible(infos) & (_column(infos, "iou") >= iou_threshold)
    return longest_run(~tracked) * frame_dt_s


def depth_or_none(depth_m: float) -> float | None:
    """A depth as `info` holds it: None where it does not exist (NaN in the stack), as float NaN != NaN."""
    return None if math.isnan(depth_m) else float(depth_m)


def decoy_switches(infos: Sequence[Info]) -> int:
    """Number of times the estimate lands on a decoy (rising edges of `on_decoy`)."""
    on = np.array([bool(i["on_decoy"]) for i in infos])
    if not len(on):
        return 0
    return int(on[0]) + int(np.sum(on[1:] & ~on[:-1]))


def depth_errors_m(infos: Sequence[Info], kind: str) -> FloatArray:
    """(T,) signed error `<kind>_depth_est - <kind>_depth_gt` [m]; NaN where either is missing."""
    if kind not in DEPTH_KINDS:
        raise ValueError(f"kind must be one of {DEPTH_KINDS}, got {kind!r}")
    if not infos:
        return np.zeros(0)
    return _column(infos, f"{kind}_depth_est") - _column(infos, f"{kind}_depth_gt")


def _finite_depth_errors(infos: Sequence[Info], kind: str) -> FloatArray:
    err = depth_errors_m(infos, kind)
    return err[np.isfinite(err)]


def depth_rmse(infos: Sequence[Info], kind: str) -> float:
    """RMSE [m] of `<kind>_depth_est` against `<kind>_depth_gt` (kind: "ground" or "target") over
    frames where both exist."""
    err = _finite_depth_errors(infos, kind)
    return float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")


def depth_bias(infos: Sequence[Info], kind: str) -> float:
    """Mean signed error [m] of `<kind>_depth_est` over frames where both depths exist: negative when the
    estimate is nearer the camera than the truth (e.g. a ground plane fitted to roofs)."""
    err = _finite_depth_errors(infos, kind)
    return float(np.mean(err)) if len(err) else float("nan")


def depth_off_fraction(infos: Sequence[Info], kind: str, threshold_m: float = GROUND_OFF_M) -> float:
    """Fraction of the frames with both depths whose |`<kind>_depth_est` - `<kind>_depth_gt`| exceeds
    `threshold_m` [m] (for the ground: frames whose plane is off the true ground); NaN without such frames."""
    err = _finite_depth_errors(infos, kind)
    return float(np.mean(np.abs(err) > threshold_m)) if len(err) else float("nan")


def initial_iou(infos: Sequence[Info]) -> float:
    """IoU with the true box of the first estimate the observation holds (a wrong initial box shows here): the first
    step's, or under a perception latency (the light stack's) the first that arrived; NaN when none did."""
    first = next((i for i in infos if np.all(np.isfinite(i["est_bbox"]))), None)
    return float("nan") if first is None else float(first["iou"])


def depth_frames(infos: Sequence[Info], kind: str) -> int:
    """Frames where both the estimated and the true `kind` depth exist."""
    return int(np.sum(np.isfinite(depth_errors_m(infos, kind))))


def mean_horizontal_distance(infos: Sequence[Info]) -> float:
    """Mean horizontal distance [m] between the drone and the target: the following error of a
    follower that keeps the target under a downward camera."""
    return float(np.mean(_column(infos, "horizontal_distance_m"))) if infos else float("nan")


def crashed(infos: Sequence[Info]) -> bool:
    """Whether any step reported a crash."""
    return any(bool(i["crashed"]) for i in infos)


def following_rate(infos: Sequence[Info]) -> float:
    """Fraction of the frames with the drone in the following band; NaN without frames or without the band in
    the infos (an open-loop replay flies nothing)."""
    if not infos or any("following" not in i for i in infos):
        return math.nan
    return float(np.mean(_column(infos, "following", bool)))


def success(infos: Sequence[Info]) -> bool | None:
    """EVT-style success: no crash and the following band held on at least SUCCESS_FOLLOWING_RATE of the frames;
    None where the following rate is undefined."""
    rate = following_rate(infos)
    return None if math.isnan(rate) else (not crashed(infos) and rate >= SUCCESS_FOLLOWING_RATE)


def vots_classes(infos: Sequence[Info]) -> dict[str, int]:
    """VOTS per-frame classes, from the truth's visibility and whether the estimate reports the target (a fresh
    box, `est_valid`): visible and reported with overlap: tracked; visible, reported, no overlap: failure (drift);
    visible, not reported: miss; absent and reported: hallucination; absent, not reported: notice."""
    visible, reported = _visible(infos), _column(infos, "est_valid", bool)
    overlap = _column(infos, "iou") > 0.0
    return {"tracked": int(np.sum(visible & reported & overlap)), "failure": int(np.sum(visible & reported & ~overlap)),
            "miss": int(np.sum(visible & ~reported)), "hallucination": int(np.sum(~visible & reported)),
            "notice": int(np.sum(~visible & ~reported))}


def vots_scores(classes: dict[str, int]) -> dict[str, float]:
    """NRE and DRE (the miss and failure fractions of the frames with the target visible; NaN without one) and
    ADQ (the notice fraction of the absent frames; NaN with at most ADQ_MIN_ABSENT_FRAMES of them)."""
    present = classes["tracked"] + classes["failure"] + classes["miss"]
    absent = classes["hallucination"] + classes["notice"]
    return {"nre": classes["miss"] / present if present else math.nan,
            "dre": classes["failure"] / present if present else math.nan,
            "adq": classes["notice"] / absent if absent > ADQ_MIN_ABSENT_FRAMES else math.nan}


def not_reported_error(infos: Sequence[Info]) -> float:
    """VOTS NRE (`vots_scores`)."""
    return vots_scores(vots_classes(infos))["nre"]


def drift_rate_error(infos: Sequence[Info]) -> float:
    """VOTS DRE (`vots_scores`)."""
    return vots_scores(vots_classes(infos))["dre"]


def absence_detection_quality(infos: Sequence[Info]) -> float:
    """VOTS ADQ (`vots_scores`)."""
    return vots_scores(vots_classes(infos))["adq"]


def steps_per_second(steps: int, wall_s: float) -> float:
    """Env steps per wall-clock second (a timing figure, kept apart from the scores)."""
    return steps / wall_s if wall_s > 0.0 else float("nan")


def episode_metrics(infos: Sequence[Info], frame_dt_s: float = FRAME_DT_S) -> dict[str, float | int | bool | None]:
    """All scores of one episode, keyed by `METRIC_NAMES` (`success` None where it is undefined)."""
    return {
        "steps": len(infos),
        "visible_fraction": visible_fraction(infos),
        "tracked_fraction": tracked_fraction(infos),
        "success_auc": success_auc(infos),
        "precision_20px": precision_at(infos),
        "longest_lost_streak_s": longest_lost_streak_s(infos, frame_dt_s),
        "decoy_switches": decoy_switches(infos),
        "ground_depth_rmse_m": depth_rmse(infos, "ground"),
        "ground_depth_frames": depth_frames(infos, "ground"),
        "target_depth_rmse_m": depth_rmse(infos, "target"),
        "target_depth_frames": depth_frames(infos, "target"),
        "mean_horizontal_error_m": mean_horizontal_distance(infos),
        "crashed": crashed(infos),
        "ground_depth_bias_m": depth_bias(infos, "ground"),
        "ground_depth_off_fraction": depth_off_fraction(infos, "ground"),
        "initial_iou": initial_iou(infos),
        "success": success(infos),
        "following_rate": following_rate(infos),
        "collision_rate": float(crashed(infos)),  # per episode 0 or 1: a suite's mean is the rate
        **vots_scores(vots_classes(infos)),  # nre, dre, adq
    }
