"""One source of truth: each setting of the env has one name and one default, wherever it is read.

EnvConfig's `oracle_<name>` arguments are OracleConfig's `<name>`; the stack's switches keep EnvConfig's names
in PipelineConfig and its nested configs; component configs (`reward=`, `quadrotor=`, `vio=`) nest whole.
"""

from __future__ import annotations

import dataclasses

import pytest

from trade.pipeline import PipelineConfig
from trade_gym.config import ORACLE_PREFIX, EnvConfig
from trade_gym.perception.oracle import OracleConfig
from trade_gym.perception.trade_stack import STACK_SWITCHES, pipeline_config
from trade_gym.sim.camera import CameraConfig
from trade_gym.sim.imu import ImuConfig

# EnvConfig's <prefix><name> is <name> of the component's config; camera_size is the side of a square image
# (CameraConfig's width_px and height_px).
COMPONENT_PREFIXES = {"imu_": ImuConfig, "camera_": CameraConfig, ORACLE_PREFIX: OracleConfig}
SQUARE_IMAGE_SIDE = "camera_size"


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


def _stack_setting(config: PipelineConfig, name: str) -> object:
    """The PipelineConfig field called `name`, on the pipeline or its tracker (trajectory guidance is the tracker's)."""
    names = {f.name for f in dataclasses.fields(PipelineConfig)}
    return getattr(config if name in names else config.tracker, name)


@pytest.mark.parametrize("switch", STACK_SWITCHES)
def test_each_stack_switch_has_the_env_name_in_the_pipeline_config(switch):
    flipped = not getattr(EnvConfig(), switch)
    extra = {"ground_mask": False} if switch == "single_image_depth" else {}  # they exclude each other
    config = EnvConfig(**{switch: flipped, **extra})
    assert _stack_setting(pipeline_config(config), switch) == flipped
    assert _stack_setting(pipeline_config(EnvConfig()), switch) == getattr(EnvConfig(), switch)


@pytest.mark.parametrize("prefix, component", COMPONENT_PREFIXES.items())
def test_each_prefixed_env_argument_names_a_field_of_its_component_config(prefix, component):
    names = [f.name for f in dataclasses.fields(EnvConfig) if f.name.startswith(prefix) and f.name != SQUARE_IMAGE_SIDE]
    component_fields = {f.name for f in dataclasses.fields(component)}
    assert names and {name.removeprefix(prefix) for name in names} <= component_fields
