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

Usage: python benchmarks/render_cost.py [--scenes desert city mountain] [--frames 20] [--rounds 3] [--json OUT]
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

from trade_gym.env import TradeFollowEnv
from trade_gym.provenance import git_commit
from trade.geometry import Pose

PIXEL_SIDES_PX = (64, 128, 256, 512)
BODY_SIDE_PX = 256
# a camera turned by pi about its own x axis looks up instead of down
TURN_UP = np.diag([1.0, -1.0, -1.0])
STATIC_ROLES_BUT_TERRAIN = ("boulders", "buildings", "road", "lake")


def _render_ms(env: TradeFollowEnv, pose: Pose, frames: int) -> float:
    start = time.perf_counter()
    for _ in range(frames):
        env.camera.render(pose)
    return (time.perf_counter() - start) / frames * 1e3


def _env(scene: str, side_px: int, seed: int) -> tuple[TradeFollowEnv, Pose]:
    env = TradeFollowEnv(scene=scene, perception="oracle", camera_size=side_px)
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


def measure_scene(scene: str, seed: int, frames: int, rounds: int) -> dict:
    samples: dict[str, list[float]] = {}
    counts: dict = {}
    for _ in range(rounds):
        for side in PIXEL_SIDES_PX:
            env, pose = _env(scene, side, seed)
            samples.setdefault(f"{side} px", []).append(_render_ms(env, pose, frames))
            env.close()
        env, pose = _env(scene, BODY_SIDE_PX, seed)
        counts = _counts(env)
        up = Pose(pose.R @ TURN_UP, pose.t)
        samples.setdefault("looking at the sky", []).append(_render_ms(env, up, frames))
        for name, ms in _body_rows(env, pose, frames).items():
            samples.setdefault(name, []).append(ms)
        env.close()
    return {"counts": counts, "render_ms_median": {k: round(float(np.median(v)), 2) for k, v in samples.items()},
            "render_ms_samples": {k: [round(x, 2) for x in v] for k, v in samples.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["desert", "city", "mountain"])
    parser.add_argument("--seed", type=int, default=0, help="world seed (a development world)")
    parser.add_argument("--frames", type=int, default=20, help="renders per measurement")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    load_start = os.getloadavg()[0]
    result = {"scenes": {s: measure_scene(s, args.seed, args.frames, args.rounds) for s in args.scenes},
              "renderer": "TinyRenderer", "seed": args.seed, "frames": args.frames, "rounds": args.rounds,
              "meta": {"commit": git_commit(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                       "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                       "python": platform.python_version(),
                       "load_average_1min": [round(load_start, 2), round(os.getloadavg()[0], 2)]}}
    print(json.dumps({s: r["counts"] | r["render_ms_median"] for s, r in result["scenes"].items()}, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
