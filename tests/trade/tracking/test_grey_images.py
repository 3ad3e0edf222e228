"""The tracker on grey images (a thermal camera's, one grey level in all three channels): the colour model turns into a
grey-level one, takes the whole warm vehicle and not its hot engine alone nor the warm rocks beside it, and the guided
tracker follows the vehicle; on a colour image nothing changes."""

from __future__ import annotations

import numpy as np
import pytest

from trade.tracking.colour_box import ColourBoxConfig, ColourBoxRefiner
from trade.tracking.guided import GuidedTracker
from trade.tracking.guided_config import GuidedTrackerConfig
from trade.tracking.pixel_bins import is_grey
from trade.types import BBox, PixelPrediction, iou

from tests.trade import car_scene
from tests.trade.thermal_scene import (
    BODY_LEVEL, ENGINE_SHARE, IMAGE_PX, VEHICLE_WH_PX, cold_ground, draw_turned_vehicle, draw_vehicle, picture,
)

START_PX = np.array([40.0, 70.0])
VELOCITY_PX = np.array([1.0, -0.75])  # per frame
N_FRAMES = 30


def _frame(ground: np.ndarray, centre_px: np.ndarray, rng: np.random.Generator,
           body_level: float | None = BODY_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """The grey image of the vehicle at `centre_px` on the ground's top-left IMAGE_PX view, and its box."""
    scene = ground[:IMAGE_PX, :IMAGE_PX].copy()
    box = draw_vehicle(scene, centre_px, body_level)
    return picture(scene, rng), box


def _drive(refiner: ColourBoxRefiner, seed: int, ground: np.ndarray | None = None) -> list[float]:
    """Init on the vehicle's box, then refine at its centre each frame (the tracker's box as the size reference);
    the refined box's IoU with the vehicle per frame (0 when refused)."""
    rng = np.random.default_rng(seed)
    ground = cold_ground(seed) if ground is None else ground
    image, gt = _frame(ground, START_PX, rng)
    refiner.init(image, BBox.from_array(gt))
    box, ious = BBox.from_array(gt), []
    for k in range(1, N_FRAMES + 1):
        image, gt = _frame(ground, START_PX + k * VELOCITY_PX, rng)
        ref = refiner.refine(image, gt[:2] + gt[2:] / 2, box, size_reference=BBox.from_array(gt))
        if ref is None or not ref.accepted:
            ious.append(0.0)
            continue
        refiner.update(image, ref)
        box = ref.box
        ious.append(iou(box.as_array(), gt))
    return ious


def test_a_grey_image_is_told_from_a_colour_one_by_its_channels():
    image, _ = _frame(cold_ground(), START_PX, np.random.default_rng(0))
    assert is_grey(image)
    image[5, 7, 2] += 1  # one channel of one pixel off
    assert not is_grey(image)


def test_init_learns_grey_levels_on_a_grey_image_and_colour_cubes_on_a_colour_one():
    cfg = ColourBoxConfig()
    grey, gt = _frame(cold_ground(), START_PX, np.random.default_rng(0))
    refiner = ColourBoxRefiner(cfg)
    refiner.init(grey, BBox.from_array(gt))
    assert refiner.grey and refiner.likelihood_lut.shape == (cfg.grey_bins,)
    colour = car_scene.textured_ground()[:IMAGE_PX, :IMAGE_PX].copy()
    car = car_scene.draw_car(colour, START_PX)
    refiner.init(colour, BBox.from_array(car))
    assert not refiner.grey and refiner.likelihood_lut.shape == (cfg.bins_per_channel,) * 3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_a_warm_vehicle_with_a_hot_engine_boxes_the_whole_vehicle(seed):
    """Its body a little warmer than the ground, its engine cover far hotter: every frame is refined to the
    whole vehicle (IoU > 0.7), not to the engine cover alone (IoU 1/3)."""
    ious = _drive(ColourBoxRefiner(), seed)
    assert min(ious) > 0.7, ious


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_the_hot_engine_alone_is_refused_against_the_trackers_box(seed):
    """A body no warmer than the ground under it leaves only the engine cover (a third of the vehicle) as a blob. At
    the engine, with a last output box of its size and the vehicle's box as the tracker's: refused as filling too
    little of the tracker's box and spanning too little of it; accepted without the fill test."""
    rng = np.random.default_rng(seed)
    image, gt = _frame(cold_ground(seed), START_PX, rng, body_level=None)
    engine_box = BBox(gt[0], gt[1], gt[2], ENGINE_SHARE * gt[3])  # the last output box, as if sized on the engine
    verdicts = []
    for min_fill in (ColourBoxConfig().grey_min_blob_fill_ratio, 0.0):
        refiner = ColourBoxRefiner(ColourBoxConfig(grey_min_blob_fill_ratio=min_fill))
        refiner.init(image, BBox.from_array(gt))
        verdicts.append(refiner.refine(image, engine_box.center, engine_box, size_reference=BBox.from_array(gt)))
    with_test, without = verdicts
    assert with_test is not None and with_test.rejection.startswith("grey blob fills"), with_test
    assert without is not None and without.accepted and without.area_px < 0.45 * VEHICLE_WH_PX.prod()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_a_vehicle_turned_45_degrees_is_accepted_by_its_span_of_the_trackers_box(seed):
    """The vehicle turned 45 deg fills about 0.4 of its axis-aligned box, which the tracker's box follows: its blob
    fills less than grey_min_blob_fill_ratio of the tracker's box but spans it, and is accepted; refused when the span
    asked for is more than the whole box."""
    rng = np.random.default_rng(seed)
    scene = cold_ground(seed)[:IMAGE_PX, :IMAGE_PX].copy()
    *turned, vehicle_px = draw_turned_vehicle(scene, START_PX, 45.0)
    image, turned_box = picture(scene, rng), BBox(*turned)
    assert vehicle_px / (turned_box.w_px * turned_box.h_px) < ColourBoxConfig().grey_min_blob_fill_ratio
    verdicts = []
    for span in (ColourBoxConfig().grey_min_blob_span_ratio, ColourBoxConfig().max_area_ratio):
        refiner = ColourBoxRefiner(ColourBoxConfig(grey_min_blob_span_ratio=span))
        refiner.init(image, turned_box)
        verdicts.append(refiner.refine(image, START_PX, turned_box, size_reference=turned_box))
    spanning, too_wide_a_span = verdicts
    assert spanning is not None and spanning.accepted, spanning
    assert iou(spanning.box.as_array(), turned_box.as_array()) > 0.7
    assert too_wide_a_span is not None and too_wide_a_span.rejection.startswith("grey blob fills"), too_wide_a_span


def test_refine_a_grey_blob_is_sized_against_the_smaller_of_the_output_box_and_the_trackers_box():
    """Grey: the vehicle's blob is accepted though the last output box had grown to 3.5 times it (the tracker's box is
    the vehicle's); a blob merged with a warm strip beside it, 3 times the vehicle, is refused though it is within
    max_area_ratio of that output box, and refused against the vehicle's output box though within it of a tracker's
    box grown to 1.4 times the vehicle."""
    rng = np.random.default_rng(4)
    scene = cold_ground(4)[:IMAGE_PX, :IMAGE_PX].copy()
    gt = BBox.from_array(draw_vehicle(scene, START_PX))

    def grown(factor: float) -> BBox:
        return BBox.from_center(*gt.center, factor**0.5 * gt.w_px, factor**0.5 * gt.h_px)

    refiner = ColourBoxRefiner()
    refiner.init(picture(scene, rng), gt)
    ref = refiner.refine(picture(scene, rng), gt.center, grown(3.5), size_reference=gt)
    assert ref is not None and ref.accepted and iou(ref.box.as_array(), gt.as_array()) > 0.8, ref
    x0, y0 = round(gt.x_px + gt.w_px + 0.5), round(gt.y_px + 0.5)
    scene[y0 : y0 + 4, x0 : x0 + 24] = BODY_LEVEL  # a warm strip off the vehicle's side (a sunlit wall)
    merged = picture(scene, rng)
    for previous, tracker in ((grown(3.5), gt), (gt, grown(1.4))):
        ref = refiner.refine(merged, gt.center, previous, size_reference=tracker)
        assert ref is not None and ref.rejection.startswith("area ratio") and ref.box.w_px > 2 * gt.w_px, ref


ROCK_OFFSET_LEVELS = (7.0, 10.0)  # warm rocks' grey levels off the body's, either way


def _rocky_ground(seed: int) -> np.ndarray:
    """The cold ground with warm rocks at grey levels a few levels off the body's (in its 16-level colour bin, not in
    its own grey bins) scattered all around the vehicle's path."""
    ground = cold_ground(seed)
    rng = np.random.default_rng(seed + 100)
    ys, xs = np.mgrid[:ground.shape[0], :ground.shape[1]]
    for _ in range(60):
        cx, cy = rng.uniform(0, IMAGE_PX, 2)
        level = BODY_LEVEL + rng.choice([-1, 1]) * rng.uniform(*ROCK_OFFSET_LEVELS)
        ground[(xs - cx) ** 2 + (ys - cy) ** 2 <= rng.uniform(3.0, 5.0) ** 2] = level
    return ground


def test_refine_among_warm_rocks_keeps_the_vehicles_box_better_than_16_level_bins():
    """Rocks a few grey levels off the body touch it on its way (4 drives of 30 frames, pooled): the grey-level model
    keeps the vehicle's box (mean IoU > 0.7, over 0.5 in 90 % of the frames); with 16 levels a bin, as a colour cube's
    side, the blob takes rocks in (mean IoU lower by more than 0.15)."""
    fine, coarse = [], []
    for seed in range(4):
        ground = _rocky_ground(seed)
        fine += _drive(ColourBoxRefiner(), seed, ground)
        coarse += _drive(ColourBoxRefiner(ColourBoxConfig(grey_bins=16, grey_histogram_blur_passes=1)), seed, ground)
    assert np.mean(fine) > 0.7 and np.mean(np.array(fine) > 0.5) >= 0.9, fine
    assert np.mean(coarse) < np.mean(fine) - 0.15, (np.mean(coarse), np.mean(fine))


@pytest.mark.parametrize("snap", [False, True])
def test_guided_tracker_follows_a_warm_vehicle_over_cold_textured_ground(snap):
    """40 frames driving diagonally, guided by a prediction at the vehicle (2 px sigma): tracked in every frame with
    IoU > 0.6, from the exact box or from one 4 px off snapped to the vehicle."""
    rng = np.random.default_rng(3)
    ground = cold_ground(3)
    tracker = GuidedTracker(GuidedTrackerConfig(snap_init_box=snap))
    image, gt = _frame(ground, START_PX, rng)
    start = tracker.init(image, BBox.from_array(gt + (np.array([4.0, -3.0, 0.0, 0.0]) if snap else 0.0)))
    assert iou(start.as_array(), gt) > 0.8
    for k in range(1, 41):
        image, gt = _frame(ground, START_PX + k * VELOCITY_PX, rng)
        prediction = PixelPrediction(gt[:2] + gt[2:] / 2, 4.0 * np.eye(2), 15.0, 0.5)
        frame = tracker.step(image, prediction)
        assert frame.tracked and iou(frame.box.as_array(), gt) > 0.6, (k, frame.box, gt)


# The colour refiner on car_scene's red car driving over its textured ground (seed 0), refined at the car's centre each
# frame: the accepted boxes (x, y, w, h) and contrasts of frames 1-6, then the likelihood of the car's colour bin and the
# separation of the last box, as the refiner gave them before the grey path (08fca38).
COLOUR_REFERENCE_BOXES = [
    (35.5, 32.5, 10.0, 16.0), (37.5, 33.5, 10.0, 16.0), (39.5, 34.5, 10.0, 16.0),
    (40.5, 35.5, 10.0, 16.0), (41.5, 36.5, 10.0, 16.0), (43.5, 37.5, 10.0, 16.0),
]
COLOUR_REFERENCE_CONTRASTS = [0.9755991285403051, 0.9765295933188091, 0.9768927015250545, 0.9765840595497458,
                              0.9750317719680465, 0.9738471314451707]
COLOUR_REFERENCE_CAR_LIKELIHOOD = 0.9956468939781189  # bin (12, 1, 1): car_scene.CAR_RGB * 16 // 256
COLOUR_REFERENCE_SEPARATION = 0.8388643264770508


def test_colour_refinement_is_the_same_as_before_the_grey_path():
    ground = car_scene.textured_ground(0)[:IMAGE_PX, :IMAGE_PX]
    start, velocity = np.array([40.0, 40.0]), np.array([1.5, 1.0])
    image = ground.copy()
    refiner = ColourBoxRefiner()
    box = BBox.from_array(car_scene.draw_car(image, start))
    refiner.init(image, box)
    boxes, contrasts = [], []
    for k in range(1, 7):
        image = ground.copy()
        gt = car_scene.draw_car(image, start + k * velocity)
        ref = refiner.refine(image, gt[:2] + gt[2:] / 2, box, size_reference=BBox.from_array(gt))
        assert ref is not None and ref.accepted, ref
        refiner.update(image, ref)
        box = ref.box
        boxes.append(tuple(float(v) for v in box.as_array()))
        contrasts.append(ref.contrast)
    assert not refiner.grey and boxes == COLOUR_REFERENCE_BOXES
    np.testing.assert_allclose(contrasts, COLOUR_REFERENCE_CONTRASTS, rtol=1e-6)
    np.testing.assert_allclose(refiner.likelihood_lut[12, 1, 1], COLOUR_REFERENCE_CAR_LIKELIHOOD, rtol=1e-6)
    np.testing.assert_allclose(refiner.separation(image, box), COLOUR_REFERENCE_SEPARATION, rtol=1e-6)
