"""Which library's SIMD path changes a closed-loop run: the same episode flown with numpy's and OpenCV's widest
runtime-dispatched targets switched off, one process per setting, compared frame by frame with the default.

Both libraries pick their kernels at run time from the CPU (numpy: `NPY_DISABLE_CPU_FEATURES`, OpenCV:
`OPENCV_CPU_DISABLE` turn targets off), so switching a target off here flies what a CPU without it flies.
onnxruntime's MLAS also picks kernels by CPU but has no such switch; it is not covered. The runs: scripted
follower, full TRADE, vio pose, evasive target, randomised looks (where the closed loop is most sensitive), on
training worlds.

    python benchmarks/simd_paths.py --out benchmarks/results/simd_paths.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

# Off-switches of the AVX-512 targets this machine's numpy and OpenCV dispatch to (numpy 2.4 names its x86-64-v4
# group and the Ice Lake set; OpenCV its Skylake-X and Cascade Lake sets); a CPU without AVX-512 runs the rest.
SETTINGS: dict[str, dict[str, str]] = {
    "default": {},
    "numpy_without_avx512": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL"},
    "opencv_without_avx512": {"OPENCV_CPU_DISABLE": "AVX512-SKX,AVX512-CLX"},
}
CASES = (("desert", 10200), ("mountain", 10202), ("city", 10201))  # training worlds (breadth-tuning's)
STEPS = 300
CAMERA_PX = 256
MOVED_PX = 1.0  # a box that moved more than this counts as a visible divergence

EPISODE = """
import json, sys
import numpy as np
from trade_gym.agents.scripted import ScriptedFollower
from trade_gym.bench.suites import UNSEEN_PROTOCOL
from trade_gym.rollout import run_episode
scene, seed, steps, size, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
kwargs = dict(UNSEEN_PROTOCOL) | dict(scene=scene, target_motion="evasive", appearance="randomized",
                                      perception="trade", pose_source="vio", decoys="ambiguous", camera_size=size)
infos = run_episode(ScriptedFollower(), seed, steps, **kwargs)
boxes = np.array([np.nan * np.ones(4) if i["est_bbox"] is None else i["est_bbox"] for i in infos], float)
tracked = float(np.mean([bool(i["est_valid"]) and (i["iou"] or 0.0) > 0.0 for i in infos]))
np.save(out, boxes)
print(json.dumps({"frames": len(infos), "tracked_fraction": round(tracked, 3)}))
"""


def fly(scene: str, seed: int, env: dict[str, str], out: Path) -> dict:
    """One episode in a fresh process with `env` added to the environment; its summary (boxes saved to `out`)."""
    done = subprocess.run([sys.executable, "-c", EPISODE, scene, str(seed), str(STEPS), str(CAMERA_PX), str(out)],
                          env=os.environ | env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def divergence(base: np.ndarray, other: np.ndarray) -> dict:
    """First frame whose box differs at all, and the first that differs by more than MOVED_PX."""
    n = min(len(base), len(other))
    diff = np.abs(np.nan_to_num(base[:n]) - np.nan_to_num(other[:n])).max(axis=1)
    first, moved = np.flatnonzero(diff > 0.0), np.flatnonzero(diff > MOVED_PX)
    return {"first_differing_frame": int(first[0]) if len(first) else None,
            "difference_there_px": float(diff[first[0]]) if len(first) else 0.0,
            "first_frame_moved_over_1px": int(moved[0]) if len(moved) else None,
            "identical": bool(len(first) == 0 and len(base) == len(other))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--work", type=Path, default=Path("simd_paths_out"))
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    import cv2

    record: dict = {"what": __doc__.split("\n\n")[0], "steps": STEPS, "camera_px": CAMERA_PX, "settings": SETTINGS,
                    "numpy": np.__version__, "opencv": cv2.__version__, "opencv_cpu": cv2.getCPUFeaturesLine(),
                    "runs": []}
    for scene, seed in CASES:
        boxes, row = {}, {"scene": scene, "world_seed": seed}
        for name, env in SETTINGS.items():
            path = args.work / f"{scene}_{seed}_{name}.npy"
            row[name] = fly(scene, seed, env, path)
            boxes[name] = np.load(path)
            if name != "default":
                row[name] |= divergence(boxes["default"], boxes[name])
        again = args.work / f"{scene}_{seed}_default_again.npy"
        fly(scene, seed, {}, again)
        row["default_repeat_identical"] = divergence(boxes["default"], np.load(again))["identical"]
        record["runs"].append(row)
        print(json.dumps(row), flush=True)
    args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
