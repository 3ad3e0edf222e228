"""results.json: per-run metrics, trajectory hashes and timing, the per-configuration summary and the run's meta
(commit, date, CPU and its vector ISA, package versions, renderer, backend), with NaN written as null; its JSON
schema ships here.
"""

from __future__ import annotations

import importlib.metadata
import json
import math
import os
import platform
import re
from collections.abc import Sequence
from dataclasses import asdict, fields
from datetime import datetime, timezone
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from trade_gym.bench.policies import policy_env_kwargs
from trade_gym.bench.runner import RunResult, RunSeries, RunTiming
from trade_gym.bench.suites import RunSpec
from trade_gym.bench.summary import metric_values, spec_record
from trade_gym.metrics import METRIC_NAMES
from trade_gym.provenance import cpu_model, git_commit  # noqa: F401  (git_commit: re-exported)

SCHEMA_VERSION = 2  # 2: the scorecard metrics (success, following_rate, collision_rate, nre, dre, adq)
SCHEMA_FILE = "results.schema.json"
PACKAGES = ("numpy", "pybullet", "gymnasium", "opencv-python-headless", "onnxruntime", "stable-baselines3",
            "filterpy", "numba", "matplotlib", "ray", "trade-gym")
RENDERER = "TinyRenderer"  # pybullet DIRECT mode's software renderer (the env's default)
RENDERER_NAMES = {"tiny": RENDERER, "egl": "EGL"}  # by EnvConfig.renderer ("egl": pybullet's eglRenderer plugin)
SERIES_FILE = "series.npz"  # every run's per-frame series, keyed "<run_id>/<field>" (see RunSeries)


def package_versions(names: Sequence[str] = PACKAGES) -> dict[str, str]:
    """The installed version of each distribution in `names`; 'not installed' for a missing one."""
    versions = {}
    for name in names:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


CPUINFO = Path("/proc/cpuinfo")
# The widest vector ISA first: its name and the cpuinfo flag that marks it (x86 "flags", Arm "Features").
VECTOR_ISAS = (("AVX-512", "avx512f"), ("AVX2", "avx2"), ("AVX", "avx"), ("SSE4.2", "sse4_2"), ("SVE2", "sve2"),
               ("SVE", "sve"), ("NEON", "asimd"))
UNKNOWN = "unknown"
NUMPY_TARGET = re.compile(r"baseline\([^)]*\)|\S+")  # one target in opt_func_info's "available" (widest first)


def vector_isa(flags: Sequence[str]) -> str:
    """The widest vector ISA among a CPU's flags, AVX-512 with its avx512 flags ('AVX-512: avx512f avx512bw');
    'unknown' when none is known."""
    for name, flag in VECTOR_ISAS:
        if flag in flags:
            return f"{name}: {' '.join(f for f in flags if f.startswith('avx512'))}" if flag == "avx512f" else name
    return UNKNOWN


def cpu_flags() -> list[str]:
    """The first processor's flags from /proc/cpuinfo (empty elsewhere or when unreadable)."""
    try:
        lines = CPUINFO.read_text().splitlines()
    except OSError:
        return []
    return next((line.split(":", 1)[1].split() for line in lines if line.split(":")[0].strip() in
                 ("flags", "Features")), [])


def widest_numpy_target(info: dict[str, dict[str, dict[str, str]]]) -> str:
    """The widest SIMD target numpy runs any loop on, from `numpy.lib.introspect.opt_func_info()`: the loops'
    current targets, one of them wider than another where some loop lists both as available (widest first)."""
    currents = {loop["current"] for loops in info.values() for loop in loops.values()}
    orders = [NUMPY_TARGET.findall(loop["available"]) for loops in info.values() for loop in loops.values()]
    narrower = {t for order in orders for i, t in enumerate(order) if currents & set(order[:i])}
    return next(iter(sorted(currents - narrower)), UNKNOWN)


def _numpy_simd() -> str:
    try:
        from numpy.lib.introspect import opt_func_info  # numpy >= 2.0
    except ImportError:
        return UNKNOWN
    return widest_numpy_target(opt_func_info())


def _opencv_simd() -> str:
    """OpenCV's widest dispatched feature this CPU has: the last '*' (dispatched) name of getCPUFeaturesLine without
    '?' (not available here)."""
    try:
        import cv2
    except ImportError:
        return UNKNOWN
    usable = [f[1:] for f in cv2.getCPUFeaturesLine().split() if f.startswith("*") and not f.endswith("?")]
    return usable[-1] if usable else UNKNOWN


@cache
def _simd() -> tuple[str, str, str]:
    return vector_isa(cpu_flags()), _numpy_simd(), _opencv_simd()


def simd_meta() -> dict[str, Any]:
    """The CPU's widest vector ISA and the SIMD path numpy and OpenCV dispatch to on it (read once per process).
    onnxruntime chooses its kernels inside its C++ library, with no Python view of the choice."""
    isa, numpy_path, opencv_path = _simd()
    return {"cpu_vector_isa": isa, "simd_dispatch": {"numpy": numpy_path, "opencv": opencv_path}}


def collect_meta(suite: str | None, argv: Sequence[str], jobs: int, n_runs: int, wall_s: float,
                 backend: str = "local", ray_address: str | None = None,
                 renderers: Sequence[str] = ("tiny",)) -> dict[str, Any]:
    """Where and when the numbers were measured (the repository is found from this file's location); `jobs` is
    how many runs executed at once (local worker processes, or the Ray cluster's CPUs); `renderers` the runs'
    `renderer` arguments (meta names each one used, e.g. "TinyRenderer" or "EGL, TinyRenderer")."""
    return {
        "suite": suite,
        "argv": list(argv),
        "commit": git_commit(Path(__file__).resolve().parent),
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "cpu": cpu_model(),
        **simd_meta(),
        "cores": os.cpu_count() or 0,
        "load_average_1min": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "packages": package_versions(),
        "renderer": ", ".join(sorted({RENDERER_NAMES[r] for r in renderers})) or RENDERER,
        "jobs": jobs,
        "backend": backend,
        "ray_address": ray_address,
        "runs": n_runs,
        "wall_s": wall_s,
    }


def run_record(result: RunResult) -> dict[str, Any]:
    s = result.spec
    return spec_record(s) | {"run_id": s.run_id, "seed": s.seed, "steps_requested": s.steps,
                             "camera_size": s.camera_size, "env_kwargs": s.env_kwargs(),
                             "metrics": dict(result.metrics), "trajectory_sha256": result.trajectory_sha256,
                             "timing": asdict(result.timing), "error": result.error}


def build_document(results: Sequence[RunResult], summary: list[dict[str, Any]], meta: dict[str, Any],
                   plots: Sequence[str], video: str | None) -> dict[str, Any]:
    """The results.json document. `runs[*].metrics` and `summary` are deterministic; timing lives only
    in `runs[*].timing`, `meta` and `timing`."""
    ok = [r for r in results if r.error is None]
    steps = int(sum(metric_values(ok, "steps")))
    loop_s = sum(r.timing.step_loop_s for r in ok)
    return {
        "schema_version": SCHEMA_VERSION,
        "meta": meta,
        "runs": [run_record(r) for r in results],
        "summary": summary,
        "timing": {"total_steps": steps, "step_loop_s": loop_s,
                   "mean_steps_per_s": steps / loop_s if loop_s > 0 else math.nan},
        "files": {"plots": list(plots), "video": video},
    }


def write_series(path: Path, results: Sequence[RunResult]) -> None:
    """The per-frame series of every finished run (float32, compressed), for analysis without a re-run."""
    arrays = {f"{r.spec.run_id}/{f.name}": getattr(r.series, f.name).astype(np.float32)
              for r in results if r.series is not None for f in fields(r.series)}
    np.savez_compressed(path, **arrays)


def _spec_of(run: dict[str, Any]) -> RunSpec:
    switches = tuple(run["switches"].items())
    own = (*RunSpec.OWN_ENV_KEYS, *policy_env_kwargs(run["policy"]))  # what the spec sets from its own fields
    extra = tuple((k, v) for k, v in run["env_kwargs"].items() if k not in own and k not in run["switches"])
    return RunSpec(run["group"], run["kind"], run["scene"], run["policy"], run["perception"], run["pose_source"],
                   run["seed"], run["steps_requested"], run["camera_size"], switches, extra, run["depth_kind"])


def _nan_for_none(metrics: dict[str, Any]) -> dict[str, Any]:
    return {k: math.nan if v is None else v for k, v in metrics.items()}


def load_results(path: Path) -> tuple[list[RunResult], dict[str, Any]]:
    """The runs and meta of a results.json written by trade-bench (with their per-frame series when the
    series.npz written beside it is there), to render its report again."""
    document = json.loads(path.read_text())
    series_path = path.with_name(SERIES_FILE)
    arrays = np.load(series_path) if series_path.is_file() else None
    results = []
    for run in document["runs"]:
        keys = [f"{run['run_id']}/{f.name}" for f in fields(RunSeries)]
        series = (RunSeries(*(arrays[k].astype(np.float64) for k in keys))
                  if arrays is not None and all(k in arrays for k in keys) else None)
        timing = RunTiming(**{k: math.nan if v is None else v for k, v in run["timing"].items()})
        metrics = _nan_for_none(run["metrics"])
        if metrics:  # a metric added after the file was written (e.g. the scorecard) is undefined there
            metrics = {name: math.nan for name in METRIC_NAMES} | metrics
        results.append(RunResult(_spec_of(run), metrics, timing, series, run["error"], run.get("trajectory_sha256")))
    meta = dict(document["meta"])
    meta.setdefault("backend", "local")  # results.json written before the Ray backend existed: runs were local
    meta.setdefault("ray_address", None)
    return results, meta


def to_json_safe(value: Any) -> Any:
    """Recursively replace non-finite floats by None (JSON has no NaN) and tuples by lists."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): to_json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_json_safe(v) for v in value]
    return value


def write_json(path: Path, document: dict[str, Any]) -> None:
    path.write_text(json.dumps(to_json_safe(document), indent=1, allow_nan=False) + "\n")


def load_schema() -> dict[str, Any]:
    """The JSON schema of results.json (package data)."""
    return json.loads(resources.files("trade_gym.bench").joinpath(SCHEMA_FILE).read_text())


def deterministic_part(document: dict[str, Any]) -> dict[str, Any]:
    """What two runs of the same command must agree on (on any backend): per-run metrics, trajectory hashes and
    errors, and the summary."""
    return {"runs": [{k: r[k] for k in ("run_id", "metrics", "trajectory_sha256", "error")} for r in document["runs"]],
            "summary": document["summary"]}
