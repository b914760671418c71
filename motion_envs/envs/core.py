"""What every environment shares: checked actions and configs built from `gym.make` kwargs."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

import numpy as np

Config = TypeVar("Config")


def check_actions(actions: Any, shape: tuple[int, ...], batch: int | None) -> np.ndarray:
    """Actions as float32, checked: `shape` for one body (batch None) or (batch, *shape); all finite.

    Raises:
        ValueError: naming the expected and received shape, or the non-finite entries.
    """
    array = np.asarray(actions, dtype=np.float32)
    expected = tuple(shape) if batch is None else (batch, *shape)
    if array.shape != expected:
        raise ValueError(f"action must have shape {expected}, got {array.shape}")
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[:5].tolist()
        raise ValueError(f"action contains NaN or inf (first at indices {bad})")
    return array


def config_from_kwargs(config_type: type[Config], kwargs: dict[str, Any], env_name: str) -> Config:
    """`config_type(**kwargs)`, with unknown keys reported by name next to the valid ones."""
    valid = {field.name for field in dataclasses.fields(config_type)}
    unknown = sorted(set(kwargs) - valid)
    if unknown:
        raise TypeError(f"{env_name} got unknown arguments {unknown}; valid: {sorted(valid)}")
    return config_type(**kwargs)
