"""Open-loop replay of the TRADE stack over a recorded sequence: the stack sees the recorded images, poses, times
and IMU samples (its frame guards are the pipeline's, as in the env) with its own generator seeded as recorded, so
a replay of a recorded episode gives that episode's estimates exactly; where the sequence has ground truth the
estimates are scored as the env scores them (`trade_gym.scoring`) and with trade-bench's metrics.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from trade.planes import Plane
from trade.types import ImuBatch
from trade_gym.config import CAMERA_RATE_HZ, EnvConfig
from trade_gym.ground_truth import GroundTruth
from trade_gym.metrics import episode_metrics
from trade_gym.perception.base import SensorFrame
from trade_gym.perception.trade_stack import STACK_SWITCHES, TradePerception, pipeline_config
from trade_gym.recording.format import (META_FILE, FrameTruth, SequenceError, current_setting_names, encode_box,
                                        encode_real, json_safe)
from trade_gym.recording.reader import Sequence
from trade_gym.scoring import ScoredEstimate, estimate_scores, ground_depth_along, horizontal_distance_m, score_estimate

FloatArray = npt.NDArray[np.float64]

REPLAY_PERCEPTIONS = ("trade", "dcf")
# The stack's seed for a sequence that records none (e.g. converted from a flight log).
DEFAULT_STACK_SEED = 0
# Faults that act inside perception, not on the recorded sensors: a replay cannot reproduce them.
IN_PERCEPTION_FAULTS = ("depth_model",)
GT_RAY, EST_RAY = "true box centre", "estimated box centre"


@dataclass(frozen=True)
class ReplaySettings:
    """The stack a replay runs: `perception` trade or dcf, its switches (name, value) from STACK_SWITCHES
    (the rest at the env's defaults) and the seed of its own generator."""

    perception: str = "trade"
    switches: tuple[tuple[str, bool], ...] = ()
    rng_seed: int = DEFAULT_STACK_SEED

    def __post_init__(self) -> None:
        if self.perception not in REPLAY_PERCEPTIONS:
            raise ValueError(f"perception must be one of {REPLAY_PERCEPTIONS}, got {self.perception!r}")
        for name, value in self.switches:
            if name not in STACK_SWITCHES:
                raise ValueError(f"unknown switch {name!r} (choose from {', '.join(STACK_SWITCHES)})")
            if not isinstance(value, bool):
                raise ValueError(f"switch {name} must be a bool, got {value!r}")
        seed = self.rng_seed
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"rng_seed must be an integer >= 0, got {seed!r}")

    def env_config(self) -> EnvConfig:
        """The env configuration whose stack this is (ValueError naming a bad switch combination)."""
        # the ignore: mypy matches the unpacked dict of bools against every field; its names are bool switches
        # (STACK_SWITCHES, checked in __post_init__)
        return EnvConfig(perception=self.perception, **dict(self.switches))  # type: ignore[arg-type]

    def as_json(self) -> dict[str, Any]:
        config = self.env_config()
        return {"mode": self.perception, "switches": {n: getattr(config, n) for n in STACK_SWITCHES},
                "rng_seed": self.rng_seed}


def recorded_settings(sequence: Sequence, perception: str | None = None,
                      overrides: tuple[tuple[str, bool], ...] = ()) -> ReplaySettings:
    """The sequence's recorded stack (meta.json `perception`: mode, switches, seed; the defaults when it has
    none), with `perception` and `overrides` replacing what they name."""
    recorded = sequence.meta.get("perception") or {}
    recorded_mode = recorded.get("mode")
    mode = perception or (recorded_mode if recorded_mode in REPLAY_PERCEPTIONS else "trade")
    switches = {n: v for n, v in (recorded.get("switches") or {}).items() if n in STACK_SWITCHES}
    switches.update(dict(overrides))
    seed = recorded.get("rng_seed")
    return ReplaySettings(mode, tuple(sorted(switches.items())), DEFAULT_STACK_SEED if seed is None else int(seed))


@dataclass(frozen=True, eq=False)
class FrameEstimate:
    """The stack's output at one frame: box (4,) x, y, w, h [px] (NaN: none), whether it is a fresh measurement,
    the target's camera-frame depth [m], the ground depth along the scoring ray [m] and the ground plane."""

    frame: int
    t_s: float
    bbox_xywh_px: FloatArray
    valid: bool
    target_depth_m: float
    ground_depth_m: float
    plane: Plane | None

    def as_json(self) -> dict[str, Any]:
        """One estimates.jsonl object (NaN written as null)."""
        plane = None if self.plane is None else {"normal_world": self.plane.normal.tolist(),
                                                 "offset_m": float(self.plane.offset_m)}
        return {"frame": self.frame, "t_s": encode_real(self.t_s), "est_bbox": encode_box(self.bbox_xywh_px),
                "valid": bool(self.valid), "target_depth_est": encode_real(self.target_depth_m),
                "ground_depth_est": encode_real(self.ground_depth_m), "ground_plane": plane}


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """A replay's estimates (one per frame), the scored infos and metrics (frames after the first, as
    trade-bench scores an episode; None without ground truth), warnings and timing."""

    settings: ReplaySettings
    estimates: tuple[FrameEstimate, ...]
    infos: list[dict[str, Any]] | None
    metrics: dict[str, Any] | None
    ground_depth_ray: str
    settings_match_recording: bool | None
    warnings: tuple[str, ...]
    wall_s: float
    video_frames: list[npt.NDArray[np.uint8]] | None = None


def replay(sequence: Sequence, settings: ReplaySettings, video: bool = False) -> ReplayResult:
    """Run the stack of `settings` open-loop over every frame of `sequence` (a flight with an initial box and an
    image at frame 0; `SequenceError` otherwise or when a frame's file cannot be decoded). `video` keeps the
    annotated frames (frames without an image are left out)."""
    init_box = _check_replayable(sequence)
    config = settings.env_config()
    perception = TradePerception(config, sequence.intrinsics)
    threshold = float((sequence.meta.get("truth") or {}).get("visible_fraction_threshold",
                                                              EnvConfig().visible_fraction_threshold))
    scored = sequence.has_truth
    estimates, infos, frames = [], [], []
    start = time.perf_counter()
    for frame in sequence:
        rgb = sequence.rgb(frame)
        sensors = SensorFrame(frame.t_s, rgb, frame.T_world_cam, frame.imu if frame.imu is not None else ImuBatch.empty())
        out = (perception.reset_seeded(sensors, init_box, settings.rng_seed) if frame.index == 0
               else perception.step(sensors))
        truth = _ground_truth(frame.truth)
        held = score_estimate(out, truth, sensors.T_world_cam, sequence.intrinsics)
        ground = (held.ground_depth_est_m if scored
                  else ground_depth_along(out.ground, out.bbox, sensors.T_world_cam, sequence.intrinsics))
        estimates.append(FrameEstimate(frame.index, frame.t_s, out.bbox, bool(out.valid), float(out.target_depth_m),
                                       float(ground), out.ground.plane))
        if scored and frame.index > 0 and frame.truth is not None:  # scored: every frame has its truth
            infos.append(_info(frame.t_s, frame.truth, truth, held, threshold))
        if video and rgb is not None:
            from trade_gym.annotate import annotate_frame

            frames.append(annotate_frame(rgb, truth, out, perception.overlay))
    wall_s = time.perf_counter() - start
    match = _settings_match(sequence, settings)
    frame_dt_s = 1.0 / float(sequence.meta.get("frame_rate_hz") or CAMERA_RATE_HZ)  # the lost streak's unit
    return ReplayResult(settings, tuple(estimates), infos if scored else None,
                        episode_metrics(infos, frame_dt_s) if scored else None, GT_RAY if scored else EST_RAY, match,
                        tuple(_warnings(sequence, match)), wall_s, frames if video else None)


def _check_replayable(sequence: Sequence) -> FloatArray:
    meta_path = sequence.path / META_FILE
    if sequence.kind != "flight":
        raise SequenceError(meta_path, f"kind {sequence.kind!r} is a set of independent views; only a flight replays")
    if not sequence.frames:
        raise SequenceError(meta_path, "the sequence has no frames")
    box = sequence.initial_bbox_xywh_px
    if box is None:
        raise SequenceError(meta_path, "initial_bbox_xywh_px is null: the tracker needs the initial box")
    if sequence.frames[0].rgb_file is None:
        raise SequenceError(sequence.path / "frames.jsonl", "no image, and the tracker starts on frame 0", 0)
    return box


def _ground_truth(truth: FrameTruth | None) -> GroundTruth:
    """A frame's recorded truth as the env's, for scoring and drawing (the stack never sees it); NaN without it."""
    nan3 = np.full(3, np.nan)
    if truth is None:
        return GroundTruth(np.full(4, np.nan), np.zeros((0, 4)), math.nan, nan3, nan3, math.nan,
                           np.full(2, np.nan), math.nan)
    decoys = np.array([v.bbox_xywh_px for v in truth.vehicles if v.role == "decoy"]).reshape(-1, 4)
    return GroundTruth(truth.target_bbox_xywh_px, decoys, truth.target_visible_fraction,
                       truth.target_position_world_m, truth.target_velocity_world_mps, truth.target_depth_m,
                       np.full(2, np.nan), truth.ground_depth_m)


def _info(t_s: float, recorded: FrameTruth, truth: GroundTruth, held: ScoredEstimate,
          threshold: float) -> dict[str, Any]:
    """The per-frame record `trade_gym.metrics` scores, as the env's `info` computes it, for the frame at `t_s` [s]
    with the `recorded` truth (`truth`: the same as the env's)."""
    drone, target = recorded.drone_position_world_m, recorded.target_position_world_m
    info = {
        "t_s": recorded.t_s if math.isfinite(recorded.t_s) else t_s,  # the true time, as the env's info
        **estimate_scores(truth, held, threshold, recorded.decoy_bboxes_in_view()),
        "crashed": recorded.crashed,
        "drone_position_m": drone,
        "target_position_m": target,
        "horizontal_distance_m": horizontal_distance_m(drone, target),
    }
    if recorded.following is not None:  # recorded by the env (not by an older recording or a real flight log)
        info["following"] = recorded.following
    return info


def _settings_match(sequence: Sequence, settings: ReplaySettings) -> bool | None:
    """Whether this code's stack for `settings` has the recorded settings (None: the sequence records none)."""
    recorded = (sequence.meta.get("perception") or {}).get("pipeline_config")
    if recorded is None:
        return None
    return json_safe(asdict(pipeline_config(settings.env_config()))) == current_setting_names(recorded)


def _warnings(sequence: Sequence, match: bool | None) -> list[str]:
    lines = []
    if match is False:
        lines.append("the stack's settings differ from those recorded in meta.json (an ablation, or the code's "
                     "defaults changed since the recording): estimates will differ from the recorded run's")
    faults = {f.get("kind") for f in (sequence.meta.get("source") or {}).get("faults", ())}
    if inside := sorted(faults & set(IN_PERCEPTION_FAULTS)):
        lines.append(f"the recording had faults inside perception ({', '.join(inside)}), which the recorded "
                     "sensors do not carry: the replay runs without them")
    return lines
