"""Angle helpers shared by the envs."""

import math

_TWO_PI = 2.0 * math.pi


def wrap_angle(x: float) -> float:
    """Wrap an angle into ``[-pi, pi)``."""
    return (x + math.pi) % _TWO_PI - math.pi
