"""Fits the oracle's noise model to the TRADE stack's closed-loop errors (scripted follower flying).

Records every frame's estimate beside the ground truth, measures the error statistics the oracle models
(box jitter, position error over depth, velocity error, their time correlation, dropouts, the delay before
the first 3D fix), fits them per scene and writes the median over scenes as the `oracle_*` defaults.

Flies training worlds only (reset seed = world seed, from `trade_gym.bench.splits.TRAINING`); the default
perception is the env's, full TRADE.

Usage: python benchmarks/fit_oracle_noise.py --scenes desert city mountain --seeds 10000 10001 10002 \
           --steps 300 --json benchmarks/results/oracle_noise_fit.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trade_gym.agents import ScriptedFollower
from trade_gym import metrics
from trade_gym.bench.splits import TRAINING, require_training_worlds
from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.env import TradeFollowEnv
from trade_gym.perception.base import FloatArray, Perception, PerceptionOutput, SensorFrame
from trade_gym.rollout import fly_episode

MIN_IOU_FOR_ERRORS = 0.3  # frames on the wrong object are dropouts of the model, not its jitter
MIN_LAG1_CORRELATION = 1e-3  # below this the errors count as white (correlation time 0)
MAX_LAG1_CORRELATION = 0.999


@dataclass
class FrameLog:
    """Per-frame arrays of one episode (filled by `RecordingPerception`)."""

    valid: list[bool] = field(default_factory=list)
    iou_ok: list[bool] = field(default_factory=list)
    visible: list[bool] = field(default_factory=list)
    box_error_px: list[FloatArray] = field(default_factory=list)  # (4,) est - gt, x y w h
    position_error_frac: list[FloatArray] = field(default_factory=list)  # (3,) camera frame, / true depth
    velocity_error_mps: list[FloatArray] = field(default_factory=list)  # (3,) world
    position_finite: list[bool] = field(default_factory=list)


class RecordingPerception:
    """Wraps the env's perception and logs its errors against the env's ground truth of the frame (the wrapped
    perception sees the sensors only)."""

    def __init__(self, inner: Perception, env: TradeFollowEnv, visible_threshold: float) -> None:
        self.inner, self.env, self.threshold, self.log = inner, env, visible_threshold, FrameLog()

    def reset(self, sensors: SensorFrame, init_box: FloatArray, rng: np.random.Generator) -> PerceptionOutput:
        self.log = FrameLog()
        return self._record(self.inner.reset(sensors, init_box, rng), sensors)

    def step(self, sensors: SensorFrame) -> PerceptionOutput:
        return self._record(self.inner.step(sensors), sensors)

    def _record(self, out: PerceptionOutput, sensors: SensorFrame) -> PerceptionOutput:
        from trade.types import iou

        log, truth = self.log, self.env.ground_truth  # already this frame's while perception runs
        log.valid.append(bool(out.valid))
        log.visible.append(truth.target_visible_fraction >= self.threshold)
        log.iou_ok.append(iou(truth.target_bbox, out.bbox) >= MIN_IOU_FOR_ERRORS)
        log.box_error_px.append(out.bbox - truth.target_bbox)
        log.position_finite.append(bool(np.all(np.isfinite(out.position_world_m))))
        T_cam_world = sensors.T_world_cam.inverse()
        est_cam = T_cam_world.apply(out.position_world_m.reshape(1, 3))[0]
        true_cam = T_cam_world.apply(truth.target_position_m.reshape(1, 3))[0]
        # e = (p_est - p_true)_cam / z_true: the oracle's noise is N(0, (sigma_frac z)^2) per camera axis
        log.position_error_frac.append((est_cam - true_cam) / max(true_cam[2], 1e-6))
        log.velocity_error_mps.append(out.velocity_world_mps - truth.target_velocity_mps)
        return out


def fly(scene: str, seed: int, steps: int, camera_size: int) -> tuple[FrameLog, dict]:
    env = TradeFollowEnv(scene=scene, perception="trade", camera_size=camera_size)
    recorder = RecordingPerception(env.perception, env, env.config.visible_fraction_threshold)
    env.perception = recorder
    try:
        infos = fly_episode(env, ScriptedFollower(), seed, steps)
    finally:
        env.close()
    run = {"scene": scene, "seed": seed, "steps": len(infos),
           "tracked_fraction": metrics.tracked_fraction(infos),
           "visible_fraction": metrics.visible_fraction(infos),
           "mean_horizontal_distance_m": metrics.mean_horizontal_distance(infos)}
    return recorder.log, run


def lag1_correlation(series: list[FloatArray], usable: np.ndarray) -> float:
    """rho = sum e_t e_{t+1} / sum e_t^2 over consecutive usable frames (all axes pooled)."""
    e = np.asarray(series, dtype=np.float64)
    pairs = usable[:-1] & usable[1:] & np.all(np.isfinite(e[:-1]), axis=1) & np.all(np.isfinite(e[1:]), axis=1)
    if not pairs.any():
        return float("nan")
    a, b = e[:-1][pairs], e[1:][pairs]
    return float(np.sum(a * b) / max(np.sum(a * a), 1e-12))


def fit(logs: list[FrameLog]) -> dict:
    """Pooled statistics over all episodes and the oracle parameters they imply."""
    dt = 1.0 / CAMERA_RATE_HZ
    box, pos, vel, rhos_p, rhos_v, drop, delays = [], [], [], [], [], [], []
    for log in logs:
        valid = np.array(log.valid) & np.array(log.iou_ok) & np.array(log.position_finite)
        box.append(np.asarray(log.box_error_px)[valid])
        pos.append(np.asarray(log.position_error_frac)[valid])
        vel.append(np.asarray(log.velocity_error_mps)[valid])
        rhos_p.append(lag1_correlation(log.position_error_frac, valid))
        rhos_v.append(lag1_correlation(log.velocity_error_mps, valid))
        visible = np.array(log.visible)[1:]
        drop.extend((~(np.array(log.valid) & np.array(log.iou_ok)))[1:][visible])
        finite = np.flatnonzero(log.position_finite)
        delays.append(float(finite[0]) * dt if len(finite) else float("nan"))
    box, pos, vel = np.concatenate(box), np.concatenate(pos), np.concatenate(vel)
    rho = float(np.clip(np.nanmean(rhos_p + rhos_v), MIN_LAG1_CORRELATION, MAX_LAG1_CORRELATION))
    stats = {
        "frames_used": int(len(box)),
        "box_error_rms_px_xywh": np.sqrt(np.mean(box ** 2, axis=0)).round(3).tolist(),
        "box_error_mean_px_xywh": box.mean(axis=0).round(3).tolist(),
        "position_error_rms_frac_cam_xyz": np.sqrt(np.mean(pos ** 2, axis=0)).round(4).tolist(),
        "position_error_mean_frac_cam_xyz": pos.mean(axis=0).round(4).tolist(),
        "velocity_error_rms_mps_xyz": np.sqrt(np.mean(vel ** 2, axis=0)).round(3).tolist(),
        "velocity_error_mean_mps_xyz": vel.mean(axis=0).round(3).tolist(),
        "lag1_correlation_position_per_run": np.round(rhos_p, 4).tolist(),
        "lag1_correlation_velocity_per_run": np.round(rhos_v, 4).tolist(),
        "first_3d_fix_delay_s_per_run": np.round(delays, 3).tolist(),
        "dropout_fraction_visible_frames": float(np.mean(drop)) if drop else float("nan"),
    }
    fitted = {
        # sigma = RMS over components: the oracle draws the same sigma for each of them
        "oracle_box_sigma_px": round(float(np.sqrt(np.mean(box ** 2))), 3),
        "oracle_depth_sigma_frac": round(float(np.sqrt(np.mean(pos ** 2))), 4),
        "oracle_velocity_sigma_mps": round(float(np.sqrt(np.mean(vel ** 2))), 3),
        "oracle_dropout_prob": round(stats["dropout_fraction_visible_frames"], 4),
        # AR(1) with rho = exp(-dt / tau)  =>  tau = -dt / ln(rho)
        "oracle_noise_correlation_s": round(-dt / float(np.log(rho)), 3),
        "oracle_first_fix_delay_s": round(float(np.nanmedian(delays)), 3),
    }
    return {"stats": stats, "fitted": fitted}


def median_fit(per_scene: dict[str, dict]) -> dict:
    """The defaults: per parameter, the median over scenes of the per-scene fits. Pooling frames instead
    lets one scene's failure mode (e.g. a plane fitted to roofs) set every scene's noise."""
    names = next(iter(per_scene.values()))["fitted"].keys()
    return {name: float(np.median([fit_["fitted"][name] for fit_ in per_scene.values()])) for name in names}


def machine_meta() -> dict:
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    return {"commit": commit, "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count()}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["desert", "city", "mountain"])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(TRAINING.seeds(3)),
                        help="reset seeds, which draw the worlds: training worlds only")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--camera-size", type=int, default=256)
    parser.add_argument("--json", type=Path, default=None)
    return parser


def main(argv: list[str] | None = None) -> None:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        require_training_worlds(args.seeds, "--seeds")
    except ValueError as exc:
        parser.error(str(exc))
    logs, runs = [], []
    for scene in args.scenes:
        for seed in args.seeds:
            log, run = fly(scene, seed, args.steps, args.camera_size)
            logs.append(log)
            runs.append(run)
            print(json.dumps(run))
    per_scene = {scene: fit([lg for lg, r in zip(logs, runs) if r["scene"] == scene]) for scene in args.scenes}
    result = {"fitted": median_fit(per_scene), "per_scene": per_scene, "pooled": fit(logs)}
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        payload = {"meta": {**machine_meta(), "load_average_1min_at_end": round(os.getloadavg()[0], 2)},
                   "command": vars(args) | {"json": str(args.json)}, "runs": runs, **result}
        args.json.write_text(json.dumps(payload, indent=2))


if __name__ == "__main__":
    main()
