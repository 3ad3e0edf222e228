"""Recording episodes (`RecordSequence`, `trade-bench --record`) and replaying them (`trade-replay`): a recorded
closed-loop episode replays to the same per-frame estimates (boxes, depths, planes) and metrics, recording does
not change the episode, and what is recorded is what perception received under sensor faults.

Development world 2 (desert), 96 px, VIO pose: the stack's first ground plane comes at about frame 84 there, so the
episode runs 100 frames.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass

import jsonschema
import numpy as np
import pytest

from trade_gym.agents import ScriptedFollower
from trade_gym.bench.cli import main as bench_main
from trade_gym.bench.runner import run_spec, trajectory_sha256
from trade_gym.bench.suites import RunSpec
from trade_gym.env import TradeFollowEnv
from trade_gym.faults import Fault, FaultSchedule, SensorFaults
from trade_gym.metrics import METRIC_NAMES, episode_metrics
from trade_gym.recording import RecordSequence
from trade_gym.recording.cli import main as replay_main
from trade_gym.recording.format import load_schema
from trade_gym.recording.reader import open_sequence
from trade_gym.recording.replay import recorded_settings, replay
from trade_gym.rollout import fly_episode

SEED = 2  # development world 2
STEPS = 100
ENV = dict(scene="desert", perception="trade", pose_source="vio", camera_size=96, episode_duration_s=STEPS / 30)
BLANK, DROP, FREEZE, DUPLICATE, IMU = 10, 14, 18, 22, 5
SCHEDULE = FaultSchedule((Fault("blank", BLANK, 2), Fault("drop", DROP, 1), Fault("freeze", FREEZE, 2),
                          Fault("duplicate", DUPLICATE, 1), Fault("imu", IMU, 2, params={"value": math.inf})))


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """One recorded episode: the per-frame estimates perception returned (frame 0 the reset), the step infos,
    and the sequence folder."""

    boxes: list[np.ndarray]
    valid: list[bool]
    depths: list[tuple[float, float]]
    planes: list
    delivered_rgb: list
    infos: list[dict]
    path: object


def _fly(env, base: TradeFollowEnv) -> tuple[list, list[dict]]:
    per_frame = []

    def grab(flown, obs, info):
        per_frame.append((info["est_bbox"].copy(), bool(info["est_valid"]),
                          (info["target_depth_est"], info["ground_depth_est"]), base.perception.last.plane,
                          base.delivered_sensors.rgb))

    infos = fly_episode(env, ScriptedFollower(), SEED, STEPS, on_reset=grab, on_step=grab)
    return per_frame, infos


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> ClosedLoop:
    root = tmp_path_factory.mktemp("recorded")
    base = TradeFollowEnv(**ENV)
    env = RecordSequence(SensorFaults(base, SCHEDULE), root, depth=True, seg=True)
    try:
        per_frame, infos = _fly(env, base)
    finally:
        env.close()
    assert env.written == [root / "episode_0000"]
    boxes, valid, depths, planes, rgb = (list(column) for column in zip(*per_frame))
    return ClosedLoop(boxes, valid, depths, planes, rgb, infos, env.written[0])


def _same(a: float | None, b: float | None) -> bool:
    """Equal depths, a missing one being NaN (the replay) or None (the env's info)."""
    a, b = (math.nan if x is None else x for x in (a, b))
    return (math.isnan(a) and math.isnan(b)) or a == b


def test_replay_reproduces_closed_loop_estimates_exactly(recorded):
    sequence = open_sequence(recorded.path)
    result = replay(sequence, recorded_settings(sequence))
    assert len(result.estimates) == len(recorded.boxes) == STEPS + 1
    assert result.settings_match_recording is True and result.warnings == ()
    for k, e in enumerate(result.estimates):
        assert np.array_equal(e.bbox_xywh_px, recorded.boxes[k], equal_nan=True), f"frame {k}"
        assert e.valid == recorded.valid[k], f"frame {k}"
        assert _same(e.target_depth_m, recorded.depths[k][0]) and _same(e.ground_depth_m, recorded.depths[k][1])
        plane = recorded.planes[k]
        assert (e.plane is None) == (plane is None), f"frame {k}"
        if plane is not None:
            assert np.array_equal(e.plane.normal, plane.normal) and e.plane.offset_m == plane.offset_m
    assert sum(p is not None for p in recorded.planes) >= 5  # the test data has planes to compare
    assert sum(not v for v in recorded.valid) >= 4  # and frames the faults kept from the tracker


def test_replay_metrics_and_trajectory_hash_equal_the_closed_loop_run(recorded, tmp_path):
    out = tmp_path / "replay"
    assert replay_main([str(recorded.path), "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    expected = episode_metrics(recorded.infos)
    assert set(results["metrics"]) == set(METRIC_NAMES)
    for name in METRIC_NAMES:
        value = results["metrics"][name]
        assert _same(math.nan if value is None else value, float(expected[name])), name
    assert results["trajectory_sha256"] == trajectory_sha256(recorded.infos)
    lines = [json.loads(line) for line in (out / "estimates.jsonl").read_text().splitlines()]
    assert [line["frame"] for line in lines] == list(range(STEPS + 1))
    assert set(lines[0]) == {"frame", "t_s", "est_bbox", "valid", "target_depth_est", "ground_depth_est",
                             "ground_plane"}


def test_recorded_frames_are_what_perception_received(recorded):
    sequence = open_sequence(recorded.path)
    frames = sequence.frames
    blank = sequence.rgb(frames[BLANK])
    assert int(blank.max()) == int(blank.min())  # the blank frame, not the rendered one
    assert frames[DROP].rgb_file is None and frames[DROP].faults == ("drop",)
    assert np.array_equal(sequence.rgb(frames[FREEZE]), sequence.rgb(frames[FREEZE - 1]))
    assert frames[DUPLICATE].t_s == frames[DUPLICATE - 1].t_s  # a duplicate: same time and pose
    assert np.all(np.isinf(frames[IMU].imu.accel_mps2))
    for k in (0, BLANK, FREEZE, STEPS):
        assert np.array_equal(sequence.rgb(frames[k]), recorded.delivered_rgb[k])
    meta = sequence.meta
    assert [f["kind"] for f in meta["source"]["faults"]] == [f.kind for f in SCHEDULE.faults]
    assert meta["perception"]["rng_seed"] is not None and meta["seeds"] == {"reset_seed": SEED, "world_seed": SEED}


def test_recorded_sequence_validates_against_the_schema(recorded):
    jsonschema.validate(json.loads((recorded.path / "meta.json").read_text()), load_schema("meta"))
    validator = jsonschema.Draft202012Validator(load_schema("frame"))
    for line in (recorded.path / "frames.jsonl").read_text().splitlines():
        validator.validate(json.loads(line))


def test_seg_layer_holds_the_target_where_its_true_box_is(recorded):
    sequence = open_sequence(recorded.path)
    frame = sequence.frames[STEPS]
    ids, depth = sequence.seg(frame), sequence.depth_m(frame)
    rows, cols = np.nonzero(ids == 1)
    box = (cols.min() - 0.5, rows.min() - 0.5, cols.max() - cols.min() + 1.0, rows.max() - rows.min() + 1.0)
    assert np.array_equal(box, frame.truth.target_bbox_xywh_px)  # both from the rendered mask
    assert np.all(depth > 0) and abs(float(np.median(depth[ids == 1])) - frame.truth.target_depth_m) < 1.0


def test_recording_does_not_change_the_episode(recorded):
    base = TradeFollowEnv(**ENV)
    env = SensorFaults(base, SCHEDULE)
    try:
        _, infos = _fly(env, base)
    finally:
        env.close()
    assert trajectory_sha256(infos) == trajectory_sha256(recorded.infos)
    assert json.dumps(episode_metrics(infos)) == json.dumps(episode_metrics(recorded.infos))


def test_replay_with_an_ablation_differs_and_says_so(recorded, tmp_path, capsys):
    out = tmp_path / "ablated"
    assert replay_main([str(recorded.path), "--ablation", "temporal_fusion=false", "--perception", "dcf",
                        "--video", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["settings_match_recording"] is False and results["perception"]["mode"] == "dcf"
    assert results["perception"]["switches"]["temporal_fusion"] is False
    assert "settings differ" in capsys.readouterr().err
    assert (out / results["video"]).stat().st_size > 0


def test_replay_of_a_recording_with_the_old_setting_names_matches_its_settings(recorded, tmp_path, capsys):
    """Recordings made before one name per switch (issue 18) name two settings depth_alignment_ransac and
    tracker.snap_initial_box; they read under the env's names, so the replay finds the settings unchanged."""
    old = tmp_path / "old_names"
    shutil.copytree(recorded.path, old)
    meta = json.loads((old / "meta.json").read_text())
    settings = meta["perception"]["pipeline_config"]
    settings["depth_alignment_ransac"] = settings.pop("depth_only_ransac")
    settings["tracker"]["snap_initial_box"] = settings["tracker"].pop("snap_init_box")
    (old / "meta.json").write_text(json.dumps(meta))
    assert replay_main([str(old), "--out", str(tmp_path / "replay")]) == 0
    assert json.loads((tmp_path / "replay" / "results.json").read_text())["settings_match_recording"] is True
    assert "settings differ" not in capsys.readouterr().err


def test_record_sequence_refuses_an_existing_episode_folder(tmp_path):
    (tmp_path / "episode_0000").mkdir()
    env = RecordSequence(TradeFollowEnv(perception="oracle", camera_size=32), tmp_path)
    try:
        with pytest.raises(FileExistsError, match="episode_0000"):
            env.reset(seed=SEED)
    finally:
        env.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episode_0000"]


def test_trade_bench_record_writes_each_run_and_replays_to_its_hash(tmp_path, capsys):
    argv = ["--scenes", "desert", "--policies", "scripted", "--perceptions", "trade", "--seeds", "1", "1",
            "--steps", "20", "--camera-size", "64"]
    assert bench_main(argv + ["--record", str(tmp_path / "rec"), "--out", str(tmp_path / "bench")]) == 0
    run = json.loads((tmp_path / "bench" / "results.json").read_text())["runs"][0]
    sequence = tmp_path / "rec" / run["run_id"] / "episode_0000"
    assert replay_main([str(sequence), "--out", str(tmp_path / "replay")]) == 0
    replayed = json.loads((tmp_path / "replay" / "results.json").read_text())
    assert replayed["trajectory_sha256"] == run["trajectory_sha256"] and replayed["metrics"] == run["metrics"]
    spec = RunSpec("custom", "custom", "desert", "scripted", "trade", "gt", 1, 20, 64)
    assert run_spec(spec).trajectory_sha256 == run["trajectory_sha256"]  # unrecorded: the same episode
    capsys.readouterr()
    assert bench_main(argv + ["--record", str(tmp_path / "rec"), "--out", str(tmp_path / "again")]) == 2
    assert "exists already" in capsys.readouterr().err and not (tmp_path / "again").exists()


def test_recording_names_the_scene_and_scenario_of_the_episode_its_reset_options_set(tmp_path):
    env = RecordSequence(TradeFollowEnv(scene="desert", perception="oracle", camera_size=32), tmp_path)
    try:
        env.reset(seed=SEED, options={"scene": "city", "decoys": "none"})
        env.step(np.zeros(4, np.float32))
    finally:
        env.close()
    meta = open_sequence(env.written[0]).meta
    assert meta["scene"] == "city"
    assert meta["source"]["env_config"]["scene"] == "city" and meta["source"]["env_config"]["decoys"] == "none"
