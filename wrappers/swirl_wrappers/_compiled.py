""":meth:`SegmentTracker.step` compiled with numba, when numba is installed (optional).

The numpy path costs a few dozen small numpy calls per vector step, each a few microseconds, so
the tracker adds more time per env-step than the step of a cheap environment. One compiled call
does the same work. It follows the numpy path line by line: the evaluation is
:meth:`TaskModel.reward_and_next_batch` on one row (the same ``weights``, summed in another
order, so results agree up to floating-point rounding), and the shaping is
``SegmentTracker._shape``. ``tests/test_wrappers.py`` checks the two paths agree in
every mode.

``pip install swirl-wrappers[numba]`` (sb3-swirl installs it); without numba the tracker uses its
numpy path. Compiled code is cached on disk (numba's ``cache=True``): the first call on a machine
compiles for a few seconds, later processes load it.
"""

from __future__ import annotations

import numpy as np

# Layout of the float64 ``settings`` array that carries the tracker's settings into the step.
SCALE, BONUS, WEIGHT, GAMMA, TIMED = range(5)


def settings(scale: float, bonus: float, weight: float, gamma: float, timed: bool) -> np.ndarray:
    """The ``settings`` argument of :func:`step`."""
    return np.array([scale, bonus, weight, gamma, float(timed)])


def _evaluate(x, index, t, weights, p, timed, t_bounds):  # pragma: no cover - compiled
    """``R_index(x)`` and ``M(x, t, index)`` for one state (one row of the batched product)."""
    n_in = weights.shape[1] - 1
    base = index * 2 * p
    # Rows base .. base + p - 1 give the reward, the next p the region distance: two loops,
    # not one with a branch per row.
    reward = 0.0
    for c in range(base, base + p):
        z = weights[c, n_in]
        for k in range(n_in):
            z += x[k] * weights[c, k]
        reward -= z * z
    dist = 0.0
    for c in range(base + p, base + 2 * p):
        z = weights[c, n_in]
        for k in range(n_in):
            z += x[k] * weights[c, k]
        dist += z * z
    if dist <= 1.0 and (not timed or (t_bounds[0, index] <= t and t <= t_bounds[1, index])):
        return reward, index + 1
    return reward, index


def _potential(x, before, reward, after, weights, p, t_bounds):  # pragma: no cover - compiled
    """``Phi(x, after)`` given ``reward = R_before(x)`` (re-evaluated if the index moved).

    The formula is :func:`swirl_wrappers.progress_potential`'s, on one state.
    """
    if after != before:
        reward = _evaluate(x, after, 0, weights, p, False, t_bounds)[0]
    return after + 1.0 / (1.0 - min(reward, 0.0))


def _lift_row(obs, index, out):  # pragma: no cover - compiled
    """Write ``obs`` (1-D) followed by the one-hot of ``index`` into ``out``."""
    d = len(obs)
    for k in range(d):
        out[k] = obs[k]
    for k in range(d, len(out)):
        out[k] = 0
    out[d + index] = 1


def _step(
    obs,
    x,
    final_obs,
    final_x,
    restart,
    before,
    start,
    clock,
    weights,
    t_bounds,
    settings,
    task_rewards,
    terminated,
    potential,
    reward,
    reward32,
    index,
    new_potential,
    lifted,
    lifted_final,
):  # pragma: no cover - compiled
    """One tracker step for every row; see ``SegmentTracker.step`` and ``step_lift``.

    ``x`` and ``final_x`` hold the task inputs (their leading columns are read) of the
    observations ``obs`` and of the ``restart`` rows' final observations ``final_obs`` (a linear
    task's are the observations themselves). Writes the rewards into ``reward``
    (and ``reward32``), the new indices into ``index[0]``, the indices the transitions ended
    with into ``index[1]``, the potentials into ``new_potential`` and the lifted observations
    into ``lifted`` and ``lifted_final``; moves ``start`` of the restarted rows to ``clock``.

    Arrays that are not given or not needed are ``None``: ``final_obs`` and ``final_x``
    without final states (the restart rows made no transition), ``restart`` without restarts,
    ``task_rewards`` when their weight is 0, ``terminated``, ``potential`` and
    ``new_potential`` outside ``"potential"`` mode, ``reward32``, ``lifted`` and
    ``lifted_final`` when not asked for. numba compiles each combination separately, without
    the branches it does not need; a ``None`` costs less to pass than an empty array.
    """
    scale, bonus, weight = settings[SCALE], settings[BONUS], settings[WEIGHT]
    gamma, timed = settings[GAMMA], settings[TIMED] != 0.0
    n = len(start)
    n_indices = t_bounds.shape[1]
    p = len(weights) // (2 * n_indices)
    # Bounds are not checked on every access (numba's boundscheck made this step about 15%
    # slower). The Python side checks the shapes of what callers pass; these are what they can
    # reach through the tracker's attributes, and the count of final states. All are checked
    # before anything changes.
    if len(before) != n or (potential is not None and len(potential) != n):
        raise ValueError("index and potential must hold one entry per environment")
    for i in range(n):
        if before[i] < 0 or before[i] >= n_indices:
            raise ValueError("index holds a segment index out of range")
    if final_obs is not None:
        if restart is None or np.count_nonzero(restart) != len(final_obs):
            raise ValueError("final_states must hold one state per restart row")
    xi = np.empty(weights.shape[1] - 1)
    j = 0  # the next row of ``final_obs``
    for i in range(n):
        restarts = False
        if restart is not None:
            restarts = restart[i]
        if restarts and final_obs is None:
            # NEXT_STEP: the row holds a new episode's first state and made no transition.
            reward[i] = 0.0
            if reward32 is not None:
                reward32[i] = 0.0
        else:
            # The transition; at a restart row it ends in the final state of the episode.
            # (A copy: ``final_x`` and ``x`` may differ in dtype or layout.)
            if restarts:
                # final_obs is given here; the test (and the one below) lets numba compile the
                # specialisation where it is None, which never reaches this branch.
                if final_obs is not None:
                    for k in range(len(xi)):
                        xi[k] = final_x[j, k]
            else:
                for k in range(len(xi)):
                    xi[k] = x[i, k]
            b = before[i]
            r, after = _evaluate(xi, b, clock - start[i], weights, p, timed, t_bounds)
            if potential is not None:
                phi = 0.0
                if not terminated[i]:
                    phi = _potential(xi, b, r, after, weights, p, t_bounds)
                r = scale * (gamma * phi - potential[i])
                new_potential[i] = phi
            elif scale != 1.0:
                r = r * scale
            if bonus != 0.0:
                r = r + bonus * (after != b)
            if task_rewards is not None:
                r = r + weight * task_rewards[i]
            reward[i] = r
            if reward32 is not None:
                reward32[i] = r
            index[0, i] = index[1, i] = after
            if not restarts:
                if lifted is not None:
                    _lift_row(obs[i], after, lifted[i])
                continue
            if final_obs is not None:
                if lifted_final is not None:
                    _lift_row(final_obs[j], after, lifted_final[j])
            j += 1
        # A new episode starts at the row's state (index 0 at t = 0, as in reset).
        start[i] = clock
        r, after = _evaluate(x[i], 0, 0, weights, p, timed, t_bounds)
        index[0, i] = after
        if final_obs is None:
            index[1, i] = after
        if potential is not None:
            new_potential[i] = _potential(x[i], 0, r, after, weights, p, t_bounds)
        if lifted is not None:
            _lift_row(obs[i], after, lifted[i])


def __getattr__(name: str):
    """``step``: :func:`_step` compiled, or ``None`` without numba; built on first use.

    Importing numba takes about half a second, which processes that build no tracker (the
    workers of a ``SubprocVecEnv`` of ``SwirlWrapper`` s, the CLI) do not pay.
    """
    if name != "step":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        import numba
    except ImportError:  # optional: the tracker falls back to numpy
        compiled = None
    else:
        # The helpers are compiled into the step where it calls them by their global names.
        for helper in ("_evaluate", "_potential", "_lift_row"):
            globals()[helper] = numba.njit(cache=True, inline="always")(globals()[helper])
        compiled = numba.njit(cache=True)(_step)
    globals()["step"] = compiled
    return compiled
