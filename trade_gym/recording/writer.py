"""Writes one sequence folder (docs/sequence_format.md): PNG frames, optional depth and instance-id layers,
frames.jsonl and meta.json, all into a hidden temporary folder that is renamed into place when complete.

The one image writer of the repository: the recording wrapper, `trade-bench --record` and the depth model's
data set all write through `SequenceWriter`.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, Any

import cv2
import numpy as np

from trade.geometry import CameraIntrinsics
from trade.validation import is_int_at_least, require
from trade_gym.recording.format import (DEPTH_ARRAY, DEPTH_DIR, DEPTH_SUFFIX, FORMAT_NAME, FORMAT_VERSION,
                                        FRAMES_FILE, KINDS, META_FILE, RGB_DIR, RGB_SUFFIX, SEG_DIR, SEG_SUFFIX,
                                        BACKGROUND_INSTANCE_ID, FrameRecord, encode_box, encode_intrinsics,
                                        encode_pose, encode_real, encode_reals, frame_file, json_safe)

# cv2's PNG level (0-9): 1 is the fastest that still deflates; renders shrink to about 60 % of level 0's size.
DEFAULT_PNG_COMPRESSION = 1
MAX_PNG_COMPRESSION = 9
PARTIAL_SUFFIX = ".partial"
UINT16_MAX = 2**16 - 1

# Units and frames of every field, copied into each meta.json so that a sequence describes itself.
FIELD_DOCS: dict[str, str] = {
    "frame": "index of the frame, 0 the first (the tracker is initialised on it)",
    "t_s": "capture time [s] since the recording's clock start; non-decreasing in a flight",
    "rgb": "path of the frame's 8-bit RGB PNG relative to the sequence folder; null: no image was delivered",
    "depth": "path of the frame's depth .npz (array depth_m, float32, camera-frame z [m])",
    "seg": "path of the frame's 16-bit PNG of vehicle instance ids (0: no vehicle)",
    "T_world_cam": "4x4 row-major rigid transform mapping camera points (OpenCV: x right, y down, z forward) "
                   "to world points (z up) [m], from the pose source perception received",
    "T_world_cam_true": "the same for the exact camera pose, when known",
    "imu.t_s": "IMU sample times [s] in the frame interval (after the previous frame, up to this one)",
    "imu.accel_body_mps2": "specific force per sample [m/s^2], body frame (x forward, y left, z up; "
                           "+9.81 on z when hovering)",
    "imu.gyro_body_radps": "angular rate per sample [rad/s], body frame",
    "truth.t_s": "the simulator's time at the frame [s]; differs from t_s where a fault re-delivered an earlier frame",
    "truth.target_bbox_xywh_px": "target's visible box x, y (top-left), w, h [px]; null when not in view",
    "truth.target_visible_fraction": "fraction of the target visible in the delivered image [-]",
    "truth.target_depth_m": "camera-frame z of the target's box centre [m]",
    "truth.ground_depth_m": "camera-frame z of the static surface on the target box centre's ray [m]",
    "truth.target_position_world_m": "target's box centre, world frame [m]",
    "truth.target_velocity_world_mps": "target's velocity, world frame [m/s]",
    "truth.drone_position_world_m": "drone's body origin, world frame [m]",
    "truth.crashed": "the drone hit terrain or a building in this frame's interval",
    "truth.following": "the drone in the env's following band this frame (null: not recorded)",
    "truth.vehicles": "every vehicle: instance_id (its seg/ value), class (vehicle kind), role (target or "
                      "decoy), bbox_xywh_px (visible box [px], null when not in view)",
    "faults": "sensor faults active at the frame (trade_gym.faults kinds)",
    "extra": "fields of the producer's own",
    "non-finite numbers": "null is NaN (no value); the strings \"+inf\" and \"-inf\" are the infinities",
}


@dataclass(frozen=True)
class SequenceMeta:
    """What meta.json says about a sequence besides its frames.

    intrinsics: the pinhole camera; kind: "flight" or "views"; frame_rate_hz: nominal rate (None for views);
    initial_bbox_xywh_px: (4,) box at frame 0 the tracker starts from [px] (needed to replay a flight);
    pose_source: where T_world_cam came from ("gt", "vio", or a converter's name); scene, seeds (reset_seed,
    world_seed), commit; perception: the stack's settings and its generator's seed; truth: how ground truth is
    scored (visible_fraction_threshold); source: the producer's own record (generator, env config, faults);
    depth_no_hit_m: the depth layer's value where the ray hit nothing."""

    intrinsics: CameraIntrinsics
    kind: str = "flight"
    frame_rate_hz: float | None = None
    initial_bbox_xywh_px: np.ndarray | None = None
    pose_source: str = "unknown"
    scene: str | None = None
    seeds: dict[str, int | None] = field(default_factory=dict)
    commit: str = "unknown"
    perception: dict[str, Any] | None = None
    truth: dict[str, Any] | None = None
    source: dict[str, Any] = field(default_factory=dict)
    depth_no_hit_m: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"SequenceMeta.kind must be one of {KINDS}, got {self.kind!r}")
        rate = self.frame_rate_hz
        if rate is not None and not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"SequenceMeta.frame_rate_hz must be None or finite and > 0, got {rate!r}")


def meta_document(meta: SequenceMeta, frame_count: int, layers: dict[str, Any]) -> dict[str, Any]:
    """meta.json's content for `meta`, `frame_count` frames and the layers written."""
    return json_safe({
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "kind": meta.kind,
        "frame_count": frame_count,
        "camera": encode_intrinsics(meta.intrinsics),
        "frame_rate_hz": meta.frame_rate_hz,
        "initial_bbox_xywh_px": encode_box(meta.initial_bbox_xywh_px),
        "pose_source": meta.pose_source,
        "scene": meta.scene,
        "seeds": meta.seeds,
        "commit": meta.commit,
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "layers": layers,
        "perception": meta.perception,
        "truth": meta.truth,
        "source": meta.source,
        "fields": FIELD_DOCS,
    })


def frame_line(index: int, record: FrameRecord, files: dict[str, str | None]) -> dict[str, Any]:
    """One frames.jsonl object; `files` maps "rgb", "depth", "seg" to the paths written (None: not written)."""
    line: dict[str, Any] = {"frame": index, "t_s": encode_real(record.t_s), "rgb": files["rgb"]}
    for name in ("depth", "seg"):
        if files.get(name) is not None:
            line[name] = files[name]
    line["T_world_cam"] = encode_pose(record.T_world_cam)
    if record.T_world_cam_true is not None:
        line["T_world_cam_true"] = encode_pose(record.T_world_cam_true)
    if record.imu is not None:
        line["imu"] = {"t_s": encode_reals(record.imu.t_s), "accel_body_mps2": encode_reals(record.imu.accel_mps2),
                       "gyro_body_radps": encode_reals(record.imu.gyro_radps)}
    if record.truth is not None:
        t = record.truth
        line["truth"] = {
            "t_s": encode_real(t.t_s),
            "target_bbox_xywh_px": encode_box(t.target_bbox_xywh_px),
            "target_visible_fraction": encode_real(t.target_visible_fraction),
            "target_depth_m": encode_real(t.target_depth_m),
            "ground_depth_m": encode_real(t.ground_depth_m),
            "target_position_world_m": encode_reals(t.target_position_world_m),
            "target_velocity_world_mps": encode_reals(t.target_velocity_world_mps),
            "drone_position_world_m": encode_reals(t.drone_position_world_m),
            "crashed": bool(t.crashed),
            "following": None if t.following is None else bool(t.following),
            "vehicles": [{"instance_id": int(v.instance_id), "class": v.vehicle_class, "role": v.role,
                          "bbox_xywh_px": encode_box(v.bbox_xywh_px)} for v in t.vehicles],
        }
    if record.faults:
        line["faults"] = list(record.faults)
    if record.extra:
        line["extra"] = json_safe(record.extra)
    return line


class SequenceWriter:
    """Writes the sequence folder `path` frame by frame; `close()` writes meta.json and renames the hidden
    temporary folder (`.<name>.partial` beside it) to `path`, so a folder under the final name is complete.

    `path` must not exist (FileExistsError naming it); its parents are created. As a context manager it closes
    on success and removes the temporary folder on an exception.
    """

    def __init__(self, path: Path | str, meta: SequenceMeta, png_compression: int = DEFAULT_PNG_COMPRESSION) -> None:
        check_png_compression(png_compression)
        self.path = Path(path)
        if self.path.exists():
            raise FileExistsError(f"{self.path}: a sequence folder is there already; choose another")
        self.meta = meta
        self._png_params = [cv2.IMWRITE_PNG_COMPRESSION, png_compression]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.parent / f".{self.path.name}{PARTIAL_SUFFIX}"
        if self._tmp.exists():  # left by a process that died mid-sequence
            shutil.rmtree(self._tmp)
        self._tmp.mkdir()
        self._lines: IO[str] | None = open(self._tmp / FRAMES_FILE, "w", encoding="utf-8")
        self._count = 0
        self._layers: dict[str, Any] = {}
        self._dirs_made: set[str] = set()

    @property
    def frame_count(self) -> int:
        return self._count

    def add(self, record: FrameRecord) -> None:
        """Write one frame (the next index)."""
        if self._lines is None:
            raise RuntimeError(f"{self.path}: add() after close() or abort()")
        k = self._count
        files = {"rgb": self._write_rgb(k, record.rgb) if record.rgb is not None else None,
                 "depth": self._write_depth(k, record.depth_m) if record.depth_m is not None else None,
                 "seg": self._write_seg(k, record.seg) if record.seg is not None else None}
        self._lines.write(json.dumps(frame_line(k, record, files), allow_nan=False, separators=(",", ":")) + "\n")
        self._count += 1

    def close(self) -> Path:
        """Write meta.json and move the folder into place; returns `path`."""
        if self._lines is None:
            raise RuntimeError(f"{self.path}: close() after close() or abort()")
        self._lines.close()
        self._lines = None
        self._layers.setdefault("rgb", {"dir": RGB_DIR, "encoding": "png", "channels": "RGB", "bits": 8})
        document = meta_document(self.meta, self._count, self._layers)
        (self._tmp / META_FILE).write_text(json.dumps(document, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Remove everything written; safe to call twice."""
        if self._lines is not None:
            self._lines.close()
            self._lines = None
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> SequenceWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # --------------------------------------------------------------- layers
    def _file(self, directory: str, k: int, suffix: str) -> tuple[str, Path]:
        if directory not in self._dirs_made:
            (self._tmp / directory).mkdir()
            self._dirs_made.add(directory)
        relative = frame_file(directory, k, suffix)
        return relative, self._tmp / relative

    def _write_rgb(self, k: int, rgb: np.ndarray) -> str:
        K = self.meta.intrinsics
        if rgb.shape != (K.height_px, K.width_px, 3) or rgb.dtype != np.uint8:
            raise ValueError(f"frame {k}: rgb must be uint8 of shape {(K.height_px, K.width_px, 3)}, "
                             f"got {rgb.dtype} {rgb.shape}")
        relative, path = self._file(RGB_DIR, k, RGB_SUFFIX)
        if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), self._png_params):
            raise OSError(f"{path}: frame {k}: the PNG could not be written")
        return relative

    def _write_depth(self, k: int, depth_m: np.ndarray) -> str:
        relative, path = self._file(DEPTH_DIR, k, DEPTH_SUFFIX)
        # the ignore: numpy's stub matches the unpacked name against savez's allow_pickle: bool as well
        np.savez(path, **{DEPTH_ARRAY: np.asarray(depth_m, dtype=np.float32)})  # type: ignore[arg-type]
        self._layers["depth"] = {"dir": DEPTH_DIR, "encoding": "npz", "array": DEPTH_ARRAY, "dtype": "float32",
                                 "quantity": "camera-frame z", "unit": "m", "no_hit_m": self.meta.depth_no_hit_m}
        return relative

    def _write_seg(self, k: int, seg: np.ndarray) -> str:
        if seg.dtype != np.uint16:
            raise ValueError(f"frame {k}: seg must be uint16 instance ids, got {seg.dtype}")
        relative, path = self._file(SEG_DIR, k, SEG_SUFFIX)
        if not cv2.imwrite(str(path), seg, self._png_params):
            raise OSError(f"{path}: frame {k}: the PNG could not be written")
        self._layers["seg"] = {"dir": SEG_DIR, "encoding": "png", "bits": 16, "quantity": "vehicle instance id",
                               "background": BACKGROUND_INSTANCE_ID}
        return relative


def check_png_compression(level: object) -> None:
    """ValueError unless `level` is an integer PNG compression level in [0, MAX_PNG_COMPRESSION]."""
    ok = is_int_at_least(level, 0, numpy_ints=False) and level <= MAX_PNG_COMPRESSION
    require(bool(ok), "png_compression", level, f"an integer in [0, {MAX_PNG_COMPRESSION}]")


def instance_lookup(body_ids: list[int]) -> np.ndarray:
    """(max id + 2,) uint16 table: index body id + 1 (pybullet's -1, no body, is index 0) -> instance id, the
    i-th body of `body_ids` getting i + 1, every other body BACKGROUND_INSTANCE_ID."""
    if len(body_ids) >= UINT16_MAX:
        raise ValueError(f"at most {UINT16_MAX - 1} vehicles fit a 16-bit instance map, got {len(body_ids)}")
    table = np.full(max(body_ids, default=-1) + 2, BACKGROUND_INSTANCE_ID, dtype=np.uint16)
    for instance, body in enumerate(body_ids, start=1):
        table[body + 1] = instance
    return table


def instance_map(seg_body_ids: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(H, W) uint16 instance ids of a pybullet segmentation mask (H, W) of body ids through `table`."""
    index = seg_body_ids.astype(np.int64) + 1
    index[(index < 0) | (index >= len(table))] = 0
    return table[index]
