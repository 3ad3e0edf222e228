"""A synthetic planar world for pipeline tests: a textured ground plane z = 0 seen straight down,
with a textured target patch moving on it. Images are exact pinhole renders (affine warps).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from trade.geometry import CameraIntrinsics, Pose

TEXTURE_M_PER_PX = 0.05
TEXTURE_SIDE_PX = 2400  # 120 m of ground
TARGET_SIDE_M = 4.0
TEXTURE_CELL_PX = 10
OCCLUDER_SCALE = 1.5  # an occluding grey patch covers the target's box scaled by this
OCCLUDER_GREY = 128
# Camera looking straight down, image top towards world +x: x_cam = -y_world, y_cam = -x_world.
R_WORLD_CAM_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class PlanarScene:
    intrinsics: CameraIntrinsics
    ground: np.ndarray  # (S, S, 3) uint8, world origin at its centre, +x along columns, +y along rows
    target: np.ndarray  # (t, t, 3) uint8 patch

    @classmethod
    def make(cls, size_px: int = 128, fov_deg: float = 90.0, seed: int = 0) -> PlanarScene:
        rng = np.random.default_rng(seed)
        # Texture detail of ~0.5 m: coarser than an image pixel at the test altitudes, so no aliasing.
        cells = TEXTURE_SIDE_PX // TEXTURE_CELL_PX
        noise = rng.integers(0, 255, (cells, cells, 3), dtype=np.uint8)
        ground = cv2.resize(noise, (TEXTURE_SIDE_PX, TEXTURE_SIDE_PX), interpolation=cv2.INTER_NEAREST)
        ground = cv2.GaussianBlur(ground, (0, 0), TEXTURE_CELL_PX / 3)
        side = int(TARGET_SIDE_M / TEXTURE_M_PER_PX)
        target = np.zeros((side, side, 3), np.uint8)
        # A red vehicle with darker red panels: one colour family, with texture for the correlation filter.
        panels = rng.integers(0, 2, (side // TEXTURE_CELL_PX, side // TEXTURE_CELL_PX)).astype(np.float64)
        shade = cv2.resize(panels, (side, side), interpolation=cv2.INTER_NEAREST)
        target[..., 0] = (220 - 90 * shade).astype(np.uint8)
        target[..., 1] = 25
        target[..., 2] = 30
        return cls(CameraIntrinsics.from_fov(size_px, size_px, fov_deg), ground, target)

    def camera_pose(self, position_m: np.ndarray) -> Pose:
        return Pose(R_WORLD_CAM_DOWN, np.asarray(position_m, dtype=np.float64))

    def texture_with_target(self, target_xy_m: np.ndarray, lookalikes_xy_m: tuple[np.ndarray, ...] = ()) -> np.ndarray:
        """The ground texture with the target pasted, centred at target_xy_m (x, y) on the plane [m], and
        identical copies of it at lookalikes_xy_m."""
        ground = self.ground.copy()
        side = self.target.shape[0]
        for xy in (target_xy_m, *lookalikes_xy_m):
            col = int(round(xy[0] / TEXTURE_M_PER_PX + TEXTURE_SIDE_PX / 2 - side / 2))
            row = int(round(xy[1] / TEXTURE_M_PER_PX + TEXTURE_SIDE_PX / 2 - side / 2))
            ground[row:row + side, col:col + side] = self.target
        return ground

    def render(self, camera_xyz_m: np.ndarray, target_xy_m: np.ndarray,
               lookalikes_xy_m: tuple[np.ndarray, ...] = ()) -> np.ndarray:
        """RGB image from a down-looking camera at camera_xyz_m with the target centred at target_xy_m
        (and identical lookalikes at lookalikes_xy_m)."""
        ground = self.texture_with_target(target_xy_m, lookalikes_xy_m)
        K = self.intrinsics
        cx, cy, h = camera_xyz_m
        s = TEXTURE_M_PER_PX
        x0 = -TEXTURE_SIDE_PX / 2 * s  # world coordinate of texture column / row 0
        # World (X, Y) = (x0 + a s, x0 + b s) for texture column a, row b; then
        # u = fx (cy - Y) / h + cx_px, v = fy (cx - X) / h + cy_px.
        A = np.array([
            [0.0, -K.fx_px * s / h, K.fx_px * (cy - x0) / h + K.cx_px],
            [-K.fy_px * s / h, 0.0, K.fy_px * (cx - x0) / h + K.cy_px],
        ])
        return cv2.warpAffine(ground, A, (K.width_px, K.height_px), flags=cv2.INTER_LINEAR)

    def target_box(self, camera_xyz_m: np.ndarray, target_xy_m: np.ndarray) -> np.ndarray:
        """Ground-truth (x, y, w, h) box of the target [px]."""
        half = TARGET_SIDE_M / 2
        corners = np.array([[target_xy_m[0] + dx, target_xy_m[1] + dy, 0.0]
                            for dx in (-half, half) for dy in (-half, half)])
        uv = self.intrinsics.project(self.camera_pose(camera_xyz_m).inverse().apply(corners))
        x0, y0 = uv.min(axis=0)
        x1, y1 = uv.max(axis=0)
        return np.array([x0, y0, x1 - x0, y1 - y0])


def occlude(image: np.ndarray, box_xywh: np.ndarray) -> None:
    """Paint a grey patch over the box (x, y, w, h) [px] scaled by OCCLUDER_SCALE about its centre, in place."""
    centre, size = box_xywh[:2] + box_xywh[2:] / 2, OCCLUDER_SCALE * box_xywh[2:]
    lo = np.floor(centre - size / 2).clip(0).astype(int)
    hi = np.ceil(centre + size / 2).astype(int)
    image[lo[1]:hi[1], lo[0]:hi[0]] = OCCLUDER_GREY
