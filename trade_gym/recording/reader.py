"""Reads and checks a sequence folder (docs/sequence_format.md): meta.json, frames.jsonl and the files they name.

`open_sequence` checks everything but the pixels before anything runs (format version, every line, rigid poses,
every named file present and, for PNGs, complete); decoding a frame's image that is still bad raises the same
one-line `SequenceError` naming the file and the frame.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image

from trade.geometry import CameraIntrinsics, Pose
from trade.types import ImuBatch
from trade_gym.recording.format import (DEPTH_ARRAY, FORMAT_NAME, FORMAT_VERSION, FRAMES_FILE, KINDS, META_FILE,
                                        VEHICLE_ROLES, FrameTruth, SequenceError, VehicleTruth, decode_box,
                                        decode_intrinsics, decode_pose, decode_real, decode_reals)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"  # the IEND chunk's type and CRC: the last 8 bytes of a complete PNG
IMU_COLUMNS = 3


@dataclass(frozen=True, eq=False)
class SequenceFrame:
    """One frames.jsonl line, decoded: files as absolute paths (None when absent), poses, IMU, truth."""

    index: int
    t_s: float
    rgb_file: Path | None
    T_world_cam: Pose
    depth_file: Path | None = None
    seg_file: Path | None = None
    T_world_cam_true: Pose | None = None
    imu: ImuBatch | None = None
    truth: FrameTruth | None = None
    faults: tuple[str, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Sequence:
    """A checked sequence: its folder, meta.json as read, the camera and every frame."""

    path: Path
    meta: dict[str, Any]
    intrinsics: CameraIntrinsics
    frames: tuple[SequenceFrame, ...]

    @property
    def kind(self) -> str:
        return self.meta["kind"]

    @property
    def initial_bbox_xywh_px(self) -> npt.NDArray[np.float64] | None:
        value = self.meta.get("initial_bbox_xywh_px")
        return None if value is None else decode_box(value)

    @property
    def has_truth(self) -> bool:
        """Whether every frame carries ground truth (then a replay is scored like trade-bench)."""
        return bool(self.frames) and all(f.truth is not None for f in self.frames)

    def __iter__(self) -> Iterator[SequenceFrame]:
        return iter(self.frames)

    def __len__(self) -> int:
        return len(self.frames)

    def rgb(self, frame: SequenceFrame) -> npt.NDArray[np.uint8] | None:
        """(H, W, 3) uint8 image of `frame`, None when no image was delivered."""
        if frame.rgb_file is None:
            return None
        image = _read_png(frame.rgb_file, frame.index)
        K = self.intrinsics
        if image.mode != "RGB":
            raise SequenceError(frame.rgb_file, f"expected an 8-bit RGB PNG, got mode {image.mode}", frame.index)
        rgb = np.asarray(image)
        if rgb.shape != (K.height_px, K.width_px, 3):
            raise SequenceError(frame.rgb_file, f"image is {rgb.shape[1]}x{rgb.shape[0]} px, the camera "
                                f"{K.width_px}x{K.height_px}", frame.index)
        return rgb

    def depth_m(self, frame: SequenceFrame) -> npt.NDArray[np.float32] | None:
        """(H, W) float32 camera-frame z [m] of `frame`, None when the frame has no depth layer."""
        if frame.depth_file is None:
            return None
        try:
            with np.load(frame.depth_file) as archive:
                depth = np.asarray(archive[DEPTH_ARRAY], dtype=np.float32)
        except (OSError, ValueError, KeyError, EOFError) as exc:
            raise SequenceError(frame.depth_file, f"unreadable depth npz ({_one_line(exc)})", frame.index) from None
        K = self.intrinsics
        if depth.shape != (K.height_px, K.width_px):
            raise SequenceError(frame.depth_file, f"depth is {depth.shape}, the camera {(K.height_px, K.width_px)}",
                                frame.index)
        return depth

    def seg(self, frame: SequenceFrame) -> npt.NDArray[np.uint16] | None:
        """(H, W) uint16 vehicle instance ids of `frame` (0: none), None when the frame has no seg layer."""
        if frame.seg_file is None:
            return None
        ids = np.asarray(_read_png(frame.seg_file, frame.index))
        if ids.ndim != 2:
            raise SequenceError(frame.seg_file, f"expected a one-channel 16-bit PNG, got shape {ids.shape}", frame.index)
        return ids.astype(np.uint16)


def open_sequence(path: Path | str) -> Sequence:
    """Read and check the sequence folder `path`; `SequenceError` (one line, naming the file and the frame)
    for a missing or malformed meta.json or frames.jsonl, another format version, a pose that is not a rigid
    transform, or a named file that is missing or (a PNG) truncated."""
    folder = Path(path)
    if not folder.is_dir():
        raise SequenceError(folder, "no such sequence folder")
    meta_path = folder / META_FILE
    meta = _read_json(meta_path)
    intrinsics = _check_meta(meta_path, meta)
    frames_path = folder / FRAMES_FILE
    if not frames_path.is_file():
        raise SequenceError(frames_path, "missing")
    frames = tuple(_frames(folder, frames_path))
    if meta["frame_count"] != len(frames):
        raise SequenceError(meta_path, f"frame_count is {meta['frame_count']} but {FRAMES_FILE} has {len(frames)} lines")
    for frame in frames:
        for file in (frame.rgb_file, frame.depth_file, frame.seg_file):
            if file is not None:
                _check_file(file, frame.index)
    return Sequence(folder, meta, intrinsics, frames)


# ------------------------------------------------------------------------------------------ meta.json
def _read_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise SequenceError(path, "missing")
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SequenceError(path, f"not valid JSON ({_one_line(exc)})") from None
    if not isinstance(value, dict):
        raise SequenceError(path, f"expected a JSON object, got {type(value).__name__}")
    return value


def _check_meta(path: Path, meta: dict[str, Any]) -> CameraIntrinsics:
    if meta.get("format") != FORMAT_NAME:
        raise SequenceError(path, f"format must be {FORMAT_NAME!r}, got {meta.get('format')!r}")
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        raise SequenceError(path, f"format_version {version!r}: this reader reads version {FORMAT_VERSION}")
    if meta.get("kind") not in KINDS:
        raise SequenceError(path, f"kind must be one of {KINDS}, got {meta.get('kind')!r}")
    count = meta.get("frame_count")
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise SequenceError(path, f"frame_count must be an integer >= 0, got {count!r}")
    try:
        intrinsics = decode_intrinsics(meta.get("camera"))
        if meta.get("initial_bbox_xywh_px") is not None:
            decode_box(meta["initial_bbox_xywh_px"])
    except (ValueError, TypeError) as exc:
        raise SequenceError(path, _one_line(exc)) from None
    return intrinsics


# --------------------------------------------------------------------------------------- frames.jsonl
def _frames(folder: Path, path: Path) -> Iterator[SequenceFrame]:
    with open(path, encoding="utf-8") as lines:
        for index, text in enumerate(lines):
            try:
                line = json.loads(text)
            except json.JSONDecodeError as exc:
                raise SequenceError(path, f"line {index + 1} is not valid JSON ({_one_line(exc)})", index) from None
            try:
                yield _frame(folder, index, line)
            except (ValueError, TypeError, KeyError) as exc:
                if isinstance(exc, SequenceError):
                    raise
                what = f"missing field {exc}" if isinstance(exc, KeyError) else _one_line(exc)
                raise SequenceError(path, what, index) from None


def _frame(folder: Path, index: int, line: Any) -> SequenceFrame:
    if not isinstance(line, dict):
        raise ValueError(f"a line must be a JSON object, got {type(line).__name__}")
    if line["frame"] != index:
        raise ValueError(f"field frame is {line['frame']!r} on the line of frame {index}")
    t_s = decode_real(line["t_s"])
    if not math.isfinite(t_s):
        raise ValueError(f"t_s must be finite, got {line['t_s']!r}")
    poses = {}
    for name in ("T_world_cam", "T_world_cam_true"):
        if name in line:
            try:
                poses[name] = decode_pose(line[name])
            except ValueError as exc:
                raise ValueError(f"{name}: {exc}") from None
    if "T_world_cam" not in poses:
        raise KeyError("T_world_cam")
    return SequenceFrame(
        index=index,
        t_s=t_s,
        rgb_file=_file(folder, line["rgb"], "rgb"),
        T_world_cam=poses["T_world_cam"],
        depth_file=_file(folder, line.get("depth"), "depth"),
        seg_file=_file(folder, line.get("seg"), "seg"),
        T_world_cam_true=poses.get("T_world_cam_true"),
        imu=_imu(line["imu"]) if "imu" in line else None,
        truth=_truth(line["truth"]) if line.get("truth") is not None else None,
        faults=tuple(str(k) for k in line.get("faults", ())),
        extra=dict(line.get("extra", {})),
    )


def _file(folder: Path, value: Any, name: str) -> Path | None:
    """The absolute path of a file the line names, which must lie inside the sequence folder."""
    if value is None:
        return None
    if not isinstance(value, str) or not value or Path(value).is_absolute() or ".." in Path(value).parts:
        raise ValueError(f"{name} must be a path relative to the sequence folder, inside it, got {value!r}")
    return folder / value


def _imu(value: Any) -> ImuBatch:
    t = np.asarray(value["t_s"], dtype=object)
    if t.ndim != 1:
        raise ValueError(f"imu.t_s must be a list of times, got {value['t_s']!r}")
    n = len(t)
    return ImuBatch(decode_reals(value["t_s"], (n,)), _samples(value["accel_body_mps2"], n, "accel_body_mps2"),
                    _samples(value["gyro_body_radps"], n, "gyro_body_radps"))


def _samples(value: Any, n: int, name: str) -> npt.NDArray[np.float64]:
    try:
        return decode_reals(value, (n, IMU_COLUMNS)) if n else np.zeros((0, IMU_COLUMNS))
    except ValueError as exc:
        raise ValueError(f"imu.{name}: {exc}") from None


def _vector(value: Any) -> npt.NDArray[np.float64]:
    return np.full(3, np.nan) if value is None else decode_reals(value, (3,))


def _truth(value: dict[str, Any]) -> FrameTruth:
    vehicles = []
    for v in value.get("vehicles", ()):
        if v.get("role") not in VEHICLE_ROLES:
            raise ValueError(f"truth.vehicles: role must be one of {VEHICLE_ROLES}, got {v.get('role')!r}")
        vehicles.append(VehicleTruth(int(v["instance_id"]), str(v["class"]), v["role"], decode_box(v["bbox_xywh_px"])))
    return FrameTruth(
        target_bbox_xywh_px=decode_box(value.get("target_bbox_xywh_px")),
        target_visible_fraction=decode_real(value.get("target_visible_fraction")),
        target_depth_m=decode_real(value.get("target_depth_m")),
        ground_depth_m=decode_real(value.get("ground_depth_m")),
        target_position_world_m=_vector(value.get("target_position_world_m")),
        target_velocity_world_mps=_vector(value.get("target_velocity_world_mps")),
        drone_position_world_m=_vector(value.get("drone_position_world_m")),
        crashed=bool(value.get("crashed", False)),
        following=None if value.get("following") is None else bool(value["following"]),
        vehicles=tuple(vehicles),
        t_s=decode_real(value.get("t_s")),
    )


# -------------------------------------------------------------------------------------------- files
def _check_file(path: Path, index: int) -> None:
    """The file exists; a PNG starts with the PNG signature and ends with the IEND chunk (else truncated)."""
    if not path.is_file():
        raise SequenceError(path, "missing", index)
    if path.suffix.lower() != ".png":
        return
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(len(PNG_SIGNATURE))
        f.seek(max(size - len(PNG_END), 0))
        tail = f.read()
    if head != PNG_SIGNATURE:
        raise SequenceError(path, "not a PNG file", index)
    if tail != PNG_END:
        raise SequenceError(path, f"truncated PNG ({size} bytes, no IEND chunk at the end)", index)


def _read_png(path: Path, index: int) -> Image.Image:
    try:
        with Image.open(path) as image:
            image.load()
            return image
    except (OSError, SyntaxError, ValueError) as exc:  # PIL raises OSError for truncated data, SyntaxError for bad chunks
        raise SequenceError(path, f"unreadable PNG ({_one_line(exc)})", index) from None


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__
