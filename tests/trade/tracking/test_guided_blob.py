"""The colour blob's hold on the guided tracker's DCF box: every blob taken as the target's re-centres the DCF (a
swerving car, a lagging DCF), and a blob merged with a look-alike is not the target's."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from trade.tracking.colour_box import BoxRefinement, ColourBoxRefiner
from trade.tracking.dcf import DcfConfig, DcfTracker
from trade.tracking.guided import GuidedTracker
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.types import BBox, PixelPrediction, iou

from tests.trade.car_scene import IMAGE_PX, area_side, draw_car, draw_turned_car, textured_ground


class _MergedPixelsRefiner(ColourBoxRefiner):
    """A refiner that accepts, as the target's blob, the car and a look-alike touching it on its right: `width`
    times the car's box width and `pixels` times its pixels (twice both by default), from its `clean_calls`+1-th call
    on (the car alone before: `car_area_px` is its blob's pixel count)."""

    def __init__(self, width: float = 2.0, pixels: float = 2.0, clean_calls: int = 0) -> None:
        super().__init__()
        self.width, self.pixels, self.clean_calls = width, pixels, clean_calls
        self.car_area_px = 0

    def refine(self, *args, **kwargs) -> BoxRefinement | None:
        refinement = super().refine(*args, **kwargs)
        self.clean_calls -= 1
        if refinement is None:
            return None
        self.car_area_px = refinement.area_px
        if self.clean_calls >= 0:
            return refinement
        box = refinement.box
        return replace(refinement, box=BBox(box.x_px, box.y_px, self.width * box.w_px, box.h_px),
                       area_px=round(self.pixels * refinement.area_px), accepted=True, rejection="")


MERGED_RUN_FRAMES = 5


def _merged_run(config: GuidedTrackerConfig, refiner: ColourBoxRefiner,
                scale: float = 1.0) -> tuple[DcfTracker, list[BBox], np.ndarray]:
    """The car (`draw_car`'s `scale`) standing at the image centre for MERGED_RUN_FRAMES frames under `refiner`: the DCF, the
    output boxes and the car's drawn box."""
    ground, centre_px = textured_ground()[:IMAGE_PX, :IMAGE_PX], np.full(2, IMAGE_PX / 2)
    dcf = DcfTracker(DcfConfig(estimate_scale=False))
    tracker = GuidedTracker(config, dcf=dcf, refiner=refiner)
    image = ground.copy()
    gt = draw_car(image, centre_px, scale)
    tracker.init(image, BBox.from_array(gt))
    boxes = []
    for _ in range(MERGED_RUN_FRAMES):
        image = ground.copy()
        draw_car(image, centre_px, scale)
        frame = tracker.step(image, PixelPrediction.none())
        assert frame.tracked
        boxes.append(frame.box)
    return dcf, boxes, gt


def test_a_blob_merged_with_a_look_alike_is_not_the_target_s():
    """Blobs of the car and a look-alike beside it (twice the car's pixels), which the refiner accepts: they are
    handled as refused, so the output box keeps the car's size at the DCF's location, and the DCF box stays on the
    car with its size instead of moving half-way to the look-alike and growing over both."""
    dcf, boxes, gt = _merged_run(GuidedTrackerConfig(), _MergedPixelsRefiner())
    assert all(iou(box.as_array(), gt) > 0.8 for box in boxes), boxes
    assert np.linalg.norm(dcf.box.center - BBox.from_array(gt).center) <= 1.0, dcf.box.center
    assert area_side(dcf.box) == pytest.approx(area_side(BBox.from_array(gt)))


MERGE_CAR_SCALE = 2.0


@pytest.mark.parametrize("box_area_ratio", [GuidedTrackerConfig().blob_max_box_area_ratio, np.inf])
def test_a_partial_merge_is_caught_by_its_box_area(box_area_ratio):
    """A look-alike joining the car's blob at an angle: 1.2 times its pixels (under `blob_max_pixel_ratio`, and more
    than the DCF box's area) but 1.76 times its box width, as at the partial merge on desert training world 10200.
    With `blob_max_box_area_ratio` the blob is handled as refused and the DCF stays on the car; with the bound off
    the DCF is re-centred half-way to the look-alike."""
    config = GuidedTrackerConfig(blob_max_box_area_ratio=box_area_ratio)
    refiner = _MergedPixelsRefiner(width=1.76, pixels=1.2, clean_calls=2)  # the box bound's reference: the car's blob
    dcf, boxes, gt = _merged_run(config, refiner, MERGE_CAR_SCALE)
    car = BBox.from_array(gt)
    assert config.blob_max_pixel_ratio > 1.2 and 1.2 * refiner.car_area_px > car.w_px * car.h_px
    offset_px = float(np.linalg.norm(dcf.box.center - car.center))
    assert refiner.clean_calls < 0  # the merge was seen
    if math.isfinite(box_area_ratio):
        assert offset_px <= 1.0 and all(iou(box.as_array(), gt) > 0.8 for box in boxes), (offset_px, boxes)
    else:
        assert offset_px > 0.3 * car.w_px, offset_px


class _LaggingDcf(DcfTracker):
    """A DCF whose peaks lag the target by `lag_px` (x, y) (weak peaks on a target whose looks barely stand out)."""

    def __init__(self, config: DcfConfig, lag_px: tuple[float, float]) -> None:
        super().__init__(config)
        self.lag_px = np.asarray(lag_px, dtype=np.float64)

    def response(self, *args, **kwargs):
        response = super().response(*args, **kwargs)
        return replace(response, origin_px=response.origin_px - self.lag_px)


SWERVE_DEG, SWERVE_PERIOD_FRAMES = 20.0, 20  # an evasive target's largest swerve (trade_gym.sim.evasive)


def test_a_swerving_car_s_blob_recentres_the_dcf_box():
    """A car driving 2 px per frame while its heading swings by up to SWERVE_DEG, and a DCF whose peak lags it by
    4 px: the turned car's axis-aligned blob box outgrows the DCF box by area, but its pixel count stays the car's,
    so every accepted blob moves the DCF box onto the car and the car is tracked throughout (an evasive target in
    randomised looks lost the DCF while its blob box was bigger than the DCF box: breadth-tuning, desert)."""
    ground, start_px, velocity_px = textured_ground()[:IMAGE_PX, :IMAGE_PX], np.array([50.0, 64.0]), np.array([2.0, 0.0])
    dcf = _LaggingDcf(DcfConfig(), (4.0, 0.0))
    tracker = GuidedTracker(GuidedTrackerConfig(), dcf=dcf)
    image = ground.copy()
    drawn = draw_car(image, start_px) + np.array([-1.0, -1.0, 2.0, 2.0])  # a box around the car and its rim
    tracker.init(image, BBox.from_array(drawn))
    overlaps, offsets_px, box_over_dcf = [], [], []
    for k in range(1, 21):
        image = ground.copy()
        heading_deg = SWERVE_DEG * np.sin(2.0 * np.pi * k / SWERVE_PERIOD_FRAMES)
        gt = draw_turned_car(image, start_px + k * velocity_px, heading_deg)
        dcf_area = dcf.box.w_px * dcf.box.h_px
        frame = tracker.step(image, PixelPrediction.none())
        overlaps.append(iou(frame.box.as_array(), gt) if frame.tracked else 0.0)
        offsets_px.append(float(np.linalg.norm(dcf.box.center - frame.box.center)))
        box_over_dcf.append(frame.box.w_px * frame.box.h_px / dcf_area)
    assert max(box_over_dcf) > 1.2, box_over_dcf  # the blob's box was bigger than the DCF box
    assert min(overlaps) > 0.5 and max(offsets_px) == pytest.approx(0.0, abs=1e-9), (overlaps, offsets_px)


@pytest.mark.parametrize("from_blob", [True, False])
def test_an_accepted_blob_recentres_the_dcf_box_on_the_target(from_blob):
    """A car driving 2 px per frame and a DCF whose peak lags it by 4 px: with `dcf_centre_from_blob` the DCF box
    is moved to each accepted blob's centre and learns the car there, and the car is tracked throughout; without it
    the DCF learns the ground behind the car and the box slides off it."""
    ground, start_px, velocity_px = textured_ground()[:IMAGE_PX, :IMAGE_PX], np.array([60.0, 70.0]), np.array([2.0, 0.0])
    dcf = _LaggingDcf(DcfConfig(), (4.0, 0.0))
    tracker = GuidedTracker(GuidedTrackerConfig(dcf_centre_from_blob=from_blob), dcf=dcf)
    image = ground.copy()
    tracker.init(image, BBox.from_array(draw_car(image, start_px)))
    overlaps, offsets_px = [], []
    for k in range(1, 21):
        image = ground.copy()
        gt = draw_car(image, start_px + k * velocity_px)
        frame = tracker.step(image, PixelPrediction.none())
        overlaps.append(iou(frame.box.as_array(), gt) if frame.tracked else 0.0)
        offsets_px.append(float(np.linalg.norm(dcf.box.center - frame.box.center)))
    if from_blob:
        assert min(overlaps) > 0.5 and max(offsets_px) == pytest.approx(0.0, abs=1e-9)
    else:
        assert min(overlaps) < 0.3
