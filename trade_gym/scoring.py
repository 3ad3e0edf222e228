"""Scoring of one frame: what `info` says about an estimate, from the estimate, the sensors and ground truth.

Owns `ScoredEstimate` (an estimate with the score that belongs to its own frame), `ground_depth_along` (the
paper's Table 1 quantity along any pixel's ray), `estimate_scores` (the info entries the env and trade-replay
share), `env_info` (the env's whole `info`) and `reward_inputs`. Perception never computes these: it sees no
ground truth.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from trade.camera_pitch import NADIR_PITCH_DEG, standoff_m
from trade.depth_alignment import sample_map
from trade.geometry import CameraIntrinsics, Pose
from trade.raycast import raycast_plane
from trade.types import iou
from trade_gym.ground_truth import GroundTruth
from trade_gym.metrics import depth_or_none, on_decoy
from trade_gym.perception.base import FloatArray, GroundEstimate, PerceptionOutput
from trade_gym.reward import RewardInputs

if TYPE_CHECKING:
    from trade_gym.sim.world import World

Box = tuple[float, ...]  # (x, y, w, h) [px]
GROUND_LIFT_M = 0.0  # the ground itself is scored, not the plane lifted by half the target's height


@dataclass(frozen=True, eq=False)
class ScoredEstimate:
    """A frame's estimate and the depth [m] of its ground along the ray through that frame's true box centre
    (scored when the estimate is made, so an estimate that reaches the observation later keeps its own frame's
    ground-depth score, as it was defined before perception latency)."""

    estimate: PerceptionOutput
    ground_depth_est_m: float

    @classmethod
    def missing(cls) -> ScoredEstimate:
        return cls(PerceptionOutput.missing(), math.nan)


def ground_depth_along(ground: GroundEstimate, box: FloatArray, T_world_cam: Pose, intrinsics: CameraIntrinsics,
                       true_ground_depth_m: float = math.nan) -> float:
    """Depth [m] of the estimated ground along the ray through the centre of `box` (4,) x, y, w, h [px], seen from
    `T_world_cam` (the pose perception was given): the camera-frame z where the ray meets the plane; in
    depth-only mode the map read at that pixel (it shows the target's top there, so it is short by about the
    target's height); for the oracle its factor times `true_ground_depth_m` (the true ground depth on that ray).
    NaN without a box or a ground estimate."""
    if not np.all(np.isfinite(box)):
        return float("nan")
    centre = box[:2] + box[2:] / 2.0
    if ground.depth_map_m is not None:
        return float(sample_map(ground.depth_map_m, centre.reshape(1, 2))[0])
    if ground.plane is not None:
        hit = raycast_plane(intrinsics, T_world_cam, centre, ground.plane, GROUND_LIFT_M)
        return hit.depth_m if hit.valid else float("nan")
    return float(true_ground_depth_m * ground.true_depth_factor)


def score_estimate(estimate: PerceptionOutput, truth: GroundTruth, T_world_cam: Pose,
                   intrinsics: CameraIntrinsics) -> ScoredEstimate:
    """`estimate` with its ground depth along the ray through the true box's centre (plane quality independent of
    tracking errors); `T_world_cam` is the pose perception was given at that frame."""
    depth = ground_depth_along(estimate.ground, truth.target_bbox, T_world_cam, intrinsics, truth.ground_depth_m)
    return ScoredEstimate(estimate, depth)


def decoys_in_view(truth: GroundTruth) -> list[Box]:
    """The boxes of the decoys in view (k <= D, usually <= 2), as tuples of plain floats."""
    return [tuple(d) for d in truth.decoy_bboxes.tolist() if d[0] == d[0]]


def horizontal_distance_m(drone_position_m: FloatArray, target_position_m: FloatArray) -> float:
    """Horizontal (world xy) distance [m] between the drone and the target."""
    return math.hypot(target_position_m[0] - drone_position_m[0], target_position_m[1] - drone_position_m[1])


def estimate_scores(truth: GroundTruth, scored: ScoredEstimate, visible_fraction_threshold: float,
                    decoys: Sequence[Box]) -> dict[str, Any]:
    """The info entries that score an estimate against the truth: `gt_bbox`, `est_bbox`, `iou`, `target_visible`
    (at least `visible_fraction_threshold` of the target's pixels visible), `target_visible_fraction`, `on_decoy`
    (against `decoys`, the boxes in view), the true and estimated target and ground depths (None where missing)
    and `est_valid`."""
    estimate = scored.estimate
    est_box = estimate.bbox.tolist()  # plain floats: scalar IoU on lists beats numpy on 4-vectors
    est_iou = iou(truth.target_bbox.tolist(), est_box)
    return {
        # The truth is fresh every frame; an estimate is not (with perception latency the one held is delivered on
        # several frames), so its box is copied: no two steps' infos share an array.
        "gt_bbox": truth.target_bbox,
        "est_bbox": estimate.bbox.copy(),
        "iou": est_iou,
        "target_visible": truth.target_visible_fraction >= visible_fraction_threshold,
        "target_visible_fraction": truth.target_visible_fraction,
        "on_decoy": on_decoy(est_box, est_iou, decoys),
        "target_depth_gt": depth_or_none(truth.target_depth_m),
        "target_depth_est": depth_or_none(estimate.target_depth_m),
        "ground_depth_gt": depth_or_none(truth.ground_depth_m),
        "ground_depth_est": depth_or_none(scored.ground_depth_est_m),
        "est_valid": estimate.valid,
    }


@dataclass(frozen=True, eq=False)
class EnvFrame:
    """What the env's info says of the frame besides the estimate: time [s], drone position (3,) world [m], the
    held estimate's age [s], whether the drone crashed, whether it is in the following band."""

    t_s: float
    drone_position_m: FloatArray
    estimate_age_s: float
    crashed: bool
    following: bool


FOLLOW_BAND_FOOTPRINT_FRACTION = 0.25  # of the footprint's half-width: the target in the image's central quarter
FOLLOW_BAND_HEIGHT_FRACTION = 0.25  # of the follow height


@dataclass(frozen=True)
class FollowBand:
    """EVT-style following band, from the follow geometry: on a frame the drone follows when the target is in view,
    its horizontal distance to the target is within a quarter of the camera footprint's half-width at the follow
    height h, h tan(fov / 2) / 4 (4-11 m across the scenes: room for a follower's lag in a turn, while a drone that
    lets the target drift into the image's outer part, e.g. by hovering, leaves the band), of the standoff, and its
    height above the target's ground is within 25 % of h (the target's image scale within 25 % of the follow
    geometry's). The standoff is where the camera's optical axis meets the target's ground from the follow height:
    0 for a downward camera, h / tan(pitch) for one pitched `camera_pitch_deg` below the horizon (the paper's
    real flight: 45 deg, one follow height behind). The band's width keeps the downward camera's rule."""

    follow_height_m: float
    max_distance_m: float
    standoff_m: float = 0.0

    @classmethod
    def of(cls, follow_height_m: float, camera_fov_deg: float, camera_pitch_deg: float = NADIR_PITCH_DEG) -> FollowBand:
        half_width_m = follow_height_m * math.tan(math.radians(camera_fov_deg) / 2.0)
        return cls(follow_height_m, FOLLOW_BAND_FOOTPRINT_FRACTION * half_width_m,
                   standoff_m(follow_height_m, camera_pitch_deg))

    def holds(self, x: RewardInputs) -> bool:
        height_error = abs(x.height_above_target_ground_m - self.follow_height_m)
        return bool(x.target_visible and x.follow_error_m <= self.max_distance_m
                    and height_error <= FOLLOW_BAND_HEIGHT_FRACTION * self.follow_height_m)


@functools.lru_cache(maxsize=16)
def follow_band(follow_height_m: float, camera_fov_deg: float, camera_pitch_deg: float = NADIR_PITCH_DEG) -> FollowBand:
    """The scene's following band (cached: an env asks for it every step)."""
    return FollowBand.of(follow_height_m, camera_fov_deg, camera_pitch_deg)


def env_info(truth: GroundTruth, held: ScoredEstimate, frame: EnvFrame, visible_fraction_threshold: float,
             terms: dict[str, float] | None) -> dict[str, Any]:
    """The env's per-step `info` (documented in `TradeFollowEnv`): `held` is the estimate the observation holds,
    `terms` the reward terms (None at reset)."""
    decoys = decoys_in_view(truth)
    info: dict[str, Any] = {
        "t_s": frame.t_s,
        **estimate_scores(truth, held, visible_fraction_threshold, decoys),
        "estimate_age_s": frame.estimate_age_s,
        "crashed": frame.crashed,
        "drone_position_m": frame.drone_position_m,
        "target_position_m": truth.target_position_m,
        "horizontal_distance_m": horizontal_distance_m(frame.drone_position_m, truth.target_position_m),
        "following": frame.following,
        # The boxes (x, y, w, h) [px] of the decoys in view, as a tuple of tuples: no NaN (check_env
        # compares infos) and no ndarray whose shape changes per frame (vector envs stack those).
        "decoy_bboxes": tuple(decoys),
    }
    for name, value in (terms or {}).items():
        info[f"reward_{name}"] = value
    return info


def reward_inputs(truth: GroundTruth, world: World, band: FollowBand, drone_position_m: FloatArray, visible: bool,
                  action: Sequence[float], crashed: bool) -> RewardInputs:
    """What the reward is computed from: the task in its own units, from ground truth and the drone's true state;
    `band` is the scene's following band (`follow_band`)."""
    drone, target = drone_position_m, truth.target_position_m
    return RewardInputs(
        target_visible=visible,
        horizontal_distance_m=horizontal_distance_m(drone, target),
        height_above_target_ground_m=float(drone[2] - world.ground_height_m(float(target[0]), float(target[1]))),
        follow_height_m=band.follow_height_m,
        follow_distance_m=band.max_distance_m,
        action=action, crashed=crashed, standoff_m=band.standoff_m)
