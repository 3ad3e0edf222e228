"""trade-bench on a Ray cluster of several nodes on one machine (Ray's own `ray.cluster_utils.Cluster`, as Ray tests
itself): runs spread over the nodes give the results of a serial local run, and a node lost mid-suite costs only
the run that was on it, which is run again on another node."""

from __future__ import annotations

import atexit
import functools
import json
import logging
import os
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import pytest

from trade_gym.bench import cli, executors, runner
from trade_gym.bench.executors import LocalExecutor, RayExecutor
from trade_gym.bench.results import deterministic_part, to_json_safe
from trade_gym.bench.suites import RunSpec, Selection, expand_suite

POLICIES = ("scripted", "hover", "random")
NODE_CPUS = 1  # per node: two nodes make the two CPUs of this machine
NODE_OBJECT_STORE_BYTES = 80 * 2**20  # Ray's minimum is 75 MiB; results are a few kB each
ORACLE_STEPS, TRADE_STEPS, SHORT_STEPS = 25, 20, 8
TRADE_CAMERA_PX = 64
HOLD_S = 120.0  # a run that starts on the node to be removed waits there this long (the node goes first)
REMOVE_TIMEOUT_S = 2 * HOLD_S  # how long the remover waits for a held run and a first result
ATTEMPTS_LOG = "attempts.log"
HELD_MARKER = "held"
MARKER_POLL_S = 0.05
NODE_DEATH_TIMEOUT_S = 60.0  # until Ray has marked a killed node dead


@pytest.fixture(scope="module")
def cluster():
    """A head node and one worker node, 1 CPU each, this process connected as the driver; shut down even when a
    test fails. A test may add and remove nodes of its own.

    Each node started here registers an exit hook that holds the node (and its gRPC client) until this process
    exits. Python 3.13's fork start method clears the exit hooks in the child, which frees those nodes there, and
    the gRPC client's destructor then crashes the child (SIGSEGV in `pollset_shutdown`: its threads live only in
    this process). A later test forking an `AsyncVectorEnv` died that way, so the hooks registered while the
    cluster lives are unregistered here once it has shut down (a crash before that still runs them at exit)."""
    ray = pytest.importorskip("ray", reason="the ray extra is not installed (make test installs it)")
    from ray.cluster_utils import Cluster

    exit_hooks = []
    register = atexit.register

    def recording_register(func, *args, **kwargs):
        exit_hooks.append(func)
        return register(func, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(atexit, "register", recording_register)
        cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": NODE_CPUS, "include_dashboard": False,
                                                                "object_store_memory": NODE_OBJECT_STORE_BYTES})
        try:
            cluster.add_node(num_cpus=NODE_CPUS, object_store_memory=NODE_OBJECT_STORE_BYTES)
            ray.init(address=cluster.address, logging_level=logging.WARNING)
            yield cluster
        finally:
            ray.shutdown()
            cluster.shutdown()
            for func in exit_hooks:  # the nodes are freed here, where their gRPC threads are
                atexit.unregister(func)


@pytest.fixture
def nodes(cluster):
    """The module's cluster once Ray counts exactly its nodes: Ray notices a killed node's death by health checks,
    ~16 s after the kill here, and counts its CPUs until then."""
    cluster.wait_for_nodes(timeout=NODE_DEATH_TIMEOUT_S)
    return cluster


def on_node(log_dir: str, hold_on: str | None, spec: RunSpec, others_wait: bool = False) -> runner.RunResult:
    """Log the run id and node id of this attempt in `log_dir`; on node `hold_on`, mark it and wait there (until
    the test removes that node), then run the spec. `others_wait`: an attempt on another node first waits (up to
    HOLD_S) for that mark, so the runs cannot all finish elsewhere before the added node has taken one: each node
    has one CPU, so with the others' CPUs busy waiting, Ray must place a run on it, however slowly it starts."""
    import ray

    node = ray.get_runtime_context().get_node_id()
    with (Path(log_dir) / ATTEMPTS_LOG).open("a") as f:
        f.write(f"{spec.run_id} {node}\n")
    marker = Path(log_dir) / HELD_MARKER
    if node == hold_on:
        marker.touch()
        time.sleep(HOLD_S)
    elif others_wait:
        deadline = time.monotonic() + HOLD_S
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(MARKER_POLL_S)
    return runner.run_spec(spec)


def _attempts(log_dir: Path) -> list[tuple[str, str]]:
    """(run id, node id) of every attempt, in the order they started."""
    return [tuple(line.split()) for line in (log_dir / ATTEMPTS_LOG).read_text().splitlines()]


def _comparable(results: list[runner.RunResult]) -> list[tuple]:
    # NaN (undefined scores) compared as null, as results.json stores them
    return [(r.spec.run_id, to_json_safe(r.metrics), r.trajectory_sha256, r.error) for r in results]


def _oracle_specs(policies: tuple[str, ...], seeds: tuple[int, int], steps: int) -> list[RunSpec]:
    return expand_suite(None, Selection(scenes=("desert", "city"), policies=policies, seeds=seeds, steps=steps),
                        POLICIES)


def test_runs_spread_over_two_nodes_equal_serial_local_runs(nodes, tmp_path):
    trade = expand_suite(None, Selection(scenes=("desert",), perceptions=("trade",), seeds=(0, 0), steps=TRADE_STEPS,
                                         camera_size=TRADE_CAMERA_PX), POLICIES)
    specs = _oracle_specs(("random",), (0, 1), ORACLE_STEPS) + trade
    executor = RayExecutor(task=functools.partial(on_node, str(tmp_path), None))
    on_ray = executor.map(specs)
    serial = LocalExecutor(1).map(specs)
    assert executor.workers() == 2 * NODE_CPUS
    assert [r.spec for r in on_ray] == specs
    assert all(r.error is None for r in on_ray), [r.error for r in on_ray]
    assert _comparable(on_ray) == _comparable(serial)
    attempts = _attempts(tmp_path)
    assert sorted(run_id for run_id, _ in attempts) == sorted(s.run_id for s in specs)  # each run once
    assert {node for _, node in attempts} == {n.node_id for n in nodes.list_all_nodes()}  # both nodes ran some


def _remove_when_held(cluster, node, log_dir: Path, first_result: threading.Event, removed: threading.Event) -> None:
    """Remove `node` (its processes killed, as a machine that fails) once a run is held on it and another run has
    finished elsewhere: mid-suite, with runs done, running and queued."""
    deadline = time.monotonic() + REMOVE_TIMEOUT_S
    while not ((log_dir / HELD_MARKER).exists() and first_result.is_set()):
        if time.monotonic() > deadline:
            return
        time.sleep(MARKER_POLL_S)
    cluster.remove_node(node, allow_graceful=False)
    removed.set()


def test_node_lost_mid_suite_costs_only_its_run_retried_on_another_node(nodes, tmp_path, caplog):
    doomed = nodes.add_node(num_cpus=NODE_CPUS, object_store_memory=NODE_OBJECT_STORE_BYTES)
    specs = _oracle_specs(("hover", "random"), (0, 1), SHORT_STEPS)
    first_result, removed = threading.Event(), threading.Event()
    remover = threading.Thread(target=_remove_when_held, args=(nodes, doomed, tmp_path, first_result, removed),
                               daemon=True)
    remover.start()
    progress: list[tuple[int, int, str]] = []

    def on_done(done: int, total: int, result: runner.RunResult) -> None:
        progress.append((done, total, result.spec.run_id))
        first_result.set()

    with caplog.at_level(logging.WARNING, logger=executors.__name__):
        on_ray = RayExecutor(task=functools.partial(on_node, str(tmp_path), doomed.node_id, others_wait=True)).map(
            specs, on_done)
    remover.join(REMOVE_TIMEOUT_S)
    assert removed.is_set(), "no run was held on the added node, or no run finished elsewhere"
    assert [r.spec for r in on_ray] == specs
    assert all(r.error is None for r in on_ray), [r.error for r in on_ray]
    assert _comparable(on_ray) == _comparable(LocalExecutor(1).map(specs))
    attempts = _attempts(tmp_path)
    lost = [run_id for run_id, node in attempts if node == doomed.node_id]
    assert len(lost) == 1  # the doomed node's one CPU held one run when it was removed
    assert Counter(run_id for run_id, _ in attempts) == Counter([s.run_id for s in specs] + lost)
    retry_node = [node for run_id, node in attempts if run_id == lost[0]][1]
    assert retry_node in {n.node_id for n in nodes.list_all_nodes()}  # a surviving node
    (retry,) = [r.getMessage() for r in caplog.records if r.name == executors.__name__]
    assert retry.startswith(f"{lost[0]}: its worker died (NodeDiedError: ") and retry.endswith("attempt 2 of 2")
    assert [(d, t) for d, t, _ in progress] == [(n, len(specs)) for n in range(1, len(specs) + 1)]
    assert sorted(run_id for _, _, run_id in progress) == sorted(s.run_id for s in specs)  # reported once each


@pytest.mark.slow
def test_cli_quick_suite_on_two_nodes_equals_jobs_1(nodes, tmp_path):
    """`trade-bench --backend ray` as a user runs it: its own driver process, `--ray-address auto` (the default)
    finding the cluster through RAY_ADDRESS."""
    ray_out, local_out = tmp_path / "ray", tmp_path / "local"
    command = [sys.executable, "-m", "trade_gym.bench.cli", "--suite", "quick", "--backend", "ray",
               "--out", str(ray_out)]
    done = subprocess.run(command, env=os.environ | {"RAY_ADDRESS": nodes.address}, capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert cli.main(["--suite", "quick", "--jobs", "1", "--out", str(local_out)]) == 0
    on_ray, local = (json.loads((out / "results.json").read_text()) for out in (ray_out, local_out))
    assert deterministic_part(on_ray) == deterministic_part(local)
    assert all(len(r["trajectory_sha256"]) == 64 for r in on_ray["runs"])
    assert (on_ray["meta"]["backend"], on_ray["meta"]["ray_address"]) == ("ray", "auto")
    assert on_ray["meta"]["jobs"] == 2 * NODE_CPUS  # the CPUs of both nodes
