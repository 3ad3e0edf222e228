"""The frames of a run's video: the annotated onboard view beside a top view of the world, over a strip of
IoU and depth error against time.

The top view is drawn over the terrain (hill shading, buildings) and shows the paths so far of the target
(green), the drone (blue) and the estimate (red), and the decoys (orange). Everything is drawn with OpenCV
from the env's world and each step's info, so a frame costs a few milliseconds beside the render.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from trade_gym.sim.world import World

Image = npt.NDArray[np.uint8]
TARGET_RGB, DRONE_RGB, ESTIMATE_RGB, DECOY_RGB = (40, 200, 40), (40, 110, 255), (230, 40, 40), (255, 150, 0)
BUILDING_RGB, TEXT_RGB, STRIP_BG_RGB, GRID_RGB = (90, 90, 100), (255, 255, 255), (25, 25, 30), (70, 70, 80)
TERRAIN_LOW_RGB, TERRAIN_HIGH_RGB = np.array((150, 125, 90.0)), np.array((235, 220, 190.0))
TERRAIN_GRID_PX = 128  # heights sampled on this grid, then scaled to the view
PATH_SAMPLES = 256
SHADE_LIGHT = np.array((-1.0, 1.0, 1.5)) / math.sqrt(1.0 + 1.0 + 1.5**2)  # light from the north-west, above
EXTENT_MARGIN_M = 15.0  # around the target's route and the drone's start
FONT, FONT_SCALE, LINE_PX = cv2.FONT_HERSHEY_SIMPLEX, 0.45, 18
MARKER_PX = 5
STRIP_FRACTION = 0.3  # strip height over the panel side
DEPTH_ERROR_AXIS_M = 5.0  # the strip's depth-error axis spans 0..5 m (errors above are drawn at the top)


@dataclass(frozen=True)
class ViewBox:
    """The square of the world the top view shows, and its map to pixels (x right, y up)."""

    x0_m: float
    y0_m: float
    side_m: float
    side_px: int

    @classmethod
    def around(cls, xy_m: npt.ArrayLike, margin_m: float, side_px: int) -> ViewBox:
        """The smallest square holding the points (N, 2+) [m] with `margin_m` on every side."""
        xy = np.asarray(xy_m, float)[:, :2]
        lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
        side, centre = float(max(hi - lo)), (lo + hi) / 2.0
        return cls(float(centre[0] - side / 2), float(centre[1] - side / 2), side, side_px)

    def to_px(self, xy_m: npt.ArrayLike) -> npt.NDArray[np.int32]:
        xy = np.atleast_2d(np.asarray(xy_m, float))[:, :2]
        u = (xy[:, 0] - self.x0_m) / self.side_m * self.side_px
        v = (1.0 - (xy[:, 1] - self.y0_m) / self.side_m) * self.side_px
        return np.round(np.column_stack([u, v])).astype(np.int32)


def view_box(world: World, side_px: int) -> ViewBox:
    """The smallest square holding the target's whole route and the drone's start, with a margin."""
    path = world.target.motion.path
    route = np.asarray(path.position_m(np.linspace(0.0, path.length_m, PATH_SAMPLES)))[:, :2]
    return ViewBox.around(np.vstack([route, world.drone_start()[0][None, :2]]), EXTENT_MARGIN_M, side_px)


def terrain_image(world: World, box: ViewBox) -> Image:
    """Hill-shaded terrain, coloured low to high, with the buildings' footprints on top."""
    n = TERRAIN_GRID_PX
    xs = box.x0_m + (np.arange(n) + 0.5) / n * box.side_m
    ys = box.y0_m + box.side_m - (np.arange(n) + 0.5) / n * box.side_m  # row 0 is the north edge
    X, Y = np.meshgrid(xs, ys)
    height = np.asarray(world.ground_height_m(X.ravel(), Y.ravel())).reshape(n, n)
    cell_m = box.side_m / n
    dz_dy, dz_dx = np.gradient(height, -cell_m, cell_m)
    normal = np.dstack([-dz_dx, -dz_dy, np.ones_like(height)])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    shade = np.clip(normal @ SHADE_LIGHT, 0.0, 1.0)
    span = np.ptp(height)
    level = (height - height.min()) / span if span > 0 else np.zeros_like(height)
    colour = TERRAIN_LOW_RGB + level[..., None] * (TERRAIN_HIGH_RGB - TERRAIN_LOW_RGB)
    image = np.clip(colour * (0.5 + 0.5 * shade[..., None]), 0, 255).astype(np.uint8)
    image = cv2.resize(image, (box.side_px, box.side_px), interpolation=cv2.INTER_LINEAR)
    for lo, hi in zip(world.buildings_lo_m, world.buildings_hi_m):
        (u0, v0), (u1, v1) = box.to_px([lo[:2], hi[:2]])
        cv2.rectangle(image, (int(u0), int(v1)), (int(u1), int(v0)), BUILDING_RGB, -1)
    return image


class Dashboard:
    """Composes one video frame per step; build it after the env's reset (it reads the world then)."""

    def __init__(self, world: World, panel_px: int, duration_s: float) -> None:
        self.world, self.panel_px, self.duration_s = world, panel_px, duration_s
        self.box = view_box(world, panel_px)
        self.background = terrain_image(world, self.box)
        self.target_xy: list[np.ndarray] = []
        self.drone_xy: list[np.ndarray] = []
        self.estimate_xy: list[np.ndarray] = []
        self.t_s: list[float] = []
        self.iou: list[float] = []
        self.depth_error_m: list[float] = []

    def frame(self, onboard: Image, info: dict, estimate_world_m: npt.ArrayLike) -> Image:
        """The onboard view (scaled to the panel) beside the top view, over the strip."""
        self._remember(info, np.asarray(estimate_world_m, float))
        side, t_s = self.panel_px, info["t_s"]
        left = cv2.resize(onboard, (side, side), interpolation=cv2.INTER_NEAREST)
        header = np.hstack([_legend(side, ["onboard: green truth box, red estimate, cyan ground mask",
                                           "magenta predicted path, dots: ROI depth (blue near)"]),
                            _legend(side, [f"top view, {self.box.side_m:.0f} m wide, north up, t = {t_s:.1f} s",
                                           "green target, blue drone, red estimate, orange decoys"])])
        panels = np.hstack([left, self._top_view(t_s)])
        return np.vstack([header, panels, self._strip(2 * side, int(round(STRIP_FRACTION * side)))])

    def _remember(self, info: dict, estimate_world_m: np.ndarray) -> None:
        self.t_s.append(float(info["t_s"]))
        self.target_xy.append(np.asarray(info["target_position_m"], float)[:2])
        self.drone_xy.append(np.asarray(info["drone_position_m"], float)[:2])
        # a position only once the estimate has a depth (before, its 3D position is a placeholder)
        if info["est_valid"] and info["target_depth_est"] is not None and np.all(np.isfinite(estimate_world_m[:2])):
            self.estimate_xy.append(estimate_world_m[:2])
        self.iou.append(float(info["iou"]) if info["target_visible"] else math.nan)
        gt, est = info["target_depth_gt"], info["target_depth_est"]
        self.depth_error_m.append(abs(est - gt) if gt is not None and est is not None else math.nan)

    def _top_view(self, t_s: float) -> Image:
        image = self.background.copy()
        for points, colour in ((self.target_xy, TARGET_RGB), (self.drone_xy, DRONE_RGB)):
            if len(points) >= 2:
                cv2.polylines(image, [self.box.to_px(np.array(points))], False, colour, 2)
        for u, v in self.box.to_px(np.array(self.estimate_xy)) if self.estimate_xy else ():
            cv2.circle(image, (int(u), int(v)), 1, ESTIMATE_RGB, -1)
        for decoy in self.world.decoys:
            (u, v), = self.box.to_px(self.world.vehicle_pose(decoy, t_s)[0])
            cv2.rectangle(image, (int(u) - MARKER_PX, int(v) - MARKER_PX), (int(u) + MARKER_PX, int(v) + MARKER_PX),
                          DECOY_RGB, -1)
        (u, v), = self.box.to_px(self.target_xy[-1])
        cv2.circle(image, (int(u), int(v)), MARKER_PX + 1, TARGET_RGB, -1)
        (u, v), = self.box.to_px(self.drone_xy[-1])
        cv2.circle(image, (int(u), int(v)), MARKER_PX + 1, DRONE_RGB, 2)
        return image

    def _strip(self, width_px: int, height_px: int) -> Image:
        strip = np.full((height_px, width_px, 3), STRIP_BG_RGB, np.uint8)
        top, bottom = LINE_PX + 4, height_px - 6
        cv2.line(strip, (0, bottom), (width_px, bottom), GRID_RGB, 1)
        cv2.line(strip, (0, top), (width_px, top), GRID_RGB, 1)
        horizon_s = max(self.duration_s, self.t_s[-1])
        for values, full_scale, colour in ((self.iou, 1.0, TARGET_RGB),
                                           (self.depth_error_m, DEPTH_ERROR_AXIS_M, ESTIMATE_RGB)):
            u = np.array(self.t_s) / horizon_s * (width_px - 1)
            v = bottom - np.clip(np.array(values) / full_scale, 0.0, 1.0) * (bottom - top)
            for run in _finite_runs(np.column_stack([u, v])):
                cv2.polylines(strip, [np.round(run).astype(np.int32)], False, colour, 1)
        cv2.putText(strip, f"green IoU (0-1), red target depth error (0-{DEPTH_ERROR_AXIS_M:.0f} m), "
                           f"0-{horizon_s:.0f} s", (6, LINE_PX - 2), FONT, FONT_SCALE, TEXT_RGB, 1, cv2.LINE_AA)
        return strip


def _finite_runs(points: np.ndarray) -> list[np.ndarray]:
    """The stretches of consecutive finite points (a gap breaks the line)."""
    finite = np.all(np.isfinite(points), axis=1)
    breaks = np.flatnonzero(np.diff(finite.astype(np.int8)) != 0) + 1
    return [seg for seg, ok in zip(np.split(points, breaks), np.split(finite, breaks)) if ok[0] and len(seg) >= 2]


def _legend(width_px: int, lines: list[str]) -> Image:
    """A dark band of text lines, drawn above a panel (off its picture)."""
    band = np.full((LINE_PX * len(lines) + 4, width_px, 3), STRIP_BG_RGB, np.uint8)
    for i, text in enumerate(lines):
        cv2.putText(band, text, (6, LINE_PX * (i + 1) - 2), FONT, FONT_SCALE, TEXT_RGB, 1, cv2.LINE_AA)
    return band
