"""Ground truth for scoring: target and decoy boxes, visibility and depths at one frame.

Boxes come from the segmentation mask (visible pixels) when a frame was rendered, else from
the projection of each vehicle's 3D box; visibility always from rays to sample points.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.geometry import CameraIntrinsics, Pose

if TYPE_CHECKING:
    from trade_gym.sim.vehicles import Vehicle
    from trade_gym.sim.world import World

FloatArray = npt.NDArray[np.float64]

# Target visibility is measured on a 3 x 3 grid of points in two layers of the vehicle's box
# (its middle and just under its top), shrunk slightly so the points sit inside its surfaces.
VISIBILITY_GRID_STEPS = 3
VISIBILITY_LAYERS_Z = (0.0, 1.0)  # box-normalised heights of the two layers
VISIBILITY_SHRINK = 0.9
# A ray that gets this close to its end point without hitting anything static is clear.
RAY_CLEAR_FRACTION = 0.999
# pybullet's rayTest has a practical range; rays longer than this are not cast.
MAX_RAY_LENGTH_M = 2000.0

_UNIT_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
_grid = np.linspace(-1.0, 1.0, VISIBILITY_GRID_STEPS)
_UNIT_GRID = np.array([[x, y, z] for x in _grid for y in _grid for z in VISIBILITY_LAYERS_Z]) * VISIBILITY_SHRINK


@dataclass(frozen=True)
class VehicleBox:
    """A vehicle's oriented 3D box: centre (3,) world [m], R_world_vehicle (3, 3), half extents (3,) [m]."""

    center_m: FloatArray
    R_world_vehicle: FloatArray
    half_extents_m: FloatArray

    def points(self, unit: FloatArray) -> FloatArray:
        """Points given in box-normalised coordinates (N, 3) in [-1, 1] -> world (N, 3) [m]."""
        return (unit * self.half_extents_m) @ self.R_world_vehicle.T + self.center_m


@dataclass(frozen=True)
class GroundTruth:
    """Ground truth at one frame; boxes (x, y, w, h) [px] with NaN where not in view."""

    target_bbox: FloatArray
    decoy_bboxes: FloatArray  # (D, 4)
    target_visible_fraction: float
    target_position_m: FloatArray  # (3,) world, centre of the target's box
    target_velocity_mps: FloatArray  # (3,) world
    target_depth_m: float  # camera-frame z of the target's centre
    target_center_px: FloatArray  # (2,) projection of the target's centre; NaN behind the camera
    ground_depth_m: float  # camera-frame z of the static surface under the box centre's ray


def box_corners(box: VehicleBox) -> FloatArray:
    """(8, 3) world corners [m] of a vehicle's box."""
    return box.points(_UNIT_CORNERS)


class VehicleBoxes:
    """An episode's vehicles as boxes: each vehicle's box at a time, and the (1 + D, 8, 3) world corners of the
    target and the D decoys in one buffer refilled in place (read-only for callers); parked decoys' corners are
    computed once, at construction (time `t_s` [s])."""

    def __init__(self, world: World, t_s: float) -> None:
        self._world = world
        decoys = world.decoys
        self.decoy_ids = [d.body_id for d in decoys]
        self._moving_decoys = [(i, d) for i, d in enumerate(decoys) if d.motion.is_moving]
        self._corners = np.zeros((1 + len(decoys), 8, 3))
        for i, decoy in enumerate(decoys):
            self._corners[1 + i] = box_corners(self.box(decoy, t_s))

    def box(self, vehicle: Vehicle, t_s: float) -> VehicleBox:
        """`vehicle`'s box at time `t_s` [s]."""
        position, R = self._world.vehicle_pose(vehicle, t_s)
        return VehicleBox(position, R, np.asarray(vehicle.half_extents_m, dtype=np.float64))

    def corners(self, target_box: VehicleBox, t_s: float) -> FloatArray:
        """(1 + D, 8, 3) world corners [m]: the target's (`target_box`), then the decoys' at time `t_s` [s]."""
        corners = self._corners
        corners[0] = box_corners(target_box)
        for i, decoy in self._moving_decoys:
            corners[1 + i] = box_corners(self.box(decoy, t_s))
        return corners


@functools.lru_cache(maxsize=8)
def _camera_matrix(K: CameraIntrinsics) -> FloatArray:
    """(3, 3) K of a camera (read-only; built once per intrinsics, not once per frame)."""
    matrix = np.array([[K.fx_px, 0.0, K.cx_px], [0.0, K.fy_px, K.cy_px], [0.0, 0.0, 1.0]])
    matrix.setflags(write=False)
    return matrix


def camera_projection(K: CameraIntrinsics, T_cam_world: Pose) -> tuple[FloatArray, FloatArray]:
    """(M (3, 3), m (3,)) with K (R x + t) = M x + m: world points to homogeneous pixels (u w, v w, w),
    w the camera-frame depth [m]."""
    M = _camera_matrix(K) @ T_cam_world.R
    return M, M @ (T_cam_world.R.T @ T_cam_world.t)


def projected_boxes(K: CameraIntrinsics, T_cam_world: Pose, corners_world: FloatArray,
                    projection: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """(B, 4) image boxes (x, y, w, h) of vehicles given their world corners (B, 8, 3) [m], clipped
    to the image; NaN rows for boxes out of view or with a corner behind the camera. `projection`:
    `camera_projection(K, T_cam_world)` when the caller has it."""
    if len(corners_world) == 0:
        return np.zeros((0, 4))
    M, m = camera_projection(K, T_cam_world) if projection is None else projection
    # one (8B, 3) product instead of B stacked (8, 3) ones: the same dot products, bit for bit
    uvw = (corners_world.reshape(-1, 3) @ M.T + m).reshape(-1, 8, 3)  # (B, 8, 3)
    depth = uvw[..., 2:]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[..., :2] / depth  # (B, 8, 2)
    # ufunc reductions directly: ndarray.min/max go through Python wrappers that cost more than the
    # arithmetic on these few corners
    out = np.empty((len(uv), 4))
    lo = np.maximum(np.minimum.reduce(uv, axis=1), -0.5, out=out[:, :2])
    hi = np.minimum(np.maximum.reduce(uv, axis=1), (K.width_px - 0.5, K.height_px - 0.5))
    np.subtract(hi, lo, out=out[:, 2:])
    behind = np.minimum.reduce(depth[..., 0], axis=1) <= 0.0
    empty = np.minimum.reduce(out[:, 2:], axis=1) <= 0.0
    out[behind | empty] = np.nan
    return out


def segmentation_boxes(seg: npt.NDArray[np.int32], body_ids: npt.ArrayLike) -> FloatArray:
    """Tight (x, y, w, h) boxes of each body's visible pixels in a segmentation mask; NaN if absent."""
    ids = np.asarray(body_ids, dtype=np.int64)
    boxes = np.full((len(ids), 4), np.nan)
    # One pass over the mask: for each requested id, its pixel rows and columns.
    lookup = {int(b): i for i, b in enumerate(ids)}
    present = np.isin(seg, ids)
    if not present.any():
        return boxes
    rows, cols = np.nonzero(present)
    labels = seg[rows, cols]
    for body, i in lookup.items():
        sel = labels == body
        if sel.any():
            r, c = rows[sel], cols[sel]
            boxes[i] = (c.min() - 0.5, r.min() - 0.5, c.max() - c.min() + 1.0, r.max() - r.min() + 1.0)
    return boxes


def _visibility_targets(K: CameraIntrinsics, box: VehicleBox, projection: tuple[FloatArray, FloatArray] | None,
                        ) -> tuple[FloatArray, int]:
    """The box's sample points (N, 3) world [m] that are in the image (all of them when `projection` is None:
    the caller knows the whole box is inside), and how many sample points there are."""
    pts = box.points(_UNIT_GRID)
    if projection is None:
        return pts, len(pts)
    M, m = projection
    uvw = pts @ M.T + m
    depth = uvw[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = uvw[:, 0] / depth, uvw[:, 1] / depth
    in_image = ((depth > 0.0) & (u >= -0.5) & (u <= K.width_px - 0.5)
                & (v >= -0.5) & (v <= K.height_px - 0.5))
    return pts[in_image], len(pts)


def _clear_fraction(hits: list, n_points: int) -> float:
    """Fraction of `n_points` whose ray (of `hits`, pybullet ray results) reaches its point unblocked."""
    return sum(1 for h in hits if h[0] < 0 or h[2] >= RAY_CLEAR_FRACTION) / n_points


def visible_fraction(
    client_id: int, K: CameraIntrinsics, T_world_cam: Pose, box: VehicleBox,
    T_cam_world: Pose | None = None, box_in_image: bool = False,
) -> float:
    """Fraction of sample points inside the target's box that are in the image and not hidden by
    terrain or buildings (vehicles carry no collision shape, so rays pass through them).

    `box_in_image`: the caller knows the whole box projects inside the image in front of the camera
    (then, the image being convex, so do all sample points, and their projection is skipped)."""
    T_cam_world = T_world_cam.inverse() if T_cam_world is None else T_cam_world
    targets, n = _visibility_targets(K, box, None if box_in_image else camera_projection(K, T_cam_world))
    if not len(targets):
        return 0.0
    hits = p.rayTestBatch([T_world_cam.t.tolist()] * len(targets), targets.tolist(), physicsClientId=client_id)
    return _clear_fraction(hits, n)


def _ground_ray(K: CameraIntrinsics, T_world_cam: Pose, pixel: FloatArray, max_range_m: float,
                ) -> tuple[list[float], list[float]] | None:
    """(start, end) world [m] of the pixel's ground-truth ray; None for a non-finite pixel."""
    u, v = float(pixel[0]), float(pixel[1])
    if not (math.isfinite(u) and math.isfinite(v)):
        return None
    # camera ray (x, y, 1) scaled to the ray length; world end = t + R ray
    x, y = (u - K.cx_px) / K.fx_px, (v - K.cy_px) / K.fy_px
    scale = min(max_range_m, MAX_RAY_LENGTH_M) / math.sqrt(x * x + y * y + 1.0)
    start = T_world_cam.t
    end = start + T_world_cam.R @ np.array([x * scale, y * scale, scale])
    return start.tolist(), end.tolist()


def _hit_depth(T_world_cam: Pose, hit: tuple) -> float:
    """Camera-frame z [m] of a pybullet ray hit, NaN for a miss: z_cam . (point - t), z_cam the third column of R."""
    if hit[0] < 0:
        return float("nan")
    return float(T_world_cam.R[:, 2] @ (np.asarray(hit[3], dtype=np.float64) - T_world_cam.t))


def ground_depth(
    client_id: int, K: CameraIntrinsics, T_world_cam: Pose, pixel: FloatArray, max_range_m: float
) -> float:
    """Cast the pixel's ray against static geometry: camera-frame z [m] of the hit, NaN if none."""
    ray = _ground_ray(K, T_world_cam, pixel, max_range_m)
    if ray is None:
        return float("nan")
    return _hit_depth(T_world_cam, p.rayTest(*ray, physicsClientId=client_id)[0])


def _pixel(K: CameraIntrinsics, x: float, y: float, z: float) -> FloatArray:
    """(2,) pixel of a camera-frame point [m]; NaN behind the camera."""
    if z <= 0.0:
        return np.full(2, np.nan)
    return np.array((K.fx_px * x / z + K.cx_px, K.fy_px * y / z + K.cy_px))


def _strictly_inside(K: CameraIntrinsics, bbox: FloatArray) -> bool:
    """Whether a projected (unclipped-looking) box lies strictly inside the image: its clipped sides
    then equal its true sides, so every point of the 3D box projects into the image."""
    x, y, w, h = bbox.tolist()
    return x > -0.5 and y > -0.5 and x + w < K.width_px - 0.5 and y + h < K.height_px - 0.5


def compute_ground_truth(
    client_id: int,
    K: CameraIntrinsics,
    T_world_cam: Pose,
    target: VehicleBox,
    target_velocity_mps: FloatArray,
    vehicle_corners_m: FloatArray,
    seg: npt.NDArray[np.int32] | None,
    target_body_id: int,
    decoy_body_ids: list[int],
    max_range_m: float,
) -> GroundTruth:
    """All ground truth of one frame. vehicle_corners_m: (1 + D, 8, 3) world corners of the target
    then the decoys (used when `seg`, the rendered mask, is None: boxes are then projected)."""
    T_cam_world = T_world_cam.inverse()
    projection = camera_projection(K, T_cam_world)
    if seg is not None:
        boxes = segmentation_boxes(seg, [target_body_id, *decoy_body_ids])
    else:
        boxes = projected_boxes(K, T_cam_world, vehicle_corners_m, projection)
    target_bbox, decoy_bboxes = boxes[0], boxes[1:]
    x, y, z = (T_cam_world.R @ target.center_m + T_cam_world.t).tolist()  # target centre, camera frame
    box_in_image = seg is None and _strictly_inside(K, target_bbox)
    targets, n_points = _visibility_targets(K, target, None if box_in_image else projection)
    centre = target_bbox[:2] + target_bbox[2:] / 2.0
    ground_ray = _ground_ray(K, T_world_cam, centre, max_range_m)
    # one batch: the visibility rays, then the ground ray (pybullet's rayTest is a batch of one: same hits)
    starts, ends = [T_world_cam.t.tolist()] * len(targets), targets.tolist()
    if ground_ray is not None:
        starts.append(ground_ray[0])
        ends.append(ground_ray[1])
    hits = p.rayTestBatch(starts, ends, physicsClientId=client_id) if starts else []
    fraction = _clear_fraction(hits[:len(targets)], n_points)
    ground = _hit_depth(T_world_cam, hits[-1]) if ground_ray is not None else float("nan")
    return GroundTruth(
        target_bbox=target_bbox,
        decoy_bboxes=decoy_bboxes,
        target_visible_fraction=fraction,
        target_position_m=target.center_m.copy(),
        target_velocity_mps=np.asarray(target_velocity_mps, dtype=np.float64),
        target_depth_m=z,
        target_center_px=_pixel(K, x, y, z),
        ground_depth_m=ground,
    )
