"""Tests of the colour-model box refinement: rotation, growth, distractors and low-contrast rejection."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trade.tracking.colour_box import ColourBoxConfig, ColourBoxRefiner
from trade.types import BBox, iou

IMAGE_SIDE_PX = 256
CAR_WH_PX = (10.0, 26.0)
SAND_RGB = np.array([194.0, 178.0, 128.0])
RED_RGB = np.array([200.0, 35.0, 30.0])
N_FRAMES = 30
CENTRE_NOISE_PX = 2.0
OPTICS_BLUR_PX = 0.7  # Gaussian sigma of the camera's point spread
SENSOR_NOISE = 4.0  # std of per-pixel noise [8-bit levels]


def _smooth_noise(rng: np.random.Generator, sigma_px: float, channels: int) -> np.ndarray:
    """(256, 256, channels) float32 Gaussian-blurred noise with unit standard deviation."""
    noise = rng.normal(size=(IMAGE_SIDE_PX, IMAGE_SIDE_PX, channels)).astype(np.float32)
    blurred = cv2.GaussianBlur(noise, (0, 0), sigma_px).reshape(IMAGE_SIDE_PX, IMAGE_SIDE_PX, channels)
    return blurred / blurred.std()


def _sand(rng: np.random.Generator, shade_std: float = 18.0) -> np.ndarray:
    """Textured sand: base colour, brightness blotches, per-channel grain; (256, 256, 3) float."""
    shade = shade_std * _smooth_noise(rng, 3.0, 1)
    grain = 10.0 * _smooth_noise(rng, 0.7, 3)
    return SAND_RGB + shade + grain


def _car_paint(rng: np.random.Generator, base_rgb: np.ndarray) -> np.ndarray:
    """Car paint with darker texture (windows, shadows): base times a blotchy factor in [0.55, 1]."""
    factor = np.clip(0.85 + 0.2 * _smooth_noise(rng, 1.5, 1), 0.55, 1.0)
    return base_rgb * factor + 6.0 * _smooth_noise(rng, 0.5, 3)


def _car_polygon(center_xy: np.ndarray, wh_px: tuple[float, float], angle_deg: float) -> np.ndarray:
    """(4, 2) corners of the rotated rectangle, for cv2.fillPoly (fixed point, 4 fractional bits)."""
    points = cv2.boxPoints(((float(center_xy[0]), float(center_xy[1])), wh_px, angle_deg))
    return np.round(points * 16).astype(np.int32)


def _car_mask(center_xy: np.ndarray, wh_px: tuple[float, float], angle_deg: float) -> np.ndarray:
    """(256, 256) uint8 mask, 1 on the pixels of the rotated rectangle."""
    mask = np.zeros((IMAGE_SIDE_PX, IMAGE_SIDE_PX), dtype=np.uint8)
    cv2.fillPoly(mask, [_car_polygon(center_xy, wh_px, angle_deg)], 1, shift=4)
    return mask


def _draw(
    rng: np.random.Generator,
    background: np.ndarray,
    paint: np.ndarray,
    cars: list[tuple[np.ndarray, tuple[float, float], float]],
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Paint the cars onto the background and take a blurred, noisy picture of it.

    Returns the uint8 image and each car's tight box (x, y, w, h) of its painted pixels.
    """
    image = background.copy()
    boxes = []
    for center, wh, angle in cars:
        mask = _car_mask(center, wh, angle)
        image[mask > 0] = paint[mask > 0]
        ys, xs = np.nonzero(mask)
        boxes.append(np.array([xs.min() - 0.5, ys.min() - 0.5, xs.max() - xs.min() + 1.0, ys.max() - ys.min() + 1.0]))
    picture = cv2.GaussianBlur(image.astype(np.float32), (0, 0), OPTICS_BLUR_PX)
    picture += rng.normal(0.0, SENSOR_NOISE, size=picture.shape).astype(np.float32)
    return np.clip(picture, 0, 255).astype(np.uint8), boxes


def _follow(
    refiner: ColourBoxRefiner,
    rng: np.random.Generator,
    frames: list[tuple[np.ndarray, np.ndarray]],
    centre_xy: np.ndarray,
    box: BBox,
) -> tuple[list[float], BBox]:
    """Feed the true centre plus noise as the tracker centre; the accepted box becomes the previous box.

    Returns the IoU with the tight box per frame and the last box."""
    ious = []
    for image, gt in frames:
        noisy = centre_xy + rng.uniform(-CENTRE_NOISE_PX, CENTRE_NOISE_PX, size=2)
        ref = refiner.refine(image, noisy, box)
        assert ref is not None and ref.accepted, f"rejected: {None if ref is None else ref.rejection}"
        refiner.update(image, ref)
        box = ref.box
        ious.append(iou(box.as_array(), gt))
    return ious, box


def _initialised(seed: int, centre_xy: np.ndarray) -> tuple[ColourBoxRefiner, np.ndarray, np.ndarray, BBox]:
    """Refiner trained on an upright car at `centre_xy`; returns it with the sand, paint and GT box."""
    rng = np.random.default_rng(seed)
    sand, paint = _sand(rng), _car_paint(rng, RED_RGB)
    image, (gt,) = _draw(rng, sand, paint, [(centre_xy, CAR_WH_PX, 0.0)])
    refiner = ColourBoxRefiner()
    box = BBox.from_array(gt)
    refiner.init(image, box)
    return refiner, sand, paint, box


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_car_rotating_90_degrees_in_place_box_follows_tight_box(seed: int) -> None:
    centre = np.array([128.3, 121.7])
    refiner, sand, paint, box = _initialised(seed, centre)
    rng = np.random.default_rng(100 + seed)
    frames = [_draw(rng, sand, paint, [(centre, CAR_WH_PX, 90.0 * k / N_FRAMES)]) for k in range(1, N_FRAMES + 1)]
    ious, last = _follow(refiner, rng, [(image, gts[0]) for image, gts in frames], centre, box)
    assert min(ious) >= 0.7, np.round(ious, 2)
    assert box.h_px > 2 * box.w_px and last.w_px > 2 * last.h_px  # the aspect ratio flipped


@pytest.mark.parametrize("seed", [3, 4])
def test_refine_car_growing_1_8x_box_follows_tight_box(seed: int) -> None:
    centre = np.array([120.6, 131.2])
    refiner, sand, paint, box = _initialised(seed, centre)
    rng = np.random.default_rng(200 + seed)
    growth = 1.8 ** (np.arange(1, N_FRAMES + 1) / N_FRAMES)
    frames = [_draw(rng, sand, paint, [(centre, (CAR_WH_PX[0] * g, CAR_WH_PX[1] * g), 0.0)]) for g in growth]
    ious, last = _follow(refiner, rng, [(image, gts[0]) for image, gts in frames], centre, box)
    assert min(ious) >= 0.7, np.round(ious, 2)
    assert last.w_px * last.h_px > 2.5 * box.w_px * box.h_px  # 1.8^2 = 3.24 x the area


@pytest.mark.parametrize("angle_deg", [0.0, 30.0])
def test_refine_identical_car_6px_away_not_merged_target_blob_wins(angle_deg: float) -> None:
    centre = np.array([110.4, 126.9])
    refiner, sand, paint, box = _initialised(5, centre)
    rng = np.random.default_rng(5)
    # the second car is parallel to the target, its side 6 px from the target's side
    side_dir = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))])
    other = centre + (CAR_WH_PX[0] + 6.0) * side_dir
    for _ in range(5):
        image, (gt, gt_other) = _draw(rng, sand, paint, [(centre, CAR_WH_PX, angle_deg), (other, CAR_WH_PX, angle_deg)])
        ref = refiner.refine(image, centre + rng.uniform(-CENTRE_NOISE_PX, CENTRE_NOISE_PX, size=2), box)
        assert ref is not None and ref.accepted, None if ref is None else ref.rejection
        assert iou(ref.box.as_array(), gt) >= 0.7
        # the distractor lies in the search window and has the target's colour, yet stays outside the blob
        x0, y0 = ref.window_origin_px
        other_px = np.round(other).astype(int) - [x0, y0]
        assert 0 <= other_px[0] < ref.mask.shape[1] and 0 <= other_px[1] < ref.mask.shape[0]
        assert refiner.likelihood_map(image)[round(other[1]), round(other[0])] > 0.9
        x1, y1 = x0 + ref.mask.shape[1], y0 + ref.mask.shape[0]
        assert not np.any(ref.mask & (_car_mask(other, CAR_WH_PX, angle_deg)[y0:y1, x0:x1] > 0))
        assert iou(ref.box.as_array(), gt_other) <= iou(gt, gt_other) + 0.05


@pytest.mark.parametrize("gap_px", [1.0, 2.0])
def test_refine_identical_car_touching_merged_blob_rejected_against_tracker_box(gap_px: float) -> None:
    """Two identical cars side by side with a 1-2 px gap merge into one blob (closing bridges the gap);
    checked against the tracker's box, that blob fills twice the box and is rejected, while the blob of
    a lone car (any turn) passes."""
    centre = np.array([110.4, 126.9])
    refiner, sand, paint, box = _initialised(7, centre)
    rng = np.random.default_rng(7)
    other = centre + np.array([CAR_WH_PX[0] + gap_px, 0.0])
    image, _ = _draw(rng, sand, paint, [(centre, CAR_WH_PX, 0.0), (other, CAR_WH_PX, 0.0)])
    merged = refiner.refine(image, centre, box, size_reference=box)
    assert merged is not None and not merged.accepted and "fills" in merged.rejection
    for angle_deg in (0.0, 45.0, 90.0):
        lone, _ = _draw(rng, sand, paint, [(centre, CAR_WH_PX, angle_deg)])
        ref = refiner.refine(lone, centre, box, size_reference=box)
        assert ref is not None and ref.accepted, ref.rejection


def test_refine_car_touching_big_red_blob_rejected_and_model_kept() -> None:
    centre = np.array([110.4, 126.9])
    refiner, sand, paint, box = _initialised(6, centre)
    rng = np.random.default_rng(6)
    blob_side_px = 40.0
    blob_centre = centre + [CAR_WH_PX[0] / 2 + blob_side_px / 2, 0.0]  # shares the car's right side
    image, _ = _draw(rng, sand, paint, [(centre, CAR_WH_PX, 0.0), (blob_centre, (blob_side_px, blob_side_px), 0.0)])
    lut_before = refiner.likelihood_lut.copy()
    ref = refiner.refine(image, centre, box)
    assert ref is not None and not ref.accepted
    assert ref.box.w_px * ref.box.h_px > 2.5 * box.w_px * box.h_px  # the merged blob, not the car
    assert not refiner.update(image, ref)
    assert np.array_equal(refiner.likelihood_lut, lut_before)


def test_refine_centre_off_the_car_snaps_to_it_within_gap_else_none() -> None:
    centre = np.array([128.0, 128.0])
    refiner, sand, paint, box = _initialised(7, centre)
    image, (gt,) = _draw(np.random.default_rng(7), sand, paint, [(centre, CAR_WH_PX, 0.0)])
    beside = centre + [CAR_WH_PX[0] / 2 + 2.0, 0.0]  # 2 px right of the car's side
    ref = refiner.refine(image, beside, box)
    assert ref is not None and ref.accepted and iou(ref.box.as_array(), gt) >= 0.7
    far = centre + [CAR_WH_PX[0] / 2 + 3.0 * refiner.config.max_centre_gap_px, 0.0]
    assert refiner.refine(image, far, box) is None


@pytest.mark.parametrize("seed", [10, 11, 12, 13])
def test_refine_target_coloured_like_background_rejected(seed: int) -> None:
    centre = np.array([128.3, 121.7])
    rng = np.random.default_rng(seed)
    sand = _sand(rng)
    paint = _sand(rng)  # same colour statistics as the ground
    image, (gt,) = _draw(rng, sand, paint, [(centre, CAR_WH_PX, 0.0)])
    box = BBox.from_array(gt)
    default = ColourBoxRefiner()
    # only the contrast test left: it alone must reject
    contrast_only = ColourBoxRefiner(ColourBoxConfig(min_area_ratio=1e-3, max_area_ratio=1e3, max_border_sides=4))
    for refiner in (default, contrast_only):
        refiner.init(image, box)
    for k in range(5):
        frame, _ = _draw(rng, sand, paint, [(centre, CAR_WH_PX, 10.0 * k)])
        noisy = centre + rng.uniform(-CENTRE_NOISE_PX, CENTRE_NOISE_PX, size=2)
        for refiner in (default, contrast_only):
            ref = refiner.refine(frame, noisy, box)
            assert ref is None or not ref.accepted
        ref = contrast_only.refine(frame, noisy, box)
        assert ref is None or ref.rejection.startswith("contrast")


def test_likelihood_map_car_pixels_high_sand_low() -> None:
    centre = np.array([128.0, 128.0])
    refiner, sand, paint, _ = _initialised(8, centre)
    image, _ = _draw(np.random.default_rng(8), sand, paint, [(centre, CAR_WH_PX, 45.0)])
    mask = _car_mask(centre, (CAR_WH_PX[0] - 2, CAR_WH_PX[1] - 2), 45.0)  # inside the blurred rim
    like = refiner.likelihood_map(image)
    assert like.shape == image.shape[:2] and like.min() >= 0.0 and like.max() <= 1.0
    assert np.median(like[mask > 0]) > 0.9
    far_from_car = np.ones_like(mask)
    far_from_car[96:160, 96:160] = 0
    assert np.mean(like[far_from_car > 0] > 0.5) < 0.01


def test_refine_car_cut_by_image_border_accepted_box_of_visible_part() -> None:
    centre = np.array([128.0, 128.0])
    refiner, sand, paint, box = _initialised(9, centre)
    at_border = np.array([3.0, 128.0])  # 3 of its 10 px width are outside the image
    image, (gt,) = _draw(np.random.default_rng(9), sand, paint, [(at_border, CAR_WH_PX, 0.0)])
    ref = refiner.refine(image, at_border + [1.0, 0.0], box)
    assert ref is not None and ref.accepted, None if ref is None else ref.rejection
    assert ref.box.x_px == -0.5 and iou(ref.box.as_array(), gt) >= 0.7


def test_refine_before_init_raises() -> None:
    with pytest.raises(RuntimeError, match="init"):
        ColourBoxRefiner().refine(np.zeros((32, 32, 3), np.uint8), (16.0, 16.0), BBox(10, 10, 5, 5))


@pytest.mark.parametrize(
    ("field", "value"),
    [("bins_per_channel", 1), ("surround_factor", 1.0), ("min_threshold", 0.0), ("learning_rate", 1.5),
     ("max_area_ratio", 0.5), ("prior_density", 0.0), ("box_rim_px", -1), ("grey_min_blob_span_ratio", -0.1),
     ("grey_min_blob_fill_ratio", 2.0)],
)
def test_config_invalid_field_raises_naming_it(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        ColourBoxConfig(**{field: value})


@pytest.mark.parametrize("seed", [0, 1])
def test_separation_highest_for_the_box_on_the_car(seed: int) -> None:
    """A box on the car separates its colours from the surround better than the same box shifted by
    2-5 px along either axis (half the car's width is 5 px), and the model in use is left untouched."""
    rng = np.random.default_rng(seed)
    image, (gt,) = _draw(rng, _sand(rng), _car_paint(rng, RED_RGB), [(np.array([128.3, 121.7]), CAR_WH_PX, 0.0)])
    refiner = ColourBoxRefiner()
    on_car = BBox.from_array(gt)
    refiner.init(image, BBox(10.0, 10.0, 10.0, 26.0))  # a model learnt elsewhere must not change
    lut = refiner.likelihood_lut.copy()
    on = refiner.separation(image, on_car)
    shifted = [refiner.separation(image, BBox(on_car.x_px + dx, on_car.y_px + dy, on_car.w_px, on_car.h_px))
               for dx, dy in ((2, 0), (-3, 0), (5, 0), (0, 4), (-4, -3), (3, 5))]
    assert on > max(shifted), (on, shifted)
    assert np.array_equal(refiner.likelihood_lut, lut)


ASPHALT_RGB = np.array([105.0, 105.0, 110.0])
WHITE_RGB = np.array([225.0, 225.0, 220.0])


def _with_road_markings(image: np.ndarray, lines: list[tuple[int, int, int, int]]) -> np.ndarray:
    """The image with 1 px wide marking-white lines (x0, y0, x1, y1) drawn on it (inclusive ends)."""
    marked = image.copy()
    for x0, y0, x1, y1 in lines:
        marked[y0 : y1 + 1, x0 : x1 + 1] = WHITE_RGB.astype(np.uint8)
    return marked


def _sides(xywh: np.ndarray) -> np.ndarray:
    """(left, top, right, bottom) [px] of an (x, y, w, h) box."""
    return np.r_[xywh[:2], xywh[:2] + xywh[2:]]


@pytest.mark.parametrize("seed", [20, 21, 22])
def test_refine_white_truck_among_road_markings_box_of_the_truck_not_the_lines(seed: int) -> None:
    """A white truck seen from above on a road with white 1 px markings: dashes ending on or 1-2 px from
    its sides (closing bridges those gaps) and one more dash on the far end of a bridged one. The blob's
    box is the truck's, each side within the opening's radius (the opening drops the lines, its core grown
    back keeps a stub that long); without the opening the box spans the dashes."""
    rng = np.random.default_rng(seed)
    asphalt = ASPHALT_RGB + 8.0 * _smooth_noise(rng, 3.0, 1) + 4.0 * _smooth_noise(rng, 0.7, 3)
    paint = WHITE_RGB + 4.0 * _smooth_noise(rng, 0.5, 3)
    centre = np.array([120.0, 128.0])
    clean, (gt,) = _draw(rng, asphalt, paint, [(centre, CAR_WH_PX, 0.0)])
    box = BBox.from_array(gt)
    left, right, top = int(gt[0] + 0.5), int(gt[0] + gt[2] - 0.5), int(gt[1] + 0.5)
    lines = [
        (left - 9, top + 20, left - 2, top + 20),  # dash ending 1 px left of the truck
        (left - 10, top + 6, left - 10, top + 20),  # joins the first dash's far end
        (right + 3, top + 4, right + 9, top + 4),  # dash ending 2 px right of it
        (left + 4, top - 6, left + 4, top - 1),  # dash touching its front
    ]
    image = _with_road_markings(clean, lines)
    for opening_radius_px in (1, 0):
        refiner = ColourBoxRefiner(ColourBoxConfig(opening_radius_px=opening_radius_px))
        refiner.init(clean, box)
        ref = refiner.refine(image, centre, box, size_reference=box)
        assert ref is not None
        if opening_radius_px:  # the core grown back by the radius keeps at most that much of a line
            assert ref.accepted, ref.rejection
            assert np.all(np.abs(_sides(ref.box.as_array()) - _sides(gt)) <= opening_radius_px), (ref.box, gt)
        else:  # (refused here by the area ratio; a box grown over a few frames passes it)
            assert ref.box.w_px >= gt[2] + 15 and ref.box.h_px >= gt[3] + 5, (ref.box, gt)


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 45.0, 70.0])
def test_refine_lone_car_box_the_same_with_and_without_the_opening(angle_deg: float) -> None:
    """Cutting lines off the blob leaves a lone car's box as it was, at any turn: the opening trims its
    rim and corners, and growing the core back by the radius within the blob restores them."""
    rng = np.random.default_rng(23)
    sand, paint = _sand(rng), _car_paint(rng, RED_RGB)
    centre = np.array([127.6, 130.2])
    image, (gt,) = _draw(rng, sand, paint, [(centre, CAR_WH_PX, angle_deg)])
    boxes = []
    for opening_radius_px in (1, 0):
        refiner = ColourBoxRefiner(ColourBoxConfig(opening_radius_px=opening_radius_px))
        refiner.init(image, BBox.from_array(gt))
        ref = refiner.refine(image, centre, BBox.from_array(gt))
        assert ref is not None and ref.accepted, None if ref is None else ref.rejection
        boxes.append(ref.box.as_array())
    assert np.array_equal(boxes[0], boxes[1]), boxes
