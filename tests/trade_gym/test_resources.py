"""Resources: resets do not leak memory and close() releases the pybullet client; steps neither leak nor stall.

Measurements that need a clean process (RSS over many make/close cycles or resets) run in a subprocess.
Timing uses the thread's CPU time, so other processes on the machine do not count.
"""

from __future__ import annotations

import gc
import json
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from trade_gym.agents import ScriptedFollower
from trade_gym.env import TradeFollowEnv

MAX_GROWTH_100_RESETS_MB = 10.0
WARMUP_RESETS = 10
REPO_ROOT = Path(__file__).resolve().parents[2]
MAKE_CLOSE_CYCLES = 200
MAKE_CLOSE_WARMUP = 20
MAX_GROWTH_PER_CYCLE_MB = 0.4
LONG_RESETS = 1000
LONG_RESETS_FROM = 100
MAX_GROWTH_LONG_RESETS_MB = 10.0
HEAP_WARMUP_STEPS = 300
HEAP_SETTLE_STEPS = 100
HEAP_STEPS = 300
MAX_HEAP_GROWTH_B_PER_STEP = 64.0
TIMED_STEPS = 1000
MAX_P99_OVER_MEDIAN = 3.0
PAGE_BYTES = 4096


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("VmRSS not found in /proc/self/status")


def test_100_resets_grow_memory_less_than_10_mb():
    env = TradeFollowEnv(scene="desert", perception="oracle", camera_size=64)
    try:
        for seed in range(WARMUP_RESETS):
            env.reset(seed=seed)
            env.step(np.zeros(4, np.float32))
        before = _rss_mb()
        for seed in range(100):
            env.reset(seed=seed)
            env.step(np.zeros(4, np.float32))
        growth = _rss_mb() - before
    finally:
        env.close()
    assert growth < MAX_GROWTH_100_RESETS_MB, f"RSS grew {growth:.1f} MB over 100 resets"


def test_close_disconnects_the_client():
    env = TradeFollowEnv(perception="oracle", camera_size=64)
    client = env._client
    env.reset(seed=0)
    assert p.getConnectionInfo(physicsClientId=client)["isConnected"] == 1
    env.close()
    assert p.getConnectionInfo(physicsClientId=client)["isConnected"] == 0


def _statm_rss_mb() -> float:
    """Resident set size [MB] from /proc/self/statm (pages)."""
    return int(Path("/proc/self/statm").read_text().split()[1]) * PAGE_BYTES / 2**20


def measure_make_close_cycles(cycles: int, warmup: int, scene: str) -> dict:
    """RSS growth per make/reset/close cycle after `warmup` cycles, and the clients left connected."""
    clients, rss = [], {}
    for i in range(cycles):
        env = TradeFollowEnv(scene=scene, perception="oracle", camera_size=64)
        clients.append(env._client)
        env.reset(seed=i)
        env.step(np.zeros(4, np.float32))
        env.close()
        if i + 1 in (warmup, cycles):
            rss[i + 1] = _statm_rss_mb()
    connected = [c for c in range(max(clients) + 1) if p.getConnectionInfo(physicsClientId=c)["isConnected"]]
    return {"mb_per_cycle": (rss[cycles] - rss[warmup]) / (cycles - warmup), "connected": connected,
            "rss_mb": rss[cycles]}


def measure_long_resets(resets: int, start: int, scene: str) -> dict:
    """RSS growth [MB] between reset `start` and reset `resets` of one env."""
    env = TradeFollowEnv(scene=scene, perception="oracle", camera_size=64)
    rss = {}
    try:
        for i in range(resets):
            env.reset(seed=i)
            env.step(np.zeros(4, np.float32))
            if i + 1 in (start, resets):
                rss[i + 1] = _statm_rss_mb()
    finally:
        env.close()
    return {"growth_mb": rss[resets] - rss[start], "rss_mb": rss[resets]}


def _in_subprocess(call: str) -> dict:
    code = f"import json; from tests.trade_gym.test_resources import *; print(json.dumps({call}))"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _fly(env: TradeFollowEnv, policy: ScriptedFollower, obs: dict, seed: int) -> tuple[dict, bool]:
    """One scripted step; on episode end a fresh reset. Returns the next observation and whether it reset."""
    action, _ = policy.predict(obs)
    obs, _, terminated, truncated, _ = env.step(action)
    if terminated or truncated:
        policy.reset()
        return env.reset(seed=seed)[0], True
    return obs, False


def measure_heap_growth_b_per_step(warmup: int, steps: int) -> float:
    """Python heap growth [B/step] (tracemalloc, live objects) over `steps` scripted oracle steps, after `warmup`
    steps untraced and HEAP_SETTLE_STEPS traced (numpy's and our small caches fill there, not in the window)."""
    env = TradeFollowEnv(scene="city", perception="oracle", camera_size=64)
    policy = ScriptedFollower()
    try:
        obs, _ = env.reset(seed=0)
        for _ in range(warmup):
            obs, _ = _fly(env, policy, obs, seed=0)
        tracemalloc.start()
        try:
            for _ in range(HEAP_SETTLE_STEPS):
                obs, _ = _fly(env, policy, obs, seed=0)
            gc.collect()  # garbage in reference cycles is not a leak: count live objects only
            before = tracemalloc.get_traced_memory()[0]
            for _ in range(steps):
                obs, reset = _fly(env, policy, obs, seed=0)
                assert not reset, "the episode ended inside the measurement"
            gc.collect()
            growth = tracemalloc.get_traced_memory()[0] - before
        finally:
            tracemalloc.stop()
    finally:
        env.close()
    return growth / steps


def measure_step_cpu_times_s(steps: int) -> np.ndarray:
    """Thread CPU time [s] of each of `steps` scripted oracle steps (desert; resets between episodes untimed)."""
    env = TradeFollowEnv(perception="oracle", camera_size=64)
    policy = ScriptedFollower()
    times = []
    try:
        obs, _ = env.reset(seed=0)
        while len(times) < steps:
            action, _ = policy.predict(obs)
            start = time.thread_time()
            obs, _, terminated, truncated, _ = env.step(action)
            times.append(time.thread_time() - start)
            if terminated or truncated:
                policy.reset()
                obs, _ = env.reset(seed=len(times))
    finally:
        env.close()
    return np.array(times)


def test_heap_grows_less_than_64_bytes_per_step_after_warmup():
    growth = measure_heap_growth_b_per_step(HEAP_WARMUP_STEPS, HEAP_STEPS)
    assert growth < MAX_HEAP_GROWTH_B_PER_STEP, f"heap grew {growth:.1f} B/step"


def test_step_cpu_time_p99_at_most_3x_median_over_1000_oracle_steps():
    median, p99 = np.percentile(measure_step_cpu_times_s(TIMED_STEPS), [50, 99])
    assert p99 <= MAX_P99_OVER_MEDIAN * median, f"p99 {p99 * 1e3:.2f} ms vs median {median * 1e3:.2f} ms"


@pytest.mark.slow
def test_200_make_reset_close_cycles_leave_no_client_and_grow_rss_under_0_4_mb_per_cycle():
    result = _in_subprocess(f"measure_make_close_cycles({MAKE_CLOSE_CYCLES}, {MAKE_CLOSE_WARMUP}, 'desert')")
    assert result["connected"] == []
    assert result["mb_per_cycle"] < MAX_GROWTH_PER_CYCLE_MB, result


@pytest.mark.slow
def test_1000_resets_grow_rss_less_than_10_mb_between_reset_100_and_1000():
    result = _in_subprocess(f"measure_long_resets({LONG_RESETS}, {LONG_RESETS_FROM}, 'city')")
    assert result["growth_mb"] < MAX_GROWTH_LONG_RESETS_MB, result
