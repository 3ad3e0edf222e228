"""The recorded-sequence format (docs/sequence_format.md): its version, folder layout and the records of a frame.

Owns `FORMAT_VERSION`, the file names, `SequenceError` (one line naming the file and the frame), the frozen
records a writer takes and a reader returns, and the JSON encoding of numbers and poses both share.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from trade.geometry import CameraIntrinsics, Pose
from trade.types import ImuBatch

FloatArray = npt.NDArray[np.float64]

FORMAT_NAME = "trade-sequence"
FORMAT_VERSION = 1
META_FILE = "meta.json"
FRAMES_FILE = "frames.jsonl"
RGB_DIR, DEPTH_DIR, SEG_DIR = "frames", "depth", "seg"
RGB_SUFFIX, DEPTH_SUFFIX, SEG_SUFFIX = ".png", ".npz", ".png"
DEPTH_ARRAY = "depth_m"  # the array in each depth/NNNNNN.npz
FRAME_DIGITS = 6
SCHEMA_FILE = "sequence.schema.json"
# Kinds of sequence: a flight (frames in capture order, replayable) or independent views (a data set: each
# frame its own pose and time, no IMU, not replayable).
KINDS = ("flight", "views")
# Non-finite numbers in JSON: null is NaN (no value), these strings are the infinities (a faulty IMU's samples).
POS_INF, NEG_INF = "+inf", "-inf"
# A pose is rigid when max |R^T R - I| and |det R - 1| are at most this, and its last row is (0, 0, 0, 1).
RIGID_TOLERANCE = 1e-6
BACKGROUND_INSTANCE_ID = 0  # seg/ pixels showing no vehicle (terrain, buildings, sky)
VEHICLE_ROLES = ("target", "decoy")
# Settings of meta.json's perception.pipeline_config renamed within format version 1 (to the env's names of the
# same switches): a recording made before reads under the new names.
RENAMED_SETTINGS = {"depth_alignment_ransac": "depth_only_ransac", "snap_initial_box": "snap_init_box"}


class SequenceError(ValueError):
    """A sequence that cannot be read: one line naming the file (its path) and, when it is one frame's, the
    frame index."""

    def __init__(self, path: Path | str, what: str, frame: int | None = None) -> None:
        self.path, self.frame = Path(path), frame
        where = f"{path}: frame {frame}" if frame is not None else f"{path}"
        super().__init__(f"{where}: {what}")


def current_setting_names(settings: Any) -> Any:
    """A recorded pipeline_config (nested mappings) with each RENAMED_SETTINGS key under its new name."""
    if not isinstance(settings, dict):
        return settings
    return {RENAMED_SETTINGS.get(key, key): current_setting_names(value) for key, value in settings.items()}


def frame_file(directory: str, frame: int, suffix: str) -> str:
    """The path of frame `frame`'s file in `directory`, relative to the sequence folder ("frames/000012.png")."""
    return f"{directory}/{frame:0{FRAME_DIGITS}d}{suffix}"


def schema_path() -> Path:
    """The JSON schema of meta.json and of one frames.jsonl line (package data beside this module)."""
    return Path(str(resources.files("trade_gym.recording").joinpath(SCHEMA_FILE)))


SCHEMA_PARTS = ("meta", "frame")


def load_schema(part: str) -> dict[str, Any]:
    """The schema of one document, `part` "meta" (meta.json) or "frame" (a frames.jsonl line), for a JSON
    schema validator (`jsonschema.validate(document, load_schema("meta"))`)."""
    if part not in SCHEMA_PARTS:
        raise ValueError(f"part must be one of {SCHEMA_PARTS}, got {part!r}")
    schema = json.loads(schema_path().read_text(encoding="utf-8"))
    return {"$schema": schema["$schema"], "$defs": schema["$defs"], "$ref": f"#/$defs/{part}"}


@dataclass(frozen=True)
class VehicleTruth:
    """One vehicle at one frame: its instance id (the value of its pixels in seg/), class (vehicle kind),
    role (target or decoy) and visible box (4,) x, y, w, h [px], NaN when not in view."""

    instance_id: int
    vehicle_class: str
    role: str
    bbox_xywh_px: FloatArray

    def __post_init__(self) -> None:
        if self.role not in VEHICLE_ROLES:
            raise ValueError(f"VehicleTruth.role must be one of {VEHICLE_ROLES}, got {self.role!r}")
        if isinstance(self.instance_id, bool) or int(self.instance_id) != self.instance_id or self.instance_id < 1:
            raise ValueError(f"VehicleTruth.instance_id must be an integer >= 1, got {self.instance_id!r}")


@dataclass(frozen=True)
class FrameTruth:
    """Ground truth of one frame (NaN where unknown): the target's visible box (4,) x, y, w, h [px], the
    fraction of it visible [-], its camera-frame depth [m] and the ground depth under its box centre's ray [m];
    world positions (3,) [m] and velocity (3,) [m/s]; whether the drone crashed; every vehicle; the true time
    of the frame [s] (not the delivered stamp when a fault re-delivered an earlier frame)."""

    target_bbox_xywh_px: FloatArray
    target_visible_fraction: float = math.nan
    target_depth_m: float = math.nan
    ground_depth_m: float = math.nan
    target_position_world_m: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    target_velocity_world_mps: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    drone_position_world_m: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    crashed: bool = False
    vehicles: tuple[VehicleTruth, ...] = ()
    t_s: float = math.nan
    following: bool | None = None  # the drone in the following band (`trade_gym.scoring.FollowBand`); None: unknown

    def decoy_bboxes_in_view(self) -> list[tuple[float, ...]]:
        """The decoys' boxes that are in view, as the env's `info["decoy_bboxes"]`."""
        return [tuple(v.bbox_xywh_px.tolist()) for v in self.vehicles
                if v.role == "decoy" and np.all(np.isfinite(v.bbox_xywh_px))]


@dataclass(frozen=True, eq=False)
class FrameRecord:
    """One frame as perception received it, and what is known about it.

    rgb (H, W, 3) uint8 or None (no image delivered); T_world_cam from the pose source; T_world_cam_true the
    exact pose when known; imu the samples of the frame interval (body frame); depth_m (H, W) camera-frame z [m]
    and seg (H, W) instance ids as rendered (optional layers); faults active at the frame; `extra` a producer's
    own JSON-safe fields."""

    t_s: float
    rgb: npt.NDArray[np.uint8] | None
    T_world_cam: Pose
    T_world_cam_true: Pose | None = None
    imu: ImuBatch | None = None
    truth: FrameTruth | None = None
    depth_m: npt.NDArray[np.float32] | None = None
    seg: npt.NDArray[np.uint16] | None = None
    faults: tuple[str, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- JSON numbers and poses
def encode_real(value: float) -> float | str | None:
    """A float as JSON: itself when finite, null for NaN, "+inf" / "-inf" for the infinities."""
    x = float(value)
    if math.isfinite(x):
        return x
    if math.isnan(x):
        return None
    return POS_INF if x > 0 else NEG_INF


def decode_real(value: Any) -> float:
    """The inverse of `encode_real`; ValueError for anything else."""
    if value is None:
        return math.nan
    if value == POS_INF:
        return math.inf
    if value == NEG_INF:
        return -math.inf
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"expected a number, null, {POS_INF!r} or {NEG_INF!r}, got {value!r}")
    return float(value)


def encode_reals(values: npt.ArrayLike) -> Any:
    """An array of floats as nested JSON lists (`encode_real` for each entry)."""
    a = np.asarray(values, dtype=np.float64)
    if a.ndim == 0:
        return encode_real(float(a))
    if np.all(np.isfinite(a)):
        return a.tolist()  # float reprs round-trip exactly
    return [encode_reals(row) for row in a]


def decode_reals(values: Any, shape: tuple[int, ...]) -> FloatArray:
    """Nested JSON lists as a float64 array of `shape` (`decode_real` for each entry); ValueError naming the
    shape when they do not fit."""
    try:
        nested = np.array(values, dtype=object)
    except ValueError:  # ragged lists
        nested = None
    if nested is None or nested.shape != shape:
        raise ValueError(f"expected numbers of shape {shape}, got {_short(values)}")
    return np.array([decode_real(v) for v in nested.reshape(-1)], dtype=np.float64).reshape(shape)


def encode_box(box: npt.ArrayLike | None) -> list[float] | None:
    """(4,) x, y, w, h [px] as a JSON list; null when missing (None or any NaN)."""
    if box is None:
        return None
    b = np.asarray(box, dtype=np.float64).reshape(4)
    return b.tolist() if np.all(np.isfinite(b)) else None


def decode_box(value: Any) -> FloatArray:
    """A JSON box (or null) as (4,) x, y, w, h [px], NaN when missing; ValueError for a box of no area."""
    if value is None:
        return np.full(4, np.nan)
    box = decode_reals(value, (4,))
    if not (np.all(np.isfinite(box)) and box[2] > 0 and box[3] > 0):
        raise ValueError(f"a box is four finite numbers x, y, w, h with w, h > 0, got {_short(value)}")
    return box


def encode_pose(pose: Pose) -> list[list[float]]:
    """T_world_cam as its 4x4 homogeneous matrix, row-major."""
    return pose.matrix.tolist()


def decode_pose(value: Any) -> Pose:
    """A 4x4 row-major matrix as a Pose; ValueError when it is not a rigid transform (rotation part orthonormal
    with determinant +1 within RIGID_TOLERANCE, last row 0 0 0 1)."""
    T = decode_reals(value, (4, 4))
    if not np.all(np.isfinite(T)):
        raise ValueError("pose has non-finite entries")
    R = T[:3, :3]
    orthogonality = float(np.max(np.abs(R.T @ R - np.eye(3))))
    det = float(np.linalg.det(R))
    if orthogonality > RIGID_TOLERANCE or abs(det - 1.0) > RIGID_TOLERANCE:
        raise ValueError(f"pose is not a rigid transform: max |R^T R - I| = {orthogonality:.3g}, det R = {det:.6g} "
                         f"(tolerance {RIGID_TOLERANCE:g})")
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"pose's last row must be 0 0 0 1, got {T[3].tolist()}")
    return Pose(R.copy(), T[:3, 3].copy())


def encode_intrinsics(K: CameraIntrinsics) -> dict[str, Any]:
    return {"model": "pinhole", "width_px": K.width_px, "height_px": K.height_px, "fx_px": K.fx_px,
            "fy_px": K.fy_px, "cx_px": K.cx_px, "cy_px": K.cy_px}


def decode_intrinsics(value: Any) -> CameraIntrinsics:
    if not isinstance(value, dict):
        raise ValueError(f"camera must be an object, got {_short(value)}")
    missing = [k for k in ("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px") if k not in value]
    if missing:
        raise ValueError(f"camera lacks {', '.join(missing)}")
    return CameraIntrinsics(float(value["fx_px"]), float(value["fy_px"]), float(value["cx_px"]),
                            float(value["cy_px"]), value["width_px"], value["height_px"])


def json_safe(value: Any) -> Any:
    """`value` with every float encoded by `encode_real` (dicts, lists and tuples walked), for strict JSON."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return encode_real(float(value))
    return value


def _short(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."
