"""Sensor faults for TradeFollow-v0: a frame-indexed, seeded fault schedule and the wrapper that injects it.

Owns `Fault` (kind, start frame, duration in frames, params), `FaultSchedule`, the `SensorFilter` hook of the env
and `SensorFaults`, a gymnasium Wrapper that applies a schedule through `TradeFollowEnv.set_sensor_filter` (and the
depth model for its faults).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol, cast

import cv2
import gymnasium as gym
import numpy as np
import numpy.typing as npt

from trade.geometry import Pose
from trade.types import ImuBatch
from trade.validation import is_finite_number, is_int_at_least, require
from trade_gym.ground_truth import GroundTruth
from trade_gym.perception.base import SensorFrame
from trade_gym.perception.trade_stack import TradePerception

if TYPE_CHECKING:
    from trade_gym.env import TradeFollowEnv

# Parameters of each kind and their defaults; a Fault's params override them.
# Overlapping faults apply in this order (the scene first, then the camera's delivery).
FAULT_PARAMS: dict[str, dict[str, Any]] = {
    "out_of_view": {"angle_deg": 135.0},  # camera rolled about the image vertical: looks above the horizon
    "occlusion": {"width_m": 6.0, "height_m": 4.0, "margin_m": 3.0, "level": 110},  # overpass over the path
    "blank": {"level": 0},  # the frame becomes one grey level: 0 black, 255 white
    "drop": {},  # no image is delivered (rgb None)
    "freeze": {},  # the previous delivered image with this frame's time and pose
    "duplicate": {},  # the previous delivered frame again: same image, time and pose
    "imu": {"value": math.nan, "samples": 0},  # samples (0: all in the window) get `value` on every axis
    "depth_model": {"output": "nan"},  # the depth model's map becomes "nan", "negative" or "constant"
}
FAULT_KINDS = tuple(FAULT_PARAMS)
DEPTH_OUTPUTS = ("nan", "negative", "constant")
HIDING_KINDS = ("blank", "drop")  # the delivered frame shows no target at all
FAULT_SEED_SALT = 0x5E5F  # fault draws use their own stream: the env's random stream is left untouched
UINT8_LEVELS = 256


@dataclass(frozen=True)
class Fault:
    """One fault: `kind` (see FAULT_PARAMS) on frames start_frame .. start_frame + duration_frames - 1.

    Frame 0 is the reset frame (never faulty: it initialises the tracker); step k delivers frame k. With
    `start_jitter_frames` J the start is drawn per episode in [start_frame, start_frame + J] (seeded).
    """

    kind: str
    start_frame: int
    duration_frames: int
    params: dict[str, Any] = field(default_factory=dict, hash=False)
    start_jitter_frames: int = 0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_PARAMS:
            raise ValueError(f"Fault.kind must be one of {FAULT_KINDS}, got {self.kind!r}")
        for name, low in (("start_frame", 1), ("duration_frames", 1), ("start_jitter_frames", 0)):
            value = getattr(self, name)
            require(is_int_at_least(value, low), f"Fault.{name}", value, f"an integer >= {low}")
        unknown = set(self.params) - set(FAULT_PARAMS[self.kind])
        if unknown:
            raise ValueError(f"Fault.params for {self.kind!r} accepts {sorted(FAULT_PARAMS[self.kind])}, "
                             f"got unknown {sorted(unknown)}")
        merged = {**FAULT_PARAMS[self.kind], **self.params}
        _check_params(self.kind, merged)
        object.__setattr__(self, "params", merged)


def _check_params(kind: str, params: dict[str, Any]) -> None:
    def number(name: str, low: float, high: float = math.inf, integer: bool = False) -> None:
        v = params[name]
        ok = is_int_at_least(v, low, numpy_ints=False) if integer else is_finite_number(v) and low <= v
        require(ok and v <= high, f"Fault.params[{name!r}] for {kind!r}", v,
                f"a finite {'integer' if integer else 'number'} in [{low}, {high}]")

    if kind in ("blank", "occlusion"):
        number("level", 0, UINT8_LEVELS - 1, integer=True)
    if kind == "imu":
        value, samples = params["value"], params["samples"]
        if not isinstance(value, float) or math.isfinite(value):
            raise ValueError(f"Fault.params['value'] for 'imu' must be nan or +-inf, got {value!r}")
        require(is_int_at_least(samples, 0, numpy_ints=False), "Fault.params['samples'] for 'imu'", samples,
                "an integer >= 0")
    if kind == "out_of_view":
        number("angle_deg", 0.0, 180.0)
    if kind == "occlusion":
        for name in ("width_m", "height_m", "margin_m"):
            number(name, 0.0)
    if kind == "depth_model" and params["output"] not in DEPTH_OUTPUTS:
        raise ValueError(f"Fault.params['output'] for 'depth_model' must be one of {DEPTH_OUTPUTS}, "
                         f"got {params['output']!r}")


@dataclass(frozen=True)
class FaultSchedule:
    """The faults of an episode (they may overlap; image faults apply in FAULT_KINDS order)."""

    faults: tuple[Fault, ...] = ()

    def __post_init__(self) -> None:
        faults = tuple(self.faults)
        bad = [f for f in faults if not isinstance(f, Fault)]
        if bad:
            raise ValueError(f"FaultSchedule.faults must hold Fault objects, got {bad!r}")
        object.__setattr__(self, "faults", faults)

    def draw_starts(self, rng: np.random.Generator) -> tuple[int, ...]:
        """Each fault's start frame this episode: start_frame + U{0..start_jitter_frames}."""
        return tuple(f.start_frame + int(rng.integers(0, f.start_jitter_frames + 1)) for f in self.faults)


class SensorFilter(Protocol):
    """Transforms what the sensors deliver before perception sees it (`TradeFollowEnv.set_sensor_filter`);
    `SensorFaults` injects faults through it. Unlike perception it sees the frame's ground truth."""

    def filter_camera_pose(self, T_world_cam: Pose) -> Pose:
        """The pose the camera actually has this frame, given its mounted pose; rendering, ground truth and
        the pose source all use the result (e.g. a camera knocked sideways)."""
        ...

    def filter_sensors(self, sensors: SensorFrame, truth: GroundTruth) -> SensorFrame:
        """The frame perception receives (e.g. blank, dropped: rgb None, stale, corrupt IMU samples);
        `truth` is read-only context (where the target is)."""
        ...


class SensorFaults(gym.Wrapper):
    """Injects a `FaultSchedule` into a TradeFollow-v0 env (also when wrapped, e.g. by `gym.make`).

    Image faults act on what perception receives (the simulator still renders the true frame; `render()`
    shows it), `out_of_view` turns the camera itself (rendering and ground truth see it), `depth_model` corrupts
    the single-image depth model's output (needs `ground_mask=True`; takes effect from the next reset). Fault
    draws come from a generator seeded by the reset seed, so the fault-free part of an episode matches the same
    episode without faults bit for bit. info gains `faults` (the kinds active this frame); `target_visible`
    (and `target_visible_fraction`) then describe the delivered image: False on blank or dropped frames and
    under the occluder.
    """

    _delivered: SensorFrame | None  # what perception received at the current frame
    _T_world_cam: Pose | None  # the camera's true pose at the current frame (after `filter_camera_pose`)

    def __init__(self, env: gym.Env, schedule: FaultSchedule) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "set_sensor_filter"):
            raise TypeError(f"SensorFaults needs a TradeFollow-v0 env, got {type(env.unwrapped).__name__}")
        self.schedule = schedule
        self._rng = np.random.default_rng(FAULT_SEED_SALT)
        self._starts = schedule.draw_starts(self._rng)
        self._frame = 0
        self._start_episode()
        self._install()

    # ----------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng([FAULT_SEED_SALT, seed])
        self._starts = self.schedule.draw_starts(self._rng)
        self._frame = 0
        self._start_episode()
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, self._annotate(info)

    def step(self, action):
        self._frame += 1
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._annotate(info)

    @property
    def _base(self) -> TradeFollowEnv:
        """The TradeFollow-v0 env under the wrappers (`__init__` checked it has the sensor-filter hook)."""
        return cast("TradeFollowEnv", self.env.unwrapped)

    @property
    def delivered(self) -> SensorFrame | None:
        """What perception received at the current frame (the faulty image, e.g. to draw it)."""
        return self._delivered

    @property
    def start_frames(self) -> tuple[int, ...]:
        """Each fault's start frame this episode (the schedule's, plus the drawn jitter)."""
        return self._starts

    def active(self, frame: int | None = None) -> tuple[Fault, ...]:
        """The faults active at `frame` (default: the current frame) this episode."""
        return tuple(f for _, f in self._active_items(frame))

    def _active_items(self, frame: int | None = None) -> list[tuple[int, Fault]]:
        """(index in the schedule, fault) of the faults active at `frame`, in FAULT_KINDS order."""
        k = self._frame if frame is None else frame
        items = [(i, f) for i, (f, s) in enumerate(zip(self.schedule.faults, self._starts))
                 if s <= k < s + f.duration_frames]
        return sorted(items, key=lambda item: FAULT_KINDS.index(item[1].kind))

    # ------------------------------------------------------------ SensorFilter
    def filter_camera_pose(self, T_world_cam: Pose) -> Pose:
        for fault in self.active():
            if fault.kind == "out_of_view":
                # roll about the camera's y axis (image vertical): R' = R Ry(angle); the heading is unchanged
                a = math.radians(fault.params["angle_deg"])
                Ry = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
                T_world_cam = T_world_cam.compose(Pose.unchecked(Ry, np.zeros(3)))
        self._T_world_cam = T_world_cam
        return T_world_cam

    def filter_sensors(self, sensors: SensorFrame, truth: GroundTruth) -> SensorFrame:
        self._hidden_fraction = 0.0
        for index, fault in self._active_items():
            sensors = self._apply(index, fault, sensors, truth)
        self._delivered = sensors
        return sensors

    # --------------------------------------------------------------- internals
    def _apply(self, index: int, fault: Fault, sensors: SensorFrame, truth: GroundTruth) -> SensorFrame:
        kind, prev = fault.kind, self._delivered
        if kind == "imu":
            return replace(sensors, imu=self._corrupt_imu(index, fault, sensors.imu))
        if sensors.rgb is None:
            return sensors  # nothing rendered (oracle mode): image faults have nothing to act on
        if kind in HIDING_KINDS:
            self._hidden_fraction = 1.0
            return replace(sensors, rgb=np.full_like(sensors.rgb, fault.params["level"]) if kind == "blank" else None)
        if kind == "duplicate" and prev is not None:
            return replace(prev, imu=sensors.imu)  # the IMU is a separate sensor: its samples are new
        if kind == "freeze" and prev is not None and prev.rgb is not None:
            return replace(sensors, rgb=prev.rgb)
        if kind == "occlusion":
            return replace(sensors, rgb=self._occlude(index, fault, sensors.rgb, sensors.t_s, truth))
        return sensors  # depth_model acts in the model; out_of_view on the camera pose

    def _corrupt_imu(self, index: int, fault: Fault, imu: ImuBatch) -> ImuBatch:
        """The first samples of the window (all of them when params samples == 0) read `value` on every axis."""
        limit = fault.params["samples"] or math.inf
        done = self._imu_corrupted.get(index, 0)
        n = int(min(len(imu.t_s), limit - done))
        if n <= 0:
            return imu
        self._imu_corrupted[index] = done + n
        accel, gyro = imu.accel_mps2.copy(), imu.gyro_radps.copy()
        accel[:n] = gyro[:n] = fault.params["value"]
        return ImuBatch(imu.t_s, accel, gyro)

    def _occlude(self, index: int, fault: Fault, rgb: npt.NDArray[np.uint8], t_s: float,
                 truth: GroundTruth) -> npt.NDArray[np.uint8]:
        """Paint the overpass (a flat roof along the target's path over the fault's window) into the image `rgb`
        of the frame at `t_s` [s], seen from the camera's true pose."""
        roof = self._roofs.get(index)
        if roof is None:  # built at the window's first frame
            roof = self._roofs[index] = self._roof_polygon(fault, t_s)
        if self._T_world_cam is None:
            raise RuntimeError("SensorFaults: filter_sensors before filter_camera_pose")
        points_cam = self._T_world_cam.inverse().apply(roof)
        if not np.all(points_cam[:, 2] > 0.0):
            return rgb  # part of the roof behind the camera: not drawn
        uv = self._base.camera.intrinsics.project(points_cam)
        mask = np.zeros(rgb.shape[:2], np.uint8)
        cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], 1)
        out = rgb.copy()
        out[mask.astype(bool)] = fault.params["level"]
        box = truth.target_bbox
        if np.all(np.isfinite(box)):
            x0, y0 = max(int(box[0]), 0), max(int(box[1]), 0)
            x1, y1 = int(math.ceil(box[0] + box[2])), int(math.ceil(box[1] + box[3]))
            covered = mask[y0:y1, x0:x1]
            self._hidden_fraction = max(self._hidden_fraction, float(covered.mean()) if covered.size else 0.0)
        return out

    def _roof_polygon(self, fault: Fault, t0_s: float) -> npt.NDArray[np.float64]:
        """(2N, 3) world outline [m] of a roof width_m wide, height_m above the target's centre, along the
        target's path over the window starting at t0_s [s], extended by margin_m at both ends."""
        base = self._base
        world, prm, dt, t0 = base.world, fault.params, base.config.frame_dt_s, t0_s
        path = np.array([world.vehicle_pose(world.target, t0 + k * dt)[0] for k in range(fault.duration_frames)])
        heading = world.vehicle_pose(world.target, t0)[1][:, 0]
        steps = np.diff(path, axis=0)
        first = steps[0] if len(steps) and np.linalg.norm(steps[0][:2]) > 0 else heading
        last = steps[-1] if len(steps) and np.linalg.norm(steps[-1][:2]) > 0 else heading
        margin = prm["margin_m"]
        path = np.vstack([path[0] - margin * _unit_xy(first), path, path[-1] + margin * _unit_xy(last)])
        # direction at each point from its neighbours (one-sided at the ends); normal n = (-u_y, u_x, 0)
        u = np.array([_unit_xy(d) for d in np.gradient(path, axis=0)])
        normal = np.stack([-u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
        roof = path + np.array([0.0, 0.0, prm["height_m"]])
        half = prm["width_m"] / 2.0
        return np.vstack([roof + half * normal, (roof - half * normal)[::-1]])

    def _annotate(self, info: dict[str, Any]) -> dict[str, Any]:
        active = self.active()
        info["faults"] = tuple(f.kind for f in active)
        if self._hidden_fraction > 0.0:
            fraction = info["target_visible_fraction"] * (1.0 - self._hidden_fraction)
            info["target_visible_fraction"] = fraction
            info["target_visible"] = fraction >= self._base.config.visible_fraction_threshold
        self._hidden_fraction = 0.0
        return info

    def _start_episode(self) -> None:
        self._delivered = None
        self._T_world_cam = None
        self._hidden_fraction = 0.0
        self._imu_corrupted: dict[int, int] = {}  # samples corrupted so far, by fault index
        self._roofs: dict[int, npt.NDArray[np.float64]] = {}  # occluder outlines, by fault index

    def _install(self) -> None:
        base = self._base
        base.set_sensor_filter(self)
        if any(f.kind == "depth_model" for f in self.schedule.faults):
            perception = base.perception
            if not isinstance(perception, TradePerception) or perception.depth_model is None:
                raise ValueError("depth_model faults need a perception with a depth model "
                                 "(perception='trade' or 'dcf' with ground_mask=True)")
            if not isinstance(perception.depth_model, _FaultyDepthModel):
                perception.depth_model = _FaultyDepthModel(perception.depth_model, self)

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._install()  # the unpickled env has a fresh simulator without the filter


class _FaultyDepthModel:
    """A depth model whose output the active `depth_model` faults corrupt (NaN, negative or constant)."""

    def __init__(self, model: Any, faults: SensorFaults) -> None:
        self.model, self.faults = model, faults

    def predict(self, rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.float32]:
        inv = self.model.predict(rgb)
        for fault in self.faults.active():
            if fault.kind == "depth_model":
                output = fault.params["output"]
                if output == "nan":
                    inv = np.full_like(inv, np.nan)
                elif output == "negative":
                    inv = -inv - 1.0  # every value < 0
                else:
                    inv = np.full_like(inv, inv.mean())
        return inv


def _unit_xy(v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(3,) horizontal unit vector along v (x, y) [-]; (1, 0, 0) for a vertical or zero v."""
    x, y = float(v[0]), float(v[1])
    n = math.hypot(x, y)
    return np.array([x / n, y / n, 0.0]) if n > 0.0 else np.array([1.0, 0.0, 0.0])
