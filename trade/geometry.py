"""Camera model and rigid transforms shared by every stage of the stack.

Frames: world z up; camera OpenCV (x right, y down, z along the optical axis).
`Pose` named by what it maps: `T_world_cam` maps camera-frame points to world.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics; pixel centres at integer coordinates (OpenCV)."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int

    def __post_init__(self) -> None:
        for name in ("fx_px", "fy_px"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"CameraIntrinsics.{name} must be finite and > 0, got {value!r}")
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if int(value) != value or value <= 0:
                raise ValueError(f"CameraIntrinsics.{name} must be a positive integer, got {value!r}")

    @classmethod
    def from_fov(cls, width_px: int, height_px: int, fov_deg: float) -> CameraIntrinsics:
        """Square pixels; `fov_deg` is the vertical field of view (OpenGL convention)."""
        if not 0.0 < fov_deg < 180.0:
            raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg!r}")
        f = 0.5 * height_px / np.tan(np.radians(fov_deg) / 2.0)
        return cls(f, f, width_px / 2.0 - 0.5, height_px / 2.0 - 0.5, int(width_px), int(height_px))

    @property
    def K(self) -> FloatArray:
        """3x3 camera matrix."""
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    def project(self, points_cam: FloatArray) -> FloatArray:
        """points_cam: (N, 3) camera frame [m] -> (N, 2) pixels; NaN where z <= 0."""
        pts = np.atleast_2d(np.asarray(points_cam, dtype=np.float64))
        z = pts[:, 2]
        ahead = z > 0
        # divide by a safe depth (1 where the point is not ahead), then mark those points NaN
        inv_z = 1.0 / np.where(ahead, z, 1.0)
        uv = np.empty((len(pts), 2))
        uv[:, 0] = self.fx_px * pts[:, 0] * inv_z + self.cx_px
        uv[:, 1] = self.fy_px * pts[:, 1] * inv_z + self.cy_px
        uv[~ahead] = np.nan
        return uv

    def project_covariance(self, point_cam: FloatArray, covariance_cam_m2: FloatArray) -> FloatArray:
        """First-order image covariance (2, 2) [px^2] of a camera-frame point (3,) [m] with camera-frame
        covariance (3, 3) [m^2]: J C J^T, J the projection's Jacobian at the point; NaN behind the camera."""
        x, y, z = (float(v) for v in np.ravel(point_cam))
        if not z > 0:
            return np.full((2, 2), np.nan)
        J = np.array([[self.fx_px / z, 0.0, -self.fx_px * x / z**2], [0.0, self.fy_px / z, -self.fy_px * y / z**2]])
        return J @ np.asarray(covariance_cam_m2, dtype=np.float64) @ J.T

    def rays(self, pixels: FloatArray) -> FloatArray:
        """pixels: (N, 2) -> (N, 3) camera-frame rays with z = 1."""
        px = np.atleast_2d(np.asarray(pixels, dtype=np.float64))
        x = (px[:, 0] - self.cx_px) / self.fx_px
        y = (px[:, 1] - self.cy_px) / self.fy_px
        return np.stack([x, y, np.ones_like(x)], axis=1)

    def backproject(self, pixels: FloatArray, depth_m: FloatArray) -> FloatArray:
        """pixels: (N, 2), depth_m: (N,) camera-frame z [m] -> (N, 3) camera-frame points."""
        return self.rays(pixels) * np.asarray(depth_m, dtype=np.float64).reshape(-1, 1)


@dataclass(frozen=True)
class Pose:
    """Rigid transform T_a_b: maps points in frame b to frame a (p_a = R p_b + t)."""

    R: FloatArray  # (3, 3) rotation
    t: FloatArray  # (3,) translation [m]

    def __post_init__(self) -> None:
        R = np.asarray(self.R, dtype=np.float64)
        t = np.asarray(self.t, dtype=np.float64).reshape(3)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.all(np.isfinite(t)):
            raise ValueError(f"Pose needs a finite 3x3 R and 3-vector t, got R={self.R!r}, t={self.t!r}")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "t", t)

    @classmethod
    def identity(cls) -> Pose:
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def unchecked(cls, R: FloatArray, t: FloatArray) -> Pose:
        """Build from arrays already known to be a finite float64 (3, 3) and (3,) (results of
        composing or inverting valid poses), skipping validation on this hot path."""
        pose = object.__new__(cls)
        object.__setattr__(pose, "R", R)
        object.__setattr__(pose, "t", t)
        return pose

    @property
    def matrix(self) -> FloatArray:
        """4x4 homogeneous matrix."""
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.t
        return T

    def inverse(self) -> Pose:
        Rt = self.R.T
        return Pose.unchecked(Rt, -(Rt @ self.t))

    def compose(self, other: Pose) -> Pose:
        """self ∘ other: T_a_b.compose(T_b_c) = T_a_c."""
        return Pose.unchecked(self.R @ other.R, self.R @ other.t + self.t)

    def apply(self, points: FloatArray) -> FloatArray:
        """points: (N, 3) in frame b -> (N, 3) in frame a."""
        return np.atleast_2d(points) @ self.R.T + self.t


@dataclass(frozen=True, eq=False)
class RotationWarp:
    """Where the camera's rotation between two frames moves an image point: the infinite homography
    H = K R K^-1 [px -> px], R the rotation from the earlier camera frame to the later. Exact for a camera that
    only rotates; a translation t adds the parallax of a point at depth z, about f |t| / z px (a drone moving
    0.3 m a frame at 25 m: 1.1 px with the default 256 px, 110 degree camera, where one degree of pitch is 1.6 px)."""

    H: FloatArray  # (3, 3)

    @classmethod
    def identity(cls) -> RotationWarp:
        return cls(np.eye(3))

    @classmethod
    def between(cls, intrinsics: CameraIntrinsics, T_world_from: Pose, T_world_to: Pose) -> RotationWarp:
        """The warp from the image of a camera at `T_world_from` to that of one at `T_world_to` (positions ignored)."""
        K = intrinsics.K
        return cls(K @ (T_world_to.R.T @ T_world_from.R) @ np.linalg.inv(K))

    def apply(self, pixel_px: FloatArray) -> FloatArray:
        """(2,) pixel (x, y) in the earlier image -> (2,) in the later; NaN when its ray is not in front of the later
        camera (as `CameraIntrinsics.project`)."""
        x, y, w = self.H @ np.array([pixel_px[0], pixel_px[1], 1.0])
        return np.array([x / w, y / w]) if w > 0 else np.full(2, np.nan)

    def apply_box(self, bbox: FloatArray) -> FloatArray:
        """(4,) box (x, y, w, h) [px] in the earlier image -> in the later: its centre warped, its size kept; the box
        unchanged when it is not finite or its centre's ray turns behind the later camera."""
        x, y, w, h = (float(v) for v in bbox)
        centre = self.apply(np.array([x + w / 2.0, y + h / 2.0]))  # NaN for a NaN entry, as for a ray behind
        if not np.all(np.isfinite(centre)):
            return np.asarray(bbox, dtype=np.float64)
        return np.array([centre[0] - w / 2.0, centre[1] - h / 2.0, w, h])


def project_world(K: CameraIntrinsics, T_world_cam: Pose, points_world: FloatArray) -> FloatArray:
    """World points (N, 3) [m] -> pixels (N, 2); NaN behind the camera."""
    return K.project(T_world_cam.inverse().apply(points_world))


def quat_xyzw_to_matrix(q: FloatArray) -> FloatArray:
    """Unit quaternion (x, y, z, w) -> 3x3 rotation matrix (the inverse of `matrix_to_quat_xyzw`)."""
    x, y, z, w = (float(c) for c in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat_xyzw(R_rowmajor: Sequence[float]) -> tuple[float, float, float, float]:
    """Rotation given by its 9 entries row-major (`R.ravel()`, or pybullet's matrix layout) -> unit quaternion
    (x, y, z, w), Shepperd's method: from the trace when it is positive, else from the largest diagonal entry.
    Plain floats: it places the scene's vehicles every rendered frame, where numpy's per-call cost dominates."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = R_rowmajor
    tr = m00 + m11 + m22
    if tr > 0.0:
        r = 2.0 * math.sqrt(tr + 1.0)
        q = ((m21 - m12) / r, (m02 - m20) / r, (m10 - m01) / r, 0.25 * r)
    elif m00 >= m11 and m00 >= m22:
        r = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = (0.25 * r, (m01 + m10) / r, (m02 + m20) / r, (m21 - m12) / r)
    elif m11 >= m22:
        r = 2.0 * math.sqrt(1.0 + m11 - m22 - m00)
        q = ((m01 + m10) / r, 0.25 * r, (m12 + m21) / r, (m02 - m20) / r)
    else:
        r = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m02 + m20) / r, (m12 + m21) / r, 0.25 * r, (m10 - m01) / r)
    inv = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv


def rotation_z(yaw_rad: float) -> FloatArray:
    """Rotation about world z by yaw [rad]."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
