"""The policy protocol shared by scripted and learned followers, defined in `trade_gym.policy` (re-exported)."""

from trade_gym.policy import Policy

__all__ = ["Policy"]
