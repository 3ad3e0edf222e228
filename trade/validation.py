"""Checks of configuration values, shared by `trade`, `trade_gym` and `agents` (they import it; it imports none
of them). Every failure is a ValueError "<name> must be <requirement>, got <value!r>", naming the field and value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping
from typing import TYPE_CHECKING, TypeGuard, TypeVar

import numpy as np

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

Config = TypeVar("Config", bound="DataclassInstance")


def require(ok: bool, name: str, value: object, requirement: str) -> None:
    """Raise ValueError "<name> must be <requirement>, got <value!r>" unless `ok`."""
    if not ok:
        raise ValueError(f"{name} must be {requirement}, got {value!r}")


def is_finite_number(value: object) -> TypeGuard[float]:
    """A finite Python int or float (numpy float64 is a float), not a bool."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def is_positive_number(value: object) -> bool:
    """A finite number > 0 (`is_finite_number`)."""
    return is_finite_number(value) and value > 0


def is_int_at_least(value: object, lowest: float, numpy_ints: bool = True) -> TypeGuard[int | np.integer]:
    """An integer >= `lowest`, not a bool; numpy integers count unless `numpy_ints` is False (a value that goes to
    JSON or to pybullet as is)."""
    types = (int, np.integer) if numpy_ints else (int,)
    return not isinstance(value, bool) and isinstance(value, types) and bool(value >= lowest)


def check_choice(name: str, value: object, choices: Collection) -> None:
    require(value in choices, name, value, f"one of {choices}")


def check_finite_number(name: str, value: object) -> float:
    """`value` as a float; ValueError unless it is a finite number (`is_finite_number`)."""
    if not is_finite_number(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def check_positive(name: str, value: object) -> None:
    require(check_finite_number(name, value) > 0.0, name, value, "> 0")


def check_non_negative(name: str, value: object) -> None:
    require(check_finite_number(name, value) >= 0.0, name, value, ">= 0")


def check_range(name: str, value: object, low: float, high: float) -> None:
    """A finite number in the closed interval [low, high]."""
    require(low <= check_finite_number(name, value) <= high, name, value, f"in [{low}, {high}]")


def nested_config(name: str, value: object, config_type: type[Config]) -> Config:
    """`value` if it is a `config_type` (a frozen dataclass), else one built from a mapping of its fields (its own
    checks then name the field and the bad value). TypeError naming a key that is not a field; ValueError for
    anything else."""
    if isinstance(value, Mapping):
        fields = [f.name for f in dataclasses.fields(config_type)]
        unknown = sorted(set(value) - set(fields))
        if unknown:
            raise TypeError(f"{name} has no field {', '.join(map(repr, unknown))}: {config_type.__name__}'s fields "
                            f"are {', '.join(fields)}")
        return config_type(**value)
    if not isinstance(value, config_type):
        raise ValueError(f"{name} must be a {config_type.__name__} or a mapping of its fields, got {value!r}")
    return value
