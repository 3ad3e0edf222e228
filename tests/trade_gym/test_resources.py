"""Resources: resets do not leak memory and close() releases the pybullet client."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet as p

from trade_gym.env import TradeFollowEnv

MAX_GROWTH_100_RESETS_MB = 10.0
WARMUP_RESETS = 10


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
