"""Box IoU: known overlaps, disjoint and touching boxes, missing (NaN/inf) and empty boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade.types import iou


def test_iou_half_overlapping_squares_is_one_third():
    assert iou((0, 0, 2, 2), (1, 0, 2, 2)) == pytest.approx(2 / 6)


def test_iou_identical_boxes_is_one_and_symmetric():
    a, b = (3.5, 1.0, 4.0, 2.0), (4.0, 1.5, 3.0, 3.0)
    assert iou(a, a) == 1.0
    assert iou(a, b) == iou(b, a)


def test_iou_contained_box_is_area_ratio():
    assert iou(np.array([0.0, 0.0, 10.0, 10.0]), [2.0, 2.0, 5.0, 5.0]) == pytest.approx(25 / 100)


@pytest.mark.parametrize("b", [(5, 0, 2, 2), (2, 0, 2, 2), (0, 2, 2, 2)])
def test_iou_disjoint_or_touching_boxes_is_zero(b):
    assert iou((0, 0, 2, 2), b) == 0.0


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_iou_missing_box_is_zero(bad):
    assert iou((bad, 0, 2, 2), (0, 0, 2, 2)) == 0.0
    assert iou((0, 0, 2, 2), (0, 0, bad, 2)) == 0.0


def test_iou_empty_boxes_is_zero():
    assert iou((0, 0, 0, 0), (0, 0, 0, 0)) == 0.0
