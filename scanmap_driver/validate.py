"""Field checks for the JSON formats (scanner model, scenes, recordings).

Each check names the field by its path (`camera.fx`, `objects[2].size`) and says what
was expected, and raises the error type of the format being read.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from .errors import ScanmapError


def check_keys(obj: Any, where: str, error: type[ScanmapError], required: Iterable[str],
               optional: Iterable[str] = ()) -> Mapping[str, Any]:
    """`obj` must be an object with all `required` keys and no key outside required+optional."""
    if not isinstance(obj, Mapping):
        raise error(f"{where}: expected an object, got {type(obj).__name__}")
    required = list(required)
    allowed = set(required) | set(optional)
    missing = [k for k in required if k not in obj]
    if missing:
        raise error(f"{where}: missing field(s) {', '.join(missing)}")
    unknown = sorted(set(obj) - allowed)
    if unknown:
        raise error(f"{where}: unknown field(s) {', '.join(unknown)} "
                    f"(allowed: {', '.join(sorted(allowed))})")
    return obj


def number(value: Any, where: str, error: type[ScanmapError], *, low: float | None = None,
           high: float | None = None, low_open: bool = False) -> float:
    """A finite real number within [low, high] (or (low, high] with `low_open`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise error(f"{where}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise error(f"{where}: expected a finite number, got {value}")
    if low is not None and (value < low or (low_open and value == low)):
        raise error(f"{where}: expected {'>' if low_open else '>='} {low}, got {value}")
    if high is not None and value > high:
        raise error(f"{where}: expected <= {high}, got {value}")
    return value


def integer(value: Any, where: str, error: type[ScanmapError], *, low: int | None = None) -> int:
    """An integer, at least `low`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise error(f"{where}: expected an integer, got {value!r}")
    if low is not None and value < low:
        raise error(f"{where}: expected >= {low}, got {value}")
    return value


def vector(value: Any, length: int, where: str, error: type[ScanmapError]) -> np.ndarray:
    """A list of `length` finite numbers, as a float64 array."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise error(f"{where}: expected a list of {length} numbers, got {value!r}")
    return np.array([number(v, f"{where}[{i}]", error) for i, v in enumerate(value)])
