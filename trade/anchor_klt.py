"""KLT refinement of point tracks against their first images, the tracks of every first image in one call.

Owns the reference mosaic: pyramid-free KLT reads its reference image only in each point's window, and where
that window sits does not change the arithmetic on the current image, so each track's window is cut from its
own first image into one tile grid (one reference for all first images) at a whole-pixel offset.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
ImageGray = npt.NDArray[np.uint8]

# KLT reads its reference at the window's pixels and one bilinear tap beyond (on the far side), and their
# Scharr gradients one px further on either side; one more px of guard on each side.
_BILINEAR_PX = 1
_GRADIENT_PX = 1
_GUARD_PX = 1


def window_tiles(points_px: FloatArray, window_px: int) -> tuple[IntArray, int]:
    """(N, 2) top-left (x, y) [px] of the reference pixels KLT reads around each point, and their square side."""
    reach = (window_px - 1) // 2 + _GRADIENT_PX + _GUARD_PX
    side = 2 * reach + 1 + _BILINEAR_PX
    return np.floor(points_px).astype(np.int64) - reach, side


def tiled(points_px: FloatArray, image_hw: tuple[int, int], window_px: int) -> BoolArray:
    """(N,) whether a point's tile lies inside the image, so that cut out it holds every pixel and gradient KLT
    reads (beyond the image edge KLT reads padding and zero gradients, which a tile would not reproduce)."""
    origins, side = window_tiles(points_px, window_px)
    limit = np.array([image_hw[1], image_hw[0]]) - side
    return np.all((origins >= 0) & (origins <= limit), axis=1)


def _mosaic(images: Mapping[int, ImageGray], image_key: IntArray, origins: IntArray, side: int,
            shape_hw: tuple[int, int]) -> tuple[ImageGray, IntArray]:
    """(H, W) reference mosaic with point k's tile at slot k (row-major grid of `side` px tiles), and the
    (N, 2) (x, y) [px] whole-pixel shift from each point's first image to the mosaic."""
    columns = shape_hw[1] // side
    slot = np.arange(len(origins))
    slot_px = side * np.stack([slot % columns, slot // columns], axis=1)
    mosaic = np.zeros(shape_hw, np.uint8)
    for key, (x0, y0), (sx, sy) in zip(image_key.tolist(), origins.tolist(), slot_px.tolist()):
        mosaic[sy : sy + side, sx : sx + side] = images[key][y0 : y0 + side, x0 : x0 + side]
    return mosaic, slot_px - origins


def refine_from_first_images(images: Mapping[int, ImageGray], image_key: IntArray, first_px: FloatArray,
                             current: ImageGray, start_px: npt.NDArray[np.float32],
                             lk_params: dict) -> tuple[npt.NDArray[np.float32], BoolArray]:
    """Pyramid-free KLT of N points from their first images to `current` (H, W), started at `start_px` (N, 2).

    images: first images (H, W) uint8 by key; image_key: (N,) key of each point's; first_px: (N, 2) (x, y)
    [px] whole pixels (corner detections); lk_params: cv2.calcOpticalFlowPyrLK keywords with a square winSize
    and maxLevel 0. Returns the refined (N, 2) pixels and the (N,) KLT status, exactly as one call per first
    image: the current image and the start coordinates are the same, the reference pixels read the same, and the
    reference coordinates move by whole pixels. Points whose tile would leave the image get that call.
    """
    window = int(lk_params["winSize"][0])
    origins, side = window_tiles(first_px, window)
    inside = tiled(first_px, current.shape, window) & np.all(first_px == np.floor(first_px), axis=1)
    refined = np.empty((len(first_px), 2), np.float32)
    status = np.zeros(len(first_px), bool)
    slots = (current.shape[0] // side) * (current.shape[1] // side)
    inner = np.flatnonzero(inside)
    for chunk in np.array_split(inner, -(-len(inner) // slots)) if len(inner) else []:
        mosaic, shift = _mosaic(images, image_key[chunk], origins[chunk], side, current.shape)
        refined[chunk], status[chunk] = _klt(mosaic, current, first_px[chunk] + shift, start_px[chunk], lk_params)
    outer = np.flatnonzero(~inside)
    for key in np.unique(image_key[outer]).tolist():
        rows = outer[image_key[outer] == key]
        refined[rows], status[rows] = _klt(images[key], current, first_px[rows], start_px[rows], lk_params)
    return refined, status


def _klt(reference: ImageGray, current: ImageGray, reference_px: FloatArray, start_px: npt.NDArray[np.float32],
         lk_params: dict) -> tuple[npt.NDArray[np.float32], BoolArray]:
    """One pyramid-free KLT call started at `start_px`: the (N, 2) refined pixels and (N,) status."""
    points, found, _ = cv2.calcOpticalFlowPyrLK(
        reference, current, reference_px.astype(np.float32).reshape(-1, 1, 2),
        np.array(start_px, np.float32).reshape(-1, 1, 2), **lk_params, flags=cv2.OPTFLOW_USE_INITIAL_FLOW
    )
    # calcOpticalFlowPyrLK returns float32 points (its stubs say only "an integer or float array")
    return cast(npt.NDArray[np.float32], points.reshape(-1, 2)), found.ravel().astype(np.bool_)
