"""Raycasting an image pixel onto a (lifted) ground plane, and the multi-plane depth Gaussian.

Paper: "Robust Object 3D Localization" (lift by half the object height) and "Multi-RANSAC plane fitting".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics, Pose
from trade.planes import Plane

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

LIFT_FRACTION_OF_HEIGHT = 0.5  # the box-centre ray meets the object at about half its height


@dataclass(frozen=True)
class RaycastConfig:
    """min_depth_sigma_m: floor of the multi-plane depth sigma (one solution, or solutions that agree);
    parallel_cos_min: |cos(ray, normal)| below this counts as a ray parallel to the plane."""

    min_depth_sigma_m: float = 0.25  # half the MSAC inlier threshold: what a plane fit can resolve
    parallel_cos_min: float = 1e-6

    def __post_init__(self) -> None:
        if not (np.isfinite(self.min_depth_sigma_m) and self.min_depth_sigma_m > 0):
            raise ValueError(f"RaycastConfig.min_depth_sigma_m must be finite and > 0, got {self.min_depth_sigma_m!r}")
        if not 0.0 <= self.parallel_cos_min < 1.0:
            raise ValueError(f"RaycastConfig.parallel_cos_min must be in [0, 1), got {self.parallel_cos_min!r}")


@dataclass(frozen=True)
class RaycastResult:
    """point_world: (3,) world [m]; depth_m: camera-frame z [m]; NaN for both when not valid
    (ray parallel to the plane, or the plane lies behind the camera)."""

    point_world: FloatArray
    depth_m: float
    valid: bool


@dataclass(frozen=True)
class DepthGaussian:
    """Gaussian fitted to the depths of all valid plane solutions; NaN when none is valid."""

    mean_m: float
    sigma_m: float
    n_valid: int

    @property
    def valid(self) -> bool:
        return self.n_valid > 0


def _check_height(object_height_m: float) -> None:
    if not (np.isfinite(object_height_m) and object_height_m >= 0):
        raise ValueError(f"object_height_m must be finite and >= 0, got {object_height_m!r}")


def raycast_depths(
    intrinsics: CameraIntrinsics,
    T_world_cam: Pose,
    pixel_px: FloatArray,
    normals: FloatArray,
    offsets_m: FloatArray,
    config: RaycastConfig,
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Intersect one pixel's ray with M planes n·x + d = 0 (vectorised over planes).

    pixel_px: (2,); normals: (M, 3) world, unit; offsets_m: (M,).
    The ray is x(s) = c + s R r with r the camera ray of z = 1, so s is the camera-frame depth:
    n·(c + s R r) + d = 0  =>  s = -(n·c + d) / (n·R r).
    Returns points (M, 3) world [m], depths (M,) [m] and valid (M,) (NaN where invalid).
    """
    ray_world = T_world_cam.R @ intrinsics.rays(np.asarray(pixel_px, dtype=np.float64).reshape(1, 2))[0]
    normals = np.atleast_2d(np.asarray(normals, dtype=np.float64))
    offsets = np.atleast_1d(np.asarray(offsets_m, dtype=np.float64))
    denom = normals @ ray_world  # n·(R r)
    numer = -(normals @ T_world_cam.t + offsets)  # -(n·c + d)
    not_parallel = np.abs(denom) > config.parallel_cos_min * np.linalg.norm(ray_world)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(not_parallel, numer / denom, np.nan)
    valid = not_parallel & (depth > 0.0)
    depth = np.where(valid, depth, np.nan)
    points = T_world_cam.t + depth[:, None] * ray_world
    return points, depth, valid


def raycast_plane(
    intrinsics: CameraIntrinsics,
    T_world_cam: Pose,
    pixel_px: FloatArray,
    plane: Plane,
    object_height_m: float = 0.0,
    config: RaycastConfig | None = None,
) -> RaycastResult:
    """Ray through pixel_px (2,) [px] meets `plane` lifted by LIFT_FRACTION_OF_HEIGHT x object_height_m
    along its normal (object_height_m = 0 gives the ground depth of the pixel)."""
    _check_height(object_height_m)
    lifted = plane.lifted(LIFT_FRACTION_OF_HEIGHT * object_height_m)
    cfg = RaycastConfig() if config is None else config
    points, depth, valid = raycast_depths(
        intrinsics, T_world_cam, pixel_px, lifted.normal[None, :], np.array([lifted.offset_m]), cfg
    )
    return RaycastResult(points[0], float(depth[0]), bool(valid[0]))


def depth_uncertainty(
    intrinsics: CameraIntrinsics,
    T_world_cam: Pose,
    pixel_px: FloatArray,
    planes: Sequence[Plane],
    object_height_m: float = 0.0,
    config: RaycastConfig | None = None,
) -> DepthGaussian:
    """Raycast every multi-RANSAC solution (each lifted like `raycast_plane`) and fit a Gaussian:
    mean = (1/K) sum z_k, sigma = max(sqrt((1/K) sum (z_k - mean)^2), min_depth_sigma_m), K valid."""
    _check_height(object_height_m)
    cfg = RaycastConfig() if config is None else config
    if len(planes) == 0:
        return DepthGaussian(float("nan"), float("nan"), 0)
    lift_m = LIFT_FRACTION_OF_HEIGHT * object_height_m
    normals = np.array([p.normal for p in planes])
    offsets = np.array([p.offset_m - lift_m for p in planes])  # lifted: d' = d - h
    _, depth, valid = raycast_depths(intrinsics, T_world_cam, pixel_px, normals, offsets, cfg)
    if not np.any(valid):
        return DepthGaussian(float("nan"), float("nan"), 0)
    z = depth[valid]
    return DepthGaussian(float(z.mean()), max(float(z.std()), cfg.min_depth_sigma_m), int(z.size))
