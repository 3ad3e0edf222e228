"""Perception latency: which estimate the observation holds at each camera frame.

Owns `EstimateDelay`, a queue of estimates stamped with their frame's time and their arrival time: the estimate
of frame k arrives at the first frame j with t_j >= t_k + latency_k, and the observation holds the newest arrived;
and `HeldEstimates`, the env's use of it: each frame's scored estimate in, the one its observation holds out, its box
carried by the camera's rotation since its frame where the config asks for it (`EnvConfig.latency_compensation`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Generic, TypeVar

from trade.geometry import CameraIntrinsics, Pose, RotationWarp
from trade_gym.scoring import ScoredEstimate

if TYPE_CHECKING:
    from trade_gym.config import EnvConfig

# An estimate due at t counts as arrived at a frame of time >= t - tolerance [s]: the accumulated physics time
# drifts by ~1e-15 s per frame, so a latency of a whole number of frames lands on its frame.
ARRIVAL_TOLERANCE_S = 1e-9

E = TypeVar("E")  # what is delayed: the env's scored estimate with its frame's camera pose (`HeldEstimates`)


@dataclass(frozen=True)
class Delivered(Generic[E]):
    """The estimate an observation holds and the time [s] of the frame it was computed from."""

    estimate: E
    frame_t_s: float


@dataclass(frozen=True)
class _Pending(Generic[E]):
    arrival_t_s: float
    delivered: Delivered[E]


class EstimateDelay(Generic[E]):
    """Delays each frame's estimate by its latency; `deliver(t)` returns the newest estimate (by frame time) that
    has arrived by t. An estimate arriving after a newer one is dropped (the newer one already replaced it), so
    with latencies that vary per frame the observation never goes back in time. Until the first estimate
    arrives the observation holds `missing` (a missing estimate), dated at the reset frame."""

    def __init__(self, reset_t_s: float, missing: E) -> None:
        self._pending: list[_Pending[E]] = []
        self._current = Delivered(missing, float(reset_t_s))

    def push(self, estimate: E, frame_t_s: float, latency_s: float) -> None:
        """The estimate of the frame at `frame_t_s` [s], arriving `latency_s` [s] (>= 0) later."""
        if not latency_s >= 0.0:
            raise ValueError(f"latency_s must be >= 0, got {latency_s!r}")
        self._pending.append(_Pending(frame_t_s + latency_s, Delivered(estimate, frame_t_s)))

    def deliver(self, t_s: float) -> Delivered[E]:
        """The estimate the observation at time `t_s` [s] holds: the newest arrived by then."""
        due = t_s + ARRIVAL_TOLERANCE_S
        arrived = [e for e in self._pending if e.arrival_t_s <= due]
        if arrived:
            self._pending = [e for e in self._pending if e.arrival_t_s > due]
            newest = max(arrived, key=lambda e: e.delivered.frame_t_s).delivered
            if newest.frame_t_s >= self._current.frame_t_s:
                self._current = newest
        return self._current


class HeldEstimates:
    """The estimate each observation holds under a config's latency mode (`EnvConfig.perception_latency`, not "none"):
    `hold` takes a frame's scored estimate, the wall-clock time perception took on it and the camera pose perception
    received, and returns the estimate held and its age [s]. With `latency_compensation` the box of an earlier frame's
    estimate is carried to the current image by the camera's rotation between the two frames' poses (perception's, not
    the true ones: `trade.geometry.RotationWarp`); its other entries are its frame's."""

    def __init__(self, config: EnvConfig, intrinsics: CameraIntrinsics, reset_t_s: float) -> None:
        self._measured = config.perception_latency == "measured"
        self._latency_s = config.perception_latency_s
        self._compensate = config.latency_compensation
        self._intrinsics = intrinsics
        missing: tuple[ScoredEstimate, Pose | None] = (ScoredEstimate.missing(), None)
        self._delay: EstimateDelay[tuple[ScoredEstimate, Pose | None]] = EstimateDelay(reset_t_s, missing)

    def hold(self, scored: ScoredEstimate, t_s: float, compute_s: float,
             T_world_cam_est: Pose) -> tuple[ScoredEstimate, float]:
        """(the estimate the observation at `t_s` [s] holds, its age [s]) after this frame's `scored` estimate."""
        self._delay.push((scored, T_world_cam_est), t_s, compute_s if self._measured else self._latency_s)
        delivered = self._delay.deliver(t_s)
        held, T_world_cam_then = delivered.estimate
        age_s = t_s - delivered.frame_t_s
        if self._compensate and T_world_cam_then is not None and age_s > 0.0:
            warp = RotationWarp.between(self._intrinsics, T_world_cam_then, T_world_cam_est)
            held = replace(held, estimate=replace(held.estimate, bbox=warp.apply_box(held.estimate.bbox)))
        return held, age_s
