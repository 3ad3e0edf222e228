"""Follower policies for TradeFollow-v0 (scripted and learned), all with SB3's `predict` shape.

`LearnedFollower` and its errors load lazily: `import agents` needs neither onnxruntime nor the policy file.
"""

from typing import Any

from trade_gym.policy import Policy
from agents.scripted import ScriptedFollower, ScriptedFollowerConfig

_LAZY = {"LearnedFollower": "agents.learned", "PolicyModelError": "agents.learned", "AgentError": "agents.learned"}

__all__ = ["AgentError", "LearnedFollower", "Policy", "PolicyModelError", "ScriptedFollower", "ScriptedFollowerConfig"]


def __dir__() -> list[str]:
    """The module's names with the lazy ones, as a user's completion and `dir(agents)` expect."""
    return sorted(set(globals()) | set(_LAZY))


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'agents' has no attribute {name!r}")
