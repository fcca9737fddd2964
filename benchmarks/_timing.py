"""Timing helpers shared by the benchmarks: random-action steppers and side-by-side medians.

The two sides of a comparison alternate, repeat after repeat, and their medians are compared,
so slow phases of a shared machine hit both alike.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np


def stepper(env: gym.Env, steps: int, seed: int) -> Callable[[], float]:
    """A function that takes ``steps`` random steps (resetting at episode ends); returns seconds."""
    env.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(env.action_space.n, size=steps).tolist()

    def run() -> float:
        step, reset = env.step, env.reset
        start = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = step(a)
            if terminated or truncated:
                reset()
        return time.perf_counter() - start

    return run


def vector_stepper(envs, steps: int, seed: int) -> Callable[[], float]:
    """The same for an SB3 ``VecEnv`` or a gymnasium ``VectorEnv`` with two actions."""
    if hasattr(envs, "seed"):  # SB3 VecEnv: seeded separately, reset without arguments
        envs.seed(seed)
        envs.reset()
    else:
        envs.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(2, size=(steps, envs.num_envs))

    def run() -> float:
        start = time.perf_counter()
        for a in actions:
            envs.step(a)
        return time.perf_counter() - start

    return run


def side_by_side(
    first: Callable[[], float], second: Callable[[], float], repeats: int
) -> tuple[float, float]:
    """Median seconds of two timed functions run alternately (after one warm-up each)."""
    first(), second()  # warm caches and lazy imports
    first_times, second_times = [], []
    for _ in range(repeats):
        first_times.append(first())
        second_times.append(second())
    return float(np.median(first_times)), float(np.median(second_times))
