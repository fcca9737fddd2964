"""Pieces the supervisors share: the env they control, and a keyboard-like step."""

from __future__ import annotations

from typing import TypeVar

import gymnasium as gym
import numpy as np

EnvT = TypeVar("EnvT", bound=gym.Env)


def controlled_env(env: gym.Env, env_class: type[EnvT], supervisor: str) -> EnvT:
    """``env.unwrapped`` if it is an ``env_class``; else a ValueError naming both classes."""
    unwrapped = env.unwrapped
    if not isinstance(unwrapped, env_class):
        raise ValueError(
            f"{supervisor} controls a {env_class.__name__}, got {type(unwrapped).__name__}"
        )
    return unwrapped


def step_towards(
    directions: np.ndarray,
    error: np.ndarray,
    step_size: float,
    rng: np.random.Generator | None = None,
) -> int | None:
    """The action whose step (a row of ``directions``) brings a point closer by ``error``.

    The one that gains most, or, with ``rng``, in 30% of the cases another one that gains at
    least half a step (so that demos from the same start differ); ``None`` if no step gains
    half of ``step_size``.
    """
    gains = directions @ error
    useful = np.flatnonzero(2.0 * gains > step_size)
    if len(useful) == 0:
        return None
    if rng is not None and len(useful) > 1 and rng.random() < 0.3:
        return int(rng.choice(useful))
    return int(np.argmax(gains))
