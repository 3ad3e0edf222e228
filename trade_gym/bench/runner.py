"""Flies and scores one benchmark episode (`run_spec`); `trade_gym.bench.executors` decides where runs execute.

A run's scores (`metrics`) and its `trajectory_sha256` depend only on its spec, so serial, parallel and
Ray runs agree exactly; wall-clock figures are kept apart in `timing`.
"""

from __future__ import annotations

import hashlib
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from trade_gym.quiet_import import import_pybullet_quietly

import_pybullet_quietly()

from trade_gym import metrics  # noqa: E402  (after the quiet pybullet import)
from trade_gym.bench.policies import make_policy  # noqa: E402
from trade_gym.bench.suites import RunSpec  # noqa: E402
from trade_gym.env import TradeFollowEnv  # noqa: E402
from trade_gym.rollout import FrameHook, fly_episode  # noqa: E402

if TYPE_CHECKING:
    from trade_gym.bench.executors import Executor

FloatArray = npt.NDArray[np.float64]
# Relative cost of a step that renders and runs the stack against an oracle step (measured ~30-60x);
# used only to submit the longest runs first, which shortens the parallel makespan.
RENDERING_STEP_COST = 40.0
# Per-frame info entries hashed into `trajectory_sha256`, in this order (1 + 3 + 3 + 4 + 1 + 1 floats a frame).
TRAJECTORY_KEYS = ("t_s", "drone_position_m", "target_position_m", "est_bbox", "target_depth_est",
                   "ground_depth_est")
TRAJECTORY_DTYPE = "<f8"  # little-endian float64, whatever the machine


@dataclass(frozen=True)
class RunSeries:
    """Per-frame records of one run for the plots: (T,) arrays and (T, 2) world xy paths [m]."""

    iou: FloatArray
    ground_depth_error_m: FloatArray  # estimate - truth, NaN where either is missing
    target_depth_error_m: FloatArray
    drone_xy_m: FloatArray
    target_xy_m: FloatArray


@dataclass(frozen=True)
class RunTiming:
    """Wall-clock figures [s] (machine- and load-dependent; never compared between runs)."""

    wall_s: float  # env construction, reset, episode and close
    reset_s: float
    step_loop_s: float  # policy + env.step over the episode
    steps_per_s: float  # env steps per second of the step loop


@dataclass(frozen=True)
class RunResult:
    spec: RunSpec
    metrics: dict[str, float | int | bool | None]  # `trade_gym.metrics.episode_metrics`; empty on error
    timing: RunTiming
    series: RunSeries | None
    error: str | None = None  # one line: the exception that ended the run
    trajectory_sha256: str | None = None  # `trajectory_sha256(infos)`; None on error


def _series(infos: list[dict]) -> RunSeries:
    def xy(key: str) -> FloatArray:
        return np.array([i[key][:2] for i in infos], dtype=np.float64).reshape(-1, 2)

    return RunSeries(
        iou=np.array([i["iou"] for i in infos], dtype=np.float64),
        ground_depth_error_m=metrics.depth_errors_m(infos, "ground"),
        target_depth_error_m=metrics.depth_errors_m(infos, "target"),
        drone_xy_m=xy("drone_position_m"),
        target_xy_m=xy("target_position_m"),
    )


def trajectory_sha256(infos: Sequence[dict]) -> str:
    """Hex SHA-256 of the frames' `TRAJECTORY_KEYS` as one row-major (T, 13) little-endian float64 array, NaN
    written as the one canonical NaN: equal hashes mean the same path, boxes and depths, bit for bit."""
    rows = [np.concatenate([np.ravel(np.asarray(info[key], dtype=np.float64)) for key in TRAJECTORY_KEYS])
            for info in infos]
    frames = np.concatenate(rows).astype(TRAJECTORY_DTYPE) if rows else np.empty(0, TRAJECTORY_DTYPE)
    frames[np.isnan(frames)] = np.nan
    return hashlib.sha256(frames.tobytes()).hexdigest()


def failed_result(spec: RunSpec, error: str, wall_s: float = float("nan")) -> RunResult:
    """The record of a run that ended without metrics; `error` is one line."""
    nan = float("nan")
    return RunResult(spec, {}, RunTiming(wall_s, nan, nan, nan), None, error)


def error_line(exc: BaseException) -> str:
    """`Type: message` on one line (the message's first line)."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def fly(spec: RunSpec, on_frame: FrameHook | None = None,
        render: bool = False, record_root: Path | None = None) -> tuple[list[dict], RunTiming]:
    """Fly one episode of `spec` (`trade_gym.rollout.fly_episode`); `on_frame(env, obs, info)` after reset and
    every step (e.g. to record video). With `record_root` the episode is also written as a sequence to
    `record_root/<run id>/episode_0000/`."""
    start = time.perf_counter()
    kwargs = spec.env_kwargs() | ({"render_mode": "rgb_array"} if render else {})
    base = TradeFollowEnv(**kwargs)
    env: gym.Env = base  # wrapped by the recorder when recording
    loop_start: list[float] = []  # when the reset returned

    def reset_done(flown: gym.Env, obs: dict, info: dict) -> None:
        loop_start.append(time.perf_counter())
        if on_frame is not None:
            on_frame(flown, obs, info)

    try:
        if record_root is not None:
            env = _recording(base, record_root / spec.run_id)
        policy = make_policy(spec.policy, spec.seed, base.config.camera_pitch_deg, base.action_scale, base.config)
        reset_start = time.perf_counter()
        infos = fly_episode(env, policy, spec.seed, spec.steps, on_reset=reset_done, on_step=on_frame)
        loop_s = time.perf_counter() - loop_start[0]
    finally:
        env.close()
    timing = RunTiming(time.perf_counter() - start, loop_start[0] - reset_start, loop_s,
                       metrics.steps_per_second(len(infos), loop_s))
    return infos, timing


def _recording(env: TradeFollowEnv, root: Path) -> gym.Wrapper:
    from trade_gym.recording import RecordSequence  # imports the stack's settings (OpenCV, filterpy)

    return RecordSequence(env, root)


def run_spec(spec: RunSpec, record_root: Path | None = None) -> RunResult:
    """Fly and score one run (recording it under `record_root` when given, see `fly`); an exception is recorded
    in `error` rather than raised."""
    start = time.perf_counter()
    try:
        infos, timing = fly(spec, record_root=record_root)
    except Exception as exc:  # noqa: BLE001 - one failed run must not end a long benchmark
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return failed_result(spec, f"{error_line(exc)} ({last.filename}:{last.lineno})", time.perf_counter() - start)
    return RunResult(spec, metrics.episode_metrics(infos), timing, _series(infos), None, trajectory_sha256(infos))


def estimated_cost(spec: RunSpec) -> float:
    """Rough cost of a run in oracle-step units (steps x per-step cost)."""
    return spec.steps * (1.0 if spec.perception == "oracle" else RENDERING_STEP_COST)


def run_all(specs: Sequence[RunSpec], jobs: int = 1,
            on_done: Callable[[int, int, RunResult], None] | None = None,
            executor: Executor | None = None) -> list[RunResult]:
    """Results of `specs` in their order, run by `executor` (default: `LocalExecutor(jobs)`: this process for
    `jobs` = 1, else that many worker processes). `on_done(n_done, n_total, result)` is called as each run
    finishes (in completion order)."""
    from trade_gym.bench.executors import LocalExecutor  # executors imports this module

    return (executor or LocalExecutor(jobs)).map(specs, on_done)
