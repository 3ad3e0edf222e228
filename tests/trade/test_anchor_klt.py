"""Spec of the shared-call KLT refinement against first images (trade/anchor_klt.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trade.anchor_klt import refine_from_first_images, tiled, window_tiles

WINDOW_PX = 11
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03)
LK = dict(winSize=(WINDOW_PX, WINDOW_PX), maxLevel=0, criteria=CRITERIA)
BLUR_SIGMA_PX = 1.5
MAX_SHIFT_PX = 3  # whole-pixel shift of each first image against the current one


def _textures(rng: np.random.Generator, size_px: int, n_images: int) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """Blurred-noise current image and first images that are it shifted by a few whole px."""
    current = cv2.GaussianBlur((rng.random((size_px, size_px)) * 255).astype(np.uint8), (0, 0), BLUR_SIGMA_PX)
    shifts = rng.integers(-MAX_SHIFT_PX, MAX_SHIFT_PX + 1, (n_images, 2))
    return {k: np.roll(current, tuple(s), axis=(0, 1)) for k, s in enumerate(shifts.tolist())}, current


def _per_image_calls(images, keys, first_px, current, start_px):
    """The reference behaviour: one whole-image KLT call per first image."""
    refined, status = np.empty((len(keys), 2), np.float32), np.zeros(len(keys), bool)
    for key in np.unique(keys).tolist():
        rows = np.flatnonzero(keys == key)
        points, found, _ = cv2.calcOpticalFlowPyrLK(
            images[key], current, first_px[rows].astype(np.float32).reshape(-1, 1, 2),
            start_px[rows].reshape(-1, 1, 2).copy(), **LK, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        refined[rows], status[rows] = points.reshape(-1, 2), found.ravel().astype(bool)
    return refined, status


@pytest.mark.parametrize("size_px, n_points", [(128, 60), (64, 40)])  # (64, 40): more points than mosaic slots
def test_refine_from_first_images_equals_one_call_per_first_image_bit_for_bit(size_px: int, n_points: int) -> None:
    rng = np.random.default_rng(7)
    images, current = _textures(rng, size_px, n_images=6)
    keys = rng.integers(0, len(images), n_points)
    first_px = rng.integers(0, size_px, (n_points, 2)).astype(np.float64)  # includes points at the border
    start_px = (first_px + rng.normal(0.0, 1.5, (n_points, 2))).astype(np.float32)
    refined, status = refine_from_first_images(images, keys, first_px, current, start_px, LK)
    expected, expected_status = _per_image_calls(images, keys, first_px, current, start_px)
    assert not tiled(first_px, current.shape, WINDOW_PX).all()  # the border path runs too
    np.testing.assert_array_equal(status, expected_status)
    np.testing.assert_array_equal(refined, expected)


def test_tiles_inside_the_image_only_are_tiled() -> None:
    size_px, y_px = 64, 40.0
    origins, side = window_tiles(np.array([[0.0, 0.0]]), WINDOW_PX)
    reach = -int(origins[0, 0])  # px from a point to its tile's first column
    last = size_px - (side - reach)  # the last x whose tile ends at the image edge
    points = np.array([[reach, y_px], [reach - 1, y_px], [last, y_px], [last + 1, y_px]], dtype=np.float64)
    np.testing.assert_array_equal(tiled(points, (size_px, size_px), WINDOW_PX), [True, False, True, False])
