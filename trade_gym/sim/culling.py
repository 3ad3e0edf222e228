"""View-frustum culling of static bodies for TinyRenderer, which draws every triangle of every body each frame.

Owns `ViewCuller`. Measured here (benchmarks/render_cost.py): TinyRenderer's time grows with the triangles in
the world whether or not they are in view, so the terrain's grid, mostly outside the downward camera's footprint,
dominates a render. The terrain is therefore built as tiles (`trade_gym.sim.world`), and before each render the
culler gives every tile whose bounding box lies wholly outside the camera's view frustum zero alpha, which
TinyRenderer skips without shading a triangle. The test is conservative (a box is dropped only when all eight of
its corners are beyond one frustum plane, widened by `FRUSTUM_MARGIN_PX`), shadows are off, and a dropped body
has no pixel in the image, so culling never changes what is drawn (`tests/trade_gym/test_culling.py` compares culled
frames with all tiles drawn). Tiles are drawn in another order than one grid mesh was, which flips a rare depth tie
on a shared edge: over 300 rendered frames of a scripted flight on development world 0, 0 pixels changed in the
desert and 2 (one pixel on each of 2 frames) in the city (`benchmarks/README.md`). A closed loop under TRADE can turn
such a pixel into a different episode.

The culler owns the colour of the bodies it manages: change it with `set_colour`, never with changeVisualShape.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pybullet as p

from trade.geometry import CameraIntrinsics, Pose

# widen the image by this much before testing, against the projection's sub-pixel sample offset and rounding
FRUSTUM_MARGIN_PX = 2.0
_CORNER_SIGNS = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64)  # (8, 3)


def boxes_in_view(lo_m: npt.ArrayLike, hi_m: npt.ArrayLike, T_world_cam: Pose, K: CameraIntrinsics,
                  near_m: float, far_m: float, margin_px: float = FRUSTUM_MARGIN_PX) -> npt.NDArray[np.bool_]:
    """(N,) False where the world-axis box [lo_m, hi_m] (N, 3) lies wholly outside the frustum of a pinhole camera
    (x right, y down, z forward) at `T_world_cam` with image K between `near_m` and `far_m`; True otherwise."""
    return corners_in_view(box_corners(lo_m, hi_m), T_world_cam, K, near_m, far_m, margin_px)


def box_corners(lo_m: npt.ArrayLike, hi_m: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """(N, 8, 3) corners of the world-axis boxes [lo_m, hi_m] (N, 3)."""
    lo, hi = np.asarray(lo_m, dtype=np.float64).reshape(-1, 3), np.asarray(hi_m, dtype=np.float64).reshape(-1, 3)
    return lo[:, None, :] + (hi - lo)[:, None, :] * _CORNER_SIGNS[None]


def corners_in_view(corners_m: npt.NDArray[np.float64], T_world_cam: Pose, K: CameraIntrinsics, near_m: float,
                    far_m: float, margin_px: float = FRUSTUM_MARGIN_PX) -> npt.NDArray[np.bool_]:
    """`boxes_in_view` of boxes given by their (N, 8, 3) world corners (`box_corners`)."""
    c = (corners_m - T_world_cam.t) @ T_world_cam.R  # (N, 8, 3) camera frame
    x, y, z = c[..., 0], c[..., 1], c[..., 2]
    u_lo, v_lo = -margin_px, -margin_px
    u_hi, v_hi = K.width_px + margin_px, K.height_px + margin_px
    # u = fx x / z + cx is in [u_lo, u_hi] for z > 0 iff fx x + (cx - u_lo) z >= 0 and fx x + (cx - u_hi) z <= 0
    outside = (
        np.all(z < near_m, axis=1) | np.all(z > far_m, axis=1)
        | np.all(K.fx_px * x + (K.cx_px - u_lo) * z < 0.0, axis=1)
        | np.all(K.fx_px * x + (K.cx_px - u_hi) * z > 0.0, axis=1)
        | np.all(K.fy_px * y + (K.cy_px - v_lo) * z < 0.0, axis=1)
        | np.all(K.fy_px * y + (K.cy_px - v_hi) * z > 0.0, axis=1)
    )
    return ~outside


class ViewCuller:
    """Shows (their colour) or hides (zero alpha) static bodies by whether their world-axis boxes can be in view.

    `body_ids` (N,) with boxes `lo_m`, `hi_m` (N, 3) and colours `rgba` (N, 4); all start shown."""

    def __init__(self, client_id: int, body_ids: Sequence[int], lo_m: npt.ArrayLike, hi_m: npt.ArrayLike,
                 rgba: npt.ArrayLike) -> None:
        self.client_id = int(client_id)
        self.body_ids = tuple(int(b) for b in body_ids)
        lo, hi = np.asarray(lo_m, dtype=np.float64).reshape(-1, 3), np.asarray(hi_m, dtype=np.float64).reshape(-1, 3)
        self._rgba = np.array(rgba, dtype=np.float64).reshape(-1, 4)
        if not (len(self.body_ids) == len(lo) == len(hi) == len(self._rgba)):
            raise ValueError(f"ViewCuller needs one box and colour per body, got {len(self.body_ids)} bodies, "
                             f"{len(lo)} / {len(hi)} boxes and {len(self._rgba)} colours")
        self._corners_m = box_corners(lo, hi)  # static bodies: their corners once
        self.shown = np.ones(len(self.body_ids), dtype=bool)

    def set_colour(self, rgba: npt.ArrayLike) -> None:
        """Give every managed body the colour `rgba` (4,), applied now to those shown, on showing to the rest."""
        self._rgba[:] = np.asarray(rgba, dtype=np.float64).reshape(4)
        for i in np.flatnonzero(self.shown).tolist():
            self._apply(i, self._rgba[i])

    def update(self, T_world_cam: Pose, K: CameraIntrinsics, near_m: float, far_m: float) -> int:
        """Show the bodies that can be in view of this camera, hide the rest; returns how many are shown."""
        want = corners_in_view(self._corners_m, T_world_cam, K, near_m, far_m)
        for i in np.flatnonzero(want != self.shown).tolist():
            self._apply(i, self._rgba[i] if want[i] else (*self._rgba[i, :3], 0.0))
        self.shown = want
        return int(want.sum())

    def _apply(self, i: int, rgba) -> None:
        p.changeVisualShape(self.body_ids[i], -1, rgbaColor=[float(v) for v in rgba], physicsClientId=self.client_id)
