"""The policy protocol the env's episode loop and the benchmark fly: stable-baselines3's `predict` shape.

Scripted and learned followers (`agents`) and the benchmark's floors satisfy it; it lives here so that
`trade_gym` needs no `agents` import to fly a policy.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np


class Policy(Protocol):
    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]: ...
