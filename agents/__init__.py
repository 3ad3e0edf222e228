"""Follower policies for TradeFollow-v0 (scripted and learned), all with SB3's `predict` shape."""

from agents.policy import Policy
from agents.scripted import ScriptedFollower, ScriptedFollowerConfig

__all__ = ["Policy", "ScriptedFollower", "ScriptedFollowerConfig"]
