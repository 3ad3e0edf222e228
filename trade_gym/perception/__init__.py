"""Perception modes of the env: what turns sensors (and, for the oracle, ground truth) into estimates."""

from trade_gym.perception.base import Perception, PerceptionOutput
from trade_gym.perception.oracle import OracleConfig, OraclePerception

__all__ = ["OracleConfig", "OraclePerception", "Perception", "PerceptionOutput"]
