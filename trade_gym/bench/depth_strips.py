"""Strips of frames for the runs whose ground depth failed: each flown again with the annotated onboard view (ground
mask tinted cyan, ROI features coloured by depth, the plane's inliers circled, true box green, estimate red), at the
frames where its ground estimate was furthest off the true ground, each captioned with both depths and the plane.

The strip is a second flight of the run's spec (rendering on, same camera), so it shows the frames; the scores
come from the benchmark's own flight.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import gymnasium as gym
import numpy as np
import numpy.typing as npt

from trade_gym import metrics
from trade_gym.bench.failures import depth_cause
from trade_gym.bench.runner import RunResult, error_line, fly
from trade_gym.bench.suites import RunSpec
from trade_gym.env import TradeFollowEnv

STRIP_FRAMES = 4  # frames per strip, spread over the frames whose ground estimate is off
CAPTION_HEIGHT_PX = 34  # two lines of text under each frame
CAPTION_SCALE = 0.36  # OpenCV font scale of the caption
CAPTION_COLOUR_RGB = (255, 255, 255)
STRIP_GAP_PX = 2
STRIP_JPEG_QUALITY = 85  # a 4-frame strip at 256 px: about 0.1 MB as JPEG, 0.5 MB as PNG


def failed_depth_runs(results: Sequence[RunResult]) -> list[RunResult]:
    """Runs of the per-world groups (kind "unseen") whose ground depth failed (`failures.depth_cause`) on frames
    that have it (a run without any ground estimate has no frame to show)."""
    return [r for r in results if r.error is None and r.spec.kind == "unseen" and r.spec.perception != "oracle"
            and r.spec.depth_kind == "ground" and r.metrics.get("ground_depth_frames")
            and depth_cause(r.metrics) is not None]


def strip_frame_indices(ground_errors_m: npt.NDArray[np.float64], count: int = STRIP_FRAMES) -> list[int]:
    """Up to `count` frame indices spread evenly over the frames whose |ground error| exceeds
    `metrics.GROUND_OFF_M` (the worst frames when none does); in time order."""
    finite = np.isfinite(ground_errors_m)
    off = np.flatnonzero(finite & (np.abs(np.where(finite, ground_errors_m, 0.0)) > metrics.GROUND_OFF_M))
    if not len(off):
        order = np.argsort(-np.abs(np.where(finite, ground_errors_m, 0.0)))
        off = np.sort(order[:count][finite[order[:count]]])
    if len(off) <= count:
        return [int(i) for i in off]
    return [int(off[i]) for i in np.round(np.linspace(0, len(off) - 1, count)).astype(int)]


def _caption(frame: npt.NDArray[np.uint8], lines: Sequence[str]) -> npt.NDArray[np.uint8]:
    panel = np.zeros((CAPTION_HEIGHT_PX, frame.shape[1], 3), np.uint8)
    for k, text in enumerate(lines):
        cv2.putText(panel, text, (3, 13 + 15 * k), cv2.FONT_HERSHEY_SIMPLEX, CAPTION_SCALE, CAPTION_COLOUR_RGB, 1,
                    cv2.LINE_AA)
    return np.vstack([frame, panel])


def _depth_text(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.1f}"


def write_strip(spec: RunSpec, path: Path) -> Path:
    """Fly `spec` again with rendering on and write the strip of its worst ground-depth frames to `path` (JPEG)."""
    frames: list[npt.NDArray[np.uint8]] = []
    planes: list[str] = []

    def grab(env: gym.Env, obs: dict, info: dict) -> None:
        base, image = env.unwrapped, env.render()
        if not isinstance(base, TradeFollowEnv) or not isinstance(image, np.ndarray):  # as `fly` builds it
            raise TypeError(f"write_strip needs a TradeFollow-v0 env rendering rgb_array, got {type(base).__name__}")
        frames.append(image)
        plane = base.estimate.ground.plane
        planes.append("no plane" if plane is None else f"plane tilt {plane.tilt_deg:.0f} deg, {plane.n_inliers} inl")

    infos, _ = fly(spec, on_frame=grab, render=True)
    frames, planes = frames[1:], planes[1:]  # the reset's frame has no info of its own
    errors = metrics.depth_errors_m(infos, "ground")
    tiles = []
    for k in strip_frame_indices(errors):
        est, gt = infos[k].get("ground_depth_est"), infos[k].get("ground_depth_gt")
        tiles.append(_caption(frames[k], [f"frame {k + 1}: ground est {_depth_text(est)} m, true {_depth_text(gt)} m",
                                          planes[k]]))
    if not tiles:
        raise ValueError(f"{spec.run_id}: no frame with a ground-depth estimate to show")
    gap = np.zeros((tiles[0].shape[0], STRIP_GAP_PX, 3), np.uint8)
    strip = np.hstack([part for tile in tiles for part in (tile, gap)][:-1])
    cv2.imwrite(str(path), cv2.cvtColor(strip, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, STRIP_JPEG_QUALITY])
    return path


def strip_name(spec: RunSpec) -> str:
    """The strip's file name: the run id with '/' as '_'."""
    return "strip_" + spec.run_id.replace("/", "_").replace("=", "-").replace(",", "-") + ".jpg"


def write_strips(results: Sequence[RunResult], out: Path) -> list[Path]:
    """One strip per failed-depth run into `out/strips/`; returns the files written. A strip that cannot be made
    (its second flight raised) is reported on stderr and skipped, so the suite's results are still written."""
    failed = failed_depth_runs(results)
    if not failed:
        return []
    folder = out / "strips"
    folder.mkdir(exist_ok=True)
    written = []
    for r in failed:
        try:
            written.append(write_strip(r.spec, folder / strip_name(r.spec)))
        except Exception as exc:  # any error: a picture must not cost the suite its results
            print(f"trade-bench: no strip for {r.spec.run_id}: {error_line(exc)}", file=sys.stderr)
    return written
