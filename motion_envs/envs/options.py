"""Checked `reset(options=...)` values: the right type and shape, finite, in range, or a ValueError naming the option.

Numbers are real numbers (int, float or numpy's; not bool, str, complex or None); points are sequences or arrays of
such numbers; indices are integers (an integral float such as 3.0 is taken, 120.9 and "120" are not: no silent
casts). Every env's `sample_initial_state` reads its options through these.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np


def check_known(options: dict[str, Any] | None, known: tuple[str, ...]) -> dict[str, Any]:
    """`options` as a dict, checked to hold only `known` keys."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"reset options must be a dict, got {type(options).__name__}")
    unknown = sorted(set(options) - set(known), key=str)
    if unknown:
        raise ValueError(f"unknown reset options {unknown}; known: {', '.join(known)}")
    return dict(options)


def _is_real(value: Any) -> bool:
    return isinstance(value, (numbers.Real, np.number)) and not isinstance(value, (bool, np.bool_, complex, np.complexfloating))


def real_array(value: Any, name: str) -> np.ndarray:
    """`value` as a float64 array of real numbers, or ValueError naming `name` (strings, bools, complex, None,
    ragged lists are refused)."""
    if isinstance(value, (str, bytes)) or value is None:
        raise ValueError(f"option {name!r} must be numbers, got {value!r}")
    try:
        array = np.asarray(value)
    except ValueError as error:  # ragged
        raise ValueError(f"option {name!r} must be a regular array of numbers, got {value!r}") from error
    if array.dtype.kind not in "iuf":  # not bool (b), complex (c), strings (U, S) or objects (O)
        raise ValueError(f"option {name!r} must hold real numbers, got {value!r} (dtype {array.dtype})")
    array = array.astype(np.float64)
    if not np.isfinite(array).all():
        raise ValueError(f"option {name!r} must be finite, got {value!r}")
    return array


def point(options: dict[str, Any], name: str, size: int, many: bool = False) -> np.ndarray | None:
    """(size,) float64 of `options[name]`, or with `many` (K, size) with K ≥ 1; None when absent; finite."""
    if name not in options:
        return None
    array = real_array(options[name], name)
    fits = (array.ndim == 2 and array.shape[1] == size and len(array) > 0) if many else array.shape == (size,)
    if not fits:
        expected = f"a list of points of {size} numbers" if many else f"{size} numbers"
        raise ValueError(f"option {name!r} must be {expected}, got shape {array.shape}: {options[name]!r}")
    return array


def number(options: dict[str, Any], name: str, low: float = -np.inf, high: float = np.inf) -> float | None:
    """`options[name]` as a float (None when absent): one finite real number in [low, high]."""
    if name not in options:
        return None
    value = options[name]
    if not _is_real(value) or not np.isfinite(value):
        raise ValueError(f"option {name!r} must be a finite real number, got {value!r}")
    if not low <= float(value) <= high:
        raise ValueError(f"option {name!r} must lie in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def index(options: dict[str, Any], name: str, count: int, low: int = 0) -> int | None:
    """`options[name]` as an int in [low, count) (None when absent): an integer, or a float with an integral value."""
    if name not in options:
        return None
    value = options[name]
    if not _is_real(value) or not np.isfinite(value) or float(value) != int(value):
        raise ValueError(f"option {name!r} must be an integer, got {value!r}")
    if not low <= int(value) < count:
        raise ValueError(f"option {name!r} must lie in [{low}, {count}), got {value!r}")
    return int(value)


def scene_seed_option(options: dict[str, Any], bodies: int) -> np.ndarray | None:
    """(bodies,) int64 scene seeds of the `scene_seed` option (one seed for all, or one per body), or None."""
    if "scene_seed" not in options:
        return None
    seeds = real_array(options["scene_seed"], "scene_seed")
    if seeds.ndim > 1 or (seeds.ndim == 1 and len(seeds) != bodies):
        raise ValueError(f"option 'scene_seed' must be one seed or one per body ({bodies}), got shape {seeds.shape}")
    if (seeds != np.round(seeds)).any() or (seeds < 0).any() or (seeds >= 2**32).any():
        raise ValueError(f"option 'scene_seed' must be integers in [0, 2**32), got {options['scene_seed']!r}")
    return np.broadcast_to(seeds.astype(np.int64), (bodies,))
