"""Regression guard: every run of the quick suite must reproduce the committed reference
(trade_gym/bench/quick_reference.json) within float drift, in either direction; `make test` runs the whole
check (`trade-bench --suite quick --check-reference`). Re-record after an intended change, from a clean git
tree, with `trade-bench --suite quick --out /tmp/quick --write-reference` and commit the file."""

from __future__ import annotations

import dataclasses
import math
import subprocess
from pathlib import Path

import pytest

from trade_gym.bench import cli, reference
from trade_gym.bench.policies import available_policies
from trade_gym.bench.results import simd_meta
from trade_gym.bench.runner import RunResult, RunTiming, run_all
from trade_gym.bench.suites import Selection, expand_suite
from trade_gym.metrics import METRIC_NAMES
from trade_gym.provenance import git_commit

# Oracle runs are cheap (~1-3 ms/step); one rendered TRADE run (128 px, 150 steps) covers the stack.
GUARD_RUN_IDS = (
    "follow/desert/scripted/oracle/gt/seed0",
    "follow/city/scripted/oracle/gt/seed0",
    "follow/mountain/scripted/oracle/gt/seed0",
    "follow/desert/random/oracle/gt/seed0",
    "tracking/desert/scripted/trade/gt/seed0",
)
ALL_POLICIES = ("scripted", "learned", "hover", "random")  # the reference's followers, available here or not
TRADE_RUN = "tracking/desert/scripted/trade/gt/seed0"
TIMING = RunTiming(wall_s=1.0, reset_s=0.1, step_loop_s=0.9, steps_per_s=100.0)  # not compared
GIT_IDENTITY = ("-c", "user.name=guard test", "-c", "user.email=guard@example.invalid")


@pytest.fixture(scope="module")
def guard_results():
    specs = {s.run_id: s for s in expand_suite("quick", Selection(), available_policies())}
    return run_all([specs[run_id] for run_id in GUARD_RUN_IDS], jobs=1)


@pytest.fixture(scope="module")
def ref():
    return reference.load_reference()


def _recorded_results(ref, **changed) -> list[RunResult]:
    """The quick suite's runs with the reference's own metrics (no episode flown); `changed` maps a run id to
    the metrics to replace in it."""
    def metrics(run_id: str) -> dict:  # NaN where the JSON has null, as a run reports it
        recorded = {k: math.nan if v is None else v for k, v in ref["runs"][run_id]["metrics"].items()}
        return recorded | changed.get(run_id, {})
    return [RunResult(s, metrics(s.run_id), TIMING, None) for s in expand_suite("quick", Selection(), ALL_POLICIES)]


def _check_one(ref, run_id: str, **metrics) -> reference.ReferenceCheck:
    """The check of one changed run on a machine with the reference's SIMD paths (where every run is strict)."""
    return reference.check_against_reference(_recorded_results(ref, **{run_id: metrics}), ref, simd=ref["simd"])


def _other_simd(current: dict) -> dict:
    """SIMD paths other than `current`'s."""
    avx2 = {"cpu_vector_isa": "AVX2", "simd_dispatch": {"numpy": "X86_V3", "opencv": "AVX2"}}
    sse = {"cpu_vector_isa": "SSE4.2", "simd_dispatch": {"numpy": "X86_V2", "opencv": "SSE4.2"}}
    return sse if current["simd_dispatch"] == avx2["simd_dispatch"] else avx2


def test_quick_slice_reproduces_committed_reference(guard_results, ref):
    check = reference.check_against_reference(guard_results, ref, filtered=True)
    assert check.problems == (), "\n".join(check.problems + (f"re-record if intended: {reference.REGENERATE_COMMAND}",))
    assert check.compared == len(GUARD_RUN_IDS)


def test_guard_trade_run_tracks_and_estimates_ground_depth(guard_results):
    trade = guard_results[-1].metrics
    assert trade["tracked_fraction"] >= 0.9 and trade["ground_depth_frames"] > 0


def test_guard_flags_degraded_tracking_and_depth(guard_results, ref):
    run = guard_results[-1]
    worse = dict(run.metrics, tracked_fraction=run.metrics["tracked_fraction"] - 0.2,
                 ground_depth_rmse_m=2.0 * run.metrics["ground_depth_rmse_m"] + 1.0)
    check = reference.check_against_reference([dataclasses.replace(run, metrics=worse)], ref, filtered=True,
                                              simd=ref["simd"])
    assert [p.split(" ")[1] for p in check.problems] == ["tracked_fraction", "ground_depth_rmse_m"]


def test_reference_records_every_quick_run_and_every_metric_has_a_stated_tolerance(ref):
    assert set(ref["runs"]) == {s.run_id for s in expand_suite("quick", Selection(), ALL_POLICIES)}
    assert len(ref["runs"]) == 18
    assert set(reference.TOLERANCES) == set(METRIC_NAMES)
    assert all(set(entry["metrics"]) == set(METRIC_NAMES) for entry in ref["runs"].values())
    assert "+dirty" not in ref["commit"] and ref["commit"] != "unknown"


def test_full_suite_with_recorded_metrics_compares_all_runs_without_problems(ref):
    check = reference.check_against_reference(_recorded_results(ref), ref)
    assert check.problems == () and check.compared == check.reference_runs == 18
    assert check.summary_line() == "reference check: 18 of 18 reference runs compared, 0 problems"


@pytest.mark.parametrize("factor", [0.9, 1.1])  # lower and higher RMSE: an improvement fails like a regression
def test_depth_rmse_change_beyond_tolerance_fails_in_either_direction(ref, factor):
    rmse = ref["runs"][TRADE_RUN]["metrics"]["ground_depth_rmse_m"]
    check = _check_one(ref, TRADE_RUN, ground_depth_rmse_m=factor * rmse)
    assert len(check.problems) == 1 and check.compared == 18
    assert check.problems[0].startswith(f"{TRADE_RUN}: ground_depth_rmse_m = ")


def test_one_more_tracked_frame_fails_and_one_fewer_decoy_switch_fails(ref):
    run_id = "follow/desert/hover/oracle/gt/seed0"  # 3 decoy switches, tracked 0.61
    metrics = ref["runs"][run_id]["metrics"]
    frames = metrics["steps"] * metrics["visible_fraction"]
    check = _check_one(ref, run_id, tracked_fraction=metrics["tracked_fraction"] + 1.0 / frames,
                       decoy_switches=metrics["decoy_switches"] - 1)
    assert [p.split(" ")[1] for p in check.problems] == ["tracked_fraction", "decoy_switches"]


def test_float_drift_within_tolerance_passes_and_just_beyond_fails(ref):
    rmse = ref["runs"][TRADE_RUN]["metrics"]["ground_depth_rmse_m"]
    allowed = reference.TOLERANCES["ground_depth_rmse_m"].allowed(rmse)
    assert 0.0 < allowed < 1e-5 * rmse  # small, but more than float64 rounding
    for sign in (-1.0, 1.0):
        assert _check_one(ref, TRADE_RUN, ground_depth_rmse_m=rmse + sign * 0.5 * allowed).problems == ()
        assert len(_check_one(ref, TRADE_RUN, ground_depth_rmse_m=rmse + sign * 2.0 * allowed).problems) == 1


def test_counts_and_flags_must_match_exactly(ref):
    check = _check_one(ref, TRADE_RUN, steps=149, crashed=True)
    assert [p.split(" ")[1] for p in check.problems] == ["steps", "crashed"]


def test_metric_defined_on_one_side_only_fails(ref):
    check = _check_one(ref, TRADE_RUN, ground_depth_rmse_m=math.nan)
    assert len(check.problems) == 1 and "defined on one side only" in check.problems[0]
    assert reference.compare_run("r", {"target_depth_rmse_m": None}, {"target_depth_rmse_m": None}) == []
    assert reference.compare_run("r", {"target_depth_rmse_m": 0.5}, {"target_depth_rmse_m": None}) != []


def test_metric_missing_on_one_side_is_reported(ref):
    metrics = dict(ref["runs"][TRADE_RUN]["metrics"])
    del metrics["initial_iou"]
    assert reference.compare_run(TRADE_RUN, metrics, ref["runs"][TRADE_RUN]["metrics"]) == [
        f"{TRADE_RUN}: initial_iou is in the reference, not in the results"]
    problems = reference.compare_run(TRADE_RUN, dict(metrics, initial_iou=0.3, new_score=1.0), metrics)
    assert [p.split(" ")[1] for p in problems] == ["initial_iou", "new_score"]


def test_reference_run_missing_from_results_is_reported_unless_filtered(ref):
    results = _recorded_results(ref)
    missing = [r for r in results if r.spec.run_id != TRADE_RUN]
    check = reference.check_against_reference(missing, ref)
    assert check.problems == (f"{TRADE_RUN}: in the reference, not in the results",) and check.compared == 17
    filtered = reference.check_against_reference(missing, ref, filtered=True)
    assert filtered.problems == () and "17 of 18 reference runs compared (suite filtered)" in filtered.summary_line()


def test_suite_run_missing_from_reference_or_of_other_length_or_failed_is_reported(ref):
    results = _recorded_results(ref)
    trimmed = {"runs": {k: v for k, v in ref["runs"].items() if k != TRADE_RUN}}
    assert reference.check_against_reference(results, trimmed).problems == (f"{TRADE_RUN}: not in the reference",)
    i = next(i for i, r in enumerate(results) if r.spec.run_id == TRADE_RUN)
    shorter = results[:i] + [dataclasses.replace(results[i], spec=dataclasses.replace(results[i].spec, steps=10))]
    assert "10 steps at 128 px, reference 150 steps" in reference.check_against_reference(shorter, ref,
                                                                                          True).problems[0]
    failed = dataclasses.replace(results[i], metrics={}, error="RuntimeError: boom")
    check = reference.check_against_reference(results[:i] + [failed] + results[i + 1:], ref)
    assert check.problems == (f"{TRADE_RUN}: failed: RuntimeError: boom",) and check.compared == 17


def _fake_runs(results: list[RunResult]):
    """A stand-in for runner.run_all that returns `results` for the specs asked for (no episode flown)."""
    by_id = {r.spec.run_id: r for r in results}

    def run_all(specs, on_done=None, executor=None):
        return [by_id[s.run_id] for s in specs]
    return run_all


def test_cli_check_reference_exits_1_on_an_improvement_and_0_when_reproduced(ref, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(reference, "simd_meta", lambda: ref["simd"])  # a machine of the reference's SIMD paths
    better = {TRADE_RUN: {"ground_depth_rmse_m": 0.5 * ref["runs"][TRADE_RUN]["metrics"]["ground_depth_rmse_m"]}}
    monkeypatch.setattr(cli, "run_all", _fake_runs(_recorded_results(ref, **better)))
    assert cli.main(["--suite", "quick", "--out", str(tmp_path / "a"), "--check-reference"]) == 1
    err = capsys.readouterr().err
    assert "reference check: 18 of 18 reference runs compared, 1 problem" in err
    assert f"{TRADE_RUN}: ground_depth_rmse_m" in err and "re-record" in err
    monkeypatch.setattr(cli, "run_all", _fake_runs(_recorded_results(ref)))
    assert cli.main(["--suite", "quick", "--out", str(tmp_path / "b"), "--check-reference"]) == 0
    assert "reference check: 18 of 18 reference runs compared, 0 problems" in capsys.readouterr().err


def test_cli_check_reference_of_a_filtered_suite_compares_the_selected_runs(ref, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run_all", _fake_runs(_recorded_results(ref)))
    assert cli.main(["--suite", "quick", "--scenes", "desert", "--out", str(tmp_path), "--check-reference"]) == 0
    expected = len(expand_suite("quick", Selection(scenes=("desert",)), available_policies()))
    assert f"reference check: {expected} of 18 reference runs compared (suite filtered), 0 problems" in (
        capsys.readouterr().err)


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *GIT_IDENTITY, *args], cwd=repo, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture
def repo(tmp_path, monkeypatch) -> Path:
    """A git repository with one committed file, standing in for the checkout the reference names."""
    root = tmp_path / "repo"
    root.mkdir()
    _git(root, "init", "--quiet")
    (root / "code.py").write_text("x = 1\n")
    _git(root, "add", "code.py")
    _git(root, "commit", "--quiet", "-m", "first")
    monkeypatch.setattr(reference, "REPO_DIR", root)
    return root


def _no_episodes(*args, **kwargs):
    raise AssertionError("an episode ran although --write-reference was refused")


def test_cli_write_reference_refuses_a_dirty_tree_before_any_episode(repo, tmp_path, monkeypatch, capsys):
    (repo / "code.py").write_text("x = 2\n")
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    target = tmp_path / "ref.json"
    assert cli.main(["--suite", "quick", "--out", str(tmp_path / "out"), "--write-reference", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trade-bench: error: --write-reference: the git tree at ") and err.count("\n") == 1
    assert "is dirty (1 changed tracked files: M code.py)" in err
    assert not target.exists() and not (tmp_path / "out").exists()


def test_write_reference_records_the_clean_commit_and_refuses_once_dirty(repo, ref, tmp_path):
    target = tmp_path / "ref.json"
    reference.write_reference(_recorded_results(ref), target)
    written = reference.load_reference(target)
    assert written["commit"] == _git(repo, "rev-parse", "--short", "HEAD") and "+dirty" not in written["commit"]
    assert reference.check_against_reference(_recorded_results(ref), written).problems == ()
    target.unlink()
    _git(repo, "rm", "--quiet", "--cached", "code.py")  # a staged change is a change too
    with pytest.raises(reference.UncleanTree, match=r"D +code\.py"):
        reference.write_reference(_recorded_results(ref), target)
    assert not target.exists()


def test_cli_write_reference_not_written_when_the_tree_turns_dirty_during_the_run(repo, ref, tmp_path,
                                                                                   monkeypatch, capsys):
    fly = _fake_runs(_recorded_results(ref))

    def fly_and_edit(specs, on_done=None, executor=None):
        (repo / "code.py").write_text("x = 3\n")
        return fly(specs)
    monkeypatch.setattr(cli, "run_all", fly_and_edit)
    target = tmp_path / "ref.json"
    assert cli.main(["--suite", "quick", "--out", str(tmp_path / "out"), "--write-reference", str(target)]) == 2
    assert "reference not written: the git tree at " in capsys.readouterr().err and not target.exists()


def test_clean_commit_outside_a_checkout_is_refused(tmp_path):
    with pytest.raises(reference.UncleanTree, match="not in a git checkout"):
        reference.clean_commit(tmp_path)


def test_git_commit_marks_changed_tracked_files_dirty_and_ignores_untracked_ones(repo, tmp_path):
    head = _git(repo, "rev-parse", "--short", "HEAD")
    (repo / "scratch.txt").write_text("not tracked\n")
    assert git_commit(repo) == head == reference.clean_commit()
    (repo / "code.py").write_text("x = 4\n")
    assert git_commit(repo) == head + "+dirty"
    assert git_commit(tmp_path / "absent") == "unknown"


def test_reference_records_the_simd_paths_and_a_check_on_other_paths_notes_it(repo, ref, tmp_path):
    target = tmp_path / "ref.json"
    reference.write_reference(_recorded_results(ref), target)
    written = reference.load_reference(target)
    assert written["simd"] == simd_meta()
    assert reference.check_against_reference(_recorded_results(ref), written).simd_note is None  # same machine
    other = _other_simd(simd_meta())
    note = reference.simd_note(other, simd_meta())
    paths = ", ".join(f"{lib} {path}" for lib, path in other["simd_dispatch"].items())
    assert note is not None and f"{paths} ({other['cpu_vector_isa']})" in note and "Reproducibility" in note
    assert reference.simd_note(None) is None  # a reference from before the paths were recorded


def test_write_reference_refuses_an_environment_off_the_pinned_stack(repo, ref, tmp_path, monkeypatch):
    installed = reference.stack_pins() | {"numpy": "2.5.5"}
    monkeypatch.setattr(reference, "stack_versions", lambda names=None: installed)
    target = tmp_path / "ref.json"
    with pytest.raises(reference.OffStack, match=r"numpy 2\.5\.5 \("):
        reference.write_reference(_recorded_results(ref), target)
    assert not target.exists()


def test_a_check_in_another_environment_names_the_packages_that_differ(ref):
    recorded = {"numpy": "2.4.6", "onnxruntime": "1.32.0"}
    assert reference.stack_note(recorded, dict(recorded)) is None
    note = reference.stack_note(recorded, {"numpy": "2.5.5", "onnxruntime": "1.32.0"})
    assert note is not None and "numpy 2.5.5 (2.4.6)" in note and "onnxruntime 1.32.0" not in note
    assert reference.stack_note(None) is None  # a reference from before the versions were recorded
    check = reference.check_against_reference(_recorded_results(ref), ref | {"stack": {"numpy": "0.0"}})
    assert check.stack_note is not None and "numpy" in check.stack_note


def test_stack_pins_name_a_malformed_line(tmp_path):
    pins = tmp_path / "pins.txt"
    pins.write_text("# comment\nnumpy==2.4.6  # why\n\nscipy>=1.17\n")
    with pytest.raises(ValueError, match=r"pins\.txt:4: expected 'name==version', got 'scipy>=1\.17'"):
        reference.stack_pins(pins)
    pins.write_text("numpy==2.4.6  # why\n")
    assert reference.stack_pins(pins) == {"numpy": "2.4.6"}


def test_reference_stack_pins_are_the_versions_the_reference_was_recorded_with(ref):
    pins = reference.stack_pins()
    assert {"numpy", "opencv-python-headless", "onnxruntime", "pybullet"} <= set(pins)
    assert ref["stack"] == pins  # the constraints make test installs with reproduce the reference


def test_on_other_simd_paths_only_the_oracle_runs_must_reproduce(ref):
    oracle_run = "follow/desert/scripted/oracle/gt/seed0"
    rmse = ref["runs"][TRADE_RUN]["metrics"]["ground_depth_rmse_m"]
    tracked = ref["runs"][oracle_run]["metrics"]["tracked_fraction"]
    other = _other_simd(ref["simd"])
    trade_moved = _recorded_results(ref, **{TRADE_RUN: {"ground_depth_rmse_m": 1.5 * rmse}})
    check = reference.check_against_reference(trade_moved, ref, simd=other)
    assert check.problems == () and check.simd_note is not None
    assert len(check.path_dependent) == 1 and check.path_dependent[0].startswith(f"{TRADE_RUN}: ground_depth_rmse_m")
    assert "1 expected on these SIMD paths" in check.summary_line()
    oracle_moved = _recorded_results(ref, **{oracle_run: {"tracked_fraction": tracked - 0.01}})
    check = reference.check_against_reference(oracle_moved, ref, simd=other)
    assert len(check.problems) == 1 and check.problems[0].startswith(f"{oracle_run}: tracked_fraction")
    assert reference.check_against_reference(trade_moved, ref, simd=ref["simd"]).path_dependent == ()
