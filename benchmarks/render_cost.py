"""What TinyRenderer's time depends on here: image size, the bodies in the world and what the camera sees.

For each scene, on one world (development world 0 unless --seed), the camera is held at the drone's start pose
(looking down at the target, as in flight) and rendered `--frames` times per measurement:

- pixels: the same view at 64, 128, 256 and 512 px;
- bodies: at 256 px, the full world, then cumulatively without the vehicles, without the static bodies other
  than the terrain (buildings, rocks, road, lake) and without the terrain (an empty world: the fixed cost);
- view: at 256 px, the full world seen from the start pose and from the same place looking up at the sky
  (nothing in view: every triangle is still transformed and clipped, none is filled).

Measurements are interleaved over `--rounds` rounds and the medians reported, so a change of the host's load
hits every row alike. Removing bodies happens in this script's own client only (the env never does that).
With `--renderers tiny egl` every row is measured with each renderer in the same rounds (rows of a renderer other
than tiny are prefixed with its name, e.g. "egl 256 px"). Each measurement first renders WARMUP_RENDERS frames
untimed (an EGL client's first two frames took ~0.3 s and ~0.2 s here, later ones ~50 ms).

Usage: python benchmarks/render_cost.py [--scenes desert city mountain] [--frames 20] [--rounds 3] [--json OUT]
       [--renderers tiny egl]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pybullet as p

from trade_gym.bench.results import RENDERER_NAMES
from trade_gym.env import TradeFollowEnv
from trade_gym.provenance import git_commit
from trade_gym.sim.camera import RENDERERS
from trade.geometry import Pose

PIXEL_SIDES_PX = (64, 128, 256, 512)
BODY_SIDE_PX = 256
WARMUP_RENDERS = 2  # per measurement, not timed
# a camera turned by pi about its own x axis looks up instead of down
TURN_UP = np.diag([1.0, -1.0, -1.0])
STATIC_ROLES_BUT_TERRAIN = ("boulders", "buildings", "road", "lake")


def _render_ms(env: TradeFollowEnv, pose: Pose, frames: int) -> float:
    for _ in range(WARMUP_RENDERS):  # untimed: slow first frames (EGL), see the docstring
        env.camera.render(pose)
    start = time.perf_counter()
    for _ in range(frames):
        env.camera.render(pose)
    return (time.perf_counter() - start) / frames * 1e3


def _env(scene: str, side_px: int, seed: int, renderer: str) -> tuple[TradeFollowEnv, Pose]:
    # frames asked for: an oracle env that renders none is built undrawn (no visual shapes)
    env = TradeFollowEnv(scene=scene, perception="oracle", camera_size=side_px, renderer=renderer,
                         render_oracle_frames=True)
    env.reset(seed=seed)
    return env, env._true_camera_pose()


def _counts(env: TradeFollowEnv) -> dict:
    world = env.world
    ny, nx = world.terrain.heights_m.shape
    return {"bodies": p.getNumBodies(physicsClientId=env._client),
            "vehicles": 1 + len(world.decoys),
            "terrain_triangles": 2 * (ny - 1) * (nx - 1),
            "static_bodies": len(world.static_body_ids)}


def _remove(env: TradeFollowEnv, body_ids) -> None:
    for body in body_ids:
        p.removeBody(body, physicsClientId=env._client)


def _body_rows(env: TradeFollowEnv, pose: Pose, frames: int) -> dict[str, float]:
    """Cumulative removal, one render measurement after each step (this env is spent afterwards)."""
    world = env.world
    rows = {"full world": _render_ms(env, pose, frames)}
    _remove(env, [v.body_id for v in (world.target, *world.decoys)])
    rows["without vehicles"] = _render_ms(env, pose, frames)
    _remove(env, [i for role in STATIC_ROLES_BUT_TERRAIN for i in world.body_ids_by_role.get(role, ())])
    rows["terrain and drone only"] = _render_ms(env, pose, frames)
    _remove(env, world.body_ids_by_role["terrain"])
    rows["drone only (empty world)"] = _render_ms(env, pose, frames)
    return rows


def measure_scene(scene: str, seed: int, frames: int, rounds: int, renderers: tuple[str, ...] = ("tiny",)) -> dict:
    samples: dict[str, list[float]] = {}
    counts: dict = {}
    for _ in range(rounds):
        for renderer in renderers:
            counts = _measure_round(scene, seed, frames, renderer, samples)
    return {"counts": counts, "render_ms_median": {k: round(float(np.median(v)), 2) for k, v in samples.items()},
            "render_ms_samples": {k: [round(x, 2) for x in v] for k, v in samples.items()}}


def _measure_round(scene: str, seed: int, frames: int, renderer: str, samples: dict[str, list[float]]) -> dict:
    prefix = "" if renderer == "tiny" else f"{renderer} "
    for side in PIXEL_SIDES_PX:
        env, pose = _env(scene, side, seed, renderer)
        samples.setdefault(f"{prefix}{side} px", []).append(_render_ms(env, pose, frames))
        env.close()
    env, pose = _env(scene, BODY_SIDE_PX, seed, renderer)
    counts = _counts(env)
    up = Pose(pose.R @ TURN_UP, pose.t)
    samples.setdefault(f"{prefix}looking at the sky", []).append(_render_ms(env, up, frames))
    for name, ms in _body_rows(env, pose, frames).items():
        samples.setdefault(prefix + name, []).append(ms)
    env.close()
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["desert", "city", "mountain"])
    parser.add_argument("--seed", type=int, default=0, help="world seed (a development world)")
    parser.add_argument("--frames", type=int, default=20, help="renders per measurement")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--renderers", nargs="+", choices=RENDERERS, default=["tiny"])
    args = parser.parse_args()
    load_start = os.getloadavg()[0]
    renderers = tuple(args.renderers)
    result = {"scenes": {s: measure_scene(s, args.seed, args.frames, args.rounds, renderers) for s in args.scenes},
              "renderer": ", ".join(RENDERER_NAMES[r] for r in renderers), "seed": args.seed, "frames": args.frames,
              "rounds": args.rounds,
              "meta": {"commit": git_commit(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                       "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                       "python": platform.python_version(),
                       "load_average_1min": [round(load_start, 2), round(os.getloadavg()[0], 2)]}}
    print(json.dumps({s: r["counts"] | r["render_ms_median"] for s, r in result["scenes"].items()}, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
