"""Checks of user-given settings that raise a ``ValueError`` naming the setting.

The one home of parameter validation outside the scikit-learn estimators (which declare
``_parameter_constraints``): the wrappers, the reward settings, SwirlDQN and the experiments.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection, Sequence
from typing import Any

import numpy as np


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    def say(x: float) -> str:
        return str(x) if isinstance(x, int) else f"{x:g}"

    if high is None:
        return "" if low is None else f" {'>' if low_open else '>='} {say(low)}"
    if low is None:
        return f" {'<' if high_open else '<='} {say(high)}"
    return f" in {'(' if low_open else '['}{say(low)}, {say(high)}{')' if high_open else ']'}"


def check_real(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """``value`` as a float: a finite real number (not a bool or a string) within the bounds."""
    ok = (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool | np.bool_)
        and (abs(value) < 2**1024 if isinstance(value, int) else math.isfinite(value))
        and (low is None or (value > low if low_open else value >= low))
        and (high is None or (value < high if high_open else value <= high))
    )
    if not ok:
        where = _interval(low, high, low_open, high_open)
        raise ValueError(f"{name} must be a finite number{where}, got {value!r}")
    return float(value)


def check_int(name: str, value: Any, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int: an integer (Python or numpy, not a bool) in ``low .. high``."""
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if not ok or (low is not None and value < low) or (high is not None and value > high):
        raise ValueError(
            f"{name} must be an integer{_interval(low, high, False, False)}, got {value!r}"
        )
    return int(value)


def check_widths(name: str, value: Any) -> list[int]:
    """``value`` as a list of layer widths: a sequence of integers >= 1 (not bools)."""
    ok = isinstance(value, Sequence) and not isinstance(value, str)
    ok = ok and all(
        isinstance(width, int | np.integer) and not isinstance(width, bool) and width >= 1
        for width in value
    )
    if not ok:
        raise ValueError(f"{name} must be a list of layer widths, got {value!r}")
    return [int(width) for width in value]


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool: True or False (Python or numpy), not a truthy string or number."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_option(name: str, value: Any, options: Collection[str]) -> str:
    """``value``, one of the strings ``options``."""
    if not isinstance(value, str) or value not in options:
        raise ValueError(f"{name} must be one of {sorted(options)}, got {value!r}")
    return value
