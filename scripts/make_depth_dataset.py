"""Render the single-image depth training set from the simulator: RGB + metric z-depth at random drone poses.

Owns the data recipe of `assets/models/depth_small.onnx` (`ViewConfig`, `render_world_views`, the split seeds).

Recipe (documented in the model card too): world k of a split is `build_world(cid, SCENES[k % 3],
default_rng(seed_base + k))` in one pybullet DIRECT client, reset (`p.resetSimulation`, gravity) before each
world. The same generator then draws `views_per_world` views: a time t ~ U(0, duration) (vehicles posed at t);
a camera xy, either around the target at t (probability `p_near_target`) or around the drone start, offset by
U(0, `xy_radius_m`) in a uniform direction; an altitude U(12, 40) m above `world.surface_height_m` (roofs
included); a yaw U(-pi, pi); a mount pitch U(60, 90) deg. 128 x 128 px, 110 deg vertical FOV, TinyRenderer.
Seeds: train 10_000.., held-out 20_000.., both training worlds (`trade_gym.bench.splits`); the benchmark
evaluates development worlds 0..99 (disjoint).
Output: one recorded sequence per world (docs/sequence_format.md, kind "views"), `<out-dir>/<split>/world_<seed>/`:
frames/*.png RGB, depth/*.npz camera-frame z [m] as float32 (far_m where nothing was hit, meta.json
layers.depth.no_hit_m), frames.jsonl with each view's time, pose and extra pitch_deg and altitude_agl_m, meta.json
with the scene, the world seed and the render time. A split is written beside its old folder and replaces it
when complete. `scripts/train_depth.py` reads it back.

Usage: python scripts/make_depth_dataset.py [--train-worlds 300] [--heldout-worlds 25] [--views-per-world 8]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pybullet as p

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from trade.geometry import CameraIntrinsics, Pose, rotation_z  # noqa: E402
from trade_gym.bench.splits import TRAINING, require_training_worlds  # noqa: E402
from trade_gym.provenance import git_commit  # noqa: E402
from trade_gym.recording import FrameRecord, SequenceMeta, SequenceWriter  # noqa: E402
from trade_gym.sim.camera import Camera, CameraConfig  # noqa: E402
from trade_gym.sim.world import World, build_world  # noqa: E402

SCENE_CYCLE = ("desert", "city", "mountain")
TRAIN_SEED_BASE = TRAINING.first  # both data splits lie in the training split of worlds
HELDOUT_SEED_BASE = TRAINING.first + 10_000
GRAVITY_MPS2 = 9.81
DEFAULT_OUT_DIR = Path(__file__).resolve().parents[1] / "build" / "depth_dataset"
WORLD_DIR = "world_{seed}"  # one sequence per world in a split's folder
GENERATOR = "scripts/make_depth_dataset.py"


@dataclass(frozen=True)
class ViewConfig:
    """Camera image and the random pose ranges of one rendered view."""

    size_px: int = 128
    fov_deg: float = 110.0
    altitude_agl_min_m: float = 12.0
    altitude_agl_max_m: float = 40.0
    pitch_min_deg: float = 60.0
    pitch_max_deg: float = 90.0
    xy_radius_m: float = 30.0  # camera xy offset from the anchor point (target at t, or drone start)
    p_near_target: float = 0.75  # probability that the anchor is the target rather than the drone start
    far_m: float = 1000.0

    def __post_init__(self) -> None:
        if int(self.size_px) != self.size_px or self.size_px <= 0:
            raise ValueError(f"ViewConfig.size_px must be a positive integer, got {self.size_px!r}")
        for lo, hi in (("altitude_agl_min_m", "altitude_agl_max_m"), ("pitch_min_deg", "pitch_max_deg")):
            if not 0.0 < getattr(self, lo) <= getattr(self, hi):
                raise ValueError(f"ViewConfig needs 0 < {lo} <= {hi}, got {getattr(self, lo)!r}, "
                                 f"{getattr(self, hi)!r}")
        if not self.pitch_max_deg <= 90.0:
            raise ValueError(f"ViewConfig.pitch_max_deg must be <= 90, got {self.pitch_max_deg!r}")
        if not 0.0 <= self.p_near_target <= 1.0:
            raise ValueError(f"ViewConfig.p_near_target must be in [0, 1], got {self.p_near_target!r}")
        if not self.xy_radius_m >= 0.0:
            raise ValueError(f"ViewConfig.xy_radius_m must be >= 0, got {self.xy_radius_m!r}")


@dataclass(frozen=True)
class View:
    """One rendered sample: rgb (H, W, 3) uint8, depth_m (H, W) float32 camera z [m], the camera pose and the
    world time it was rendered at [s], and its pose draw."""

    rgb: np.ndarray
    depth_m: np.ndarray
    T_world_cam: Pose
    t_s: float
    pitch_deg: float
    altitude_agl_m: float


def _anchor_xy(world: World, t_s: float, near_target: bool) -> np.ndarray:
    """(2,) world xy [m]: the target's box centre at t_s, or the drone start."""
    if near_target:
        centre, _ = world.vehicle_pose(world.target, t_s)
        return np.asarray(centre[:2], dtype=np.float64)
    start, _ = world.drone_start()
    return start[:2].astype(np.float64)


def render_world_views(cid: int, scene: str, seed: int, count: int, cfg: ViewConfig) -> list[View]:
    """Reset `cid`, build world `seed` of `scene` and render `count` random views of it (same seed -> same views)."""
    p.resetSimulation(physicsClientId=cid)
    p.setGravity(0.0, 0.0, -GRAVITY_MPS2, physicsClientId=cid)
    rng = np.random.default_rng(seed)
    world = build_world(cid, scene, rng)
    half_extent_m = 0.5 * world.spec.terrain_size_m
    views = []
    for _ in range(count):
        t_s = float(rng.uniform(0.0, max(world.duration_s, 0.0)))
        world.update(t_s)
        anchor = _anchor_xy(world, t_s, bool(rng.random() < cfg.p_near_target))
        angle, radius = rng.uniform(-np.pi, np.pi), cfg.xy_radius_m * np.sqrt(rng.random())  # uniform on a disc
        xy = np.clip(anchor + radius * np.array([np.cos(angle), np.sin(angle)]), -half_extent_m, half_extent_m)
        agl = float(rng.uniform(cfg.altitude_agl_min_m, cfg.altitude_agl_max_m))
        z = float(world.surface_height_m(float(xy[0]), float(xy[1]))) + agl
        pitch = float(rng.uniform(cfg.pitch_min_deg, cfg.pitch_max_deg))
        camera = Camera(cid, CameraConfig(width_px=cfg.size_px, height_px=cfg.size_px, fov_deg=cfg.fov_deg,
                                          pitch_deg=pitch, far_m=cfg.far_m))
        pose = camera.pose(rotation_z(float(rng.uniform(-np.pi, np.pi))), (xy[0], xy[1], z))
        world.prepare_render(pose, camera.intrinsics, camera.config.near_m, camera.config.far_m)
        frame = camera.render(pose)
        views.append(View(frame.rgb, frame.depth_m, frame.T_world_cam, t_s, pitch, agl))
    return views


def write_world(path: Path, scene: str, seed: int, views: list[View], cfg: ViewConfig, render_s: float,
                commit: str) -> Path:
    """One world's views as a sequence folder of kind "views" (depth capped at far_m, float32)."""
    meta = SequenceMeta(
        intrinsics=CameraIntrinsics.from_fov(cfg.size_px, cfg.size_px, cfg.fov_deg), kind="views",
        pose_source="gt", scene=scene, seeds={"world_seed": seed}, commit=commit,
        source={"generator": GENERATOR, "view_config": asdict(cfg), "render_s": render_s},
        depth_no_hit_m=cfg.far_m)
    with SequenceWriter(path, meta) as writer:
        for v in views:
            writer.add(FrameRecord(t_s=v.t_s, rgb=v.rgb, T_world_cam=v.T_world_cam, T_world_cam_true=v.T_world_cam,
                                   depth_m=np.minimum(v.depth_m, cfg.far_m).astype(np.float32),
                                   extra={"pitch_deg": v.pitch_deg, "altitude_agl_m": v.altitude_agl_m}))
    return path


def render_split(out_dir: Path, seed_base: int, worlds: int, views_per_world: int, cfg: ViewConfig) -> list[Path]:
    """Render one split into `out_dir` (one sequence per world, see the module docstring), in one DIRECT client
    closed after. The split is written to a hidden folder beside `out_dir` that replaces it when complete."""
    require_training_worlds(range(seed_base, seed_base + worlds), "depth dataset")
    tmp = out_dir.parent / f".{out_dir.name}.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    commit = git_commit()
    cid = p.connect(p.DIRECT)
    try:
        for k in range(worlds):
            scene, seed = SCENE_CYCLE[k % len(SCENE_CYCLE)], seed_base + k
            start = time.perf_counter()
            views = render_world_views(cid, scene, seed, views_per_world, cfg)
            write_world(tmp / WORLD_DIR.format(seed=seed), scene, seed, views, cfg, time.perf_counter() - start, commit)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        p.disconnect(physicsClientId=cid)
    shutil.rmtree(out_dir, ignore_errors=True)
    os.replace(tmp, out_dir)
    return sorted(out_dir.glob(WORLD_DIR.format(seed="*")))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=DEFAULT_OUT_DIR)
    ap.add_argument("--train-worlds", type=int, default=300)
    ap.add_argument("--heldout-worlds", type=int, default=25)
    ap.add_argument("--views-per-world", type=int, default=8)
    args = ap.parse_args(argv)
    cfg = ViewConfig()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for name, base, worlds in (("train", TRAIN_SEED_BASE, args.train_worlds),
                               ("heldout", HELDOUT_SEED_BASE, args.heldout_worlds)):
        start = time.perf_counter()
        split = render_split(args.out_dir / name, base, worlds, args.views_per_world, cfg)
        elapsed = time.perf_counter() - start
        print(f"{name}: {worlds * args.views_per_world} frames from {len(split)} worlds (seeds {base}.."
              f"{base + worlds - 1}) in {elapsed:.1f} s -> {args.out_dir / name}", flush=True)


if __name__ == "__main__":
    main()
