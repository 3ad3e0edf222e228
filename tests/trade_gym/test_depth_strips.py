"""The depth failure finder's strips: which runs get one, which frames they show, and the image itself."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from trade_gym.bench import depth_strips, runner
from trade_gym.bench.failures import FAIL_GROUND_RMSE_M
from trade_gym.bench.suites import RunSpec
from trade_gym.metrics import GROUND_OFF_M, METRIC_NAMES


def _result(kind: str, rmse: float, perception: str = "trade", frames: int = 250) -> runner.RunResult:
    metrics = dict.fromkeys(METRIC_NAMES, 0.0) | {"ground_depth_rmse_m": rmse, "ground_depth_bias_m": -rmse,
                                                   "ground_depth_frames": frames}
    spec = RunSpec("g", kind, "city", "scripted", perception, "gt", 10_000, 300, 256)
    return runner.RunResult(spec, metrics, runner.RunTiming(1.0, 0.1, 0.9, 300.0), None)


def test_only_per_world_runs_whose_ground_depth_failed_get_a_strip():
    failed = _result("unseen", FAIL_GROUND_RMSE_M + 1.0)
    results = [failed, _result("unseen", FAIL_GROUND_RMSE_M - 0.5), _result("table1", FAIL_GROUND_RMSE_M + 1.0),
               _result("unseen", math.nan, perception="oracle"),
               _result("unseen", math.nan, frames=0)]  # no ground estimate at all: no frame to show
    assert depth_strips.failed_depth_runs(results) == [failed]


def test_strip_frames_spread_over_the_frames_whose_plane_is_off_in_time_order():
    errors = np.full(100, 0.2)
    errors[[3, 10, 20, 40, 60, 99]] = [-5.0, 2.0, -1.5, 8.0, 3.0, 1.01]
    errors[50] = math.nan
    picked = depth_strips.strip_frame_indices(errors, count=4)
    assert picked == sorted(picked) and len(picked) == 4
    assert set(picked) <= {3, 10, 20, 40, 60, 99} and picked[0] == 3 and picked[-1] == 99
    assert all(abs(errors[k]) > GROUND_OFF_M for k in picked)


def test_strip_frames_without_an_off_frame_are_the_worst_ones():
    errors = np.array([0.1, math.nan, 0.9, 0.3, 0.8, 0.05])
    assert depth_strips.strip_frame_indices(errors, count=2) == [2, 4]
    assert depth_strips.strip_frame_indices(np.full(5, math.nan), count=2) == []


def test_strip_of_a_flown_run_is_a_row_of_captioned_frames(tmp_path):
    camera_px, steps = 128, 90  # the first plane comes after about 20 frames
    spec = RunSpec("g", "unseen", "desert", "scripted", "trade", "gt", 10_000, steps, camera_px)
    path = depth_strips.write_strip(spec, tmp_path / depth_strips.strip_name(spec))
    image = cv2.imread(str(path))
    assert image is not None and path.name == "strip_g_desert_scripted_trade_gt_seed10000.jpg"
    tiles = depth_strips.STRIP_FRAMES
    assert image.shape[0] == camera_px + depth_strips.CAPTION_HEIGHT_PX
    assert image.shape[1] == tiles * camera_px + (tiles - 1) * depth_strips.STRIP_GAP_PX
    caption = image[camera_px:]
    assert caption.max() > 0  # text was written under each frame
    assert path.read_bytes()[:2] == b"\xff\xd8"  # JPEG (a PNG strip is about five times larger)


def test_strip_without_any_ground_estimate_raises_naming_the_run(tmp_path, monkeypatch):
    spec = RunSpec("g", "unseen", "desert", "scripted", "trade", "gt", 10_000, 3, 64)
    with pytest.raises(ValueError, match="g/desert/scripted/trade/gt/seed10000"):
        depth_strips.write_strip(spec, tmp_path / "s.jpg")


def test_a_strip_that_cannot_be_made_is_reported_and_the_others_are_written(tmp_path, monkeypatch, capsys):
    bad, good = (_result("unseen", FAIL_GROUND_RMSE_M + 1.0) for _ in range(2))
    bad = runner.RunResult(RunSpec("g", "unseen", "city", "learned", "trade", "vio", 10_001, 300, 256), bad.metrics,
                           bad.timing, None)

    def fake_strip(spec, path):
        if spec.policy == "learned":
            raise ValueError("boom")
        path.write_bytes(b"\xff\xd8")
        return path

    monkeypatch.setattr(depth_strips, "write_strip", fake_strip)
    written = depth_strips.write_strips([bad, good], tmp_path)
    assert [p.name for p in written] == [depth_strips.strip_name(good.spec)]
    assert "no strip for g/city/learned/trade/vio/seed10001: ValueError: boom" in capsys.readouterr().err
