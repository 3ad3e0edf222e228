"""Follower policies for TradeFollow-v0 (scripted, waypoint and learned), all with SB3's `predict` shape.

Imported as `trade_gym.agents` (the repo's agents/ folder, mapped in pyproject.toml). `LearnedFollower` and its
errors load lazily: `import trade_gym.agents` needs neither onnxruntime nor the policy file.
"""

from typing import Any

from trade_gym.agents.scripted import ScriptedFollower, ScriptedFollowerConfig
from trade_gym.agents.waypoint import WaypointFollower, WaypointFollowerConfig
from trade_gym.policy import Policy

_LEARNED = "trade_gym.agents.learned"
_LAZY = {"LearnedFollower": _LEARNED, "PolicyModelError": _LEARNED, "AgentError": _LEARNED}

__all__ = ["AgentError", "LearnedFollower", "Policy", "PolicyModelError", "ScriptedFollower", "ScriptedFollowerConfig",
           "WaypointFollower", "WaypointFollowerConfig"]


def __dir__() -> list[str]:
    """The module's names with the lazy ones, as a user's completion and `dir(trade_gym.agents)` expect."""
    return sorted(set(globals()) | set(_LAZY))


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
