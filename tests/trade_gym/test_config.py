"""One source of truth: each setting of the env has one name and one default, wherever it is read.

EnvConfig's `oracle_<name>` arguments are OracleConfig's `<name>`; the stack's switches keep EnvConfig's names
in PipelineConfig and its nested configs; component configs (`reward=`, `quadrotor=`, `vio=`) nest whole.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from trade.pipeline import PipelineConfig
from trade_gym.config import NESTED_CONFIGS, ORACLE_PREFIX, EnvConfig
from trade_gym.env import TradeFollowEnv
from trade_gym.perception.oracle import OracleConfig
from trade_gym.perception.trade_stack import STACK_SWITCHES, pipeline_config
from trade_gym.sim.camera import CameraConfig
from trade_gym.sim.imu import ImuConfig
from trade_gym.sim.pose_source import VioConfig

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


@pytest.mark.parametrize("name, config_type", NESTED_CONFIGS.items())
def test_nested_config_defaults_to_its_config_and_takes_the_config_or_a_mapping(name, config_type):
    default = config_type()
    assert getattr(EnvConfig(), name) == default
    assert EnvConfig(**{name: default}) == EnvConfig() == EnvConfig(**{name: dataclasses.asdict(default)})
    first = dataclasses.fields(config_type)[0]
    value = getattr(default, first.name)
    changed = 2 * value if not isinstance(value, tuple) else tuple(2 * v for v in value)
    assert getattr(getattr(EnvConfig(**{name: {first.name: changed}}), name), first.name) == changed


@pytest.mark.parametrize("name, bad", [
    ("quadrotor", {"max_speed_horizontal_mps": -1.0}), ("quadrotor", {"mass_kg": "heavy"}),
    ("quadrotor", {"inertia_kgm2": [0.03, 0.03]}), ("vio", {"position_drift_sigma_m_per_sqrt_m": float("nan")}),
    ("vio", {"yaw_drift_sigma_rad_per_sqrt_m": -0.1}), ("reward", {"crash_penalty": -1.0}),
])
def test_nested_config_bad_value_raises_value_error_naming_the_field(name, bad):
    (field,) = bad
    with pytest.raises(ValueError, match=f"{NESTED_CONFIGS[name].__name__}.{field} must be"):
        EnvConfig(**{name: bad})


@pytest.mark.parametrize("name", NESTED_CONFIGS)
def test_nested_config_unknown_field_or_wrong_type_raises_naming_the_argument(name):
    with pytest.raises(TypeError, match=f"{name} has no field 'max_speed'"):
        EnvConfig(**{name: {"max_speed": 1.0}})
    with pytest.raises(ValueError, match=f"{name} must be a {NESTED_CONFIGS[name].__name__} or a mapping"):
        EnvConfig(**{name: 3})


def test_gym_make_vio_drift_reaches_the_pose_source():
    still = {"position_drift_sigma_m_per_sqrt_m": 0.0, "yaw_drift_sigma_rad_per_sqrt_m": 0.0}
    env = TradeFollowEnv(scene="city", perception="oracle", camera_size=32, pose_source="vio", vio=still)
    try:
        env.reset(seed=0)
        for _ in range(10):
            env.step(np.array([1.0, 0.0, 0.0, 0.0], np.float32))
        assert env.pose_source.config == VioConfig(**still)
        assert np.all(env.pose_source.position_error_m == 0.0) and env.pose_source.yaw_error_rad == 0.0
    finally:
        env.close()
