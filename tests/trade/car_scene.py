"""A synthetic downward view for tracker tests: red cars (a darker panel across each) on a blurred random
texture of grey-to-brown cells."""

from __future__ import annotations

import cv2
import numpy as np

from trade.types import BBox

IMAGE_PX = 128
GROUND_PX = 256  # the textured ground the camera's view is cropped from
GROUND_CELL_PX = 4  # texture cells, blurred: detail for the DCF, but no edges as sharp as a car's
CAR_WH_PX = np.array([10.0, 16.0])  # at scale 1
CAR_RGB, PANEL_RGB = (200, 30, 30), (120, 10, 10)  # a red car with a darker panel across it


def textured_ground(seed: int = 0) -> np.ndarray:
    """(GROUND_PX, GROUND_PX, 3) uint8 ground: random grey-to-brown cells, blurred."""
    cells = np.random.default_rng(seed).integers(60, 160, (GROUND_PX // GROUND_CELL_PX,) * 2 + (3,), dtype=np.uint8)
    ground = cv2.resize(cells, (GROUND_PX, GROUND_PX), interpolation=cv2.INTER_NEAREST)
    return cv2.GaussianBlur(ground, (0, 0), 1.5)


def draw_car(image: np.ndarray, centre_px: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Draw a car of CAR_WH_PX x scale centred at `centre_px` (x, y) into `image`; its box (x, y, w, h) [px]."""
    x0, y0 = np.round(centre_px - scale * CAR_WH_PX / 2).astype(int)
    x1, y1 = np.round(centre_px + scale * CAR_WH_PX / 2).astype(int)
    image[y0:y1, x0:x1] = CAR_RGB
    panel_y = y0 + (y1 - y0) // 3
    image[panel_y:panel_y + 3, x0 + 2:x1 - 2] = PANEL_RGB
    return np.array([x0, y0, x1 - x0, y1 - y0], dtype=np.float64)



def draw_turned_car(image: np.ndarray, centre_px: np.ndarray, heading_deg: float) -> np.ndarray:
    """Draw a car of CAR_WH_PX (no panel) turned by `heading_deg` from the image's y axis, centred at `centre_px`
    (x, y), into `image` (the pixels whose centres lie on it, so that it keeps its area at any heading); its
    axis-aligned box (x, y, w, h) [px]."""
    ys, xs = np.mgrid[:image.shape[0], :image.shape[1]] + 0.5
    c, s = np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg))
    dx, dy = xs - centre_px[0], ys - centre_px[1]
    inside = (np.abs(c * dx + s * dy) <= CAR_WH_PX[0] / 2) & (np.abs(-s * dx + c * dy) <= CAR_WH_PX[1] / 2)
    image[inside] = CAR_RGB
    rows, cols = np.nonzero(inside)
    return np.array([cols.min(), rows.min(), cols.max() - cols.min() + 1, rows.max() - rows.min() + 1],
                    dtype=np.float64)


def area_side(box: BBox) -> float:
    """The square root of a box's area [px]: the size a DCF's scale tracks."""
    return float(np.sqrt(box.w_px * box.h_px))
