"""One source of truth: each setting of the env has one name and one default, wherever it is read.

EnvConfig's `oracle_<name>` arguments are OracleConfig's `<name>`; the stack's switches keep EnvConfig's names
in PipelineConfig and its nested configs; component configs (`reward=`, `quadrotor=`, `vio=`) nest whole.
"""

from __future__ import annotations

import dataclasses

import pytest

from trade_gym.config import ORACLE_PREFIX, EnvConfig
from trade_gym.perception.oracle import OracleConfig


def test_env_oracle_arguments_are_exactly_oracle_config_fields_with_its_defaults():
    oracle_fields = {f.name for f in dataclasses.fields(OracleConfig)}
    env_oracle_fields = {f.name.removeprefix(ORACLE_PREFIX) for f in dataclasses.fields(EnvConfig)
                         if f.name.startswith(ORACLE_PREFIX)}
    assert env_oracle_fields == oracle_fields
    assert EnvConfig().oracle == OracleConfig()


def test_env_oracle_property_carries_every_oracle_argument():
    values = {f.name: 0.1 * (i + 1) for i, f in enumerate(dataclasses.fields(OracleConfig))}
    config = EnvConfig(**{ORACLE_PREFIX + name: value for name, value in values.items()})
    assert config.oracle == OracleConfig(**values)


@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(OracleConfig)])
def test_env_bad_oracle_argument_names_the_env_argument(name):
    with pytest.raises(ValueError, match=ORACLE_PREFIX + name):
        EnvConfig(**{ORACLE_PREFIX + name: -1.0})
