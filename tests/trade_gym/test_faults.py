"""Injected sensor faults (trade_gym.faults): the schedule, the wrapper, and the env's behaviour under each fault.

Fast tests check the mechanism and one or two episodes; the issue's 20 seeded episodes per fault are marked slow
(`make test-slow`). The TRADE stack needs ~60-70 frames at 160 px before its first 3D fix (the trajectory model
it coasts on), so the coasting faults start after frame 90 at that size.
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

import trade_gym  # noqa: F401  (registers TradeFollow-v0)
from trade_gym.agents import ScriptedFollower
from trade.geometry import CameraIntrinsics, Pose
from trade.ground_filter import GroundFilter, GroundFilterConfig
from trade.roi_features import RoiFeatures
from trade.types import BBox
from trade_gym.faults import Fault, FaultSchedule, SensorFaults
from trade_gym.rollout import fly_episode

TRACKED_IOU = 0.3
REACQUIRE_FRAMES = 10
MIN_REACQUIRED_FRACTION = 0.95
N_EPISODES = 20
KALMAN_RECOVERY_STEPS = 20
MAX_RECOVERED_POSITION_ERROR_M = 2.0
IMAGE_FAULT_ENV = dict(perception="trade", camera_size=96)  # 2D tracking only: fast, no 3D fix needed
COAST_ENV = dict(perception="trade", camera_size=160)  # the 3D fix (trajectory model) arrives by ~frame 70
COAST_START = 90
# Out of view: the trajectory model's velocity needs ~30 frames after the first fix to converge; a gap right
# after the fix (seed 6 at frame 90: 0.25 of 2.9 m/s) coasts on a velocity that is not yet there.
OUT_OF_VIEW_START = 120
COAST_JITTER = 10
MAX_OCCLUSION_SWITCH_EPISODES = 1  # of N_EPISODES: occlusion episodes whose estimate switches to a look-alike
ORACLE = dict(scene="city", perception="oracle", camera_size=64)


@dataclass(frozen=True)
class Frame:
    """What a test checks at one frame of a faulted episode."""

    k: int
    faults: tuple[str, ...]
    finite: bool  # every observation value finite
    track_valid: float
    est_valid: bool
    iou: float
    target_visible: bool
    coasting: bool  # the estimate has a 3D position (the observation's relative position is not zero)
    trajectory_finite: bool  # the TRADE trajectory model's state and covariance are finite (or not started)
    position_error_m: float  # estimated minus true target position [m] (NaN without an estimate)
    on_decoy: bool = False  # the estimate's box is on a look-alike (info["on_decoy"])


def run_episode(schedule: FaultSchedule, seed: int, steps: int, **env_kwargs) -> list[Frame]:
    """Fly the scripted follower through `steps` frames of a SensorFaults-wrapped env (or until it ends)."""
    env = SensorFaults(gym.make("TradeFollow-v0", **env_kwargs), schedule)
    frames: list[Frame] = []

    def record(flown, obs, info):  # frame k = 1, 2, ... after the k-th step
        frames.append(_frame(len(frames) + 1, flown, obs, info))

    try:
        fly_episode(env, ScriptedFollower(), seed, steps, on_step=record)
    finally:
        env.close()
    return frames


def _frame(k: int, env: SensorFaults, obs: dict, info: dict) -> Frame:
    pipeline = getattr(env.unwrapped.perception, "pipeline", None)
    trajectory_finite = True
    if pipeline is not None and pipeline.trajectory.initialized:
        state = pipeline.trajectory.state
        trajectory_finite = all(np.all(np.isfinite(a)) for a in (state.position_m, state.velocity_mps,
                                                                   state.acceleration_mps2, state.covariance))
    return Frame(k, info["faults"], all(bool(np.all(np.isfinite(v))) for v in obs.values()),
                 float(obs["track_valid"][0]), bool(info["est_valid"]), float(info["iou"]),
                 bool(info["target_visible"]), bool(np.any(obs["target_pos_rel_m"] != 0.0)), trajectory_finite,
                 float(np.linalg.norm(env.unwrapped._last_estimate.position_world_m - info["target_position_m"])),
                 bool(info["on_decoy"]))


def window(frames: list[Frame], kind: str) -> tuple[int, int]:
    """(first, last) frame of the fault `kind` in an episode."""
    ks = [f.k for f in frames if kind in f.faults]
    assert ks, f"the {kind} fault never became active"
    return ks[0], ks[-1]


def reacquired_within(frames: list[Frame], after_k: int, n: int) -> bool:
    """A fresh box with IoU >= TRACKED_IOU within n frames of the target reappearing after frame `after_k`."""
    later = [f for f in frames if f.k > after_k]
    back = next((f.k for f in later if f.target_visible), None)
    if back is None:
        return False
    return any(f.est_valid and f.iou >= TRACKED_IOU for f in later if back <= f.k < back + n)


def assert_no_bad_values(frames: list[Frame]) -> None:
    assert all(f.finite for f in frames), [f.k for f in frames if not f.finite]
    assert all(f.trajectory_finite for f in frames), [f.k for f in frames if not f.trajectory_finite]


# ------------------------------------------------------------------------------ the schedule
@pytest.mark.parametrize("kwargs, name", [
    (dict(kind="smoke", start_frame=1, duration_frames=1), "kind"),
    (dict(kind="blank", start_frame=0, duration_frames=1), "start_frame"),
    (dict(kind="blank", start_frame=1, duration_frames=0), "duration_frames"),
    (dict(kind="blank", start_frame=1, duration_frames=1, start_jitter_frames=-1), "start_jitter_frames"),
    (dict(kind="blank", start_frame=1.5, duration_frames=1), "start_frame"),
    (dict(kind="blank", start_frame=1, duration_frames=1, params={"colour": 3}), "colour"),
    (dict(kind="blank", start_frame=1, duration_frames=1, params={"level": 300}), "level"),
    (dict(kind="imu", start_frame=1, duration_frames=1, params={"value": 1.0}), "value"),
    (dict(kind="imu", start_frame=1, duration_frames=1, params={"samples": -1}), "samples"),
    (dict(kind="out_of_view", start_frame=1, duration_frames=1, params={"angle_deg": math.nan}), "angle_deg"),
    (dict(kind="occlusion", start_frame=1, duration_frames=1, params={"width_m": -2.0}), "width_m"),
    (dict(kind="depth_model", start_frame=1, duration_frames=1, params={"output": "zero"}), "output"),
])
def test_fault_bad_field_raises_value_error_naming_it(kwargs, name):
    with pytest.raises(ValueError, match=name):
        Fault(**kwargs)


def test_fault_params_merge_over_the_kind_defaults():
    fault = Fault("occlusion", 5, 10, {"width_m": 9.0})
    assert fault.params["width_m"] == 9.0 and fault.params["height_m"] > 0.0


def test_schedule_start_draws_are_seeded_and_within_the_jitter():
    schedule = FaultSchedule((Fault("blank", 10, 3, start_jitter_frames=20), Fault("drop", 40, 1)))
    draws = [schedule.draw_starts(np.random.default_rng(s)) for s in range(30)]
    assert draws[:5] == [schedule.draw_starts(np.random.default_rng(s)) for s in range(5)]
    assert all(10 <= a <= 30 and b == 40 for a, b in draws)
    assert len({a for a, _ in draws}) > 5


def test_wrapper_reset_seed_fixes_the_fault_starts():
    schedule = FaultSchedule((Fault("blank", 10, 3, start_jitter_frames=50),))
    env = SensorFaults(gym.make("TradeFollow-v0", **ORACLE), schedule)
    try:
        starts = []
        for seed in (1, 2, 1):
            env.reset(seed=seed)
            starts.append(env._starts)
    finally:
        env.close()
    assert starts[0] == starts[2] != starts[1]


def test_wrapper_needs_a_trade_follow_env():
    with pytest.raises(TypeError, match="TradeFollow"):
        SensorFaults(gym.make("CartPole-v1"), FaultSchedule())


def test_depth_model_fault_without_ground_mask_raises_value_error():
    env = gym.make("TradeFollow-v0", **ORACLE)
    try:
        with pytest.raises(ValueError, match="ground_mask"):
            SensorFaults(env, FaultSchedule((Fault("depth_model", 5, 5),)))
    finally:
        env.close()


# ------------------------------------------------------------------------------ the depth model check
class _BadModel:
    def __init__(self, output: str) -> None:
        self.output = output

    def predict(self, rgb):
        h, w = rgb.shape[:2]
        base = np.linspace(0.1, 1.0, h * w, dtype=np.float32).reshape(h, w)
        return {"nan": np.full((h, w), np.nan, np.float32), "negative": -base,
                "constant": np.full((h, w), 0.5, np.float32)}[self.output]


@pytest.mark.parametrize("output", ["nan", "negative", "constant"])
def test_ground_filter_rejects_bad_model_output_and_falls_back_to_all_tracks(output):
    K = CameraIntrinsics.from_fov(64, 64, 110.0)
    n = 12
    rng = np.random.default_rng(1)
    pixels = rng.uniform(8, 56, (n, 2))
    roi = RoiFeatures(pixels, pixels.copy(), np.zeros((n, 3)), rng.uniform(10, 20, n), np.full(n, 0.1),
                      np.ones(n, bool), np.arange(n), np.zeros(n, int), BBox(0, 0, 64, 64))
    ground = GroundFilter(GroundFilterConfig(), K, _BadModel(output), rng)
    labels = ground.update(np.zeros((64, 64, 3), np.uint8), roi, BBox(28, 28, 8, 8), Pose.identity())
    assert labels.ran_model and labels.model_rejected and ground.model_rejected
    assert labels.ground is not None and labels.ground.all()


# ------------------------------------------------------------------------------ fast episodes
def test_empty_schedule_changes_nothing_but_adds_the_faults_key():
    plain = gym.make("TradeFollow-v0", **ORACLE)
    wrapped = SensorFaults(gym.make("TradeFollow-v0", **ORACLE), FaultSchedule())
    try:
        outs = [e.reset(seed=4) for e in (plain, wrapped)]
        for _ in range(10):
            outs += [e.step(np.full(4, 0.2, np.float32)) for e in (plain, wrapped)]
        for a, b in zip(outs[0::2], outs[1::2]):
            assert b[-1].pop("faults") == ()
            assert pickle.dumps(a) == pickle.dumps(b)
    finally:
        plain.close()
        wrapped.close()


@pytest.mark.parametrize("value, samples", [(math.nan, 10), (math.inf, 1), (-math.inf, 0)])
def test_imu_fault_drops_bad_samples_and_touches_nothing_else(value, samples):
    """Oracle mode, same actions: the faulted run equals a fault-free one except the imu observation of frames
    with corrupt samples, which averages the good samples (zeros when none is left)."""
    window_frames = 3
    schedule = FaultSchedule((Fault("imu", 5, window_frames, {"value": value, "samples": samples}),))
    envs = [gym.make("TradeFollow-v0", **ORACLE), SensorFaults(gym.make("TradeFollow-v0", **ORACLE), schedule)]
    corrupted = 0
    try:
        for e in envs:
            e.reset(seed=6)
        for k in range(1, 15):
            (clean, *_), (faulty, *_) = (e.step(np.full(4, 0.1, np.float32)) for e in envs)
            imu = envs[1].delivered.imu
            bad = int(np.sum(~np.isfinite(imu.accel_mps2[:, 0])))
            corrupted += bad
            assert all(np.all(np.isfinite(v)) for v in faulty.values())
            for key in clean:
                if key != "imu" or bad == 0:
                    assert np.array_equal(clean[key], faulty[key]), (k, key)
            if bad == len(imu.t_s):
                assert not np.any(faulty["imu"])
            elif bad:  # the mean of the remaining samples: close to, not equal to, the full mean
                assert not np.array_equal(clean["imu"], faulty["imu"])
                assert np.allclose(clean["imu"], faulty["imu"], atol=0.5)
    finally:
        for e in envs:
            e.close()
    assert corrupted == (samples or corrupted) and corrupted >= 1


def test_out_of_view_oracle_gap_counted_estimate_coasts_and_returns():
    # after the oracle's first 3D fix (oracle_first_fix_delay_s), so there is an estimate to coast on
    frames = run_episode(FaultSchedule((Fault("out_of_view", 60, 30),)), 0, 100, **ORACLE)
    first, last = window(frames, "out_of_view")
    gap = [f for f in frames if first <= f.k <= last]
    assert (first, last) == (60, 89) and not any(f.target_visible for f in gap)
    assert all(not f.est_valid and f.track_valid == 0.0 and f.coasting for f in gap)
    back = next(f for f in frames if f.k == last + 1)
    assert back.target_visible and back.est_valid  # the oracle measures again on the first frame back


def test_image_faults_in_one_trade_episode_report_loss_on_their_first_frame_and_recover():
    schedule = FaultSchedule((Fault("blank", 8, 1), Fault("blank", 14, 5, {"level": 255}), Fault("drop", 24, 3),
                              Fault("duplicate", 31, 2), Fault("freeze", 37, 4)))
    frames = run_episode(schedule, 0, 48, **IMAGE_FAULT_ENV)
    assert_no_bad_values(frames)
    assert len(frames) == 48
    for f in frames:
        if f.faults:
            assert f.track_valid == 0.0 and not f.est_valid, f
    for kind in ("drop", "duplicate", "freeze"):
        assert reacquired_within(frames, window(frames, kind)[1], REACQUIRE_FRAMES), kind
    assert not any(f.target_visible for f in frames if set(f.faults) & {"blank", "drop"})


def test_sensor_faults_survive_pickling_with_their_filter():
    schedule = FaultSchedule((Fault("out_of_view", 3, 2),))
    env = SensorFaults(gym.make("TradeFollow-v0", **ORACLE), schedule)
    try:
        copied = pickle.loads(pickle.dumps(env))
        try:
            assert copied.unwrapped._sensor_filter is copied
            for e in (env, copied):
                e.reset(seed=1)
            infos = [[e.step(np.zeros(4, np.float32))[-1] for _ in range(6)] for e in (env, copied)]
            assert [i["target_visible"] for i in infos[0]] == [i["target_visible"] for i in infos[1]]
            assert [i["faults"] for i in infos[1]][2:4] == [("out_of_view",)] * 2
        finally:
            copied.close()
    finally:
        env.close()


# ------------------------------------------------------------------------------ 20 seeded episodes per fault
def _episodes(make_schedule, steps: int, **env_kwargs) -> list[list[Frame]]:
    return [run_episode(make_schedule(i), seed, steps, **env_kwargs) for i, seed in enumerate(range(N_EPISODES))]


def _reacquired_fraction(episodes: list[list[Frame]], kind: str) -> float:
    return float(np.mean([reacquired_within(fr, window(fr, kind)[1], REACQUIRE_FRAMES) for fr in episodes]))


@pytest.mark.slow
@pytest.mark.parametrize("length", [1, 5, 30])
def test_blank_frames_20_episodes_loss_reported_on_first_frame_and_reacquired(length):
    episodes = _episodes(lambda i: FaultSchedule((Fault("blank", 15, length, {"level": 255 * (i % 2)},
                                                        start_jitter_frames=10),)), 25 + length + 15,
                         **IMAGE_FAULT_ENV)
    for frames in episodes:
        assert_no_bad_values(frames)
        blank = [f for f in frames if "blank" in f.faults]
        assert len(blank) == length
        assert all(f.track_valid == 0.0 and not f.est_valid and not f.target_visible for f in blank)
    assert _reacquired_fraction(episodes, "blank") >= MIN_REACQUIRED_FRACTION


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["drop", "duplicate", "freeze"])
def test_dropped_duplicated_frozen_frames_20_episodes_coast_and_reacquire(kind):
    episodes = _episodes(lambda i: FaultSchedule((Fault(kind, 15, 1 + i % 8, start_jitter_frames=10),)), 45,
                         **IMAGE_FAULT_ENV)
    for frames in episodes:
        assert_no_bad_values(frames)
        assert all(f.track_valid == 0.0 and not f.est_valid for f in frames if f.faults)
    assert _reacquired_fraction(episodes, kind) >= MIN_REACQUIRED_FRACTION


@pytest.mark.slow
def test_imu_nan_inf_samples_20_episodes_kalman_finite_and_recovered_within_20_steps():
    variants = [(math.nan, 1), (math.nan, 10), (math.inf, 1), (math.inf, 10)]

    def schedule(i: int) -> FaultSchedule:
        value, samples = variants[i % len(variants)]
        return FaultSchedule((Fault("imu", COAST_START, 2, {"value": value, "samples": samples},
                                    start_jitter_frames=COAST_JITTER),))

    episodes = _episodes(schedule, COAST_START + COAST_JITTER + 2 + KALMAN_RECOVERY_STEPS, **COAST_ENV)
    recovered = []
    for frames in episodes:
        assert_no_bad_values(frames)
        end = window(frames, "imu")[1]
        after = [f for f in frames if end < f.k <= end + KALMAN_RECOVERY_STEPS]
        recovered.append(any(f.est_valid and f.position_error_m <= MAX_RECOVERED_POSITION_ERROR_M for f in after))
    assert np.mean(recovered) >= MIN_REACQUIRED_FRACTION, recovered


@pytest.mark.slow
def test_target_out_of_view_2s_20_episodes_coasts_counts_gap_and_reacquires():
    gap_frames = 60
    episodes = _episodes(lambda i: FaultSchedule((Fault("out_of_view", OUT_OF_VIEW_START, gap_frames,
                                                        start_jitter_frames=COAST_JITTER),)),
                         OUT_OF_VIEW_START + COAST_JITTER + gap_frames + 2 * REACQUIRE_FRAMES, **COAST_ENV)
    for frames in episodes:
        assert_no_bad_values(frames)
        gap = [f for f in frames if "out_of_view" in f.faults]
        assert len(gap) == gap_frames and not any(f.target_visible for f in gap)  # the gap is counted
        assert all(f.coasting and not f.est_valid for f in gap)  # the trajectory model carries the estimate
    assert _reacquired_fraction(episodes, "out_of_view") >= MIN_REACQUIRED_FRACTION


@pytest.mark.slow
def test_occlusion_half_to_3s_20_episodes_no_bad_values_and_reacquired():
    def schedule(i: int) -> FaultSchedule:
        frames = 15 + (i * 75) // (N_EPISODES - 1)  # 0.5 s .. 3 s
        return FaultSchedule((Fault("occlusion", COAST_START, frames, start_jitter_frames=COAST_JITTER),))

    episodes = [run_episode(schedule(i), i, COAST_START + COAST_JITTER + 15 + (i * 75) // (N_EPISODES - 1)
                            + 2 * REACQUIRE_FRAMES, **COAST_ENV) for i in range(N_EPISODES)]
    switched = 0
    for frames in episodes:
        assert_no_bad_values(frames)
        # Under the roof the tracker reports the target lost; it may hold on to what is still visible of it
        # (the visible fraction is then below the threshold but the box overlaps the visible pixels), but a
        # valid estimate never sits on the roof alone.
        hidden = [f for f in frames if "occlusion" in f.faults and not f.target_visible]
        assert all(not f.est_valid or f.iou > 0.0 or f.on_decoy for f in hidden)
        switched += any(f.est_valid and f.on_decoy for f in hidden)
    # Re-detection at the end of a long occlusion may take an identical car crossing near the prediction, whose gate
    # has grown while the target was hidden (the decoy switch after occlusion, issue 41): episode 7 (42 hidden frames)
    # does, from 31e004b on (the earliest commit checked). More than that is a regression.
    assert switched <= MAX_OCCLUSION_SWITCH_EPISODES, switched
    assert _reacquired_fraction(episodes, "occlusion") >= MIN_REACQUIRED_FRACTION


@pytest.mark.slow
def test_depth_model_nan_negative_constant_20_episodes_rejected_and_fallback_fit_on_all_tracks():
    outputs, fault_frames, after_frames = ("nan", "negative", "constant"), 60, 15
    cleared = []
    for i in range(N_EPISODES):
        fault = Fault("depth_model", 50, fault_frames, {"output": outputs[i % len(outputs)]},
                      start_jitter_frames=COAST_JITTER)
        env = SensorFaults(gym.make("TradeFollow-v0", ground_mask=True, **COAST_ENV), FaultSchedule((fault,)))
        policy, fallback_frames = ScriptedFollower(), 0
        try:
            obs, _ = env.reset(seed=i)
            ground = env.unwrapped.perception.pipeline.ground
            end = env._starts[0] + fault_frames
            for k in range(1, end + after_frames):
                action, _ = policy.predict(obs, episode_start=np.array([k == 1]))
                obs, _, terminated, truncated, info = env.step(action)
                assert all(np.all(np.isfinite(v)) for v in obs.values()), k
                est = env.unwrapped.perception.last
                if ground.model_rejected and est.roi is not None:
                    fallback_frames += 1
                    usable = est.roi.promoted & np.all(np.isfinite(est.roi.points_world), axis=1)
                    assert est.n_plane_points == int(usable.sum())  # the fit runs on every promoted track
                assert not (terminated or truncated), k
            cleared.append(not ground.model_rejected)  # a valid map after the fault brings the mask back
        finally:
            env.close()
        assert fallback_frames > 0, f"episode {i}: the model never ran inside the fault window"
    assert np.mean(cleared) >= MIN_REACQUIRED_FRACTION, cleared
