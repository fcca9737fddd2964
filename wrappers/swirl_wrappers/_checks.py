"""Type checks of user-given settings, shared by the wrappers and by sb3-swirl (which depends on
swirl-wrappers): the estimators, SwirlDQN and the experiments."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np


def is_finite_real(value: Any) -> bool:
    """Whether ``value`` is a finite real number (not a bool, string or None)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def is_integer(value: Any, minimum: int) -> bool:
    """Whether ``value`` is an integer (Python or numpy, not a bool) of at least ``minimum``."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= minimum


def is_bool(value: Any) -> bool:
    """Whether ``value`` is a bool (Python or numpy), not a truthy string or number."""
    return isinstance(value, bool | np.bool_)
