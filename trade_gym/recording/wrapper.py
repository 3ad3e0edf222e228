"""`RecordSequence`: a Gymnasium wrapper that writes each episode of a TradeFollow-v0 env as a sequence folder.

What is written is what perception received (after `SensorFaults` or any sensor filter), with the frame's ground
truth, the stack's settings and the seed of its own generator, so `trade-replay` can reproduce the estimates.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np

from trade_gym.config import CAMERA_RATE_HZ
from trade_gym.faults import SensorFaults
from trade_gym.ground_truth import GroundTruth
from trade_gym.provenance import git_commit
from trade_gym.recording.format import FrameRecord, FrameTruth, VehicleTruth, json_safe
from trade_gym.recording.writer import (DEFAULT_PNG_COMPRESSION, SequenceMeta, SequenceWriter, check_png_compression,
                                        instance_lookup, instance_map)

if TYPE_CHECKING:
    from trade_gym.env import TradeFollowEnv

EPISODE_DIR = "episode_{k:04d}"
GENERATOR = "trade_gym.recording.RecordSequence"


class RecordSequence(gym.Wrapper):
    """Writes the k-th episode after each reset to `root/episode_{k:04d}/` (docs/sequence_format.md).

    A sequence is complete once its episode ends (terminated or truncated), at the next reset or at `close()`:
    until then it is written into a hidden temporary folder. Frame 0 is the reset frame. `depth` adds the
    rendered camera-frame depth (depth/*.npz), `seg` the vehicles' instance ids (seg/*.png); both are the
    renderer's, not touched by sensor faults. Recording reads the env and never changes it: the episode is the
    same with and without the wrapper. Wrap `SensorFaults` (not the other way round) to record the faults'
    effect: `RecordSequence(SensorFaults(env, schedule), root)`.
    """

    def __init__(self, env: gym.Env, root: Path | str, depth: bool = False, seg: bool = False,
                 png_compression: int = DEFAULT_PNG_COMPRESSION) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "delivered_sensors"):
            raise TypeError(f"RecordSequence needs a TradeFollow-v0 env, got {type(env.unwrapped).__name__}")
        check_png_compression(png_compression)
        self.root = Path(root)
        self.record_depth, self.record_seg = bool(depth), bool(seg)
        self.png_compression = png_compression
        self.episodes_started = 0
        self.written: list[Path] = []  # the sequence folders completed so far
        self._writer: SequenceWriter | None = None
        self._commit: str | None = None
        self._instances: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._finish()
        path = self.root / EPISODE_DIR.format(k=self.episodes_started)
        if path.exists():  # checked before the env moves, so nothing is half done
            raise FileExistsError(f"{path}: a sequence folder is there already; record into another root")
        obs, info = self.env.reset(seed=seed, options=options)
        writer = self._writer = SequenceWriter(path, self._meta(seed), self.png_compression)
        self.episodes_started += 1
        world = self._base.world
        self._instances = instance_lookup([world.target.body_id, *(d.body_id for d in world.decoys)])
        self._write_or_discard(writer, info)
        return obs, info

    def step(self, action):
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except BaseException:
            self.discard()
            raise
        if self._writer is not None:
            self._write_or_discard(self._writer, info)
            if terminated or truncated:
                self._finish()
        return obs, reward, terminated, truncated, info

    def discard(self) -> None:
        """Drop the episode being written (nothing of it stays); the env raised, or the caller does not want it."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.abort()

    def close(self) -> None:
        self._finish()
        super().close()

    # --------------------------------------------------------------- internals
    @property
    def _base(self) -> TradeFollowEnv:
        """The TradeFollow-v0 env under the wrappers (`__init__` checked it has the recorder's properties)."""
        return cast("TradeFollowEnv", self.env.unwrapped)

    def _finish(self) -> None:
        if self._writer is not None:
            writer, self._writer = self._writer, None
            self.written.append(writer.close())

    def _write_or_discard(self, writer: SequenceWriter, info: dict[str, Any]) -> None:
        try:
            self._write(writer, info)
        except BaseException:
            self.discard()
            raise

    def _write(self, writer: SequenceWriter, info: dict[str, Any]) -> None:
        base, instances = self._base, self._instances
        sensors, frame, truth = base.delivered_sensors, base.camera_frame, base.ground_truth
        if sensors is None or truth is None or instances is None:
            raise RuntimeError("RecordSequence: no frame to write before the env's reset")
        writer.add(FrameRecord(
            t_s=sensors.t_s,
            rgb=sensors.rgb,
            T_world_cam=sensors.T_world_cam,
            T_world_cam_true=base.true_camera_pose,
            imu=sensors.imu,
            truth=self._truth(info, truth),
            depth_m=frame.depth_m if self.record_depth and frame is not None else None,
            seg=instance_map(frame.seg, instances) if self.record_seg and frame is not None else None,
            faults=tuple(info.get("faults", ())),
        ))

    def _truth(self, info: dict[str, Any], truth: GroundTruth) -> FrameTruth:
        """The frame's ground `truth` as recorded; the visible fraction from `info`, where a fault wrapper lowers it
        for what the delivered image shows."""
        world = self._base.world
        vehicles = [VehicleTruth(1, world.target.kind, "target", truth.target_bbox)]
        vehicles += [VehicleTruth(i + 2, d.kind, "decoy", box) for i, (d, box) in
                     enumerate(zip(world.decoys, truth.decoy_bboxes))]
        return FrameTruth(
            target_bbox_xywh_px=truth.target_bbox,
            target_visible_fraction=float(info["target_visible_fraction"]),
            target_depth_m=truth.target_depth_m,
            ground_depth_m=truth.ground_depth_m,
            target_position_world_m=truth.target_position_m,
            target_velocity_world_mps=truth.target_velocity_mps,
            drone_position_world_m=np.asarray(info["drone_position_m"], dtype=np.float64),
            crashed=bool(info["crashed"]),
            following=info.get("following"),
            vehicles=tuple(vehicles),
            t_s=float(info["t_s"]),
        )

    def _meta(self, seed: int | None) -> SequenceMeta:
        base = self._base
        config = base.episode_config  # the episode's scene and scenario (reset options included)
        if self._commit is None:
            self._commit = git_commit()
        world_seed = config.world_seed if config.world_seed is not None else seed
        far_m = base.camera.config.far_m
        return SequenceMeta(
            intrinsics=base.camera.intrinsics,
            kind="flight",
            frame_rate_hz=float(CAMERA_RATE_HZ),
            initial_bbox_xywh_px=base.initial_box,
            pose_source=config.pose_source,
            scene=config.scene,
            seeds={"reset_seed": seed, "world_seed": world_seed},
            commit=self._commit,
            perception=perception_record(base),
            truth={"visible_fraction_threshold": config.visible_fraction_threshold},
            source={"generator": GENERATOR, "env_config": json_safe(asdict(config)), "faults": self._faults()},
            depth_no_hit_m=far_m if self.record_depth else None,
        )

    def _faults(self) -> list[dict[str, Any]]:
        """The fault schedule of a `SensorFaults` below this wrapper, with this episode's drawn start frames."""
        env = self.env
        while isinstance(env, gym.Wrapper):
            if isinstance(env, SensorFaults):
                return [json_safe({"kind": f.kind, "start_frame": start, "duration_frames": f.duration_frames,
                                   "params": f.params}) for f, start in zip(env.schedule.faults, env.start_frames)]
            env = env.env
        return []


def perception_record(base: Any) -> dict[str, Any]:
    """The perception mode of an env, the stack's switches and full settings, and its generator's seed (None
    for the oracle, which has no stack)."""
    from trade_gym.perception.trade_stack import STACK_SWITCHES, pipeline_config  # OpenCV, filterpy

    config = base.config
    record: dict[str, Any] = {"mode": config.perception,
                              "switches": {name: getattr(config, name) for name in STACK_SWITCHES},
                              "rng_seed": getattr(base.perception, "rng_seed", None)}
    if config.perception != "oracle":
        record["pipeline_config"] = json_safe(asdict(pipeline_config(config)))
    return record

