"""Checking and converting operation arguments before anything is queued."""

from __future__ import annotations

from collections.abc import Iterable
from typing import SupportsFloat, SupportsInt

import numpy as np

JOINTS = 6
WORD_MAX = 0xFFFF

FloatArray = Iterable[SupportsFloat] | Iterable[Iterable[SupportsFloat]]
"""Numbers, flat or nested (a 6x6 matrix), or a numpy array."""


def float_vector(values: FloatArray, count: int, what: str) -> tuple[float, ...]:
    """``count`` finite floats (numpy arrays and nested 2-D sequences are flattened)."""
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    if array.size != count:
        raise ValueError(f"{what} needs {count} numbers, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{what} must be finite")
    return tuple(float(v) for v in array)


def scalar(value: SupportsFloat, what: str) -> float:
    return float_vector([value], 1, what)[0]


def word(value: SupportsInt, what: str, low: int = 0, high: int = WORD_MAX) -> int:
    """An integer in ``low..high`` (a 16-bit word unless narrower)."""
    if isinstance(value, bool | float):
        raise TypeError(f"{what} must be an integer, not {type(value).__name__}")
    number = int(value)
    if not low <= number <= high:
        raise ValueError(f"{what} must be {low}..{high}, got {number}")
    return number


def int_vector(values: Iterable[SupportsInt], count: int, what: str, low: int, high: int) -> tuple[int, ...]:
    items = [word(v, f"{what}[{i}]", low, high) for i, v in enumerate(values)]
    if len(items) != count:
        raise ValueError(f"{what} needs {count} integers, got {len(items)}")
    return tuple(items)
