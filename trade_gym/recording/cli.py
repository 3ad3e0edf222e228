"""`trade-replay`: run the TRADE stack open-loop over a recorded sequence and write its per-frame estimates,
the trade-bench metrics where the sequence has ground truth, and optionally an annotated video.

Every input is checked before the stack runs; outputs go to a hidden temporary folder renamed to --out at the
end, so a failed replay leaves nothing behind. Errors are one line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time
from collections.abc import Sequence as Seq
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from trade_gym.bench.runner import trajectory_sha256  # first: imports pybullet without its banner
from trade_gym.cli_args import OneLineParser, UsageError, parse_switch
from trade_gym.perception.trade_stack import STACK_SWITCHES, pipeline_config
from trade_gym.provenance import cpu_model, git_commit
from trade_gym.recording.format import SequenceError, json_safe
from trade_gym.recording.reader import Sequence, open_sequence
from trade_gym.recording.replay import REPLAY_PERCEPTIONS, ReplayResult, recorded_settings, replay

PROG = "trade-replay"
EXIT_USAGE = 2
ESTIMATES_FILE, RESULTS_FILE, VIDEO_STEM = "estimates.jsonl", "results.json", "video"
RESULTS_KIND = "trade-replay"
PARTIAL_SUFFIX = ".partial"


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog=PROG, description="Replay the TRADE stack open-loop over a recorded sequence "
                "(docs/sequence_format.md). By default the stack runs as recorded (meta.json: mode, switches and "
                "the seed of its own generator), which reproduces the recorded run's estimates exactly.")
    p.add_argument("sequence", type=Path, help="sequence folder (with meta.json and frames.jsonl)")
    p.add_argument("--perception", choices=REPLAY_PERCEPTIONS, help="trade or dcf (default: as recorded, else trade)")
    p.add_argument("--ablation", action="append", default=[], metavar="SWITCH=VALUE",
                   help=f"stack switch ({', '.join(STACK_SWITCHES)}) = true|false; repeatable")
    p.add_argument("--out", type=Path, help="output folder (created; must not exist or be empty; its parent must exist)")
    p.add_argument("--video", action="store_true", help="also write the annotated frames as video.mp4 (GIF "
                   "without an mp4 encoder): green the true box, red the estimate, the stack's overlay")
    return p


def _overrides(items: Seq[str]) -> tuple[tuple[str, bool], ...]:
    return tuple((name, values[0]) for name, values in (parse_switch(item, STACK_SWITCHES) for item in items))


def _check_out(out: Path | None) -> Path:
    if out is None:
        raise UsageError("--out DIR is required")
    if not out.parent.is_dir():
        raise UsageError(f"--out {out}: parent folder {out.parent} does not exist")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UsageError(f"--out {out} exists and is not an empty folder")
    return out


def results_document(sequence: Sequence, result: ReplayResult, argv: Seq[str], video: str | None) -> dict[str, Any]:
    """results.json: the replay's settings, its metrics (as trade-bench's per run) and trajectory hash where the
    sequence has ground truth, and where and when it ran."""
    n = len(result.estimates)
    return json_safe({
        "kind": RESULTS_KIND,
        "sequence": str(sequence.path),
        "sequence_commit": sequence.meta.get("commit"),
        "frames": n,
        "valid_frames": sum(e.valid for e in result.estimates),
        "perception": result.settings.as_json(),
        "settings_match_recording": result.settings_match_recording,
        "ground_depth_ray": result.ground_depth_ray,
        "scored_frames": len(result.infos) if result.infos is not None else 0,
        "metrics": result.metrics,
        # trade-bench's trajectory_sha256 of the scored frames: equal to the recorded run's when the replay
        # reproduces it (same boxes and depths, bit for bit)
        "trajectory_sha256": trajectory_sha256(result.infos) if result.infos is not None else None,
        "warnings": list(result.warnings),
        "video": video,
        "timing": {"wall_s": result.wall_s, "ms_per_frame": 1e3 * result.wall_s / n if n else None},
        "meta": {"argv": list(argv), "commit": git_commit(), "cpu": cpu_model(), "cores": os.cpu_count() or 0,
                 "python": platform.python_version(),
                 "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")},
    })


def write_outputs(out: Path, sequence: Sequence, result: ReplayResult, argv: Seq[str]) -> None:
    """estimates.jsonl, results.json and the video into a temporary folder beside `out`, then renamed to it."""
    tmp = out.parent / f".{out.name}{PARTIAL_SUFFIX}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        with open(tmp / ESTIMATES_FILE, "w", encoding="utf-8") as f:
            for estimate in result.estimates:
                f.write(json.dumps(estimate.as_json(), allow_nan=False, separators=(",", ":")) + "\n")
        video = None
        if result.video_frames:
            from trade_gym.bench.video import write_video

            rate = sequence.meta.get("frame_rate_hz")
            video = write_video(result.video_frames, tmp / VIDEO_STEM, *(() if rate is None else (float(rate),))).name
        document = results_document(sequence, result, argv, video)
        (tmp / RESULTS_FILE).write_text(json.dumps(document, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        if out.exists():
            out.rmdir()  # checked empty before the run
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def main(argv: Seq[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
        overrides = _overrides(args.ablation)
        out = _check_out(args.out)
        sequence = open_sequence(args.sequence)
        try:
            settings = recorded_settings(sequence, args.perception, overrides)
            pipeline_config(settings.env_config())  # the stack's own checks of the switches, before it runs
        except ValueError as exc:
            raise UsageError(f"the stack rejects these settings: {exc}") from None
        start = time.perf_counter()
        result = replay(sequence, settings, video=args.video)
        for line in result.warnings:
            print(f"{PROG}: warning: {line}", file=sys.stderr)
        write_outputs(out, sequence, result, argv)
    except (UsageError, SequenceError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    n = len(result.estimates)
    valid = sum(e.valid for e in result.estimates)
    scored = "" if result.metrics is None else (f", tracked {result.metrics['tracked_fraction']:.3g}, ground-depth "
                                                f"RMSE {result.metrics['ground_depth_rmse_m']:.3g} m")
    print(f"{n} frames ({valid} with a fresh box{scored}) in {time.perf_counter() - start:.1f} s -> {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
