"""Synthetic demonstrations with known switch points, for tests and the segmentation benchmark.

:func:`make_switching_demos` draws demonstrations of a task made of phases, each phase its own
dynamics, and returns the steps at which the phase changes. The family is broad on purpose
(``benchmarks/bench_segmentation.py`` chooses the segmentation defaults on it):

* ``"constant_velocity"`` -- straight lines at constant speed, each phase a new direction;
* ``"goal_reaching"`` -- each phase an attractor ``dx/dt = k (g_i - x)`` towards its own
  sub-goal, left once 90 % of the way there (speed falls towards each sub-goal);
* ``"linear_dynamics"`` -- each phase a linear system ``dx/dt = A_i (x - c_i)``, a damped
  rotation in a random plane about its own centre;
* ``"one_dimension"`` -- every dimension drifts at its own constant speed throughout, except
  dimension 0, whose speed changes at every switch (the phases differ in one dimension only).

Every phase ends at a place (a distance travelled, a fraction of the way to a sub-goal, an
angle turned), not after a time, so the demonstrations share their transition states, as SWIRL
assumes; each demonstrator moves at its own speed per phase. On top of that: observation
noise, nuisance dimensions (smooth motion unrelated to the phases), demonstrators up to
``speed_ratio`` times slower than others, time-warping inside a demonstration, and several
sampling rates in one set.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from sb3_swirl.demos import Demonstration
from swirl_wrappers._validation import check_int, check_real

KINDS = ("constant_velocity", "goal_reaching", "linear_dynamics", "one_dimension")

_DT = 0.1  # integration step, in units of one sample at rate 1
Field = Callable[[np.ndarray], np.ndarray]
# (vector field, guard): the phase ends when guard(x, x_at_phase_start) is true
Phase = tuple[Field, Callable[[np.ndarray, np.ndarray], bool]]


def _directions(rng: np.random.Generator, n: int, dim: int) -> list[np.ndarray]:
    """Unit vectors, each at least 60 degrees from the one before."""
    out = [rng.normal(size=dim)]
    while len(out) < n:
        cand = -out[-1] if dim == 1 else rng.normal(size=dim)
        if dim == 1 or cand @ out[-1] < math.cos(math.radians(60)) * np.linalg.norm(
            cand
        ) * np.linalg.norm(out[-1]):
            out.append(cand)
    return [d / np.linalg.norm(d) for d in out]


def _phases(
    kind: str, rng: np.random.Generator, n_phases: int, dim: int, length: float
) -> tuple[np.ndarray, list[Phase]]:
    """The start state and the phases of one task (shared by all its demonstrations).

    ``length`` is the number of samples (at rate 1, unit speed) of an average phase.
    """
    start = np.zeros(dim)
    phases: list[Phase] = []
    if kind == "constant_velocity":
        for d, dist in zip(
            _directions(rng, n_phases, dim), length * rng.uniform(0.7, 1.3, n_phases), strict=True
        ):
            phases.append((lambda x, d=d: d, lambda x, x0, d=d, dist=dist: (x - x0) @ d >= dist))
    elif kind == "goal_reaching":
        # k such that 90 % of the way takes about `length` samples: exp(-k length) = 0.1
        k = math.log(10.0) / length
        goal = start
        for d, dist in zip(
            _directions(rng, n_phases, dim), length * rng.uniform(0.7, 1.3, n_phases), strict=True
        ):
            prev, goal = goal, goal + d * dist
            phases.append(
                (
                    lambda x, g=goal: k * (g - x),
                    lambda x, x0, g=goal, a=prev: (
                        np.linalg.norm(g - x) <= 0.1 * np.linalg.norm(g - a)
                    ),
                )
            )
    elif kind == "linear_dynamics":
        x = start
        for _ in range(n_phases):
            u, v = np.linalg.qr(rng.normal(size=(dim, 2)))[0].T if dim > 1 else (np.ones(1),) * 2
            radius = length / rng.uniform(1.5, 2.5)  # arc length ~ length over the turn
            centre = x - radius * u
            turn = rng.uniform(0.6, 1.0) * math.pi / 2 * rng.choice([-1.0, 1.0])
            omega = math.copysign(1.0 / radius, turn)  # unit speed on the circle
            rot = omega * (np.outer(v, u) - np.outer(u, v)) - 0.002 * np.eye(dim)
            if dim == 1:
                rot = -np.eye(1) / length
            end_angle = abs(turn)

            def guard(y, y0, c=centre, u=u, v=v, a=end_angle) -> bool:
                r0, r1 = y0 - c, y - c
                return math.atan2(abs(r1 @ v * (r0 @ u) - r1 @ u * (r0 @ v)), r1 @ r0) >= a * 0.999

            phases.append((lambda y, c=centre, m=rot: m @ (y - c), guard))
            # the nominal end state: the next phase's centre is placed from it
            x = centre + radius * (math.cos(turn) * u + math.sin(turn) * v)
    elif kind == "one_dimension":
        drift = rng.normal(size=dim) * 0.5
        drift[0] = 0.0
        speeds = [rng.choice([-1.0, 1.0])]
        while len(speeds) < n_phases:
            speeds.append(-speeds[-1] * rng.choice([1.0, 0.5]))
        for s, dist in zip(speeds, length * rng.uniform(0.7, 1.3, n_phases), strict=True):
            vel = drift.copy()
            vel[0] = s
            phases.append(
                (
                    lambda x, v=vel: v,
                    lambda x, x0, s=s, dist=dist: (x[0] - x0[0]) * math.copysign(1.0, s) >= dist,
                )
            )
    else:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    return start, phases


def _simulate(
    start: np.ndarray, phases: list[Phase], speeds: np.ndarray, limit: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate the phases in turn; returns times, states and the switch times."""
    times, states, switches = [0.0], [start.copy()], []
    x, t = start.copy(), 0.0
    for i, ((field, guard), speed) in enumerate(zip(phases, speeds, strict=True)):
        x0 = x.copy()
        for _ in range(limit):
            if guard(x, x0):
                break
            x = x + _DT * speed * field(x)
            t += _DT
            times.append(t)
            states.append(x.copy())
        else:
            raise RuntimeError(f"phase {i} did not end within {limit} steps")  # pragma: no cover
        if i < len(phases) - 1:
            switches.append(t)
    return np.asarray(times), np.asarray(states), np.asarray(switches)


def make_switching_demos(
    kind: str = "constant_velocity",
    *,
    n_demos: int = 10,
    n_phases: int = 3,
    dim: int = 4,
    phase_length: float = 40.0,
    noise: float = 0.1,
    nuisance_dims: int = 0,
    speed_ratio: float = 1.5,
    time_warp: float = 0.0,
    rates: Sequence[int] = (1,),
    random_state: int | np.random.Generator | None = None,
) -> tuple[list[Demonstration], list[np.ndarray]]:
    """Demonstrations of a phased task with known switch points.

    Parameters
    ----------
    kind : {"constant_velocity", "goal_reaching", "linear_dynamics", "one_dimension"}
        The dynamics of each phase (see the module docstring).
    n_demos, n_phases, dim : int
        ``dim`` task dimensions, nuisance dimensions come on top.
    phase_length : float
        Mean samples per phase for the fastest demonstrator at rate 1.
    noise : float
        Standard deviation of the Gaussian observation noise, in units of the distance the
        fastest demonstrator moves per sample at rate 1.
    nuisance_dims : int
        Extra dimensions that move on their own, unrelated to the phases: each the sum of two
        sinusoids with periods of 1 to 3 phase lengths, at their peak half as fast as the task.
    speed_ratio : float
        Each demonstrator's speed in each phase is drawn from ``[1 / speed_ratio, 1]``: demo
        lengths vary up to ``speed_ratio`` times.
    time_warp : float in [0, 1)
        Amplitude of a smooth monotone warp of time inside each demonstration (speeding up and
        slowing down twice over the demonstration, with a random phase).
    rates : sequence of int
        Sampling rates, one sample every ``rate`` time units; demonstration ``i`` uses
        ``rates[i % len(rates)]``.
    random_state : int or numpy Generator, optional

    Returns
    -------
    demos : list of Demonstration
    switches : list of int arrays
        For each demonstration, the ``n_phases - 1`` steps at which a new phase starts.

    Examples
    --------
    >>> demos, switches = make_switching_demos("goal_reaching", n_demos=3, random_state=0)
    >>> len(demos), [len(s) for s in switches]
    (3, [2, 2, 2])
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    n_demos, n_phases, dim = (
        check_int(k, v, low=1)
        for k, v in (("n_demos", n_demos), ("n_phases", n_phases), ("dim", dim))
    )
    nuisance_dims = check_int("nuisance_dims", nuisance_dims, low=0)
    phase_length = check_real("phase_length", phase_length, low=0.0, low_open=True)
    noise = check_real("noise", noise, low=0.0)
    if not 0.0 <= time_warp < 1.0:
        raise ValueError(f"time_warp must be in [0, 1), got {time_warp}")
    if speed_ratio < 1.0:
        raise ValueError(f"speed_ratio must be >= 1, got {speed_ratio}")
    if not rates or any(int(r) != r or r < 1 for r in rates):
        raise ValueError(f"rates must be positive integers, got {rates}")
    rng = np.random.default_rng(random_state)
    start, phases = _phases(kind, rng, n_phases, dim, phase_length)
    limit = int(50 * phase_length * speed_ratio / _DT)
    demos, switches = [], []
    for i in range(n_demos):
        speeds = rng.uniform(1.0 / speed_ratio, 1.0, 1 if kind == "one_dimension" else n_phases)
        # in "one_dimension" a demonstrator keeps its speed, so the drift never changes
        speeds = np.resize(speeds, n_phases)
        x0 = start + rng.normal(scale=0.5, size=dim)
        times, states, switch_times = _simulate(x0, phases, speeds, limit)
        end = times[-1]
        rate = int(rates[i % len(rates)])
        sample = np.arange(0.0, end + 1e-9, rate)
        if sample[-1] < end - 1e-9:
            sample = np.append(sample, end)
        if time_warp:
            shift = rng.uniform(0, 2 * math.pi)
            # tau -> tau + a T / (4 pi) (sin(4 pi tau / T + shift) - sin(shift)): monotone
            sample = sample + time_warp * end / (4 * math.pi) * (
                np.sin(4 * math.pi * sample / end + shift) - math.sin(shift)
            )
            sample = np.clip(sample, 0.0, end)
            sample = np.maximum.accumulate(sample)
        obs = np.column_stack([np.interp(sample, times, states[:, j]) for j in range(dim)])
        if nuisance_dims:
            # two sinusoids per dimension, periods of 1-3 phases, each at half the task's speed
            period = rng.uniform(1.0, 3.0, size=(2, nuisance_dims)) * phase_length
            offset = rng.uniform(0.0, 2 * math.pi, size=(2, nuisance_dims))
            angle = 2 * math.pi * sample[:, None, None] / period + offset
            obs = np.concatenate(
                [obs, (0.5 * period / (2 * math.pi) * np.sin(angle)).sum(1)], axis=1
            )
        obs = obs + rng.normal(scale=noise, size=obs.shape)
        demos.append(Demonstration(obs))
        switches.append(np.searchsorted(sample, switch_times - 1e-9).astype(np.int64))
    return demos, switches
