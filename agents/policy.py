"""The policy protocol shared by scripted and learned followers (stable-baselines3's shape)."""

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
