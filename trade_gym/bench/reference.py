"""Regression guard: the quick suite's fixed-seed metrics, committed as a reference, and the check that a
new run reproduces every one of them, in either direction, within a stated float tolerance.

The rule (`TOLERANCES`): counts and flags (steps, frames, decoy switches, crashed) must match exactly; every
other metric may differ from the reference by at most FLOAT_ABS_TOL + FLOAT_REL_TOL x |reference|. Why so
tight: on one machine the runs are bit-identical, so any difference is a change in behaviour; across CPUs that
take the same SIMD paths float results drift in the last digits (~1e-15 relative seen so far), and 1e-6 leaves
ample room for that while one frame scored differently moves a fraction of a 150-300-frame run by >= 3e-3. Across
SIMD paths the image pipeline's closed loop does not reproduce: with numpy's AVX-512 dispatch turned off, one TRADE
run of the suite differed by 0.19 m in ground RMSE (benchmarks/results/simd_paths.json, docs/benchmark.md). The
reference therefore records the SIMD paths it was measured on (`simd_meta`). A check on other paths says so, and
there only the oracle runs (no image pipeline) must reproduce; the image-perception runs' differences are printed as
expected ones (`ReferenceCheck.path_dependent`), so `make test` passes on any CPU and stays strict on the reference's.
Across package versions it does not reproduce either (numpy 2.5 against 2.4 moves the mountain TRADE run's ground
RMSE by 0.17 m): the versions of the numeric stack are pinned in `reference_stack.txt`, a pip constraints file that
`make test` installs with, the reference records the versions it was measured with (`stack_versions`), writing
one refuses an environment off the pins, and a check in another environment names the packages that differ.
A change is a failure whether it is better or worse: an improvement is re-recorded on purpose, with its
numbers in the commit message. The check also fails on a run of the suite missing from the reference, a
reference run missing from the results (unless the suite was filtered), a run that failed, and a metric
present on one side only.

Regenerate (after an intended change, from a clean git tree, whose commit the reference records):
    trade-bench --suite quick --out /tmp/quick --write-reference
"""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import Any

from trade_gym.bench.results import package_versions, simd_meta, to_json_safe
from trade_gym.bench.runner import RunResult
from trade_gym.provenance import git_head, tracked_changes

ORACLE_PERCEPTION = "oracle"  # runs without the image pipeline: they reproduce on any SIMD path

REFERENCE_FILE = "quick_reference.json"
STACK_FILE = "reference_stack.txt"  # pip constraints: the numeric packages the reference reproduces with
REGENERATE_COMMAND = "trade-bench --suite quick --out /tmp/quick --write-reference"
REPO_DIR = Path(__file__).resolve().parent  # git runs here: the checkout this code was loaded from
SHOWN_CHANGES = 5  # changed files named in the dirty-tree error


@dataclass(frozen=True)
class Tolerance:
    """A metric may differ from its reference, either way, by at most abs_tol + rel_tol * |reference|."""

    abs_tol: float = 0.0
    rel_tol: float = 0.0

    def __post_init__(self) -> None:
        for name in ("abs_tol", "rel_tol"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"Tolerance.{name} must be >= 0, got {getattr(self, name)!r}")

    def allowed(self, reference: float) -> float:
        return self.abs_tol + self.rel_tol * abs(reference)

    def exceeded_by(self, reference: float, value: float) -> float:
        """How far |value - reference| is beyond the allowed difference (> 0 fails)."""
        return abs(value - reference) - self.allowed(reference)


# Float drift across CPUs and libraries (see the module docstring for why these values).
FLOAT_ABS_TOL, FLOAT_REL_TOL = 1e-9, 1e-6
EXACT = Tolerance()
FLOAT_DRIFT = Tolerance(FLOAT_ABS_TOL, FLOAT_REL_TOL)
TOLERANCES: dict[str, Tolerance] = {
    "steps": EXACT,
    "visible_fraction": FLOAT_DRIFT,
    "tracked_fraction": FLOAT_DRIFT,
    "success_auc": FLOAT_DRIFT,
    "precision_20px": FLOAT_DRIFT,
    "longest_lost_streak_s": FLOAT_DRIFT,
    "decoy_switches": EXACT,
    "ground_depth_rmse_m": FLOAT_DRIFT,
    "ground_depth_frames": EXACT,
    "target_depth_rmse_m": FLOAT_DRIFT,
    "target_depth_frames": EXACT,
    "mean_horizontal_error_m": FLOAT_DRIFT,
    "crashed": EXACT,
    "ground_depth_bias_m": FLOAT_DRIFT,
    "ground_depth_off_fraction": FLOAT_DRIFT,
    "initial_iou": FLOAT_DRIFT,
    "success": EXACT,
    "following_rate": FLOAT_DRIFT,
    "collision_rate": EXACT,
    "nre": FLOAT_DRIFT,
    "dre": FLOAT_DRIFT,
    "adq": FLOAT_DRIFT,
}


class UncleanTree(ValueError):
    """The checkout has changes to tracked files (or is no checkout), so no clean commit names the code."""


def reference_path() -> Path:
    """The committed reference (package data next to this module)."""
    return Path(str(resources.files("trade_gym.bench").joinpath(REFERENCE_FILE)))


def clean_commit(repo: Path | None = None) -> str:
    """HEAD's short hash when the checkout at `repo` (default REPO_DIR) has no changed tracked files; else
    UncleanTree naming the changes."""
    repo = REPO_DIR if repo is None else repo
    try:
        commit, changes = git_head(repo), tracked_changes(repo)
    except (OSError, subprocess.SubprocessError) as exc:
        raise UncleanTree(f"{repo} is not in a git checkout ({type(exc).__name__}); the reference records "
                          f"the commit it was measured at") from None
    if changes:
        shown = ", ".join(changes[:SHOWN_CHANGES]) + (", ..." if len(changes) > SHOWN_CHANGES else "")
        raise UncleanTree(f"the git tree at {commit} is dirty ({len(changes)} changed tracked files: {shown}); "
                          f"commit or stash them first, the reference records a clean commit")
    return commit


def stack_pins(path: Path | None = None) -> dict[str, str]:
    """The pinned versions of `STACK_FILE` (lines 'name==version'; '#' starts a comment)."""
    path = Path(str(resources.files("trade_gym.bench").joinpath(STACK_FILE))) if path is None else path
    pins = {}
    for number, raw in enumerate(path.read_text().splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        if not sep or not name.strip() or not version.strip():
            raise ValueError(f"{path}:{number}: expected 'name==version', got {raw!r}")
        pins[name.strip()] = version.strip()
    return pins


def stack_versions(names: Sequence[str] | None = None) -> dict[str, str]:
    """The installed versions of the pinned packages (or of `names`); 'not installed' for a missing one."""
    return package_versions(tuple(stack_pins()) if names is None else names)


def stack_differences(recorded: dict[str, str], current: dict[str, str]) -> list[str]:
    """'name current (recorded)' for each package of `recorded` whose version differs in `current`."""
    return [f"{name} {current.get(name, 'not installed')} ({version})" for name, version in recorded.items()
            if current.get(name) != version]


def stack_note(recorded: dict[str, str] | None, current: dict[str, str] | None = None) -> str | None:
    """A note when this environment's numeric stack differs from the one the reference was measured with (None
    in an older reference that did not record it)."""
    if recorded is None:
        return None
    differences = stack_differences(recorded, stack_versions(list(recorded)) if current is None else current)
    if not differences:
        return None
    return (f"note: this environment differs from the reference's package versions: {', '.join(differences)} "
            f"(installed (recorded)). Closed-loop runs differ across numpy/OpenCV/onnxruntime versions; make "
            f"test installs the pinned versions of trade_gym/bench/{STACK_FILE}.")


def reference_document(results: Sequence[RunResult]) -> dict[str, Any]:
    """The reference of `results` (finished runs only); UncleanTree on a dirty checkout."""
    return {
        "about": "trade-bench quick-suite metrics for fixed seeds (regression guard); regenerate with: "
                 + REGENERATE_COMMAND,
        "commit": clean_commit(),
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "simd": simd_meta(),
        "stack": stack_versions(),
        "runs": {r.spec.run_id: {"steps_requested": r.spec.steps, "camera_size": r.spec.camera_size,
                                 "metrics": dict(r.metrics)} for r in results if r.error is None},
    }


class OffStack(ValueError):
    """The installed numeric stack differs from the pins of `STACK_FILE`."""


def write_reference(results: Sequence[RunResult], path: Path) -> None:
    """Write the reference; UncleanTree on a dirty checkout and OffStack off the pinned versions (nothing
    written)."""
    differences = stack_differences(stack_pins(), stack_versions())
    if differences:
        raise OffStack(f"the installed packages differ from trade_gym/bench/{STACK_FILE}: {', '.join(differences)} "
                       f"(installed (pinned)); record in a venv that make builds, or change the pins on purpose")
    document = reference_document(results)
    path.write_text(json.dumps(to_json_safe(document), indent=1, allow_nan=False) + "\n")


def load_reference(path: Path | None = None) -> dict[str, Any]:
    return json.loads((path or reference_path()).read_text())


def _as_float(value: Any) -> float:
    return math.nan if value is None else float(value)


def _metric_problem(name: str, reference: Any, value: Any) -> str | None:
    """Why `value` does not reproduce `reference` for metric `name`, or None when it does."""
    tol = TOLERANCES.get(name)
    if tol is None:
        return f"{name} has no stated tolerance (add it to trade_gym.bench.reference.TOLERANCES)"
    ref, now = _as_float(reference), _as_float(value)
    if math.isnan(ref) and math.isnan(now):
        return None
    if math.isnan(ref) or math.isnan(now):
        return f"{name} = {now:.12g}, reference {ref:.12g} (defined on one side only)"
    if tol.exceeded_by(ref, now) > 0.0:
        return (f"{name} = {now:.12g}, reference {ref:.12g} ({now - ref:+.3g}, allowed "
                f"±{tol.allowed(ref):.3g}: {tol.abs_tol:g} + {tol.rel_tol:g} x |ref|)")
    return None


def compare_run(run_id: str, metrics: dict[str, Any], reference: dict[str, Any]) -> list[str]:
    """One line per metric of `metrics` that differs from `reference`, either way, beyond its tolerance, or
    that is on one side only."""
    problems = []
    for name in dict.fromkeys([*reference, *metrics]):
        if name not in metrics:
            problems.append(f"{run_id}: {name} is in the reference, not in the results")
        elif name not in reference:
            problems.append(f"{run_id}: {name} is in the results, not in the reference")
        elif (problem := _metric_problem(name, reference[name], metrics[name])) is not None:
            problems.append(f"{run_id}: {problem}")
    return problems


@dataclass(frozen=True)
class ReferenceCheck:
    """Outcome of `check_against_reference`: every difference found, and how many runs were compared."""

    problems: tuple[str, ...]
    compared: int  # runs whose metrics were compared (all present, same length and camera, no error)
    reference_runs: int  # runs in the reference
    filtered: bool  # only a part of the suite was run, so reference runs without a result were not required
    # set when the reference was measured on other SIMD paths than this machine's (`simd_note`)
    simd_note: str | None = None
    # set when the reference was measured with other package versions than this environment's (`stack_note`)
    stack_note: str | None = None
    # differences of image-perception runs where this machine's SIMD paths are not the reference's: expected, not
    # problems (only the oracle runs must reproduce there)
    path_dependent: tuple[str, ...] = ()

    def summary_line(self) -> str:
        scope = " (suite filtered)" if self.filtered else ""
        count = len(self.problems)
        expected = f", {len(self.path_dependent)} expected on these SIMD paths" if self.path_dependent else ""
        return (f"reference check: {self.compared} of {self.reference_runs} reference runs compared{scope}, "
                f"{count} problem{'' if count == 1 else 's'}{expected}")


def _run_problem(result: RunResult, entry: dict[str, Any]) -> str | None:
    """Why `result` cannot be compared with its reference entry, or None."""
    spec = result.spec
    if (entry["steps_requested"], entry["camera_size"]) != (spec.steps, spec.camera_size):
        return (f"{spec.run_id}: {spec.steps} steps at {spec.camera_size} px, reference "
                f"{entry['steps_requested']} steps at {entry['camera_size']} px")
    if result.error is not None:
        return f"{spec.run_id}: failed: {result.error}"
    return None


def check_against_reference(results: Sequence[RunResult], reference: dict[str, Any], filtered: bool = False,
                            simd: dict[str, Any] | None = None) -> ReferenceCheck:
    """Compare every result with its reference entry. A result without an entry (or of another length or
    camera size, or failed) is a problem; so is a reference run without a result, unless `filtered` says
    only a part of the suite was run. `simd`: this machine's SIMD paths (`simd_meta()` when None); where they are
    not the reference's, an image-perception run's differences go to `path_dependent`, not `problems`."""
    runs: dict[str, Any] = reference["runs"]
    note = simd_note(reference.get("simd"), simd)
    problems, expected, compared = [], [], 0
    for result in results:
        entry = runs.get(result.spec.run_id)
        if entry is None:
            problems.append(f"{result.spec.run_id}: not in the reference")
            continue
        if (problem := _run_problem(result, entry)) is not None:
            problems.append(problem)
            continue
        compared += 1
        differences = compare_run(result.spec.run_id, result.metrics, entry["metrics"])
        if note is not None and result.spec.perception != ORACLE_PERCEPTION:
            expected += differences
        else:
            problems += differences
    if not filtered:
        present = {r.spec.run_id for r in results}
        problems += [f"{run_id}: in the reference, not in the results" for run_id in runs if run_id not in present]
    return ReferenceCheck(tuple(problems), compared, len(runs), filtered, note, stack_note(reference.get("stack")),
                          tuple(expected))


def simd_note(recorded: dict[str, Any] | None, current: dict[str, Any] | None = None) -> str | None:
    """A note when the reference's SIMD paths (`simd_meta` at recording; None in an older reference) differ from
    this machine's: its closed-loop runs are then not expected to reproduce to float tolerance."""
    current = simd_meta() if current is None else current
    if recorded is None or recorded.get("simd_dispatch") == current["simd_dispatch"]:
        return None
    def paths(meta: dict[str, Any]) -> str:
        return ", ".join(f"{lib} {path}" for lib, path in meta["simd_dispatch"].items())
    return (f"note: the reference was measured with {paths(recorded)} ({recorded.get('cpu_vector_isa')}); this "
            f"machine dispatches {paths(current)}. The image pipeline's closed loop differs across SIMD paths, so "
            f"here only the oracle runs must reproduce (docs/benchmark.md, 'Reproducibility').")
