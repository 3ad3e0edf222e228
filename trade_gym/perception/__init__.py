"""Perception modes of the env: what turns sensors into estimates (the oracle reads ground truth through providers
the env gives it at construction; the env scores every mode, `trade_gym.scoring`)."""

from trade_gym.perception.base import GroundEstimate, Perception, PerceptionOutput
from trade_gym.perception.oracle import OracleConfig, OraclePerception

__all__ = ["GroundEstimate", "OracleConfig", "OraclePerception", "Perception", "PerceptionOutput"]
