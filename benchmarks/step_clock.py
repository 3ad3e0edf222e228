"""`StepClock`: a wrapper timing the env's own reset and step calls (wall and CPU time), so a benchmark that
flies through `trade_gym.rollout.fly_episode` counts the env's time alone, not the policy's or the loop's.
"""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym


class StepClock(gym.Wrapper):
    """Appends each `step` call's wall and process-CPU time and each `reset` call's wall time [s]."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.step_s: list[float] = []
        self.step_cpu_s: list[float] = []
        self.reset_s: list[float] = []

    def reset(self, **kwargs: Any) -> tuple[Any, dict]:
        start = time.perf_counter()
        out = self.env.reset(**kwargs)
        self.reset_s.append(time.perf_counter() - start)
        return out

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        start, start_cpu = time.perf_counter(), time.process_time()
        out = self.env.step(action)
        self.step_cpu_s.append(time.process_time() - start_cpu)
        self.step_s.append(time.perf_counter() - start)
        return out
