"""Checks of plain arrays read back from a file (checkpoints), before anything computes with them.

A checkpoint comes from disk and may have been damaged or crafted; the numba kernels read indices
unchecked. So every array is taken by name with its expected shape and dtype, floats must be finite
and indices must lie in range; a failure raises ValueError naming the array and what was expected
(the checkpoint reader turns it into a message for people). :func:`jsonable` turns the other
way: numbers, arrays and dataclasses into the plain types a JSON file holds. A leaf module: numpy
only.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np


def take(arrays, name, shape, dtype) -> np.ndarray:
    """``arrays[name]`` with exactly ``dtype`` and ``shape`` (a tuple; None matches any length).

    Returns a C-contiguous array that owns its data (a copy when needed)."""
    if name not in arrays:
        raise ValueError(f"array {name!r} is missing")
    a = arrays[name]
    if not isinstance(a, np.ndarray) or a.dtype != np.dtype(dtype):
        found = a.dtype if isinstance(a, np.ndarray) else type(a).__name__
        raise ValueError(f"array {name!r} has dtype {found}, expected {np.dtype(dtype)}")
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"array {name!r} has shape {a.shape}, expected {want}")
    return np.array(a, order="C", copy=True)


def scalar(arrays, name, dtype):
    """A 0-d array of ``arrays`` as a Python int / float / bool."""
    return take(arrays, name, (), dtype).item()


def finite(name, a, allow_nan=False) -> np.ndarray:
    """``a`` if every value is finite (or NaN where ``allow_nan``), else ValueError."""
    bad = ~np.isfinite(a)
    if allow_nan:
        bad &= ~np.isnan(a)
    if np.any(bad):
        raise ValueError(f"array {name!r} holds {int(bad.sum())} non-finite value(s)")
    return a


def in_range(name, a, low, high) -> np.ndarray:
    """``a`` if ``low <= a < high`` everywhere, else ValueError naming the first bad value."""
    bad = (a < low) | (a >= high)
    if np.any(bad):
        value = a[bad].flat[0]
        raise ValueError(f"array {name!r} holds the index {value}, expected {low} <= index < {high}")
    return a


def prefixed(prefix, arrays) -> dict:
    """``arrays`` with every name prefixed by ``prefix`` (``"zone."``)."""
    return {prefix + k: v for k, v in arrays.items()}


def unprefixed(prefix, arrays) -> dict:
    """The arrays whose name starts with ``prefix``, the prefix removed."""
    n = len(prefix)
    return {k[n:]: v for k, v in arrays.items() if k.startswith(prefix)}


def jsonable(value):
    """Plain JSON types: dataclasses -> dicts, Paths -> str, tuples -> lists, numpy -> Python,
    non-finite floats -> None (a NaN in a result file would look like data)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)
