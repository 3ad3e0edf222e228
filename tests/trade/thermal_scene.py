"""A synthetic thermal downward view for tracker tests: a driving vehicle (a warm body with a hot engine cover at one
end) on a textured cold ground, as a grey image in three channels (a thermal camera's output)."""

from __future__ import annotations

import cv2
import numpy as np

IMAGE_PX = 128
GROUND_PX = 256  # the textured ground the camera's view is cropped from
GROUND_CELL_PX = 4  # texture cells, blurred
GROUND_LEVELS = (40, 140)  # grey levels of the cold ground's cells, drawn uniformly
VEHICLE_WH_PX = np.array([10.0, 26.0])
BODY_LEVEL = 165  # the body's grey level: warmer than the ground, far colder than the engine
ENGINE_LEVEL = 250  # the engine cover: far hotter than anything else
ENGINE_SHARE = 1.0 / 3.0  # of the vehicle's length, at its front (top)
NOISE_LEVELS = 1.5  # std of the temporal noise [grey levels] (NETD through the gain)
BLUR_PX = 0.45  # optics' Gaussian sigma [px]


def cold_ground(seed: int = 0) -> np.ndarray:
    """(GROUND_PX, GROUND_PX) float grey levels: random cells in GROUND_LEVELS, blurred."""
    cells = np.random.default_rng(seed).uniform(*GROUND_LEVELS, (GROUND_PX // GROUND_CELL_PX,) * 2)
    ground = cv2.resize(cells, (GROUND_PX, GROUND_PX), interpolation=cv2.INTER_NEAREST)
    return cv2.GaussianBlur(ground, (0, 0), 1.0)


def draw_vehicle(image: np.ndarray, centre_px: np.ndarray, body_level: float | None = BODY_LEVEL) -> np.ndarray:
    """Draw the vehicle centred at `centre_px` (x, y) into the float grey `image` (body_level None: its body is the
    ground under it, only the engine cover shows); its box (x, y, w, h) [px]."""
    x0, y0 = np.round(centre_px - VEHICLE_WH_PX / 2).astype(int)
    x1, y1 = np.round(centre_px + VEHICLE_WH_PX / 2).astype(int)
    if body_level is not None:
        image[y0:y1, x0:x1] = body_level
    image[y0:y0 + round(ENGINE_SHARE * (y1 - y0)), x0:x1] = ENGINE_LEVEL
    return np.array([x0 - 0.5, y0 - 0.5, x1 - x0, y1 - y0], dtype=np.float64)


def draw_turned_vehicle(image: np.ndarray, centre_px: np.ndarray, heading_deg: float) -> np.ndarray:
    """Draw the vehicle's body (no engine cover) turned by `heading_deg` from the image's y axis, centred at
    `centre_px` (x, y), into the float grey `image`; its axis-aligned box (x, y, w, h) [px] and pixel count."""
    corners = cv2.boxPoints(((float(centre_px[0]), float(centre_px[1])), tuple(VEHICLE_WH_PX), heading_deg))
    mask = np.zeros(image.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(corners).astype(np.int32), 1)
    image[mask > 0] = BODY_LEVEL
    ys, xs = np.nonzero(mask)
    return np.array([xs.min() - 0.5, ys.min() - 0.5, xs.max() - xs.min() + 1, ys.max() - ys.min() + 1, xs.size])


def picture(scene: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The camera's (h, w, 3) uint8 grey image of the float grey `scene`: blurred, noisy, one channel in all three."""
    grey = cv2.GaussianBlur(scene.astype(np.float32), (0, 0), BLUR_PX)
    grey += rng.normal(0.0, NOISE_LEVELS, grey.shape).astype(np.float32)
    return np.repeat(np.clip(np.round(grey), 0, 255).astype(np.uint8)[..., None], 3, axis=2)
