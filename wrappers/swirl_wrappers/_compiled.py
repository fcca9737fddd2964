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

try:
    import numba
except ImportError:  # optional: the tracker falls back to numpy
    numba = None

# Layout of the small arrays that carry the tracker's settings into the compiled step.
P, TIMED, POTENTIAL, HAS_FINAL = range(4)  # int64 ``config``
SCALE, BONUS, WEIGHT, GAMMA = range(4)  # float64 ``consts``


def _evaluate(x, index, t, weights, p, timed, t_bounds):  # pragma: no cover - compiled
    """``R_index(x)`` and ``M(x, t, index)`` for one state (one row of the batched product)."""
    n_in = weights.shape[1] - 1
    reward = 0.0
    dist = 0.0
    for c in range(2 * p):
        w = weights[index * 2 * p + c]
        z = 0.0
        for k in range(n_in):
            z += x[k] * w[k]
        z += w[n_in]
        if c < p:
            reward -= z * z
        else:
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
    x,
    obs,
    final_x,
    final_obs,
    restart,
    before,
    start,
    clock,
    weights,
    t_bounds,
    config,
    consts,
    task_rewards,
    terminated,
    potential,
    reward,
    index,
    new_potential,
    lifted,
    lifted_final,
):  # pragma: no cover - compiled
    """One tracker step for every row; see ``SegmentTracker.step`` and ``step_lift``.

    ``x`` and ``final_x`` hold the task inputs (their leading columns are read) of the
    observations ``obs`` and of the ``restart`` rows' final observations ``final_obs``.
    ``restart``, ``final_*``, ``task_rewards``, ``terminated``, ``lifted`` and ``lifted_final``
    are empty when not given (or not needed). Writes the rewards into ``reward``, the new indices
    into ``index[0]``, the indices the transitions ended with into ``index[1]``, the potentials
    (``"potential"`` mode) into ``new_potential`` and the lifted observations into ``lifted``
    and ``lifted_final``; moves ``start`` of the restarted rows to ``clock``.
    """
    p, timed, potential_mode = config[P], config[TIMED], config[POTENTIAL]
    has_final = config[HAS_FINAL]
    scale, bonus, weight, gamma = consts[SCALE], consts[BONUS], consts[WEIGHT], consts[GAMMA]
    has_restart = len(restart) > 0
    if has_final and np.count_nonzero(restart) != len(final_x):
        raise ValueError("final_states must hold one state per restart row")
    xi = np.empty(weights.shape[1] - 1)
    j = 0  # the next row of ``final_x``
    for i in range(len(before)):
        restarts = has_restart and restart[i]
        if restarts and not has_final:
            # NEXT_STEP: the row holds a new episode's first state and made no transition.
            reward[i] = 0.0
        else:
            # The transition; at a restart row it ends in the final state of the episode.
            # (A copy: ``final_x`` and ``x`` may differ in dtype or layout.)
            for k in range(len(xi)):
                xi[k] = final_x[j, k] if restarts else x[i, k]
            b = before[i]
            r, after = _evaluate(xi, b, clock - start[i], weights, p, timed, t_bounds)
            if potential_mode:
                phi = 0.0
                if not terminated[i]:
                    phi = _potential(xi, b, r, after, weights, p, t_bounds)
                r = scale * (gamma * phi - potential[i])
                new_potential[i] = phi
            elif scale != 1.0:
                r = r * scale
            if bonus != 0.0:
                r = r + bonus * (after != b)
            if weight != 0.0:
                r = r + weight * task_rewards[i]
            reward[i] = r
            index[0, i] = index[1, i] = after
            if not restarts:
                if len(lifted):
                    _lift_row(obs[i], after, lifted[i])
                continue
            if len(lifted_final):
                _lift_row(final_obs[j], after, lifted_final[j])
            j += 1
        # A new episode starts at the row's state (index 0 at t = 0, as in reset).
        start[i] = clock
        r, after = _evaluate(x[i], 0, 0, weights, p, timed, t_bounds)
        index[0, i] = after
        if not has_final:
            index[1, i] = after
        if potential_mode:
            new_potential[i] = _potential(x[i], 0, r, after, weights, p, t_bounds)
        if len(lifted):
            _lift_row(obs[i], after, lifted[i])


if numba is not None:
    _evaluate = numba.njit(cache=True, inline="always")(_evaluate)
    _potential = numba.njit(cache=True, inline="always")(_potential)
    _lift_row = numba.njit(cache=True)(_lift_row)
    # boundscheck: a wrong shape or index from a caller is an IndexError, never a stray read.
    step = numba.njit(cache=True, boundscheck=True)(_step)
else:
    step = None
