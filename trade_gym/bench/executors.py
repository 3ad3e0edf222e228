"""Where benchmark runs execute: this process, local worker processes, or a Ray cluster (one task per run).
All backends share the progress callback, the one retry of a run whose worker died (a logged warning), and the
result order.
"""

from __future__ import annotations

import logging
import multiprocessing
import re
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from types import ModuleType
from typing import Any, Protocol

from trade_gym.bench.runner import RunResult, error_line, estimated_cost, failed_result, run_spec
from trade_gym.bench.suites import RunSpec

OnDone = Callable[[int, int, RunResult], None]  # (runs done, runs in all, the run that just finished)
Task = Callable[[RunSpec], RunResult]  # picklable: a module-level function (or a partial of one)
BACKENDS = ("local", "ray")
# Worker processes start fresh ("spawn"): no pybullet client or thread pool is inherited.
WORKER_START_METHOD = "spawn"
# A run whose worker process died is run once more; dying again makes it a failed run.
WORKER_DEATH_RETRIES = 1
RAY_MISSING = "--backend ray needs the ray extra: pip install 'trade-gym[ray]'"
# --ray-address: the cluster this machine belongs to (`ray start`), a one-node cluster started for this
# run, or a Ray Client server. `auto` is the default, so a forgotten `ray start` fails instead of silently
# running a cluster's workload on one machine.
RAY_AUTO, RAY_LOCAL = "auto", "local"
DEFAULT_RAY_ADDRESS = RAY_AUTO
RAY_CLIENT_ADDRESS = re.compile(r"ray://(?P<host>[A-Za-z0-9.\-]+|\[[0-9A-Fa-f:]+\]):(?P<port>[0-9]{1,5})")
MAX_PORT = 65535
TASK_CPUS = 1  # one episode per CPU: the env, its pybullet client and onnxruntime are single-threaded
# A local cluster's object store holds only finished results (a few kB each).
LOCAL_OBJECT_STORE_BYTES = 96 * 2**20
logger = logging.getLogger(__name__)  # a retried run is a warning here; nothing else is logged


class BackendUnavailable(RuntimeError):
    """The chosen backend cannot run here (ray missing, no cluster at the address); the message is one line."""


class Executor(Protocol):
    """Runs specs and returns their results in spec order, calling `on_done` as each run finishes."""

    backend: str  # one of BACKENDS, recorded in results.json meta

    @property
    def address(self) -> str | None:
        """The Ray address; None for the local backend (read-only here, so an executor may narrow its type)."""
        ...

    def workers(self) -> int:
        """How many runs execute at once."""
        ...

    def map(self, specs: Sequence[RunSpec], on_done: OnDone | None = None) -> list[RunResult]:
        """One result per spec, in spec order; `on_done(n_done, n_total, result)` in completion order."""
        ...

    def close(self) -> None:
        """Release what the executor holds (a Ray connection); safe to call twice."""
        ...


def longest_first(specs: Sequence[RunSpec]) -> list[int]:
    """Indices of `specs` by decreasing estimated cost: submitting the longest runs first shortens the makespan."""
    return sorted(range(len(specs)), key=lambda i: -estimated_cost(specs[i]))


class _Ledger:
    """Results by spec index, worker deaths by run, and progress reports: the part every backend shares."""

    def __init__(self, specs: Sequence[RunSpec], on_done: OnDone | None) -> None:
        self.specs = specs
        self._on_done = on_done
        self._results: list[RunResult | None] = [None] * len(specs)
        self._deaths = [0] * len(specs)
        self._n_done = 0

    def finish(self, index: int, result: RunResult) -> None:
        self._results[index] = result
        self._n_done += 1
        if self._on_done is not None:
            self._on_done(self._n_done, len(self.specs), result)

    def fail(self, index: int, error: str) -> None:
        self.finish(index, failed_result(self.specs[index], error))

    def worker_died(self, index: int, reason: str) -> bool:
        """Count a death of run `index`'s worker: True to run it again, else it is recorded as failed."""
        self._deaths[index] += 1
        if self._deaths[index] <= WORKER_DEATH_RETRIES:
            logger.warning("%s: its worker died (%s); running it again, attempt %d of %d", self.specs[index].run_id,
                           reason, self._deaths[index] + 1, WORKER_DEATH_RETRIES + 1)
            return True
        self.fail(index, f"its worker process died in all {self._deaths[index]} attempts ({reason})")
        return False

    def results(self) -> list[RunResult]:
        done = [r for r in self._results if r is not None]
        if len(done) < len(self._results):
            missing = [self.specs[i].run_id for i, r in enumerate(self._results) if r is None]
            raise RuntimeError(f"runs without a result: {', '.join(missing)}")
        return done


class LocalExecutor:
    """`jobs` = 1: every run in this process, in spec order. `jobs` > 1: that many spawned worker processes,
    each its own one-worker pool, so a worker that dies breaks only its own run, which is retried once."""

    backend = "local"
    address = None

    def __init__(self, jobs: int = 1, task: Task = run_spec) -> None:
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise ValueError(f"jobs must be an integer >= 1, got {jobs!r}")
        self.jobs = jobs
        self.task = task

    def workers(self) -> int:
        return self.jobs

    def close(self) -> None:
        """Nothing to release: worker processes end with each `map`."""

    def map(self, specs: Sequence[RunSpec], on_done: OnDone | None = None) -> list[RunResult]:
        ledger = _Ledger(specs, on_done)
        if self.jobs == 1 or len(specs) <= 1:
            for index, spec in enumerate(specs):
                ledger.finish(index, self.task(spec))
        else:
            self._map_in_workers(ledger, min(self.jobs, len(specs)))
        return ledger.results()

    def _map_in_workers(self, ledger: _Ledger, n_slots: int) -> None:
        context = multiprocessing.get_context(WORKER_START_METHOD)
        pools: list[ProcessPoolExecutor | None] = [None] * n_slots
        queue = deque(longest_first(ledger.specs))
        running: dict[Future[RunResult], tuple[int, int]] = {}  # future -> (slot, spec index)
        try:
            while queue or running:
                busy = {slot for slot, _ in running.values()}
                for slot in (s for s in range(n_slots) if s not in busy):
                    if not queue:
                        break
                    pool = pools[slot]
                    if pool is None:
                        pool = pools[slot] = ProcessPoolExecutor(max_workers=1, mp_context=context)
                    index = queue.popleft()
                    running[pool.submit(self.task, ledger.specs[index])] = (slot, index)
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in finished:
                    slot, index = running.pop(future)
                    try:
                        result = future.result()
                    except BrokenProcessPool as exc:  # this slot's only worker died running this run
                        broken = pools[slot]
                        if broken is not None:  # it is: the run was submitted to it
                            broken.shutdown(wait=True)
                        pools[slot] = None
                        if ledger.worker_died(index, error_line(exc)):
                            queue.appendleft(index)
                        continue
                    except Exception as exc:  # noqa: BLE001 - e.g. a result that does not unpickle
                        result = failed_result(ledger.specs[index], error_line(exc))
                    ledger.finish(index, result)
        finally:
            for pool in pools:
                if pool is not None:
                    pool.shutdown(wait=True, cancel_futures=True)


def import_ray() -> ModuleType:
    """The `ray` module, imported only for the Ray backend."""
    try:
        import ray
    except ImportError:
        raise BackendUnavailable(RAY_MISSING) from None
    return ray


def run_task(task: Task, spec: RunSpec) -> RunResult:
    """The body of every Ray task: `task(spec)` in the worker (`task` may be any picklable callable)."""
    return task(spec)


def check_ray_address(address: str) -> str:
    """`address` if it is `auto`, `local` or `ray://HOST:PORT`, else ValueError naming it."""
    match = RAY_CLIENT_ADDRESS.fullmatch(address)
    if address in (RAY_AUTO, RAY_LOCAL) or (match is not None and 1 <= int(match["port"]) <= MAX_PORT):
        return address
    raise ValueError(f"--ray-address {address!r}: expected auto, local or ray://HOST:PORT (port 1-{MAX_PORT})")


class RayExecutor:
    """Each run a Ray task (`TASK_CPUS` CPU, no automatic retry) that builds its own env in the worker and
    returns the run's `RunResult`. A task whose worker dies is submitted once more by `map` itself.

    `address`: `auto` (this machine's cluster, from `ray start`), `local` (start a one-node cluster of
    `num_cpus` CPUs, default all cores, for this executor) or `ray://HOST:PORT` (Ray Client). A process
    already connected to Ray (`ray.is_initialized()`) keeps that connection.
    """

    backend = "ray"

    def __init__(self, address: str = DEFAULT_RAY_ADDRESS, num_cpus: int | None = None, task: Task = run_spec) -> None:
        self.address = check_ray_address(address)
        if num_cpus is not None and (address != RAY_LOCAL or num_cpus < 1):
            raise ValueError(f"num_cpus sets the CPUs of --ray-address local (>= 1), got {num_cpus!r} "
                             f"for address {address!r}")
        self.num_cpus = num_cpus
        self.task = task
        self._ray: ModuleType | None = None
        self._owns_connection = False

    def connect(self) -> ModuleType:
        """Import ray and connect to (or start) the cluster; BackendUnavailable with one line if it cannot."""
        if self._ray is not None:
            return self._ray
        ray = import_ray()
        if not ray.is_initialized():
            try:
                ray.init(**self._init_kwargs())
            except (ConnectionError, TimeoutError, ValueError) as exc:  # ValueError: Ray Client not installed
                raise BackendUnavailable(f"--ray-address {self.address}: cannot connect ({error_line(exc)})") from None
            self._owns_connection = True
        self._ray = ray
        return ray

    def _init_kwargs(self) -> dict[str, Any]:
        if self.address == RAY_LOCAL:
            return {"address": RAY_LOCAL, "num_cpus": self.num_cpus, "include_dashboard": False,
                    "object_store_memory": LOCAL_OBJECT_STORE_BYTES, "logging_level": logging.WARNING}
        if self.address == RAY_AUTO:
            return {"address": RAY_AUTO, "logging_level": logging.WARNING}
        return {"address": self.address}

    def close(self) -> None:
        """Disconnect if `connect` connected (a cluster started by `local` stops with it); safe to call twice."""
        if self._owns_connection and self._ray is not None:
            self._ray.shutdown()
        self._ray, self._owns_connection = None, False

    def workers(self) -> int:
        return int(self.connect().cluster_resources().get("CPU", 0) // TASK_CPUS)

    def map(self, specs: Sequence[RunSpec], on_done: OnDone | None = None) -> list[RunResult]:
        ray = self.connect()
        died = (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError, ray.exceptions.OutOfMemoryError,
                ray.exceptions.ObjectLostError)
        remote = ray.remote(num_cpus=TASK_CPUS, max_retries=0)(run_task)

        def submit(index: int) -> Any:  # an ObjectRef; tasks are named by run in Ray's dashboard and logs
            return remote.options(name=specs[index].run_id).remote(self.task, specs[index])

        ledger = _Ledger(specs, on_done)
        pending = {submit(index): index for index in longest_first(specs)}
        try:
            while pending:
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                index = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except died as exc:
                    if ledger.worker_died(index, error_line(exc)):
                        pending[submit(index)] = index
                    continue
                except ray.exceptions.RayTaskError as exc:  # raised outside run_spec, e.g. unpickling it
                    result = failed_result(specs[index], error_line(exc.cause or exc))
                except ray.exceptions.RayError as exc:
                    result = failed_result(specs[index], error_line(exc))
                ledger.finish(index, result)
        finally:
            for ref in pending:  # only after an interrupt or an error in on_done
                ray.cancel(ref, force=True)
        return ledger.results()
