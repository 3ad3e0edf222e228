"""The microbolometer model: NETD and column noise as configured, AGC to the full 8 bits, flat-field freezes, seeded."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trade_gym.sim.thermal_sensor import (
    MK_PER_K, OUT_MAX_DN, RAW_K_PER_COUNT, RAW_ZERO_K, ThermalConfig, ThermalSensor, plateau_equalize,
)

FRAME_DT_S = 1.0 / 30.0
SCENE_K = 300.0
QUANTISATION_K = RAW_K_PER_COUNT / math.sqrt(12.0)  # rms of rounding to one count


def _raw_k(sensor: ThermalSensor) -> np.ndarray:
    assert sensor.last_raw is not None
    return sensor.last_raw.astype(np.float64) * RAW_K_PER_COUNT + RAW_ZERO_K


def _quiet(**changes) -> ThermalConfig:
    """Only what a test looks at: no blur, no column noise unless asked."""
    return ThermalConfig(**({"blur_sigma_px": 0.0, "column_fpn_mk": 0.0} | changes))


@pytest.mark.parametrize("netd_mk", [25.0, 50.0, 100.0])
def test_noise_std_of_a_uniform_scene_matches_the_configured_netd(netd_mk):
    sensor = ThermalSensor(_quiet(netd_mk=netd_mk), 256, np.random.default_rng(0))
    frames = []
    for k in range(4):
        sensor.capture(np.full((256, 256), SCENE_K, np.float32), k * FRAME_DT_S)
        frames.append(_raw_k(sensor))
    expected_k = math.hypot(netd_mk / MK_PER_K, QUANTISATION_K)
    spatial = np.std(frames[0])  # one frame, 65536 pixels: std error ~0.3 %
    temporal = np.sqrt(np.mean(np.var(np.stack(frames), axis=0, ddof=1)))  # per pixel over frames
    assert spatial == pytest.approx(expected_k, rel=0.03)
    assert temporal == pytest.approx(expected_k, rel=0.03)
    assert np.mean(frames[0]) == pytest.approx(SCENE_K, abs=0.01)


def test_column_noise_is_one_offset_per_column_with_the_configured_std():
    sensor = ThermalSensor(_quiet(netd_mk=0.0, column_fpn_mk=40.0), 4000, np.random.default_rng(1))
    sensor.capture(np.full((8, 4000), SCENE_K, np.float32), 0.0)
    first = _raw_k(sensor)
    assert np.all(first == first[0])  # every row the same: the offsets are per column
    assert np.std(first[0]) == pytest.approx(math.hypot(0.040, QUANTISATION_K), rel=0.05)
    sensor.capture(np.full((8, 4000), SCENE_K, np.float32), FRAME_DT_S)
    np.testing.assert_array_equal(_raw_k(sensor), first)  # fixed between flat-field corrections


def test_agc_maps_to_the_full_8_bit_range_and_keeps_the_order_of_counts():
    raw = np.random.default_rng(2).integers(1000, 3000, size=(64, 64)).astype(np.uint16)
    out = plateau_equalize(raw, 0.002, 0.002, 0.2)
    assert out.dtype == np.uint8 and out.min() == 0 and out.max() == OUT_MAX_DN
    order = np.argsort(raw, axis=None, kind="stable")
    assert np.all(np.diff(out.ravel()[order].astype(int)) >= 0)  # hotter never darker


def test_agc_plateau_keeps_a_large_uniform_area_from_taking_the_grey_levels():
    # 90 % of the image one temperature (the ground), 10 % a ramp of 200 counts (the objects)
    raw = np.full((100, 100), 5000, np.uint16)
    raw[:10] = np.linspace(5200, 5400, 1000).astype(np.uint16).reshape(10, 100)
    plain = plateau_equalize(raw, 1.0, 0.0, 0.0)  # no plateau: classic histogram equalisation
    plateau = plateau_equalize(raw, 0.002, 0.0, 0.0)
    spread = [len(np.unique(image[:10])) for image in (plain, plateau)]
    assert spread[1] > 4 * spread[0]  # the ramp gets most grey levels instead of ~10 %
    assert plateau[10:].max() == 0 and plateau[:10].max() == OUT_MAX_DN


def test_agc_of_a_flat_image_is_mid_grey():
    out = plateau_equalize(np.full((4, 4), 7000, np.uint16), 0.002, 0.002, 0.2)
    assert np.all(out == 128)


def test_flat_field_correction_holds_the_last_image_for_the_configured_time():
    duration_s, interval_s = 0.3, 2.0
    sensor = ThermalSensor(_quiet(ffc_freeze=True, ffc_interval_s=interval_s, ffc_duration_s=duration_s), 32,
                           np.random.default_rng(3))
    times = np.arange(180) * FRAME_DT_S  # 6 s
    outputs = [sensor.capture(np.full((32, 32), SCENE_K, np.float32)
                              + np.linspace(0.0, 1.0 + k, 32 * 32, dtype=np.float32).reshape(32, 32), t)
               for k, t in enumerate(times)]
    held = np.array([np.array_equal(a, b) for a, b in zip(outputs, outputs[1:])])  # frame k + 1 repeats frame k
    starts = sensor.first_ffc_s + interval_s * np.arange(3)
    in_freeze = np.array([any(0.0 <= t - s < duration_s for s in starts) for t in times[1:]])
    np.testing.assert_array_equal(held, in_freeze)
    runs = [len(run) for run in "".join("1" if h else "0" for h in held).split("0") if run]
    assert len(runs) == 3
    for frames in runs:  # each freeze lasts the configured time, to within one frame
        assert abs(frames * FRAME_DT_S - duration_s) <= FRAME_DT_S


def test_without_ffc_freeze_every_frame_is_live():
    sensor = ThermalSensor(_quiet(ffc_interval_s=0.1, ffc_duration_s=0.05), 16, np.random.default_rng(4))
    outputs = [sensor.capture(np.full((16, 16), SCENE_K + k, np.float32), k * FRAME_DT_S) for k in range(30)]
    assert not any(np.array_equal(a, b) for a, b in zip(outputs, outputs[1:]))


def test_one_seed_gives_the_same_frames_and_fresh_noise_each_frame():
    scene = np.random.default_rng(5).uniform(280.0, 320.0, size=(48, 48)).astype(np.float32)
    runs = []
    for _ in range(2):
        sensor = ThermalSensor(ThermalConfig(), 48, np.random.default_rng(6))
        runs.append([sensor.capture(scene, k * FRAME_DT_S).copy() for k in range(3)])
        assert not np.array_equal(runs[-1][0], runs[-1][1])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("field, bad", [
    ("netd_mk", -5.0), ("netd_mk", math.nan), ("column_fpn_mk", -1.0), ("blur_sigma_px", -0.1),
    ("agc_plateau_fraction", 0.0), ("agc_tail_fraction", 0.5), ("agc_linear_fraction", 1.5),
    ("ffc_freeze", 1), ("ffc_interval_s", 0.0), ("ffc_duration_s", -0.2), ("ffc_duration_s", 180.0),
])
def test_bad_thermal_config_raises_value_error_naming_field_and_value(field, bad):
    with pytest.raises(ValueError, match=rf"ThermalConfig\.{field} must be .*got {bad!r}"):
        ThermalConfig(**{field: bad})
