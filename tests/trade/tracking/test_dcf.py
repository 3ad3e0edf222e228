"""Tests of the correlation filter tracker: features, window sampling, translation and scale tracking."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trade.tracking import (
    DcfConfig,
    DcfTracker,
    FeatureConfig,
    PeakConfig,
    extract_features,
    highest_peak,
    sample_windows,
    select_peak,
)
from trade.tracking.scale import ScaleConfig, ScaleFilter
from trade.types import BBox, iou

IMAGE_SIDE_PX = 256


def _texture(rng: np.random.Generator, height: int, width: int, blur_sigma_px: float, std: float) -> np.ndarray:
    """Smoothed Gaussian noise, uint8 RGB, grey level 128 +- std."""
    noise = cv2.GaussianBlur(rng.normal(size=(height, width, 3)).astype(np.float32), (0, 0), blur_sigma_px)
    return np.clip(noise / noise.std() * std + 128.0, 0, 255).astype(np.uint8)


def _scene(seed: int, target_side_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Background (256, 256, 3) and a higher-contrast target texture, both uint8 RGB."""
    rng = np.random.default_rng(seed)
    background = _texture(rng, IMAGE_SIDE_PX, IMAGE_SIDE_PX, blur_sigma_px=2.0, std=40.0)
    target = _texture(rng, target_side_px, target_side_px, blur_sigma_px=1.5, std=60.0)
    return background, target


def _paste(background: np.ndarray, patch: np.ndarray, x0: int, y0: int) -> tuple[np.ndarray, BBox]:
    image = background.copy()
    image[y0 : y0 + patch.shape[0], x0 : x0 + patch.shape[1]] = patch
    return image, BBox(float(x0), float(y0), float(patch.shape[1]), float(patch.shape[0]))


def _track_step(tracker: DcfTracker, image: np.ndarray) -> BBox:
    """The "dcf" baseline: search window on the last box, highest peak wins, always update."""
    resp = tracker.response(image, tracker.box.center)
    tracker.commit(highest_peak(resp).location_px, resp.scale)
    tracker.update(image)
    return tracker.box


def test_extract_features_vertical_edge_fills_orientation_bin_zero() -> None:
    config = FeatureConfig()
    patch = np.zeros((32, 32, 3), dtype=np.uint8)
    patch[:, 16:] = 255  # horizontal gradient: orientation 0
    features = extract_features(patch, config)
    assert features.shape == (8, 8, config.n_channels) and features.dtype == np.float32
    edge_cells = features[:, 3, : config.n_orientation_bins]  # column 15 lies in cell 3
    assert np.all(edge_cells[:, 0] > 0)
    assert np.allclose(edge_cells[:, 1:], 0.0)
    assert np.allclose(features[:, 0, : config.n_orientation_bins], 0.0)  # flat cells carry no gradient


def test_extract_features_batch_matches_single_patches() -> None:
    rng = np.random.default_rng(0)
    patches = rng.integers(0, 256, size=(5, 24, 16, 3), dtype=np.uint8)
    config = FeatureConfig()
    batch = extract_features(patches, config)
    assert batch.shape == (5, 6, 4, config.n_channels)
    for i in range(5):
        np.testing.assert_allclose(batch[i], extract_features(patches[i], config), atol=1e-6)


def test_sample_windows_unit_scale_copies_pixels_and_replicates_border() -> None:
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, size=(64, 80, 3), dtype=np.uint8)
    # pixel centres at integers: a 16 px window centred at 27.5 spans columns 20..35
    same = sample_windows(image, np.array([27.5, 40.5]), np.array([[16.0, 16.0]]), (16, 16))
    np.testing.assert_array_equal(same[0], image[33:49, 20:36])
    outside = sample_windows(image, np.array([-100.0, 200.0]), np.array([[20.0, 20.0], [90.0, 90.0]]), (8, 8))
    assert outside.shape == (2, 8, 8, 3)
    assert np.all(outside == image[-1, 0])  # beyond the bottom-left corner: the corner pixel


def test_sample_windows_of_several_sizes_follow_the_template_geometry_on_a_ramp() -> None:
    # I(x, y) = x on a 256 px ramp: template pixel (u, v) of window (w, h) must read x = c + (u - (out - 1) / 2) w / out
    ramp = np.broadcast_to(np.arange(256, dtype=np.uint8)[None, :, None], (256, 256, 3)).copy()
    ramp_y = np.ascontiguousarray(ramp.transpose(1, 0, 2))
    center, out = np.array([120.3, 90.7]), (12, 20)
    windows = np.array([[6.0, 10.0], [9.0, 15.0], [13.5, 22.5]])  # < 2 image px per template px: no pre-shrink
    steps = windows / np.array(out)
    expected_x = center[0] + (np.arange(out[0]) - (out[0] - 1) / 2) * steps[:, :1]  # (S, out_w)
    expected_y = center[1] + (np.arange(out[1]) - (out[1] - 1) / 2) * steps[:, 1:]  # (S, out_h)
    along_x = sample_windows(ramp, center, windows, out)[..., 0].astype(float)  # (S, out_h, out_w)
    along_y = sample_windows(ramp_y, center, windows, out)[..., 0].astype(float)
    np.testing.assert_allclose(along_x, np.broadcast_to(expected_x[:, None, :], along_x.shape), atol=0.55)
    np.testing.assert_allclose(along_y, np.broadcast_to(expected_y[:, :, None], along_y.shape), atol=0.55)


def test_dcf_response_static_shift_peaks_at_displacement() -> None:
    background, target = _scene(seed=2, target_side_px=30)
    first, box = _paste(background, target, 100, 100)
    tracker = DcfTracker()
    tracker.init(first, box)
    shifted, moved = _paste(background, target, 107, 96)
    resp = tracker.response(shifted, box.center)
    assert resp.scores.dtype == np.float32 and resp.scores.shape == (24, 24)
    np.testing.assert_allclose(highest_peak(resp).location_px, moved.center, atol=1.0)
    assert abs(resp.scale - 1.0) < 0.03


def test_dcf_tracker_translating_texture_mean_iou_above_0_8() -> None:
    side, radius_px, speed_px = 30, 70.0, 3.0
    background, target = _scene(seed=3, target_side_px=side)
    tracker = DcfTracker()
    ious = []
    for frame in range(100):
        # circular path at 3 px per frame around the image centre
        angle = speed_px * frame / radius_px
        center = IMAGE_SIDE_PX / 2 + radius_px * np.array([np.cos(angle), np.sin(angle)])
        x0, y0 = np.round(center - side / 2).astype(int)
        image, truth = _paste(background, target, int(x0), int(y0))
        if frame == 0:
            tracker.init(image, truth)
            continue
        ious.append(iou(_track_step(tracker, image).as_array(), truth.as_array()))
    assert np.mean(ious) >= 0.8
    assert np.min(ious) > 0.5


@pytest.mark.parametrize("growth_per_frame", [1.01, 0.99])
def test_dcf_tracker_growing_patch_box_size_within_15_percent(growth_per_frame: float) -> None:
    background, texture = _scene(seed=4, target_side_px=64)
    tracker = DcfTracker()
    ratios = []
    for frame in range(31):
        side = int(round(30 * growth_per_frame**frame))  # changes 1 % per frame
        patch = cv2.resize(texture, (side, side), interpolation=cv2.INTER_AREA)
        center = np.array([110.0, 120.0]) + np.array([1.0, 0.5]) * frame
        x0, y0 = np.round(center - side / 2).astype(int)
        image, truth = _paste(background, patch, int(x0), int(y0))
        if frame == 0:
            tracker.init(image, truth)
            continue
        box = _track_step(tracker, image)
        ratios.append([box.w_px / truth.w_px, box.h_px / truth.h_px])
    assert np.all(np.abs(np.array(ratios) - 1.0) <= 0.15)
    # it really followed: the final size is nearer the truth than the initial size is
    final_truth = 30 * growth_per_frame**30
    assert abs(tracker.box.w_px - final_truth) < 0.5 * abs(30 - final_truth)


def test_dcf_tracker_box_partly_beyond_border_still_tracks() -> None:
    background, target = _scene(seed=5, target_side_px=30)
    # target cut by the left image border: only 15 of its 30 columns visible
    image, _ = _paste(background, target[:, 15:], 0, 60)
    box = BBox(-15.0, 60.0, 30.0, 30.0)
    tracker = DcfTracker()
    tracker.init(image, box)
    moved, _ = _paste(background, target[:, 12:], 0, 64)  # 3 px right, 4 px down
    resp = tracker.response(moved, box.center)
    assert np.all(np.isfinite(resp.scores))
    location = highest_peak(resp).location_px
    np.testing.assert_allclose(location, box.center + np.array([3.0, 4.0]), atol=1.5)
    committed = tracker.commit(location, resp.scale)
    tracker.update(moved)
    assert committed.center[0] >= 0.0  # the committed centre is clamped into the image


def test_dcf_response_two_identical_objects_window_centre_decides() -> None:
    background, target = _scene(seed=6, target_side_px=20)
    first, box = _paste(background, target, 100, 100)
    tracker = DcfTracker()
    tracker.init(first, box)
    both, _ = _paste(first, target, 124, 100)  # an identical decoy 24 px to the right
    decoy_center = box.center + np.array([24.0, 0.0])
    config = PeakConfig()
    near_target = select_peak(tracker.response(both, box.center + np.array([6.0, 0.0])), config)
    near_decoy = select_peak(tracker.response(both, decoy_center - np.array([6.0, 0.0])), config)
    np.testing.assert_allclose(near_target.location_px, box.center, atol=1.0)
    np.testing.assert_allclose(near_decoy.location_px, decoy_center, atol=1.0)


@pytest.mark.parametrize(
    ("field", "value"),
    [("learning_rate", 0.0), ("padding", 1.0), ("template_side_px", 0), ("regularisation", -1.0)],
)
def test_dcf_config_invalid_value_raises_naming_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        DcfConfig(**{field: value})


def test_dcf_tracker_use_before_init_raises() -> None:
    with pytest.raises(RuntimeError, match="init"):
        DcfTracker().response(np.zeros((8, 8, 3), dtype=np.uint8), np.zeros(2))


def _counting_scale_filter(config: ScaleConfig, image: np.ndarray, box: BBox) -> tuple[ScaleFilter, list[int]]:
    """A ScaleFilter trained on `box`, and a list that grows by one each time it samples its pyramid."""
    scale_filter = ScaleFilter(config, FeatureConfig())
    scale_filter.init(image, box.center, np.array([box.w_px, box.h_px]))
    calls: list[int] = []
    sample = scale_filter._spectrum

    def counting(*args):
        calls.append(1)
        return sample(*args)

    scale_filter._spectrum = counting
    return scale_filter, calls


def test_scale_update_reuses_the_same_frames_estimate_at_its_centre_within_half_a_step_once() -> None:
    background, target = _scene(seed=7, target_side_px=24)
    image, box = _paste(background, target, 100, 90)
    size = np.array([box.w_px, box.h_px])
    scale_filter, calls = _counting_scale_filter(ScaleConfig(), image, box)
    other_frame = image.copy()  # same pixels, another frame
    cases = [  # (image, centre offset [px], size factor of the update, pyramids sampled by the update)
        (image, 0.0, 1.0, 0), (image, 0.0, 1.03**0.4, 0), (image, 0.0, 1.03**0.6, 1),
        (image, 0.5, 1.0, 1), (other_frame, 0.0, 1.0, 1)]
    for frame, offset, factor, sampled in cases:
        scale_filter.estimate(image, box.center, size)
        before = len(calls)
        scale_filter.update(frame, box.center + offset, factor * size)
        assert len(calls) - before == sampled
    scale_filter.estimate(image, box.center, size)
    scale_filter.update(image, box.center, size)
    before = len(calls)
    scale_filter.update(image, box.center, size)  # the estimate's samples serve one update only
    assert len(calls) - before == 1


def test_scale_update_reusing_the_estimate_learns_the_same_model_for_an_unchanged_box() -> None:
    background, target = _scene(seed=8, target_side_px=24)
    image, box = _paste(background, target, 90, 100)
    moved, _ = _paste(background, target, 92, 101)
    size = np.array([box.w_px, box.h_px])
    reusing, _ = _counting_scale_filter(ScaleConfig(), image, box)
    fresh, _ = _counting_scale_filter(ScaleConfig(), image, box)
    reusing.estimate(moved, box.center, size)
    reusing.update(moved, box.center, size)
    fresh.update(moved, box.center, size)
    np.testing.assert_array_equal(reusing._num, fresh._num)
    np.testing.assert_array_equal(reusing._den, fresh._den)


def test_scale_config_negative_reuse_tolerance_raises_naming_field() -> None:
    with pytest.raises(ValueError, match="update_reuse_max_steps"):
        ScaleConfig(update_reuse_max_steps=-0.5)
