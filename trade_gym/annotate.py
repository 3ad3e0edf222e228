"""Draws ground truth and estimates onto a camera frame for `render()` and videos.

Green: ground-truth box; red: estimated box; extra overlays (trajectory, features, inliers)
come from the perception mode when it has them. A thermal camera's grey image is shown in false colour first
(`display_image`): only here, never in what perception or `env.camera_frame` receive.
"""

from __future__ import annotations

from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import PerceptionOutput

GT_COLOUR_RGB = (0, 255, 0)
EST_COLOUR_RGB = (255, 0, 0)
BOX_THICKNESS_PX = 1
# False colour of thermal images: dark (cold) through purple and orange to pale yellow (hot), like thermal cameras'
# "ironbow" palette (OpenCV's inferno map, perceptually uniform)
THERMAL_PALETTE = cv2.COLORMAP_INFERNO


class Overlay(Protocol):
    def draw(self, image_rgb: npt.NDArray[np.uint8]) -> None: ...


def draw_box(image_rgb: npt.NDArray[np.uint8], box: npt.NDArray[np.float64], colour: tuple[int, int, int]) -> None:
    """Draw an (x, y, w, h) box in place; nothing when it is missing (NaN)."""
    if not np.all(np.isfinite(box)):
        return
    x0, y0 = int(round(box[0] + 0.5)), int(round(box[1] + 0.5))
    x1, y1 = int(round(box[0] + box[2] - 0.5)), int(round(box[1] + box[3] - 0.5))
    cv2.rectangle(image_rgb, (x0, y0), (x1, y1), colour, BOX_THICKNESS_PX)


def display_image(image_rgb: npt.NDArray[np.uint8], modality: str) -> npt.NDArray[np.uint8]:
    """The (H, W, 3) camera image as shown: itself for "rgb"; for "thermal" (grey in all three channels) its grey level
    through THERMAL_PALETTE."""
    if modality != "thermal":
        return image_rgb
    bgr = cv2.applyColorMap(np.ascontiguousarray(image_rgb[:, :, 0]), THERMAL_PALETTE)
    return np.ascontiguousarray(bgr[:, :, ::-1])


def annotate_frame(
    rgb: npt.NDArray[np.uint8] | None,
    truth: GroundTruth | None,
    estimate: PerceptionOutput | None,
    overlay: Overlay | None = None,
) -> npt.NDArray[np.uint8]:
    """A copy of `rgb` with the overlays drawn."""
    if rgb is None:
        raise RuntimeError("no camera frame to annotate (was the frame rendered?)")
    image = np.ascontiguousarray(rgb.copy())
    if overlay is not None:
        overlay.draw(image)
    if truth is not None:
        draw_box(image, truth.target_bbox, GT_COLOUR_RGB)
    if estimate is not None:
        draw_box(image, estimate.bbox, EST_COLOUR_RGB)
    return image
