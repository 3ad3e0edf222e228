"""Evaluate a trained follower against the scripted one: `python -m trade_gym.agents.evaluate --model DIR/policy.onnx`.

Both fly the same development worlds (reset seed = world seed) with the same env kwargs; per scene it reports
the mean horizontal distance to the target, the tracked and visible fractions and the env's return, and the
ratio of the model's distance to the scripted follower's. `trade-bench` scores the shipped follower; this scores
any ONNX file `trade_gym.agents.train` wrote (its SHA-256 from `train_record.json` when that file sits beside it).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trade_gym.agents.learned import LearnedFollower
from trade_gym.agents.scripted import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.bench.splits import DEVELOPMENT, refuse_evaluation_worlds
from trade_gym.config import CAMERA_RATE_HZ, SCENE_NAMES
from trade_gym.env import TradeFollowEnv
from trade_gym.metrics import mean_horizontal_distance, tracked_fraction, visible_fraction
from trade_gym.rollout import fly_episode

REWARD_PREFIX = "reward_"  # the env's per-term reward keys in info, which sum to the reward
DEFAULT_WORLDS = (0, 9)  # development worlds 0..9: ten per scene
DEFAULT_STEPS = 450  # 15 s at 30 Hz, the benchmark's episode length


def episode_scores(infos: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Mean horizontal distance [m], tracked and visible fractions and the return of one episode's infos."""
    ret = sum(float(v) for info in infos for k, v in info.items() if k.startswith(REWARD_PREFIX))
    return {"mean_horizontal_distance_m": mean_horizontal_distance(infos), "tracked_fraction": tracked_fraction(infos),
            "visible_fraction": visible_fraction(infos), "return": ret, "steps": len(infos)}


def _model_sha256(model: Path, given: str | None) -> str | None:
    if given is not None:
        return given
    record = model.parent / "train_record.json"
    return json.loads(record.read_text())["onnx_sha256"] if record.is_file() else None


def evaluate(model: Path, sha256: str, scenes: Sequence[str], worlds: Sequence[int], steps: int,
             env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Per scene, per follower: the per-world scores and their means; the learned / scripted distance ratio."""
    refuse_evaluation_worlds(worlds, "trade_gym.agents.evaluate --worlds")
    out: dict[str, Any] = {"model": str(model), "worlds": list(worlds), "steps": steps, "env_kwargs": env_kwargs,
                           "scenes": {}}
    for scene in scenes:
        env = TradeFollowEnv(scene=scene, episode_duration_s=steps / CAMERA_RATE_HZ, **env_kwargs)
        try:
            scripted = ScriptedFollowerConfig.of(env.config, env.action_scale)  # also a residual policy's base
            followers: dict[str, Callable[[], ScriptedFollower | LearnedFollower]] = {
                "scripted": lambda: ScriptedFollower(scripted),
                "learned": lambda: LearnedFollower(model, expected_sha256=sha256, base_config=scripted)}
            runs = {name: [episode_scores(fly_episode(env, make(), w, steps)) for w in worlds]
                    for name, make in followers.items()}
        finally:
            env.close()
        means = {name: {k: float(np.mean([r[k] for r in rs])) for k in rs[0]} for name, rs in runs.items()}
        ratio = means["learned"]["mean_horizontal_distance_m"] / means["scripted"]["mean_horizontal_distance_m"]
        out["scenes"][scene] = {"runs": runs, "mean": means, "distance_ratio_learned_to_scripted": ratio}
    return out


def _parse_kwarg(text: str) -> tuple[str, Any]:
    key, _, value = text.partition("=")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description="Fly a trained ONNX follower and the scripted one on development worlds.")
    p.add_argument("--model", type=Path, required=True, help="policy.onnx written by trade_gym.agents.train")
    p.add_argument("--sha256", default=None, help="expected SHA-256 (default: train_record.json beside the model)")
    p.add_argument("--scenes", nargs="+", default=list(SCENE_NAMES), choices=SCENE_NAMES)
    p.add_argument("--worlds", nargs=2, type=int, default=DEFAULT_WORLDS, metavar=("FIRST", "LAST"),
                   help=f"development world seeds, inclusive (default {DEFAULT_WORLDS[0]} {DEFAULT_WORLDS[1]})")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS)
    p.add_argument("--env", type=_parse_kwarg, action="append", default=[], metavar="KEY=VALUE",
                   help="gym.make kwarg (repeatable); default perception=oracle")
    p.add_argument("--out", type=Path, default=None, help="write the full JSON here")
    args = p.parse_args(argv)
    worlds = list(range(args.worlds[0], args.worlds[1] + 1))
    if not worlds or any(w not in DEVELOPMENT for w in worlds):
        p.error(f"--worlds must be development worlds ({DEVELOPMENT.first}..{DEVELOPMENT.last}), got {args.worlds}")
    sha256 = _model_sha256(args.model, args.sha256)
    if sha256 is None:
        p.error(f"--sha256 is needed: no train_record.json beside {args.model}")
    result = evaluate(args.model, sha256, args.scenes, worlds, args.steps, {"perception": "oracle"} | dict(args.env))
    if args.out is not None:
        args.out.write_text(json.dumps(result, indent=2))
    for scene, r in result["scenes"].items():
        cells = [f"{name} {m['mean_horizontal_distance_m']:.2f} m / {m['tracked_fraction']:.3f} / {m['return']:.0f}"
                 for name, m in r["mean"].items()]
        print(f"{scene}: distance / tracked / return: {'; '.join(cells)}; "
              f"ratio {r['distance_ratio_learned_to_scripted']:.2f}")


if __name__ == "__main__":
    main()
