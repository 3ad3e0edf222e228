"""The recorded-sequence format (trade_gym.recording, docs/sequence_format.md) without the simulator: the writer
and reader round-trip, the JSON schema, a sequence written by hand as a converter would, and bad sequences that
`open_sequence` and `trade-replay` reject with one line naming the file and the frame, writing nothing.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from trade.geometry import CameraIntrinsics, Pose, rotation_z
from trade.types import ImuBatch
from trade_gym.recording import FORMAT_VERSION, FrameRecord, FrameTruth, SequenceError, SequenceMeta, SequenceWriter
from trade_gym.recording import VehicleTruth
from trade_gym.recording.cli import main as replay_main
from trade_gym.recording.format import decode_pose, encode_pose, load_schema
from trade_gym.recording.reader import open_sequence

SIZE_PX = 32
FRAMES = 3
FOV_DEG = 90.0
ALTITUDE_M = 20.0


def _pose(k: int) -> Pose:
    """A camera looking straight down from ALTITUDE_M, turning and moving a little per frame."""
    R_down = np.diag([1.0, -1.0, -1.0])  # camera z along world -z
    return Pose(rotation_z(0.1 * k) @ R_down, np.array([0.5 * k, 0.0, ALTITUDE_M]))


def _records(n: int = FRAMES) -> list[FrameRecord]:
    rng = np.random.default_rng(0)
    records = []
    for k in range(n):
        imu = ImuBatch(np.array([k - 0.5, k]) / 30.0, rng.normal(size=(2, 3)), rng.normal(size=(2, 3)))
        if k == 1:  # a faulty IMU: NaN and infinite samples
            imu = ImuBatch(imu.t_s, np.array([[math.nan, math.inf, -math.inf], [1.0, 2.0, 3.0]]), imu.gyro_radps)
        box = np.array([10.0 + k, 12.0, 6.0, 4.0])
        truth = FrameTruth(box, 0.9, 19.0, 20.0, np.array([0.5 * k, 0.0, 1.0]), np.array([15.0, 0.0, 0.0]),
                           np.array([0.5 * k, 0.0, ALTITUDE_M]), False,
                           (VehicleTruth(1, "car", "target", box), VehicleTruth(2, "truck", "decoy", np.full(4, np.nan))))
        seg = np.zeros((SIZE_PX, SIZE_PX), np.uint16)
        seg[12:16, 10 + k:16 + k] = 1
        records.append(FrameRecord(
            t_s=k / 30.0,
            rgb=None if k == 2 else rng.integers(0, 256, (SIZE_PX, SIZE_PX, 3), dtype=np.uint8),
            T_world_cam=_pose(k), T_world_cam_true=_pose(k), imu=imu, truth=truth,
            depth_m=rng.uniform(5.0, 50.0, (SIZE_PX, SIZE_PX)).astype(np.float32), seg=seg,
            faults=("drop",) if k == 2 else (), extra={"note": k}))
    return records


def _meta() -> SequenceMeta:
    return SequenceMeta(CameraIntrinsics.from_fov(SIZE_PX, SIZE_PX, FOV_DEG), frame_rate_hz=30.0,
                        initial_bbox_xywh_px=np.array([10.0, 12.0, 6.0, 4.0]), pose_source="gt", scene="desert",
                        seeds={"reset_seed": 1, "world_seed": 1}, depth_no_hit_m=1000.0)


@pytest.fixture
def written(tmp_path) -> tuple[Path, list[FrameRecord]]:
    records = _records()
    with SequenceWriter(tmp_path / "seq", _meta()) as writer:
        for r in records:
            writer.add(r)
    return tmp_path / "seq", records


def test_writer_reader_round_trip_is_exact(written):
    path, records = written
    sequence = open_sequence(path)
    assert len(sequence) == FRAMES and sequence.kind == "flight" and sequence.has_truth
    assert sequence.intrinsics == _meta().intrinsics
    for frame, record in zip(sequence, records):
        assert frame.t_s == record.t_s
        assert np.array_equal(frame.T_world_cam.R, record.T_world_cam.R) and np.array_equal(frame.T_world_cam.t,
                                                                                           record.T_world_cam.t)
        rgb = sequence.rgb(frame)
        assert (rgb is None) == (record.rgb is None) and (rgb is None or np.array_equal(rgb, record.rgb))
        assert np.array_equal(sequence.depth_m(frame), record.depth_m)
        assert np.array_equal(sequence.seg(frame), record.seg)
        assert np.array_equal(frame.imu.accel_mps2, record.imu.accel_mps2, equal_nan=True)  # NaN and +-inf too
        assert np.array_equal(frame.truth.target_bbox_xywh_px, record.truth.target_bbox_xywh_px)
        assert [v.role for v in frame.truth.vehicles] == ["target", "decoy"]
        assert np.all(np.isnan(frame.truth.vehicles[1].bbox_xywh_px))
        assert frame.faults == record.faults and frame.extra == record.extra


def test_written_files_validate_against_the_shipped_schema(written):
    path, _ = written
    meta = json.loads((path / "meta.json").read_text())
    assert meta["format_version"] == FORMAT_VERSION
    jsonschema.validate(meta, load_schema("meta"))
    validator = jsonschema.Draft202012Validator(load_schema("frame"))
    lines = [json.loads(line) for line in (path / "frames.jsonl").read_text().splitlines()]
    assert len(lines) == FRAMES
    for line in lines:
        validator.validate(line)
    assert lines[1]["imu"]["accel_body_mps2"][0] == [None, "+inf", "-inf"]  # strict JSON, no NaN literals
    assert lines[2]["rgb"] is None


def test_schema_rejects_another_version_and_a_malformed_pose(written):
    path, _ = written
    meta = json.loads((path / "meta.json").read_text())
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(dict(meta, format_version=FORMAT_VERSION + 1), load_schema("meta"))
    line = json.loads((path / "frames.jsonl").read_text().splitlines()[0])
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(dict(line, T_world_cam=[[1.0, 0.0, 0.0]]), load_schema("frame"))


def test_sequence_folder_appears_only_when_complete(tmp_path):
    writer = SequenceWriter(tmp_path / "seq", _meta())
    writer.add(_records(1)[0])
    assert not (tmp_path / "seq").exists()
    writer.close()
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == ["depth", "frames", "frames.jsonl", "meta.json",
                                                                    "seg"]
    with pytest.raises(FileExistsError, match="seq"):
        SequenceWriter(tmp_path / "seq", _meta())
    with pytest.raises(ValueError, match="png_compression must be an integer in \\[0, 9\\], got 12"):
        SequenceWriter(tmp_path / "other", _meta(), png_compression=12)
    with pytest.raises(ValueError, match="boom"), SequenceWriter(tmp_path / "other", _meta()) as w:
        w.add(_records(1)[0])
        raise ValueError("boom")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]


def test_pose_round_trips_and_a_non_rigid_one_is_refused():
    pose = _pose(3)
    back = decode_pose(json.loads(json.dumps(encode_pose(pose))))
    assert np.array_equal(back.R, pose.R) and np.array_equal(back.t, pose.t)
    sheared = pose.matrix
    sheared[0, 1] += 1e-3
    with pytest.raises(ValueError, match="not a rigid transform"):
        decode_pose(sheared.tolist())


# ------------------------------------------------------------------------------------------ bad sequences
def _edit_line(path: Path, index: int, **fields) -> None:
    lines = (path / "frames.jsonl").read_text().splitlines()
    lines[index] = json.dumps(dict(json.loads(lines[index]), **fields))
    (path / "frames.jsonl").write_text("\n".join(lines) + "\n")


def _missing_png(path: Path) -> tuple[Path, int]:
    (path / "frames" / "000001.png").unlink()
    return path / "frames" / "000001.png", 1


def _truncated_png(path: Path) -> tuple[Path, int]:
    png = path / "frames" / "000001.png"
    png.write_bytes(png.read_bytes()[:-20])
    return png, 1


def _non_rigid_pose(path: Path) -> tuple[Path, int]:
    T = _pose(2).matrix
    T[:3, :3] *= 1.01  # a scaled rotation
    _edit_line(path, 2, T_world_cam=T.tolist())
    return path / "frames.jsonl", 2


def _wrong_version(path: Path) -> tuple[Path, None]:
    meta = json.loads((path / "meta.json").read_text())
    (path / "meta.json").write_text(json.dumps(dict(meta, format_version=FORMAT_VERSION + 1)))
    return path / "meta.json", None


BAD = {"missing png": (_missing_png, "missing"), "truncated png": (_truncated_png, "truncated PNG"),
       "non-rigid pose": (_non_rigid_pose, "not a rigid transform"), "wrong version": (_wrong_version, "format_version")}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_sequence_is_refused_naming_file_and_frame(case, written):
    path, _ = written
    spoil, words = BAD[case]
    bad_file, frame = spoil(path)
    with pytest.raises(SequenceError) as info:
        open_sequence(path)
    message = str(info.value)
    assert str(bad_file) in message and words in message and "\n" not in message
    assert (f"frame {frame}:" in message) if frame is not None else ("frame" not in message)


@pytest.mark.parametrize("case", sorted(BAD))
def test_trade_replay_refuses_bad_sequence_in_one_line_and_writes_nothing(case, written, tmp_path, capsys):
    path, _ = written
    bad_file, _ = BAD[case][0](path)
    out = tmp_path / "replay"
    assert replay_main([str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("trade-replay: error: ") and str(bad_file) in err and "\n" not in err
    assert not out.exists() and not list(tmp_path.glob(".replay*"))


@pytest.mark.parametrize("argv, words", [
    (["--ablation", "single_image_depth=true"], "the stack rejects these settings"),  # needs ground_mask off
    (["--ablation", "imu_noise=false"], "unknown switch 'imu_noise'"),  # an env switch, not the stack's
    (["--ablation", "ground_mask=both"], "value must be true or false"),
])
def test_trade_replay_refuses_bad_settings_in_one_line_and_writes_nothing(argv, words, written, tmp_path, capsys):
    path, _ = written
    out = tmp_path / "replay"
    assert replay_main([str(path), *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("trade-replay: error: ") and words in err and "\n" not in err
    assert not out.exists()


# ----------------------------------------------------------------------------- a converted flight log
def _moving_box_images(n: int, size_px: int, box_px: int, step_px: int) -> list[np.ndarray]:
    """A red box moving right by step_px per frame over a fixed random texture."""
    rng = np.random.default_rng(7)
    texture = rng.integers(60, 140, (size_px, size_px, 3), dtype=np.uint8)
    images = []
    for k in range(n):
        image = texture.copy()
        x, y = 20 + k * step_px, size_px // 2
        image[y:y + box_px, x:x + box_px] = (220, 30, 30)
        images.append(image)
    return images


def test_minimal_hand_written_sequence_replays(tmp_path):
    """What a converter of a real flight log writes: images, poses, intrinsics and the initial box only."""
    n, size, box, step = 12, 96, 10, 2
    seq = tmp_path / "log"
    (seq / "frames").mkdir(parents=True)
    from PIL import Image

    lines = []
    for k, image in enumerate(_moving_box_images(n, size, box, step)):
        Image.fromarray(image).save(seq / "frames" / f"{k:06d}.png")
        lines.append({"frame": k, "t_s": k / 30.0, "rgb": f"frames/{k:06d}.png", "T_world_cam": _pose(0).matrix.tolist()})
    (seq / "frames.jsonl").write_text("".join(json.dumps(line) + "\n" for line in lines))
    f = 0.5 * size
    meta = {"format": "trade-sequence", "format_version": FORMAT_VERSION, "kind": "flight", "frame_count": n,
            "camera": {"width_px": size, "height_px": size, "fx_px": f, "fy_px": f, "cx_px": size / 2 - 0.5,
                       "cy_px": size / 2 - 0.5},
            "initial_bbox_xywh_px": [20.0 - 0.5, size / 2 - 0.5, float(box), float(box)]}
    (seq / "meta.json").write_text(json.dumps(meta))
    jsonschema.validate(meta, load_schema("meta"))
    out = tmp_path / "out"
    assert replay_main([str(seq), "--out", str(out)]) == 0
    estimates = [json.loads(line) for line in (out / "estimates.jsonl").read_text().splitlines()]
    results = json.loads((out / "results.json").read_text())
    assert [e["frame"] for e in estimates] == list(range(n))
    assert results["metrics"] is None and results["ground_depth_ray"] == "estimated box centre"
    x, y, w, h = estimates[-1]["est_bbox"]
    true_centre_x = 20 + (n - 1) * step + box / 2 - 0.5
    assert abs(x + w / 2 - true_centre_x) <= 2.0  # the tracker followed the box
