"""trade-bench executors: a one-node Ray cluster gives the metrics and trajectory hashes of a serial local run,
and a run that raises or whose worker dies is that run's error on either backend; --backend ray's usage errors."""

from __future__ import annotations

import functools
import json
import logging
import os
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from trade_gym.bench import cli, runner
from trade_gym.bench.executors import RAY_MISSING, LocalExecutor, RayExecutor, check_ray_address
from trade_gym.bench.results import deterministic_part, load_schema, to_json_safe
from trade_gym.bench.suites import RunSpec, Selection, expand_suite

POLICIES = ("scripted", "hover", "random")
CLUSTER_CPUS = 2
OBJECT_STORE_BYTES = 96 * 2**20
ORACLE_STEPS, TRADE_STEPS, SHORT_STEPS = 25, 20, 8
TRADE_CAMERA_PX = 64
RAISING_SEED, DEAD_SEED, DIES_ONCE_SEED = 3, 2, 1  # development seeds
WORKER_EXIT_CODE = 17


@pytest.fixture(scope="module")
def cluster():
    """A one-node cluster for this module's tests, shut down even when a test fails."""
    ray = pytest.importorskip("ray", reason="the ray extra is not installed (make test installs it)")
    ray.init(address="local", num_cpus=CLUSTER_CPUS, include_dashboard=False, object_store_memory=OBJECT_STORE_BYTES,
             logging_level=logging.WARNING)
    try:
        yield ray
    finally:
        ray.shutdown()


def _oracle_specs(seeds: tuple[int, int], steps: int) -> list[RunSpec]:
    return expand_suite(None, Selection(scenes=("desert", "city"), policies=("random",), seeds=seeds, steps=steps),
                        POLICIES)


def _comparable(results: list[runner.RunResult]) -> list[tuple]:
    # NaN (undefined scores) compared as null, as results.json stores them
    return [(r.spec.run_id, to_json_safe(r.metrics), r.trajectory_sha256, r.error) for r in results]


def raise_on_seed(spec: RunSpec) -> runner.RunResult:
    """A task that fails outside `run_spec` (as a worker that cannot unpickle the spec would)."""
    if spec.seed == RAISING_SEED:
        raise RuntimeError(f"no episode for seed {spec.seed}")
    return runner.run_spec(spec)


def die_on_attempts(log_dir: str, deaths: dict[int, int], spec: RunSpec) -> runner.RunResult:
    """Log each attempt in `log_dir`; the worker exits hard on the first `deaths[seed]` attempts of a seed."""
    log = Path(log_dir) / f"seed{spec.seed}.log"
    with log.open("a") as f:
        f.write("attempt\n")
    if len(log.read_text().splitlines()) <= deaths.get(spec.seed, 0):
        os._exit(WORKER_EXIT_CODE)
    return runner.run_spec(spec)


def test_ray_runs_equal_serial_local_runs_metrics_and_trajectory_hash(cluster):
    trade = expand_suite(None, Selection(scenes=("desert",), perceptions=("trade",), seeds=(0, 0), steps=TRADE_STEPS,
                                         camera_size=TRADE_CAMERA_PX), POLICIES)
    specs = _oracle_specs((0, 1), ORACLE_STEPS) + trade
    progress = []
    on_ray = RayExecutor().map(specs, lambda done, total, r: progress.append((done, total, r.spec.run_id)))
    serial = LocalExecutor(1).map(specs)
    assert [r.spec for r in on_ray] == specs
    assert all(r.error is None for r in on_ray), [r.error for r in on_ray]
    assert _comparable(on_ray) == _comparable(serial)
    assert len({r.trajectory_sha256 for r in on_ray}) == len(specs)  # every run flew its own path
    np.testing.assert_array_equal(on_ray[-1].series.target_depth_error_m, serial[-1].series.target_depth_error_m)
    assert [(d, t) for d, t, _ in progress] == [(n, len(specs)) for n in range(1, len(specs) + 1)]
    assert sorted(run_id for _, _, run_id in progress) == sorted(s.run_id for s in specs)


def test_ray_run_raising_is_that_runs_error_while_others_finish(cluster):
    bad_env = RunSpec("custom", "custom", "desert", "hover", "oracle", "gt", 1, SHORT_STEPS, TRADE_CAMERA_PX,
                      extra=(("camera_fov_deg", -5.0),))
    specs = [_oracle_specs((0, 0), SHORT_STEPS)[0], bad_env, _oracle_specs((RAISING_SEED, RAISING_SEED), SHORT_STEPS)[0]]
    ok, env_rejected, raised = RayExecutor(task=raise_on_seed).map(specs)
    assert ok.error is None and ok.metrics["steps"] == SHORT_STEPS
    assert env_rejected.error.startswith("ValueError: ") and "camera_fov_deg" in env_rejected.error
    assert raised.error == f"RuntimeError: no episode for seed {RAISING_SEED}"
    assert env_rejected.metrics == raised.metrics == {} and raised.trajectory_sha256 is None


@pytest.mark.parametrize("backend", ["ray", "local"])
def test_dead_worker_run_retried_once_then_reported_others_finish(backend, request, tmp_path, caplog):
    if backend == "ray":
        request.getfixturevalue("cluster")
    task = functools.partial(die_on_attempts, str(tmp_path), {DIES_ONCE_SEED: 1, DEAD_SEED: 2})
    executor = RayExecutor(task=task) if backend == "ray" else LocalExecutor(CLUSTER_CPUS, task=task)
    specs = expand_suite(None, Selection(scenes=("desert",), policies=("hover",), seeds=(0, DEAD_SEED),
                                         steps=SHORT_STEPS), POLICIES)
    with caplog.at_level(logging.WARNING, logger=LocalExecutor.__module__):
        never, once, always = executor.map(specs)
    assert never.error is None and once.error is None
    assert _comparable([never, once]) == _comparable(LocalExecutor(1).map(specs[:2]))
    assert always.error.startswith("its worker process died in all 2 attempts (") and always.metrics == {}
    attempts = {seed: len((tmp_path / f"seed{seed}.log").read_text().splitlines()) for seed in (0, 1, 2)}
    assert attempts == {0: 1, DIES_ONCE_SEED: 2, DEAD_SEED: 2}  # our one retry, none by Ray or the pool
    retried = sorted(r.getMessage() for r in caplog.records if r.name == LocalExecutor.__module__)
    assert [m.split(": ")[0] for m in retried] == [once.spec.run_id, always.spec.run_id]
    assert all(": its worker died (" in m and m.endswith("running it again, attempt 2 of 2") for m in retried)


def test_cli_ray_backend_results_match_local_and_record_backend(cluster, tmp_path, capsys):
    args = ["--scenes", "desert", "--policies", "scripted", "--seeds", "0", "1", "--steps", str(SHORT_STEPS)]
    assert cli.main(args + ["--out", str(tmp_path / "local"), "--jobs", "1"]) == 0
    assert cli.main(args + ["--out", str(tmp_path / "ray"), "--backend", "ray", "--ray-address", "local"]) == 0
    local, on_ray = (json.loads((tmp_path / name / "results.json").read_text()) for name in ("local", "ray"))
    jsonschema.validate(on_ray, load_schema())
    assert deterministic_part(on_ray) == deterministic_part(local)
    assert all(len(r["trajectory_sha256"]) == 64 for r in on_ray["runs"])
    assert (local["meta"]["backend"], local["meta"]["ray_address"], local["meta"]["jobs"]) == ("local", None, 1)
    assert (on_ray["meta"]["backend"], on_ray["meta"]["ray_address"]) == ("ray", "local")
    assert on_ray["meta"]["jobs"] == CLUSTER_CPUS  # the running cluster's CPUs
    assert cluster.is_initialized()  # the CLI did not shut down a connection it did not open


def _no_episodes(*args, **kwargs):
    raise AssertionError("an episode ran although the arguments were invalid")


BAD_BACKEND_ARGUMENTS = {
    "ray address without ray backend": ["--ray-address", "auto"],
    "ray address not auto, local or ray://": ["--backend", "ray", "--ray-address", "10.0.0.1"],
    "ray client address without port": ["--backend", "ray", "--ray-address", "ray://head"],
    "jobs on a cluster": ["--backend", "ray", "--jobs", "2"],
    "unknown backend": ["--backend", "dask"],
}


@pytest.mark.parametrize("name", BAD_BACKEND_ARGUMENTS)
def test_cli_bad_backend_argument_exits_2_with_one_line(name, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    status = cli.main(BAD_BACKEND_ARGUMENTS[name] + ["--steps", "5", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("trade-bench: error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_cli_ray_backend_without_ray_exits_2_naming_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    monkeypatch.setattr(cli, "run_all", _no_episodes)
    status = cli.main(["--backend", "ray", "--steps", "5", "--out", str(tmp_path / "out")])
    assert status == 2
    assert capsys.readouterr().err == f"trade-bench: error: {RAY_MISSING}\n"
    assert RAY_MISSING == "--backend ray needs the ray extra: pip install 'trade-gym[ray]'"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("address", ["auto", "local", "ray://head-node:10001", "ray://10.0.0.1:10001"])
def test_check_ray_address_accepts_auto_local_and_client_addresses(address):
    assert check_ray_address(address) == address


@pytest.mark.parametrize("address", ["", "AUTO", "head:6379", "ray://head", "ray://head:0", "ray://head:70000"])
def test_check_ray_address_rejects_other_forms_naming_them(address):
    with pytest.raises(ValueError, match=f"--ray-address {address!r}"):
        check_ray_address(address)


def _frames(n: int, depth: float) -> list[dict]:
    return [{"t_s": i / 30, "drone_position_m": np.array([i, 0.0, 16.0]), "target_position_m": (i + 1.0, 2.0, 0.0),
             "est_bbox": np.array([10.0, 12.0, 4.0, 3.0]), "target_depth_est": depth, "ground_depth_est": np.nan}
            for i in range(n)]


def test_trajectory_hash_sees_one_changed_value_but_not_nan_payloads():
    base = runner.trajectory_sha256(_frames(3, 16.0))
    assert base == runner.trajectory_sha256(_frames(3, 16.0)) and len(base) == 64
    assert runner.trajectory_sha256(_frames(3, np.nextafter(16.0, 17.0))) != base
    assert runner.trajectory_sha256(_frames(2, 16.0)) != base
    other_nan = _frames(3, 16.0)
    other_nan[1]["ground_depth_est"] = np.frombuffer(np.uint64(0x7FF8000000000001).tobytes(), np.float64)[0]
    assert runner.trajectory_sha256(other_nan) == base
