"""Sequence learning (§5 of the paper, Algorithm 1): transition state clustering.

A *transition indicator* marks candidate transitions in every demonstration; a Dirichlet-process
GMM clusters the transition states (state and time); clusters that do not hold a transition from
(almost) every demonstration are pruned; each survivor becomes an ellipsoidal
:class:`swirl_wrappers.Region`, and the regions, ordered by time, define the Markov segmentation
function of the proxy task.

Five indicators are provided (§9.5 of the paper compares the first three), several can be
joined (``"gmm+velocity"``: the union of their candidates), and any callable
``f(states, random_state) -> list of index arrays`` can be plugged in:

* :func:`gmm_indicator` -- GMM on windows normalised to their first state (the paper's, §5.3);
* :func:`velocity_indicator` -- a change in the direction of velocity;
* :func:`linear_indicator` -- a change of local linear dynamic regime;
* :func:`phases_indicator` -- phases with their own linear dynamics that every demonstration
  goes through in order, fitted to all demonstrations together;
* :func:`ruptures_indicator` -- change points of the velocity from the ``ruptures`` library.

``indicator="auto"`` (the default) fits with each of the first four and keeps the segmentation
under which locally linear dynamics best predict the demonstrations (:func:`dynamics_cv_error`,
leave one demonstration out). Each transition region is then placed where the online
segmentation enters it closest to the demonstrations' own transitions (``align_entries``).

``benchmarks/bench_segmentation.py`` measures them against known switch points
(:func:`switch_scores`) on :func:`sb3_swirl.datasets.make_switching_demos`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from scipy.stats import chi2
from sklearn.base import BaseEstimator, clone
from sklearn.decomposition import PCA
from sklearn.kernel_approximation import Nystroem
from sklearn.mixture import BayesianGaussianMixture, GaussianMixture
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, InvalidParameterError, StrOptions
from threadpoolctl import threadpool_limits

from sb3_swirl.demos import _typical_step, as_demonstrations, check_demos_agree, check_window
from swirl_wrappers import QuadraticReward, RBFFeatures, Region, TaskModel
from swirl_wrappers._validation import check_int, check_option, check_real

Indicator = Callable[[list[np.ndarray], Any], list[np.ndarray]]

_CHUNK = 100_000  # rows per predict call: bounds peak memory on 1000 x 1000-step demo sets
_SEED_MAX = np.iinfo(np.int32).max
_DEFAULT_WINDOW = 3  # of the GMM and velocity indicators
# A demo enters a segment far from its own transition into it when the gap is over this share
# of its previous segment (and the benchmark's tolerance): on the benchmark's tuning sets, fits
# with switch F1 >= 0.95 had median gaps of at most 0.06, those over 0.1 read F1 0.4-0.8
# (docs/segmentation.md)
_ENTRY_GAP = 0.1


# ---------------------------------------------------------------------------- helpers
def _constant_columns(x: np.ndarray, std: np.ndarray | None = None) -> np.ndarray:
    """Which columns of ``x`` are constant: no spread beyond rounding of their own values
    (``std``: the columns' standard deviations, when already at hand)."""
    std = x.std(axis=0) if std is None else std
    return ~(std > 1e-12 * np.maximum(1.0, np.abs(x).max(axis=0, initial=0.0)))


def _scale(x: np.ndarray) -> np.ndarray:
    """Per-column standard deviation, with constant columns given scale 1."""
    std = x.std(axis=0)
    return np.where(_constant_columns(x, std), 1.0, std)


def _local_maxima(score: np.ndarray, threshold: float, radius: int) -> np.ndarray:
    """Indices of peaks of ``score`` above ``threshold``, at least ``radius`` apart (greedy NMS)."""
    candidates = np.flatnonzero(score > threshold)
    keep: list[int] = []
    for j in candidates[np.argsort(-score[candidates], kind="stable")]:
        if all(abs(j - k) > radius for k in keep):
            keep.append(int(j))
    return np.sort(np.asarray(keep, dtype=np.int64))


def _interior(idx: np.ndarray, n_states: int) -> np.ndarray:
    """Sorted unique indices without the first and last state (they never count as transitions)."""
    idx = np.unique(np.asarray(idx, dtype=np.int64))
    return idx[(idx > 0) & (idx < n_states - 1)]


def _merge_close(idx: np.ndarray, radius: int) -> np.ndarray:
    """Sorted unique steps, each within ``radius`` of the previous kept one dropped."""
    keep: list[int] = []
    for j in np.unique(idx.astype(np.int64)):
        if not keep or j - keep[-1] > radius:
            keep.append(int(j))
    return np.asarray(keep, dtype=np.int64)


def _shared_course_dims(
    states: list[np.ndarray], n_points: int = 50, low: float = 0.3, high: float = 0.8
) -> np.ndarray | None:
    """The dimensions to cluster transitions on, leaving out those that move on their own.

    Each demonstration is resampled to ``n_points`` states evenly spaced over its length. Per
    dimension, the share of its variance explained by the mean resampled demonstration (an
    R^2) says how much the demonstrations move alike along it. A dimension that moves on its
    own in each demonstration (a nuisance dimension) has R^2 below ``low`` *and* no stretch
    where the demonstrations agree: its spread across demonstrations stays above 10 % of its
    variance at 90 % of the resampled steps (a relative offset that every demonstration
    brings to zero, as a gripper reaching its object does, is kept). Returns the other
    indices when some dimension has R^2 >= ``high`` and some are nuisance; otherwise
    ``None`` (e.g. oscillations whose timing differs between demonstrations align along no
    dimension, so none is called a nuisance).
    """
    grid = [np.linspace(0, len(s) - 1, n_points) for s in states]
    resampled = np.stack(
        [
            np.column_stack([np.interp(g, np.arange(len(s)), col) for col in s.T])
            for g, s in zip(grid, states, strict=True)
        ]
    )  # (n_demos, n_points, p)
    total = np.maximum(resampled.reshape(-1, resampled.shape[2]).var(axis=0), 1e-300)
    spread = resampled.var(axis=0)  # across demonstrations, per resampled step
    r2 = 1.0 - spread.mean(axis=0) / total
    nuisance = (r2 < low) & (np.quantile(spread, 0.1, axis=0) > 0.1 * total)
    if r2.max() < high or not nuisance.any():
        return None
    return np.flatnonzero(~nuisance)


def _time_scales(states: list[np.ndarray]) -> np.ndarray:
    """Each demonstration's typical step over the median of all demonstrations' (1 if 0).

    The typical step (``sb3_swirl.demos._typical_step``: while it moves, not at rest at its
    start or end) is measured with each dimension divided by its standard deviation over all
    states.
    """
    scale = _scale(np.concatenate(states))
    typical = np.array([_typical_step(x, scale)[0] for x in states])
    reference = float(np.median(typical))
    if not reference > 0:
        return np.ones(len(states))
    return np.where(typical > 0, typical / reference, 1.0)


def _resample(x: np.ndarray, factor: float, min_states: int) -> tuple[np.ndarray, float]:
    """``x`` resampled to about ``factor`` times as many steps; also old steps per new step."""
    n_steps = len(x) - 1
    new_steps = max(min_states - 1, round(n_steps * factor))
    if new_steps == n_steps:
        return x, 1.0
    t = np.linspace(0.0, n_steps, new_steps + 1)
    grid = np.arange(len(x))
    resampled = np.column_stack([np.interp(t, grid, x[:, j]) for j in range(x.shape[1])])
    return resampled, n_steps / new_steps


def _windows(x: np.ndarray, window: int) -> np.ndarray:
    """Windows ``n_t = [s_{t-l+1} - s_{t-l}, ..., s_t - s_{t-l}]`` for ``t = l .. T`` (§5.3).

    The leading ``s_{t-l} - s_{t-l} = 0`` is dropped: it carries no information.
    """
    n = len(x) - window
    base = x[:n]
    return np.concatenate([x[j : j + n] - base for j in range(1, window + 1)], axis=1)


def _majority_filter(labels: np.ndarray, radius: int, n_labels: int) -> np.ndarray:
    """Most frequent label in a window of ``2 radius + 1`` steps around each step.

    Windows straddling a component boundary flip labels back and forth under noise; a
    majority vote removes that flicker while keeping changes that persist (radius 1 is the
    authors' single-step smoothing).
    """
    if radius < 1 or len(labels) < 3:
        return labels
    counts = np.zeros((len(labels) + 1, n_labels))
    counts[1:] = np.cumsum(np.eye(n_labels)[labels], axis=0)
    idx = np.arange(len(labels))
    lo, hi = np.maximum(idx - radius, 0), np.minimum(idx + radius + 1, len(labels))
    window = counts[hi] - counts[lo]
    # Ties keep the current label, so the filter never invents a change.
    window[idx, labels] += 0.5
    return window.argmax(axis=1)


# ---------------------------------------------------------------------------- indicators
def gmm_indicator(
    states: list[np.ndarray],
    random_state: Any = None,
    *,
    window: int = _DEFAULT_WINDOW,
    n_components: int = 5,
    max_samples: int = 20_000,
    smooth: int | None = None,
) -> list[np.ndarray]:
    """Candidate transitions where the most likely GMM component of the window changes (§5.3).

    Windows of ``window + 1`` states normalised to their first state are pooled over all
    demonstrations and standardised; a GMM (``sklearn.mixture.GaussianMixture``, fitted on at most
    ``max_samples`` windows drawn at random) labels every window with its most likely component.
    Label flicker is smoothed away first by a majority vote over ``2 smooth + 1`` windows. A
    label change between the windows ending at ``t - 1`` and ``t`` is reported at the middle
    of the window, ``t - (window + 1) // 2``, which is where a switch of motion makes the label
    change.

    Parameters
    ----------
    states : list of arrays of shape (T_i + 1, p)
    random_state : int, RandomState or None
    window : int
        Window length ``l`` (the authors used 2 to 8).
    n_components : int
        Number of GMM components (motion primitives); over-segmenting is fine, since
        transitions not shared by the demonstrations are pruned later.
    max_samples : int
        At most this many windows are used to fit the GMM (all are labelled).
    smooth : int, optional
        Radius of the majority filter on the labels; default ``window``. ``1`` removes only
        single-step flicker (``a b a``), as the authors' code did.

    Returns
    -------
    list of int arrays
        Candidate transition steps per demonstration.

    Raises
    ------
    ValueError
        If a demonstration has fewer than ``window + 2`` states.
    """
    rs = check_random_state(random_state)
    check_window(states, window)
    smooth = window if smooth is None else int(smooth)
    wins = [_windows(x, window) for x in states]
    pooled = np.concatenate(wins)
    scale = _scale(pooled)
    sample = (
        pooled
        if len(pooled) <= max_samples
        else pooled[rs.choice(len(pooled), max_samples, replace=False)]
    )
    n_distinct = len(np.unique(sample, axis=0))
    if n_distinct < 2:
        return [np.zeros(0, dtype=np.int64) for _ in states]
    gmm = GaussianMixture(
        n_components=min(n_components, n_distinct),
        covariance_type="full",
        reg_covar=1e-4,
        random_state=rs.randint(_SEED_MAX),
    ).fit(sample / scale)
    labels = np.concatenate(
        [gmm.predict(pooled[i : i + _CHUNK] / scale) for i in range(0, len(pooled), _CHUNK)]
    )
    out, start = [], 0
    for x, w in zip(states, wins, strict=True):
        lab = labels[start : start + len(w)].copy()
        start += len(w)
        lab = _majority_filter(lab, smooth, gmm.n_components)
        change = np.flatnonzero(lab[1:] != lab[:-1]) + 1  # window index of the new label
        out.append(_interior(change + window - (window + 1) // 2, len(x)))
    return out


def turn_angles(x: np.ndarray, window: int, min_speed: float = 0.0) -> np.ndarray:
    """The change of direction of motion at steps ``window .. len(x) - window - 1``.

    The angle (radians) between the displacement over the ``window`` steps before a step and
    over the ``window`` steps after it; 0 where either is not longer than ``min_speed``.
    """
    before = x[window:-window] - x[: -2 * window]
    after = x[2 * window :] - x[window:-window]
    nb, na = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    valid = (nb > min_speed) & (na > min_speed)
    cos = np.einsum("ij,ij->i", before, after) / np.where(valid, nb * na, 1.0)
    return np.where(valid, np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)


def velocity_indicator(
    states: list[np.ndarray],
    random_state: Any = None,
    *,
    window: int = _DEFAULT_WINDOW,
    angle_threshold: float = math.pi / 4,
    min_speed: float = 0.1,
) -> list[np.ndarray]:
    """Candidate transitions where the direction of velocity changes.

    At every step ``t`` the mean velocity over the ``window`` steps before and after ``t`` is
    compared; ``t`` is a candidate where the angle between the two exceeds ``angle_threshold``
    (radians) and is a local maximum (peaks closer than ``window`` steps are merged). Steps
    where either velocity is slower than ``min_speed`` times the median speed have no defined
    direction and are skipped.

    Parameters
    ----------
    states : list of arrays of shape (T_i + 1, p)
    random_state : ignored (the indicator is deterministic)
    window : int
    angle_threshold : float
    min_speed : float

    Raises
    ------
    ValueError
        If a demonstration has fewer than ``window + 2`` states.
    """
    del random_state
    check_window(states, window)
    speeds = np.concatenate([np.linalg.norm(x[window:] - x[:-window], axis=1) for x in states])
    floor = min_speed * float(np.median(speeds)) + 1e-12
    out = []
    for x in states:
        if len(x) < 2 * window + 1:
            out.append(np.zeros(0, dtype=np.int64))
            continue
        angle = turn_angles(x, window, floor)
        out.append(_interior(_local_maxima(angle, angle_threshold, window) + window, len(x)))
    return out


def _ridge_sse(
    stats: tuple[np.ndarray, np.ndarray, np.ndarray],
    lo: np.ndarray,
    hi: np.ndarray,
    penalty: np.ndarray,
) -> np.ndarray:
    """Residual sum of squares of ridge fits ``y ~ z B`` on the transitions ``lo .. hi - 1``.

    ``stats`` holds cumulative sums of ``z z^T``, ``z y^T`` and ``|y|^2``, so every window costs
    one small solve.
    """
    czz, czy, cyy = stats
    zz, zy, yy = czz[hi] - czz[lo], czy[hi] - czy[lo], cyy[hi] - cyy[lo]
    coef = np.linalg.solve(zz + penalty, zy)
    fit = np.einsum("kij,kij->k", coef, zy)  # tr(B^T Z^T Y)
    return np.maximum(yy - 2 * fit + np.einsum("kij,kil,klj->k", coef, zz, coef), 0.0)


def linear_indicator(
    states: list[np.ndarray],
    random_state: Any = None,
    *,
    window: int | None = None,
    threshold: float = 3.0,
    ridge: float = 0.1,
) -> list[np.ndarray]:
    """Candidate transitions where the local linear dynamics change (a Chow-type test).

    States are standardised over all demonstrations. At every step ``t`` an affine model
    ``s_{t+1} - s_t = A s_t + b`` (ridge-regularised on ``A``) is fitted to the ``window``
    transitions before ``t``, to the ``window`` after, and to both together; the score is the
    relative increase of the residual when one model must explain both sides,
    ``SSE_both - SSE_before - SSE_after``, in units of its expected size without a change
    (``p (p + 1)`` coefficients times the residual variance per transition, one median
    estimate over all demonstrations: a local estimate from ``2 window`` points is too noisy).
    Peaks above ``threshold`` (at least ``window`` steps apart) are candidates. Sufficient
    statistics are accumulated with cumulative sums, so the cost is linear in the number of
    steps.

    Parameters
    ----------
    states : list of arrays of shape (T_i + 1, p)
    random_state : ignored (the indicator is deterministic)
    window : int, optional
        Transitions per side; default ``max(2 (p + 1), 8)``, enough to fit the ``p + 1``
        coefficients per output with noise.
    threshold : float
    ridge : float
        Ridge penalty on ``A`` (in standardised units); keeps fits on nearly collinear states
        (straight-line motion) well posed.
    """
    del random_state
    p = states[0].shape[1]
    w = max(2 * (p + 1), 8) if window is None else int(window)
    pooled = np.concatenate(states)
    mean, scale = pooled.mean(axis=0), _scale(pooled)
    penalty = ridge * np.diag(np.r_[np.ones(p), 0.0])
    excess, residual = [], []
    for raw in states:
        x = (raw - mean) / scale
        n = len(x) - 1  # transitions
        if n < 2 * w:
            excess.append(np.zeros(0))
            continue
        z = np.column_stack([x[:-1], np.ones(n)])
        y = x[1:] - x[:-1]
        stats = tuple(
            np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])
            for a in (z[:, :, None] * z[:, None, :], z[:, :, None] * y[:, None, :], (y * y).sum(1))
        )
        t = np.arange(w, n - w + 1)
        left, right = _ridge_sse(stats, t - w, t, penalty), _ridge_sse(stats, t, t + w, penalty)
        both = _ridge_sse(stats, t - w, t + w, penalty)
        excess.append(both - left - right)
        residual.append((left + right) / (2 * w * p))
    # One noise level for all demonstrations: a local estimate from 2w points is too noisy.
    noise = float(np.median(np.concatenate(residual))) if residual else 0.0
    noise = max(noise, 1e-12 * float(np.mean(pooled.var(axis=0) / scale**2)), 1e-300)
    out = []
    for raw, exc in zip(states, excess, strict=True):
        score = exc / (noise * p * (p + 1))
        out.append(_interior(_local_maxima(score, threshold, w) + w, len(raw)))
    return out


def _noise_scale(velocities: list[np.ndarray]) -> np.ndarray:
    """Per-dimension noise of step velocities, from the spread of their changes.

    Where velocity is piecewise smooth, a change of velocity between steps is mostly noise:
    its median absolute value over all demonstrations, over ``0.6745 sqrt 2``, estimates the
    noise of one velocity (robust to the few steps where the motion really changes).
    """
    changes = np.concatenate([np.abs(np.diff(v, axis=0)) for v in velocities if len(v) > 1])
    sd = np.median(changes, axis=0) / (0.6745 * math.sqrt(2.0))
    floor = 1e-6 * max(float(np.concatenate(velocities).std()), 1e-300)
    return np.maximum(sd, floor)


def ruptures_indicator(
    states: list[np.ndarray],
    random_state: Any = None,
    *,
    method: str = "pelt",
    penalty: float | None = None,
    min_size: int = 3,
) -> list[np.ndarray]:
    """Candidate transitions from the ``ruptures`` change-point library, per demonstration.

    Step velocities ``s_{t+1} - s_t`` are standardised by their noise (pooled over all
    demonstrations, see ``_noise_scale``) and each demonstration is cut by ``ruptures``:
    ``"pelt"`` and ``"binseg"`` with the l2 cost (a change of mean velocity),
    ``"kernel"`` with ``KernelCPD`` and the RBF kernel (any change of the velocity
    distribution). A change between velocities ``t - 1`` and ``t`` is reported at step ``t``.
    Needs the optional ``ruptures`` package (``pip install ruptures``).

    Parameters
    ----------
    states : list of arrays of shape (T_i + 1, p)
    random_state : ignored (the indicator is deterministic)
    method : {"pelt", "binseg", "kernel"}
    penalty : float, optional
        Penalty per change point; default ``2 p log T`` for the l2 cost (BIC-like in units of
        the noise) and ``log T`` for the kernel cost (bounded by one per step).
    min_size : int
        Fewest steps between change points.

    Returns
    -------
    list of int arrays
        Per demonstration, the steps of its candidate transitions.
    """
    del random_state
    try:
        import ruptures as rpt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the ruptures indicator needs the ruptures package: pip install ruptures"
        ) from exc
    method = check_option("method", method, ("pelt", "binseg", "kernel"))
    velocities = [np.diff(x, axis=0) for x in states]
    scale = _noise_scale(velocities)
    out = []
    for x, v in zip(states, velocities, strict=True):
        signal = v / scale
        n, p = signal.shape
        if n < 2 * min_size:
            out.append(np.zeros(0, dtype=np.int64))
            continue
        if method == "kernel":
            pen = math.log(n) if penalty is None else penalty
            algo = rpt.KernelCPD(kernel="rbf", min_size=min_size)
        else:
            pen = 2 * p * math.log(n) if penalty is None else penalty
            cls = rpt.Pelt if method == "pelt" else rpt.Binseg
            algo = cls(model="l2", min_size=min_size, jump=1)
        bkps = algo.fit(signal).predict(pen=pen)[:-1]
        out.append(_interior(np.asarray(bkps, dtype=np.int64), len(x)))
    return out


def _phase_dp(cost: np.ndarray, lengths: np.ndarray, min_size: int) -> tuple[list, np.ndarray]:
    """Cut demonstrations into the phases ``0 .. K-1`` in order, each at its least total cost.

    ``cost[d, t, k]`` is the cost of transition ``t`` of demonstration ``d`` in phase ``k``
    (demonstration ``d`` holds ``lengths[d]`` transitions; the rest is padding); every phase
    holds at least ``min_size`` transitions (the caller checks ``lengths >= K * min_size``).
    Dynamic programming with running minima, all demonstrations at once: O(K T) each.
    """
    n_demos, n, n_phases = cost.shape
    prefix = np.zeros((n_demos, n + 1, n_phases))
    np.cumsum(cost, axis=1, out=prefix[:, 1:])
    # best[:, k, t]: transitions < t in phases 0 .. k; start: where phase k then starts
    best = np.full((n_demos, n_phases, n + 1), np.inf)
    start = np.zeros((n_demos, n_phases, n + 1), dtype=np.int64)
    best[:, 0, min_size:] = prefix[:, min_size:, 0]
    steps = np.arange(n + 1 - min_size)
    for k in range(1, n_phases):
        before = best[:, k - 1, : n + 1 - min_size] - prefix[:, : n + 1 - min_size, k]
        running = np.minimum.accumulate(before, axis=1)
        start[:, k, min_size:] = np.maximum.accumulate(
            np.where(before <= running, steps, 0), axis=1
        )
        best[:, k, min_size:] = running + prefix[:, min_size:, k]
    labels = []
    for d, end in enumerate(lengths):
        lab = np.empty(end, dtype=np.int64)
        for k in range(n_phases - 1, -1, -1):
            begin = int(start[d, k, end]) if k else 0
            lab[begin:end] = k
            end = begin
        labels.append(lab)
    return labels, best[np.arange(n_demos), -1, lengths]


class _PhaseData:
    """Steps ``s_{t+1} - s_t`` of demonstrations and their affine features ``[m_t, 1]``, at the
    midpoint ``m_t = (s_t + s_{t+1}) / 2`` (the centred estimate of a derivative), pooled."""

    def __init__(self, states: list[np.ndarray]) -> None:
        self.feats = np.concatenate(
            [np.column_stack([(x[:-1] + x[1:]) / 2, np.ones(len(x) - 1)]) for x in states]
        )
        self.steps = np.concatenate([np.diff(x, axis=0) for x in states])
        self.bounds = np.cumsum([0] + [len(x) - 1 for x in states])
        self.owner = np.repeat(np.arange(len(states)), np.diff(self.bounds))
        self._products: np.ndarray | None = None

    def split(self, values: np.ndarray) -> list[np.ndarray]:
        return [values[a:b] for a, b in zip(self.bounds[:-1], self.bounds[1:], strict=True)]

    def _sums(self, keys: np.ndarray, n_keys: int) -> tuple[np.ndarray, np.ndarray]:
        """Per key, ``z^T z`` and ``z^T y`` over the rows with that key: sums over the runs of
        equal keys (a phase is one run in each demonstration), then over the runs."""
        if self._products is None:  # z z^T and z y^T of every row, flattened side by side
            z, y = self.feats, self.steps
            self._products = np.concatenate(
                [
                    (z[:, :, None] * z[:, None, :]).reshape(len(z), -1),
                    (z[:, :, None] * y[:, None, :]).reshape(len(z), -1),
                ],
                axis=1,
            )
        runs = np.r_[0, np.flatnonzero(np.diff(keys)) + 1]
        sums = np.zeros((n_keys, self._products.shape[1]))
        np.add.at(sums, keys[runs], np.add.reduceat(self._products, runs, axis=0))
        p1, p = self.feats.shape[1], self.steps.shape[1]
        return sums[:, : p1 * p1].reshape(-1, p1, p1), sums[:, p1 * p1 :].reshape(-1, p1, p)

    def models(self, labels: np.ndarray, n_phases: int, penalty: np.ndarray) -> np.ndarray:
        """Ridge fit of one affine model per phase, shape (K, p + 1, p)."""
        gram, cross = self._sums(labels, n_phases)
        return np.linalg.solve(gram + penalty, cross)

    def assign(self, models: np.ndarray, min_size: int) -> tuple[np.ndarray, float]:
        """Each demonstration's best cut into the phases in order, and the total cost."""
        residual = np.matmul(self.feats, models) - self.steps
        cost = np.einsum("knp,knp->nk", residual, residual)
        lengths = np.diff(self.bounds)
        labels, total = [], 0.0
        # demonstrations padded to the longest of a batch, batches of about 2^18 transitions
        batch = max(1, (1 << 18) // (int(lengths.max()) * cost.shape[1]))
        for first in range(0, len(lengths), batch):
            sizes = lengths[first : first + batch]
            padded = np.zeros((len(sizes), int(sizes.max()), cost.shape[1]))
            for d, part in enumerate(self.split(cost)[first : first + batch]):
                padded[d, : len(part)] = part
            lab, costs = _phase_dp(padded, sizes, min_size)
            labels += lab
            total += float(costs.sum())
        return np.concatenate(labels), total

    def refine(
        self,
        labels: np.ndarray,
        n_phases: int,
        min_size: int,
        penalty: np.ndarray,
        max_iter: int = 10,
    ) -> tuple[np.ndarray, float]:
        """Alternate fitting the models and cutting the demonstrations (hard EM)."""
        total = math.inf
        for _ in range(max_iter):
            new, total = self.assign(self.models(labels, n_phases, penalty), min_size)
            if np.array_equal(new, labels):
                break
            labels = new
        return labels, total

    def uniform(self, n_phases: int) -> np.ndarray:
        """Every demonstration cut into ``n_phases`` equal parts."""
        return np.concatenate([np.arange(n) * n_phases // n for n in np.diff(self.bounds)]).astype(
            np.int64
        )

    def split_one(
        self, labels: np.ndarray, n_phases: int, min_size: int, penalty: np.ndarray
    ) -> np.ndarray:
        """``n_phases + 1`` phases from ``n_phases``: each phase in turn halved in every
        demonstration (then one refit and cut); the split that explains the steps best."""
        best: tuple[np.ndarray, float] | None = None
        for j in range(n_phases):
            out = []
            for lab in self.split(labels):
                lab = np.where(lab > j, lab + 1, lab)
                rows = np.flatnonzero(lab == j)
                if len(rows) >= 2:
                    lab[rows[len(rows) // 2] : rows[-1] + 1] = j + 1
                out.append(lab)
            fit = self.refine(np.concatenate(out), n_phases + 1, min_size, penalty, max_iter=1)
            if best is None or fit[1] < best[1]:
                best = fit
        assert best is not None
        return best[0]

    def cv_error(self, labels: np.ndarray, n_phases: int, penalty: np.ndarray) -> float:
        """Mean squared error of each demo's steps under models fitted on the other demos."""
        n_demos = len(self.bounds) - 1
        gram, cross = self._sums(self.owner * n_phases + labels, n_demos * n_phases)
        gram = gram.reshape(n_demos, n_phases, *gram.shape[1:])
        cross = cross.reshape(n_demos, n_phases, *cross.shape[1:])
        models = np.linalg.solve(gram.sum(0) - gram + penalty, cross.sum(0) - cross)
        z = self.feats[:, None, :]
        residual = np.matmul(z, models[self.owner, labels])[:, 0] - self.steps
        return float((residual**2).sum() / len(self.steps))


def phases_indicator(
    states: list[np.ndarray],
    random_state: Any = None,
    *,
    max_phases: int = 8,
    min_size: int = _DEFAULT_WINDOW,
    ridge: float = 1.0,
    tolerance: float = 0.03,
    ignore_nuisance_dims: bool = True,
    max_samples: int = 20_000,
) -> list[np.ndarray]:
    """Candidate transitions where the demonstrations pass from one shared phase to the next.

    The model is the one SWIRL assumes (§5): every demonstration goes through the same phases
    in the same order, each phase with its own locally linear dynamics. For ``K = 1, 2, ...``
    phases, one affine model per phase, ``s_{t+1} - s_t = W_k [m_t, 1]`` at the midpoint
    ``m_t = (s_t + s_{t+1}) / 2`` (ridge on the standardised states), is fitted to all
    demonstrations together, alternating with cutting each demonstration into the ``K``
    phases in order by dynamic programming (hard EM, from equal parts and from the ``K - 1``
    fit with one of its phases halved, the split that fits best; the better start is kept).
    ``K`` is the fewest phases whose leave-one-demonstration-out error (each demo's steps
    predicted by the models of the others) is within ``tolerance`` of the lowest: a phase that
    only soaks up the few steps around a switch lowers the error by less. A change between
    transitions ``t - 1`` and ``t`` is reported at step ``t``. Unlike the windowed indicators
    it pools every demonstration, so it finds a change too slight to see in one noisy demo.

    Parameters
    ----------
    states : list of arrays of shape (T_i + 1, p)
        At least two demonstrations (the number of phases is chosen by leaving one out).
    random_state : int, RandomState or None
        Chooses the demonstrations the models are fitted on when they hold more than
        ``max_samples`` steps (all demonstrations are cut).
    max_phases : int
        Most phases tried (fewer when a demo has under ``K * min_size`` steps).
    min_size : int
        Fewest steps of a phase in every demonstration.
    ridge : float
        Ridge penalty on the linear part (standardised units).
    tolerance : float
        Relative slack on the lowest error when choosing the number of phases.
    ignore_nuisance_dims : bool
        Leave out the dimensions that move on their own in each demonstration (as
        ``TransitionStateClustering(ignore_nuisance_dims=True)`` does; see
        ``_shared_course_dims``).
    max_samples : int
        The models are fitted on whole demonstrations drawn at random until they hold more
        than this many steps (at least two demonstrations; all when they hold fewer).

    Returns
    -------
    list of int arrays
        Candidate transition steps per demonstration (``K - 1`` each; none when ``K = 1``).

    Examples
    --------
    >>> from sb3_swirl.datasets import make_switching_demos
    >>> demos, switches = make_switching_demos("goal_reaching", random_state=0)
    >>> phases_indicator([d.observations for d in demos])[0].tolist(), switches[0].tolist()
    ([33, 45, 63, 91, 107], [46, 91])

    Extra candidates (a short phase where a demonstrator slows down before a switch, at its
    own speed) are left to the clustering, which keeps the transitions every demonstration
    shares:

    >>> tsc = TransitionStateClustering(indicator="phases", random_state=0).fit(demos)
    >>> tsc.switches_[0].tolist()
    [46, 89]
    """
    max_phases, min_size, max_samples = (
        check_int(name, value, low=1)
        for name, value in (
            ("max_phases", max_phases),
            ("min_size", min_size),
            ("max_samples", max_samples),
        )
    )
    ridge = check_real("ridge", ridge, low=0.0, low_open=True)
    tolerance = check_real("tolerance", tolerance, low=0.0)
    rs = check_random_state(random_state)
    # two or more finite (T_i + 1, p) arrays, or an error naming the demonstration
    states = [d.observations for d in as_demonstrations(states)]
    if ignore_nuisance_dims:
        shared = _shared_course_dims(states)
        if shared is not None:
            states = [x[:, shared] for x in states]
    pooled = np.concatenate(states)
    mean, scale = pooled.mean(axis=0), _scale(pooled)
    standard = [(x - mean) / scale for x in states]
    order = rs.permutation(len(standard))
    sizes = np.cumsum([len(standard[i]) - 1 for i in order])
    subset = np.sort(order[: max(2, int(np.searchsorted(sizes, max_samples)) + 1)])
    fit_on = _PhaseData([standard[i] for i in subset])
    p = pooled.shape[1]
    penalty = ridge * np.diag(np.r_[np.ones(p), 1e-6])  # the bias barely penalised
    shortest = min(len(x) - 1 for x in standard)
    fits: dict[int, tuple[float, np.ndarray]] = {}
    labels = None
    for n_phases in range(1, min(max_phases, shortest // min_size) + 1):
        starts = [fit_on.uniform(n_phases)]
        if labels is not None:
            starts.append(fit_on.split_one(labels, n_phases - 1, min_size, penalty))
        labels = min(
            (fit_on.refine(s, n_phases, min_size, penalty) for s in starts), key=lambda f: f[1]
        )[0]
        fits[n_phases] = (fit_on.cv_error(labels, n_phases, penalty), labels)
        if len(fits) - min(fits, key=lambda k: fits[k][0]) >= 2:  # two without improving
            break
    if not fits:
        return [np.zeros(0, dtype=np.int64) for _ in states]
    lowest = min(error for error, _ in fits.values())
    n_phases = min(k for k, (error, _) in fits.items() if error <= lowest * (1 + tolerance))
    data = _PhaseData(standard)
    models = fit_on.models(fits[n_phases][1], n_phases, penalty)
    labels = data.assign(models, min_size)[0]
    return [
        _interior(np.flatnonzero(np.diff(lab)) + 1, len(x))
        for lab, x in zip(data.split(labels), states, strict=True)
    ]


_INDICATORS = ("gmm", "velocity", "linear", "phases", "ruptures")
# the paper's Fig. 6, then ours; in order of preference (ties go to the first)
_AUTO_CANDIDATES = ("gmm", "velocity", "linear", "phases")
_BUILTIN = (
    gmm_indicator,
    velocity_indicator,
    linear_indicator,
    phases_indicator,
    ruptures_indicator,
)


# ---------------------------------------------------------------------------- regions
def segment_boundaries(states: np.ndarray, regions: Sequence[Region]) -> np.ndarray:
    """Run the Markov segmentation function along one trajectory in task space.

    The trajectory is segmented by :meth:`swirl_wrappers.TaskModel.reach_steps`, where the
    wrappers advance the index online, so the fit sees the segments an agent will be given.

    Parameters
    ----------
    states : array of shape (T + 1, p)
        Task-space states (after ``dims`` selection and the feature map), at steps ``0 .. T``
        (read by regions with time bounds).
    regions : sequence of Region

    Returns
    -------
    int array of shape (k,)
        ``out[i]`` is the step at which region ``i`` is reached, checking region ``i`` only
        after region ``i - 1`` was reached at an earlier step; ``-1`` if never reached.
    """
    states = np.asarray(states, dtype=np.float64)
    if states.ndim != 2:
        raise ValueError(f"states must have shape (T+1, p), got {states.shape}")
    return _regions_task(regions).reach_steps([states])[0]


def _regions_task(regions: Sequence[Region]) -> TaskModel:
    """A task of the regions alone (its rewards are never read), to segment with."""
    p = regions[0].mean.size
    return TaskModel(regions, [QuadraticReward(r.mean, np.zeros((p, p))) for r in regions])


def _separation_scale(a: Region, b: Region) -> float:
    """Largest factor ``s <= 1`` such that a hyperplane separates the two scaled ellipsoids.

    The ellipsoid ``{x : (x - m)^T P (x - m) <= r^2}`` has support function
    ``h(u) = m.u + r ||Sigma^{1/2} u||``; two ellipsoids are disjoint if some normal ``u`` gives
    ``(m_b - m_a).u > r_a ||Sigma_a^{1/2} u|| + r_b ||Sigma_b^{1/2} u||``. Four normals are
    tried: the line between the centres, each region's Mahalanobis gradient at the other's
    centre and the pooled (Fisher) direction. Any one that separates proves disjointness, so
    the returned factor is a sufficient (conservative) condition.
    """
    delta = b.mean - a.mean
    normals = [
        delta,
        a.precision @ delta,
        b.precision @ delta,
        np.linalg.solve(a.covariance + b.covariance, delta),
    ]
    best = 0.0
    ra, rb = math.sqrt(a.threshold), math.sqrt(b.threshold)
    for u in normals:
        gap = float(delta @ u)
        spread = ra * math.sqrt(max(u @ a.covariance @ u, 0.0)) + rb * math.sqrt(
            max(u @ b.covariance @ u, 0.0)
        )
        if gap > 0:
            best = max(best, gap / spread if spread > 0 else math.inf)
    return min(1.0, best)


def _make_disjoint(regions: list[Region], margin: float = 0.99) -> list[Region]:
    """Shrink radii (thresholds) so that every pair of regions is separated by a hyperplane.

    For each pair the largest common radius factor that separates them is computed
    (:func:`_separation_scale`); each region is then scaled by ``margin`` times the smallest
    factor over its pairs. Shrinking a region only helps every other pair, so the result is
    pairwise disjoint. Regions whose time windows do not intersect are disjoint already.
    """
    factors = np.ones(len(regions))
    for i in range(len(regions)):
        for j in range(i + 1, len(regions)):
            if _apart_in_time(regions[i], regions[j]):
                continue
            s = _separation_scale(regions[i], regions[j])
            if s < 1.0:
                factors[i] = min(factors[i], margin * s)
                factors[j] = min(factors[j], margin * s)
    return [
        r
        if f >= 1.0
        else Region(r.mean, r.covariance, r.threshold * f**2, time_bounds=r.time_bounds)
        for r, f in zip(regions, factors, strict=True)
    ]


def _n_complete(segments: Sequence[np.ndarray]) -> int:
    """Demonstrations that reach every region in order, the first after their start."""
    return sum(bool(b[0] != 0 and (b >= 0).all()) for b in segments)


def _apart_in_time(a: Region, b: Region) -> bool:
    """Whether the regions' time windows do not intersect (then they are disjoint anyway)."""
    if a.time_bounds is None or b.time_bounds is None:
        return False
    return a.time_bounds[1] < b.time_bounds[0] or b.time_bounds[1] < a.time_bounds[0]


def _overlaps(a: Region, b: Region) -> bool:
    """Whether either centre lies inside the other region (the two mark the same place)."""
    if _apart_in_time(a, b):
        return False
    return bool(a.contains(b.mean) or b.contains(a.mean))


def _merge_fragments(
    fragments: list[tuple[np.ndarray, np.ndarray]],
    owner: np.ndarray,
    times: np.ndarray,
    window: int,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Merge state clusters that share no demonstration and overlap in time.

    One transition that every demonstration makes once, with states spread along dimensions
    the phases do not depend on (nuisance dimensions), is cut by the state DP-GMM into
    fragments, each holding the transitions of some of the demonstrations, none of them
    enough to survive pruning. Two fragments are one transition when no demonstration has a
    transition in both and their (time-normalised) transition times overlap, each range
    widened by ``window`` steps. The closest such pair by median time is merged, until none
    is left.

    Parameters
    ----------
    fragments : list of (members, score)
        Indices into the pooled candidate transitions, and each member's responsibility.
    owner, times : arrays over the pooled candidate transitions
        The demonstration of each and its normalised time.
    window : int
        Slack on each time range, in steps.
    """
    groups = list(fragments)
    while True:
        best = None
        for i, (a, _) in enumerate(groups):
            for j in range(i + 1, len(groups)):
                b = groups[j][0]
                if np.intersect1d(owner[a], owner[b]).size:
                    continue
                low = max(times[a].min(), times[b].min()) - window
                high = min(times[a].max(), times[b].max()) + window
                gap = abs(float(np.median(times[a]) - np.median(times[b])))
                if low <= high and (best is None or gap < best[0]):
                    best = (gap, i, j)
        if best is None:
            return groups
        _, i, j = best
        merged = tuple(np.concatenate(parts) for parts in zip(groups[i], groups[j], strict=True))
        groups = [g for k, g in enumerate(groups) if k not in (i, j)] + [merged]


def _check_switches(name: str, switches: Sequence[Any], lengths: Sequence[int]) -> list[np.ndarray]:
    """``switches`` as int arrays, one per demonstration, each step in ``0 .. lengths[i]``."""
    if len(switches) != len(lengths):
        raise ValueError(f"{name} has {len(switches)} entries for {len(lengths)} demos")
    out = []
    for i, (sw, n) in enumerate(zip(switches, lengths, strict=True)):
        a = np.asarray(sw)
        if a.size == 0:
            out.append(np.zeros(0, dtype=np.int64))
            continue
        whole = a.dtype.kind in "iu" or (a.dtype.kind == "f" and np.all(np.mod(a, 1) == 0))
        if a.ndim != 1 or not whole or a.min() < 0 or a.max() > n:
            raise ValueError(
                f"{name}[{i}] must be a 1-D array of whole steps in 0..{n} (the demo's "
                f"length), got {np.array2string(a, threshold=8)}"
            )
        out.append(a.astype(np.int64))
    return out


def dynamics_cv_error(
    states: Sequence[np.ndarray],
    switches: Sequence[np.ndarray],
    time_scale: Sequence[float] | None = None,
    *,
    ridge: float = 10.0,
) -> float:
    """How well a segmentation explains the demonstrations as locally linear dynamics.

    Each segment gets an affine model of the motion, ``s_{t+1} - s_t = W_k [s_t, 1]`` (the
    locally linear dynamics the paper's §5 assumes), fitted by ridge regression on the steps of
    that segment in every *other* demonstration; the error is the mean squared prediction error
    of each demonstration's steps (leave one demonstration out). States are divided by their
    spread over all demonstrations (a dimension whose mean lies over 1000 spreads from 0 is
    centred first), and each demonstration's steps by its ``time_scale``.
    A segmentation that misses a change of dynamics, or cuts in the wrong place, predicts
    worse; one that cuts too often has less data per segment to predict from.
    ``TransitionStateClustering(indicator="auto")`` chooses its indicator by it.

    Parameters
    ----------
    states : sequence of arrays of shape (T_i + 1, p)
    switches : sequence of int arrays
        Per demonstration, the steps at which it enters a new segment (e.g.
        ``TransitionStateClustering.switches_``).
    time_scale : sequence of float, optional
        Per demonstration, old steps per step of a common rate (e.g. ``time_scale_``); ones
        by default.
    ridge : float
        Ridge penalty on the standardised features (> 0).

    Returns
    -------
    float
        The mean squared error per step (lower is better).
    """
    ridge = check_real("ridge", ridge, low=0.0, low_open=True)
    if len(states) == 0:
        raise ValueError("dynamics_cv_error needs the states of at least one demonstration")
    states = [np.asarray(x, dtype=np.float64) for x in states]
    for i, x in enumerate(states):
        if x.ndim != 2 or len(x) < 2 or x.shape[1] != states[0].shape[1]:
            raise ValueError(
                f"states[{i}] must be an array of shape (T + 1, {states[0].shape[-1]}) with "
                f"T >= 1, like states[0]; got shape {x.shape}"
            )
        if not np.isfinite(x).all():
            raise ValueError(f"states[{i}] holds NaN or infinite values")
    switches = _check_switches("switches", switches, [len(x) for x in states])
    if time_scale is None:
        time_scale = np.ones(len(states))
    elif len(time_scale) != len(states):
        raise ValueError(f"time_scale has {len(time_scale)} values for {len(states)} demos")
    for i, r in enumerate(time_scale):
        check_real(f"time_scale[{i}]", r, low=0.0, low_open=True)
    pooled = np.concatenate(states)
    scale = _scale(pooled)
    # a dimension far from its origin (a timestamp, a UTM coordinate) is centred, or its sums
    # of squares would cancel in the leave-one-out Gram matrices
    mean = pooled.mean(axis=0)
    offset = np.where(np.abs(mean) > 1e3 * scale, mean, 0.0)
    blocks = []  # per demo: features, targets, segment labels
    gram: dict[int, np.ndarray] = {}
    cross: dict[int, np.ndarray] = {}
    for x, sw, r in zip(states, switches, time_scale, strict=True):
        z = (np.asarray(x, dtype=np.float64) - offset) / scale
        targets = np.diff(z, axis=0) / r
        feats = np.column_stack([z[:-1], np.ones(len(targets))])
        labels = np.searchsorted(np.sort(sw), np.arange(len(targets)), side="right")
        mine = {}
        for k in np.unique(labels).tolist():
            f, t = feats[labels == k], targets[labels == k]
            mine[k] = (f.T @ f, f.T @ t)
            gram[k] = gram.get(k, 0.0) + mine[k][0]
            cross[k] = cross.get(k, 0.0) + mine[k][1]
        blocks.append((feats, targets, labels, mine))
    penalty = ridge * np.eye(states[0].shape[1] + 1)
    sse = 0.0
    for feats, targets, labels, mine in blocks:
        for k, (g, c) in mine.items():
            w = np.linalg.solve(gram[k] - g + penalty, cross[k] - c)
            rows = labels == k
            sse += float(np.sum((feats[rows] @ w - targets[rows]) ** 2))
    return sse / sum(len(t) for _, t, _, _ in blocks)


def switch_scores(
    found: Sequence[np.ndarray],
    true: Sequence[np.ndarray],
    lengths: Sequence[int],
    *,
    tolerance: float = 0.03,
    min_tolerance: int = 3,
) -> dict[str, float]:
    """Precision, recall and F1 of found switch points against known ones.

    In demonstration ``i`` a found switch is a hit when a true switch lies within
    ``max(min_tolerance, ceil(tolerance * lengths[i]))`` steps; each true switch is matched at
    most once (closest pairs first). Hits are pooled over the demonstrations.

    Parameters
    ----------
    found, true : sequences of int arrays, one per demonstration
        E.g. ``TransitionStateClustering.switches_`` and annotated phase changes.
    lengths : sequence of int
        Steps per demonstration.
    tolerance : float
        Fraction of a demonstration's length.
    min_tolerance : int
        Steps, at least.

    Returns
    -------
    dict
        ``precision``, ``recall``, ``f1``, ``hits``, ``found``, ``true``.

    Examples
    --------
    >>> switch_scores([np.array([10, 52])], [np.array([11, 30])], [100])["f1"]
    0.5
    """
    tolerance = check_real("tolerance", tolerance, low=0.0)
    min_tolerance = check_int("min_tolerance", min_tolerance, low=0)
    lengths = [check_int(f"lengths[{i}]", n, low=1) for i, n in enumerate(lengths)]
    found = _check_switches("found", found, lengths)
    true = _check_switches("true", true, lengths)
    hits = n_found = n_true = 0
    for f, t, n in zip(found, true, lengths, strict=True):
        tol = max(min_tolerance, math.ceil(tolerance * n))
        pairs = sorted(
            (abs(int(a) - int(b)), i, j)
            for i, a in enumerate(f)
            for j, b in enumerate(t)
            if abs(int(a) - int(b)) <= tol
        )
        used_f: set[int] = set()
        used_t: set[int] = set()
        for _, i, j in pairs:
            if i not in used_f and j not in used_t:
                used_f.add(i)
                used_t.add(j)
        hits += len(used_f)
        n_found += len(f)
        n_true += len(t)
    precision = hits / n_found if n_found else float(n_true == 0)
    recall = hits / n_true if n_true else 1.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {
        "precision": precision,
        "recall": recall,
        "f1": f1,
        "hits": hits,
        "found": n_found,
        "true": n_true,
    }


class SegmentationWarning(UserWarning):
    """The segmentation kept no transition region, or dropped regions most demos share."""


class StrictParamsMixin:
    """scikit-learn's parameter validation (``_parameter_constraints``), refusing a bool where
    a number is expected: scikit-learn takes ``True`` for 1."""

    _parameter_constraints: ClassVar[dict[str, list[Any]]]

    def _validate_params(self) -> None:
        super()._validate_params()  # type: ignore[misc]
        for name, constraints in self._parameter_constraints.items():
            value = getattr(self, name)
            if isinstance(value, bool | np.bool_) and "boolean" not in constraints:
                raise InvalidParameterError(
                    f"The {name!r} parameter of {type(self).__name__} must be a number, not a "
                    f"bool. Got {value!r} instead."
                )


# Finite and with a finite square and inverse square: a bandwidth of the RBF kernel.
_SIGMA_RANGE = Interval(Real, 1e-100, 1e100, closed="both")
_POSITIVE = Interval(Real, 0, np.inf, closed="neither")
_COUNT = Interval(Integral, 1, None, closed="left")


class TransitionStateClustering(StrictParamsMixin, BaseEstimator):
    """Learn the ordered transition regions of a task from demonstrations (§5, Algorithm 1).

    1. Optionally map states through an approximate RBF kernel PCA (§5.3; Nyström on
       ``n_landmarks`` seeded landmarks, then PCA to ``n_kernel_components`` dimensions); the
       map is kept as a :class:`swirl_wrappers.RBFFeatures` (``feature_map_``) so the runtime
       evaluates it with numpy alone, and regions live in that feature space.
    2. A transition indicator marks candidate transitions in every demonstration
       (``transitions_``).
    3. A Dirichlet-process GMM (``BayesianGaussianMixture``, concentration ``concentration``,
       on standardised features) clusters the candidate transition states, then a second one
       clusters each state cluster by time; the time split is kept only when every part
       holds enough demonstrations (a place visited more than once), since otherwise
       demonstrators' differing speeds would fragment one transition.
    4. Clusters holding transitions from fewer than ``ceil(min_demo_fraction * n_demos)``
       demonstrations are pruned, after (``merge_fragments``) merging those that share no
       demonstration and overlap in time: one transition spread along dimensions the phases
       do not depend on is cut into such fragments. If some are still too small and
       (``ignore_nuisance_dims``) some dimensions move on their own in each demonstration,
       steps 3 to 6 run again with the state clustering on the other dimensions only, and
       that fit is kept if it keeps more regions (``cluster_dims_``). From each
       survivor one representative transition per demonstration is kept (the most probable
       member), which discards stray indicator noise merged into the cluster.
    5. Each survivor becomes a :class:`swirl_wrappers.Region`: the mean and regularised
       covariance of its representative states and the chi-square quantile of ``confidence``
       (raised where needed so that the region holds every state it was built from).
       With ``include_goal`` a final *goal* region is added from the demonstrations' final
       states: the last state is never a transition, yet the last segment needs a target.
       Regions are ordered by median transition time (the goal last). A transition region
       whose centre lies inside the goal region, or inside an earlier region, marks the same
       place and is dropped (without time windows the later one could never be told apart).
       Finally thresholds are shrunk until every pair of regions is separated by a hyperplane
       (a sufficient condition for disjoint ellipsoids; see ``_make_disjoint``).
    6. Step 4 again, for the Markov segmentation function: transition regions are removed
       greedily until ``ceil(min_demo_fraction * n_demos)`` demonstrations reach every region
       in order, the first one after their start state (a demonstration may pass through a
       region before the previous one, e.g. a place on a growing oscillation, or start inside
       it). With ``merge_same_dynamics``, transition regions the locally linear dynamics do
       not need are then dropped too. ``segments_`` runs the resulting segmentation along
       every demonstration.

    States holding wrapped angles need continuous features first (a region straddling
    ``±pi`` is meaningless): :func:`sb3_swirl.fitting.fit_task` maps them to ``(cos, sin)`` with
    its ``angles`` argument.

    Parameters
    ----------
    indicator : {"auto", "gmm", "velocity", "linear", "phases", "ruptures"}, several joined \
by "+", or callable, default "auto"
        Transition indicator (the README's "Choosing a transition indicator" compares them).
        ``"auto"`` fits with each of the paper's three indicators (``"gmm"``, §5.3, the
        paper's default; ``"velocity"``; ``"linear"``) and with ``"phases"``
        (:func:`phases_indicator`: phases with their own linear dynamics, shared by every
        demonstration) and keeps the segmentation that best explains the demonstrations as
        locally linear dynamics (the lowest :func:`dynamics_cv_error`); only the kept fit's
        warnings are shown, ``indicator_`` says which it kept and ``indicator_scores_`` gives
        every score. It is the default because it found switch points best on
        ``benchmarks/bench_segmentation.py`` (README); every shipped task's entry fits with
        ``"gmm"`` instead (or ``"velocity"``), the segmentations their agents were tuned on.
        ``"ruptures"`` needs the ``ruptures`` package; ``"gmm+velocity"`` takes the union of
        both indicators' candidates. A callable ``f(states, random_state) -> list of int
        arrays`` gets the list of task-space state arrays (T_i + 1, p) and an int seed and
        returns candidate transition steps per demonstration (use ``functools.partial`` of
        :func:`gmm_indicator`, :func:`velocity_indicator`, :func:`linear_indicator`,
        :func:`phases_indicator` or :func:`ruptures_indicator` to change their settings).
    window : int, optional
        Window length of the indicators (``--window`` in the CLI). By default 3 for ``"gmm"``
        and ``"velocity"``; ``"linear"`` then uses its own default, ``max(2 (p + 1), 8)``
        transitions per side (it fits ``p + 1`` coefficients on each); ``"phases"`` and
        ``"ruptures"`` take it as the fewest steps of a phase (``min_size``). Every
        demonstration needs ``window + 2`` states (at least 5 by default).
    n_indicator_components : int, default 5
        GMM components of the ``"gmm"`` indicator.
    max_indicator_samples : int, default 20000
        Windows (drawn at random) used to fit the indicator GMM; all windows are labelled.
        For ``"phases"``, the steps its models are fitted on (``max_samples``).
    kernel : {None, "rbf"}, default None
        Featurise states with an approximate RBF kernel PCA before windowing.
    kernel_sigma : float, default 0.1
        RBF bandwidth, ``gamma = 1 / (2 sigma^2)`` (the paper uses 0.1 for the acrobot,
        Appendix B.3). Choose it on the scale of the states: with a bandwidth much smaller
        than the distance between states, most states map to nearly the same features.
    n_kernel_components : int, default 5
        Dimension ``p'`` of the kernel PCA features.
    n_landmarks : int, default 200
        Nyström landmarks (a seeded sample of the demonstration states).
    n_regions_max : int, default 10
        Truncation level of the Dirichlet process (upper bound on the number of clusters).
    concentration : float, default 0.1
        Dirichlet-process concentration (the paper's "prior weight of 0.1").
    min_demo_fraction : float, default 1.0
        A cluster survives when it holds transitions from at least
        ``ceil(min_demo_fraction * n_demos)`` demonstrations (1.0: all, as in Algorithm 1).
    merge_fragments : bool, default True
        Before pruning, merge state clusters that hold no demonstration in common and whose
        transition times overlap (within ``window`` steps, time-normalised): the DP-GMM cuts
        one transition whose states spread along nuisance dimensions (motion unrelated to
        the phases) into such fragments, each too small to survive. ``False`` prunes them as
        Algorithm 1 does. Chosen by ``benchmarks/bench_segmentation.py`` (README).
    ignore_nuisance_dims : bool, default True
        When clustering leaves transitions too few demonstrations share (step 4), cluster
        the transition states again without the dimensions that move on their own in each
        demonstration: those along which the mean of the demonstrations, each resampled to a
        common length, explains under 30 % of the variance (while another dimension's
        explains 80 % or more) and the demonstrations agree nowhere (their spread stays
        above 10 % of the variance at 90 % of the steps). Such dimensions scatter one
        transition's states, and the clustering cuts it into fragments. Where no dimension
        follows a shared course (e.g. oscillations whose timing differs between
        demonstrations) nothing is ignored. Regions still span every dimension.
        That second fit is kept only if it ends with more regions. ``indicator="auto"`` also
        scores its candidates without those dimensions, and ``"phases"`` leaves them out of
        its models. Chosen by
        ``benchmarks/bench_segmentation.py`` (README).
    merge_same_dynamics : bool, default False
        After pruning, drop each transition region (greedily, the best first) without which
        the demonstrations are explained as locally linear dynamics at least as well
        (:func:`dynamics_cv_error` not higher, on the dimensions the demonstrations share:
        see ``ignore_nuisance_dims``). A state-clustering indicator also cuts where the motion
        slows down within one phase, as it does on approaching a sub-goal; the dynamics
        there are the same on both sides. On the synthetic benchmark it raised the
        defaults' held-out mean switch F1 from 0.81 to 0.85 and lowered none of the 28
        generators' medians, but it changes the fits of our own tasks (the acrobot's
        swing-up phases, parking's, Fetch pick-and-place's down to one segment), where the
        agents were not measured with it, so it is off by default (README, "Choosing a
        transition indicator"). Dropped regions are recorded in ``dropped_regions_``.
    align_entries : bool, default True
        Build each transition region from the demonstrations' states up to ``window`` steps
        (at the common rate) after their transitions, at the offset where entering the region
        online best matches them (``_align_entries``). A demonstration that slows down into a
        transition under noise is inside the region of its transition states several steps
        early, and the segmentation an agent gets then switches early; just after the
        transition it moves on quickly. ``False`` builds the regions from the transition states
        themselves, as Algorithm 1 does (every shipped task's fit does: its agent was tuned
        so). Chosen by ``benchmarks/bench_segmentation.py`` (README).
    confidence : float, default 0.95
        Chi-square confidence level of the region ellipsoids (before shrinking for
        disjointness).
    covariance_type : {"diag", "tied", "spherical", "full"}, default "diag"
        Covariance of the DP-GMM components; with few transition points per cluster full
        covariances over-split.
    reg_covar : float, default 1e-4
        Added to each region covariance, relative to the variance of all demonstration states
        along each axis; keeps regions built from few or identical points well posed. It sets
        how early a demonstration that slows down towards a transition enters its region:
        the default is the one ``benchmarks/bench_segmentation.py`` chose (a larger floor
        makes regions of slow approaches too wide). With very few demos a region
        rests on one point per demo, which can agree along an axis far more than new episodes
        will: for reinforcement learning raise it (e.g. to 0.1) so that new start states
        still enter the regions (the parking, dVRK tensioning, Fetch push and pick-and-place
        entries of ``zoo_configs/swirl_dqn.yml`` train with 0.1: agents did better with it
        there).
    use_time : bool, default False
        Give each region a time window (the range of its transition times, widened on each
        side by that range or ``window`` steps, whichever is larger). Off by default: an RL
        agent early in training is much slower than the demonstrator and would miss regions
        that expire.
    normalize_time : bool, default True
        Resample every demonstration (linear interpolation) so that its typical step, the
        median of ``||s_{t+1} - s_t||`` over its steps in motion (each dimension divided by its
        spread over all states; a long rest at its start or end left out, see
        ``sb3_swirl.demos._typical_step``), equals the median over all demonstrations,
        before a built-in indicator runs and transitions are clustered in time (a callable
        indicator gets the demonstrations as given). Demonstrations recorded at other sampling
        rates, or by slower demonstrators, then look alike to the windowed indicators.
        Candidate steps are mapped back to each demonstration's own steps; the regions, and
        the segmentation an agent gets, depend on states only.
    include_goal : bool, default True
        Add the goal region built from the demonstrations' final states.
    random_state : int, RandomState or None
        Seeds every random choice (landmarks, PCA, indicator GMM, DP-GMM).

    Warns
    -----
    SegmentationWarning
        When no transition region survived (one segment to the goal: the message says
        whether the indicator found no candidates or which step dropped them), or when
        candidate regions that all but a few demos share were dropped; the message names the
        demos, the reason and the threshold.

    Attributes
    ----------
    regions_ : list of Region
        The ordered regions (task space).
    transitions_ : list of int arrays
        Candidate transition steps per demonstration (the indicator's output).
    segments_ : list of int arrays of shape (n_regions,)
        Per demonstration, the step at which each region is reached under the Markov
        segmentation function (``-1`` when not reached).
    switches_ : list of int arrays
        Per demonstration, the steps at which it enters a new segment (entering the goal
        region is the end, not a switch): compare them with known phase changes using
        :func:`switch_scores`.
    region_transitions_ : list of list of (demo, step)
        The representative transitions of each transition region (empty for the goal
        region). With ``align_entries`` a region may be built from the states up to
        ``window`` steps after them.
    dropped_regions_ : list of dict
        The candidate regions the fit dropped, each with its median transition ``"time"``,
        ``"centre"``, the ``"reason"`` and the ``"demos"`` concerned (those without a
        transition there, or that do not reach it in order).
    indicator_ : str or callable
        The indicator used (with ``"auto"``, the one chosen).
    indicator_scores_ : dict of str to float
        :func:`dynamics_cv_error` of each indicator tried (``inf`` where its fit failed;
        ``"callable"`` for your own).
    indicator_segments_ : dict of str to int
        The number of segments each indicator tried gave (0 where its fit failed): with
        ``"auto"``, candidates whose scores lie close with other counts show how firmly the
        demonstrations decide between them.
    indicator_failures_ : dict of str to str
        Why each indicator ``"auto"`` tried and that failed gave no segmentation (empty
        otherwise).
    feature_map_ : RBFFeatures or None
        The kernel feature map when ``kernel="rbf"``.
    cluster_dims_ : int array or None
        The task-space dimensions the transition states were clustered on when
        ``ignore_nuisance_dims`` left some out; ``None`` when all were used.
    time_scale_ : array of shape (n_demos,)
        Each demonstration's resampling factor (its typical step over the median; all ones
        without ``normalize_time`` or with a callable indicator).
    n_demos_ : int
    state_dim_ : int
        Dimension of the states given to ``fit``.

    Examples
    --------
    >>> from sb3_swirl.demos import make_piecewise_linear_demos
    >>> demos, switches = make_piecewise_linear_demos(n_demos=8, random_state=0)
    >>> tsc = TransitionStateClustering(random_state=0).fit(demos)
    >>> len(tsc.regions_)  # two corners and the goal
    3
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "indicator": [str, callable],
        "window": [_COUNT, None],
        "n_indicator_components": [_COUNT],
        "max_indicator_samples": [_COUNT],
        "kernel": [StrOptions({"rbf"}), None],
        "kernel_sigma": [_SIGMA_RANGE],
        "n_kernel_components": [_COUNT],
        "n_landmarks": [_COUNT],
        "n_regions_max": [_COUNT],
        "concentration": [_POSITIVE],
        "min_demo_fraction": [Interval(Real, 0, 1, closed="right")],
        "merge_fragments": ["boolean"],
        "ignore_nuisance_dims": ["boolean"],
        "merge_same_dynamics": ["boolean"],
        "align_entries": ["boolean"],
        "confidence": [Interval(Real, 0, 1, closed="neither")],
        "covariance_type": [StrOptions({"diag", "tied", "spherical", "full"})],
        "reg_covar": [_POSITIVE],
        "use_time": ["boolean"],
        "normalize_time": ["boolean"],
        "include_goal": ["boolean"],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        indicator: str | Indicator = "auto",
        window: int | None = None,
        n_indicator_components: int = 5,
        max_indicator_samples: int = 20_000,
        kernel: str | None = None,
        kernel_sigma: float = 0.1,
        n_kernel_components: int = 5,
        n_landmarks: int = 200,
        n_regions_max: int = 10,
        concentration: float = 0.1,
        min_demo_fraction: float = 1.0,
        merge_fragments: bool = True,
        ignore_nuisance_dims: bool = True,
        merge_same_dynamics: bool = False,
        align_entries: bool = True,
        confidence: float = 0.95,
        covariance_type: str = "diag",
        reg_covar: float = 1e-4,
        use_time: bool = False,
        normalize_time: bool = True,
        include_goal: bool = True,
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        self.indicator = indicator
        self.window = window
        self.n_indicator_components = n_indicator_components
        self.max_indicator_samples = max_indicator_samples
        self.kernel = kernel
        self.kernel_sigma = kernel_sigma
        self.n_kernel_components = n_kernel_components
        self.n_landmarks = n_landmarks
        self.n_regions_max = n_regions_max
        self.concentration = concentration
        self.min_demo_fraction = min_demo_fraction
        self.merge_fragments = merge_fragments
        self.ignore_nuisance_dims = ignore_nuisance_dims
        self.merge_same_dynamics = merge_same_dynamics
        self.align_entries = align_entries
        self.confidence = confidence
        self.covariance_type = covariance_type
        self.reg_covar = reg_covar
        self.use_time = use_time
        self.normalize_time = normalize_time
        self.include_goal = include_goal
        self.random_state = random_state

    # ------------------------------------------------------------------ fitting
    def fit(self, demos: Any, y: None = None) -> TransitionStateClustering:
        """Learn the regions from demonstrations.

        Parameters
        ----------
        demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts
            At least two demonstrations, each with at least ``window + 2`` states.
        y : ignored

        Returns
        -------
        self
        """
        self._validate_params()
        demos = as_demonstrations(demos, window=self._window)
        check_demos_agree(demos)
        # The work is many small (p x p) factorisations, where BLAS threads only add
        # synchronisation overhead.
        with threadpool_limits(limits=1, user_api="blas"):
            if self.indicator == "auto":
                self._fit_auto(demos)
            else:
                x = self._fit(demos)
                self.indicator_ = self.indicator
                name = self.indicator if isinstance(self.indicator, str) else "callable"
                self.indicator_scores_ = {name: self._dynamics_error(x)}
                self.indicator_segments_ = {name: len(self.regions_)}
                self.indicator_failures_ = {}
        self._warn_lost()
        self._warn_entries([len(d) for d in demos])
        return self

    def _fit_auto(self, demos: list) -> TransitionStateClustering:
        """Fit with each of ``_AUTO_CANDIDATES``; keep the lowest :func:`dynamics_cv_error`."""
        fits: dict[str, tuple[TransitionStateClustering, list]] = {}
        scores: dict[str, float] = {}
        segments: dict[str, int] = {}
        failures: dict[str, str] = {}
        # with a seed (an int, a RandomState) every candidate draws the same seeds (a clone
        # each), so the kernel feature map each would fit is this one: fitted and applied once
        # (with random_state=None the candidates now share one map where each drew its own)
        features = None
        if self.kernel == "rbf":
            rs = check_random_state(clone(self).random_state)
            seed = int(rs.randint(_SEED_MAX, size=3)[0])
            features = self._task_space([d.observations for d in demos], seed)
        for name in _AUTO_CANDIDATES:
            candidate = clone(self).set_params(indicator=name)
            with warnings.catch_warnings(record=True) as caught:
                try:
                    x = candidate._fit(demos, features)
                except ValueError as exc:
                    failures[name] = str(exc)
                    scores[name], segments[name] = math.inf, 0
                    continue
            scores[name] = candidate._dynamics_error(x)
            segments[name] = len(candidate.regions_)
            fits[name] = (candidate, caught)
        if not fits:
            reasons: dict[str, list[str]] = {}
            for name, why in failures.items():
                reasons.setdefault(why, []).append(name)
            raise ValueError(
                "indicator='auto': no indicator gave a segmentation; "
                + "; ".join(f"{', '.join(names)}: {why}" for why, names in reasons.items())
            )
        best = min(fits, key=scores.__getitem__)  # ties: the first in order of preference
        chosen, caught = fits[best]
        for key, value in vars(chosen).items():
            if key.endswith("_") and not key.startswith("_"):
                setattr(self, key, value)
        self.indicator_ = best
        self.indicator_scores_ = scores
        self.indicator_segments_ = segments
        self.indicator_failures_ = failures
        for w in caught:  # e.g. a GMM that did not converge: the chosen fit's only
            warnings.warn(w.message, w.category, stacklevel=3)
        return self

    def _dynamics_error(self, x: list[np.ndarray]) -> float:
        """:func:`dynamics_cv_error` of the fitted segmentation on its demonstrations, given in
        task space (``_fit``'s result)."""
        shared = _shared_course_dims(x) if self.ignore_nuisance_dims else None
        if shared is not None:  # motion no demo shares is no segmentation's to explain
            x = [s[:, shared] for s in x]
        return dynamics_cv_error(x, self.switches_, self.time_scale_)

    def _task_space(
        self, states: list[np.ndarray], seed: int
    ) -> tuple[RBFFeatures | None, list[np.ndarray]]:
        """The kernel feature map (``None`` without a kernel) and the states mapped by it."""
        if self.kernel != "rbf":
            return None, states
        feature_map = self._fit_feature_map(states, seed)
        return feature_map, [feature_map(s) for s in states]

    def _fit(
        self,
        demos: list,
        features: tuple[RBFFeatures | None, list[np.ndarray]] | None = None,
    ) -> list[np.ndarray]:
        """Fit with one indicator; return the demonstrations' states in task space.
        ``features``: the feature map and mapped states, when already made for these seeds."""
        if isinstance(self.indicator, str):
            unknown = [n for n in self.indicator.split("+") if n not in _INDICATORS]
            if unknown:
                raise InvalidParameterError(
                    f"The 'indicator' parameter of {type(self).__name__} must be 'auto', one of "
                    f"{list(_INDICATORS)}, several of them joined by '+' (e.g. "
                    f"'gmm+velocity'), or a callable. Got {self.indicator!r} instead."
                )
        rs = check_random_state(self.random_state)
        seeds = rs.randint(_SEED_MAX, size=3)
        states = [d.observations for d in demos]
        self.n_demos_ = len(states)
        self.state_dim_ = states[0].shape[1]
        self.feature_map_, x = features or self._task_space(states, int(seeds[0]))
        # a callable indicator is the user's own method: it gets the demos as they are
        normalize = self.normalize_time and (
            isinstance(self.indicator, str) or getattr(self.indicator, "func", None) in _BUILTIN
        )
        self.time_scale_ = _time_scales(x) if normalize else np.ones(len(x))
        resampled = [
            _resample(s, r, self._window + 2) for s, r in zip(x, self.time_scale_, strict=True)
        ]
        try:
            found = self._indicate([s for s, _ in resampled], int(seeds[1]))
        except ValueError as exc:
            if np.all(self.time_scale_ == 1.0):
                raise
            raise ValueError(
                f"{exc} (in the demos resampled to a common rate by normalize_time=True, "
                f"{[len(s) for s, _ in resampled]} states; as given "
                f"{[len(s) for s in x]}: pass normalize_time=False to run the indicator on "
                "the demos as given)"
            ) from exc
        self.transitions_ = [
            _interior(np.rint(idx * step).astype(np.int64), len(s))
            for idx, (_, step), s in zip(found, resampled, x, strict=True)
        ]

        pooled = np.concatenate(x)
        reg = self.reg_covar * np.diag(_scale(pooled) ** 2)
        threshold = float(chi2.ppf(self.confidence, df=pooled.shape[1]))
        self.cluster_dims_: np.ndarray | None = None
        regions, members, kept, fragmented = self._kept_regions(x, reg, threshold, int(seeds[2]))
        shared = _shared_course_dims(x) if self.ignore_nuisance_dims and fragmented else None
        if shared is not None:  # cluster again without the dims no demo shares
            dropped = self.dropped_regions_
            again = self._kept_regions(x, reg, threshold, int(seeds[2]), shared)
            better = len(again[2]) > len(kept)
            if len(again[2]) == len(kept) and kept:
                on_shared = [s[:, shared] for s in x]
                errors = [
                    dynamics_cv_error(
                        on_shared,
                        self._segmentation(x, _make_disjoint([r[i] for i in k]))[1],
                        self.time_scale_,
                    )
                    for r, k in ((regions, kept), (again[0], again[2]))
                ]
                better = errors[1] < errors[0]
            if better:
                regions, members, kept, _ = again
                self.cluster_dims_ = shared
            else:
                self.dropped_regions_ = dropped
        if not kept:
            raise ValueError(
                f"no transition region is shared by at least "
                f"{self._min_demos(len(states))} of the {len(states)} demonstrations; "
                "lower min_demo_fraction, change the indicator or window, or set "
                "include_goal=True"
            )
        self.regions_ = _make_disjoint([regions[i] for i in kept])
        self.region_transitions_ = [members[i] for i in kept]
        if self.merge_same_dynamics:
            self._merge_same_dynamics(x)
        if self.align_entries:
            self._align_entries(x, reg, threshold)
        self.segments_, self.switches_ = self._segmentation(x, self.regions_)
        self._check_complete(self.segments_, x)
        return x

    def _align_entries(self, x: list[np.ndarray], reg: np.ndarray, threshold: float) -> None:
        """Build each transition region where entering it online matches the transitions.

        The agent (and ``segments_``) enters a segment at the first state inside the next
        region, but a demonstration that creeps into a transition (slowing down towards it,
        under noise) is inside the region built from its transition states several steps
        before it: the online segmentation switches early. In turn for each transition region,
        the region as it is and the region rebuilt from the demonstrations' states ``1 ..
        window`` steps (at the common rate of ``normalize_time``) after their own transitions
        are tried, and the one kept is the one with which most demonstrations reach every
        region in order, then the one whose entries lie closest to those transitions (median;
        the earliest offset on a tie). So the number of demonstrations that reach every region
        never drops (which ones may change). A rebuilt region whose centre lies inside another
        region, or that holds the other's centre, is not tried: it would mark that place.
        """
        lengths = [len(s) for s in x]
        pooled = np.concatenate(x)
        steps = np.concatenate([np.arange(n) for n in lengths])
        cuts = np.cumsum(lengths)[:-1]

        def distances(region: Region) -> np.ndarray:
            d2 = region.mahalanobis2(pooled)
            if region.time_bounds is not None:
                lo, hi = region.time_bounds
                d2 = np.where((steps >= lo) & (steps <= hi), d2, np.inf)
            return d2

        def reached(candidate: list[Region], d2: list[np.ndarray]) -> list[np.ndarray]:
            """``_segmentation``'s segments, from the distances (searching only)."""
            inside = [
                np.split(d <= r.threshold, cuts)
                for r, d in zip(_make_disjoint(candidate), d2, strict=True)
            ]
            out = []
            for demo in range(len(x)):
                found = np.full(len(candidate), -1, dtype=np.int64)
                t = -1
                for i, mask in enumerate(inside):
                    later = np.flatnonzero(mask[demo][t + 1 :])
                    if not later.size:
                        break
                    t += 1 + int(later[0])
                    found[i] = t
                out.append(found)
            return out

        regions = list(self.regions_)
        d2 = [distances(r) for r in regions]
        for k in range(len(regions) - (1 if self.include_goal else 0)):
            members = self.region_transitions_[k]
            times = np.array([step for _, step in members], dtype=np.float64)
            best: tuple[tuple[int, float], Region, np.ndarray] | None = None
            for offset in range(self._window + 1):
                if offset:
                    points = np.array(
                        [
                            x[d][min(step + round(offset / self.time_scale_[d]), len(x[d]) - 2)]
                            for d, step in members
                        ]
                    )
                    region = self._region(points, reg, threshold, times)
                    if any(_overlaps(region, r) for j, r in enumerate(regions) if j != k):
                        continue  # shifted onto another region's states: it marks that one
                    mine = distances(region)
                else:  # as it is (shrunk to be disjoint from the others)
                    region, mine = regions[k], d2[k]
                segments = reached(
                    [*regions[:k], region, *regions[k + 1 :]], [*d2[:k], mine, *d2[k + 1 :]]
                )
                errors = [abs(segments[d][k] - step) for d, step in members if segments[d][k] > 0]
                key = (-_n_complete(segments), float(np.median(errors)) if errors else math.inf)
                if best is None or key < best[0]:
                    best = (key, region, mine)
            assert best is not None
            _, regions[k], d2[k] = best
        self.regions_ = _make_disjoint(regions)

    def _merge_same_dynamics(self, x: list[np.ndarray]) -> None:
        """Drop transition regions (greedily) whose removal does not raise the dynamics error."""
        shared = _shared_course_dims(x)
        on_shared = x if shared is None else [s[:, shared] for s in x]
        regions, members = list(self.regions_), list(self.region_transitions_)

        def error(kept: list[Region]) -> float:
            switches = self._segmentation(x, _make_disjoint(kept))[1]
            return dynamics_cv_error(on_shared, switches, self.time_scale_)

        current = error(regions)
        removable = len(regions) - (1 if self.include_goal else 0)
        while removable > 0 and len(regions) > 1:  # the last region is never merged away
            best, k = min((error(regions[:k] + regions[k + 1 :]), k) for k in range(removable))
            if best > current:
                break
            self._drop(
                np.array([step for _, step in members[k]], dtype=np.float64),
                regions[k].mean,
                "the segments on either side follow the same locally linear dynamics "
                f"(dynamics error {best:.4g} without it, {current:.4g} with it; "
                "merge_same_dynamics=True)",
            )
            del regions[k], members[k]
            current, removable = best, removable - 1
        if len(regions) < len(self.regions_):
            self.regions_, self.region_transitions_ = _make_disjoint(regions), members

    def _segmentation(
        self, x: list[np.ndarray], regions: list[Region]
    ) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Per demonstration, the step each region is reached at, and the switches."""
        task = _regions_task(regions)
        segments = task.reach_steps(x)
        ends = slice(None, -1) if self.include_goal else slice(None)
        return segments, [b[ends][b[ends] > 0] for b in segments]

    def _kept_regions(
        self,
        x: list[np.ndarray],
        reg: np.ndarray,
        threshold: float,
        seed: int,
        dims: np.ndarray | None = None,
    ) -> tuple[list[Region], list, list[int], bool]:
        """Steps 3-6 on the candidate transitions (the state clustering on ``dims`` if given).

        Returns the regions, their representative transitions, the indices of those kept and
        whether the clustering dropped fragments; fills ``dropped_regions_`` afresh.
        """
        self.dropped_regions_: list[dict[str, Any]] = []
        candidates, fragmented = self._cluster(x, seed, dims)
        regions = [self._region(points, reg, threshold, times) for times, points, _ in candidates]
        members = [reps for _, _, reps in candidates]
        times = [t for t, _, _ in candidates]
        if self.include_goal:
            ends = np.array([len(s) - 1 for s in x], dtype=np.float64)
            goal = self._region(np.array([s[-1] for s in x]), reg, threshold, ends)
            keep = []
            for i, region in enumerate(regions):
                if _overlaps(region, goal):
                    self._drop(times[i], region.mean, "marks the same place as the goal")
                else:
                    keep.append(i)
            regions = [regions[i] for i in keep] + [goal]
            members = [members[i] for i in keep] + [[]]
            times = [times[i] for i in keep] + [ends]
        kept: list[int] = []
        for i, region in enumerate(regions):
            if any(_overlaps(region, regions[j]) for j in kept):
                self._drop(times[i], region.mean, "marks the same place as an earlier region")
            else:
                kept.append(i)
        kept = self._prune_unreached(x, [regions[i] for i in kept], kept, times)
        return regions, members, kept, fragmented

    def _warn_entries(self, lengths: list[int]) -> None:
        """Warn when the segment index switches far from the demos' own transitions.

        A region built from transitions at different places (a corner each demo turns at
        another point) is entered at its edge: the online segmentation, and the agent's, then
        switches before or after the demos' transitions. A demo is far from its transition
        into a region when the gap exceeds both ``max(3, 3 %`` of its length``)`` steps (the
        segmentation benchmark's tolerance, :func:`switch_scores`, before rounding up) and
        ``_ENTRY_GAP`` of its segment that ends there; warned when most of the region's demos
        are. Only with ``align_entries=True``: without
        it the regions of Algorithm 1 are entered early by construction (the shipped tasks'
        fit).
        """
        if not self.align_entries:
            return
        n_transition_regions = len(self.regions_) - (1 if self.include_goal else 0)
        for k in range(n_transition_regions):
            members = self.region_transitions_[k]
            far: dict[int, int] = {}
            for d, step in members:
                entry, start = self.segments_[d][k], self.segments_[d][k - 1] if k else 0
                gap = int(entry - step)
                tolerance = max(3.0, 0.03 * lengths[d])  # switch_scores' before rounding up
                if entry > 0 and abs(gap) > tolerance and abs(gap) > _ENTRY_GAP * (step - start):
                    far[d] = gap
            if 2 * len(far) <= len(members):
                continue
            gap = float(np.median(list(far.values())))
            warnings.warn(
                f"Segment {k + 1} starts a median {abs(gap):.0f} steps "
                f"{'before' if gap < 0 else 'after'} the demos' own transitions into it in "
                f"demos {sorted(far)} of {sorted(d for d, _ in members)}: region {k} spans "
                "transitions at different places, and a demo enters it at its edge. The "
                "rewards and the agent's segment index follow these entries, not the "
                "transitions. Look at `sb3-swirl show --plot` with the demos: where the demos "
                "change phase at different states, a region of states cannot mark the change "
                "(the paper's §5 assumes it can); dims= (the dimensions the task lives in) may "
                "help",
                SegmentationWarning,
                stacklevel=3,
            )

    def _warn_lost(self) -> None:
        """Warn when the fit found candidates but kept almost none of their structure."""
        n = self.n_demos_
        n_candidates = sum(len(t) for t in self.transitions_)
        n_transition_regions = len(self.regions_) - (1 if self.include_goal else 0)
        if self.indicator == "auto":
            other = (
                f"try indicator='ruptures' (with the ruptures package; 'auto' tried "
                f"{', '.join(_AUTO_CANDIDATES)} and kept {self.indicator_})"
            )
        else:
            other = (
                f"try another indicator (indicator='auto' tries {', '.join(_AUTO_CANDIDATES)}; "
                "'ruptures' needs the ruptures package)"
            )
        merge = "" if self.merge_fragments else ", merge_fragments=True"
        merge += ", merge_same_dynamics=False" if self.merge_same_dynamics else ""
        advice = (
            f"{other}, a longer window{merge}, or a lower min_demo_fraction, and look at "
            "`sb3-swirl show --plot` with the demos"
        )
        # Candidate regions that all but a few demos share: the few are worth a look (a demo
        # at another rate, one that skipped a phase). Where many demos disagree, the drops are
        # the demonstrators' variety, recorded in dropped_regions_ only.
        few = max(1, n // 4)
        lost = sorted(
            (d for d in self.dropped_regions_ if 0 < len(d["demos"]) <= few),
            key=lambda d: d["time"],
        )
        threshold = (
            f"min_demo_fraction={self.min_demo_fraction} needs {self._min_demos(n)} of {n} demos"
        )
        parts = []
        if n_transition_regions == 0 and not n_candidates:
            parts.append(
                "no transition region: the indicator found no candidate transition in any "
                "demo (the motion shows no change it detects), so the task has one segment "
                "to the goal"
            )
        elif n_transition_regions == 0:
            reasons = sorted({d["reason"].split(" (")[0] for d in self.dropped_regions_})
            proposed = (
                f"no transition region: the indicator proposed {n_candidates} candidate "
                f"transitions in {sum(len(t) > 0 for t in self.transitions_)} of {n} demos, "
            )
            if not self.dropped_regions_:
                dropped = f"but they formed no candidate region ({threshold})"
            else:
                dropped = (
                    "and the one candidate region was dropped "
                    if len(self.dropped_regions_) == 1
                    else f"and all {len(self.dropped_regions_)} candidate regions were dropped "
                ) + f"({'; '.join(reasons)}; {threshold})"
            parts.append(proposed + dropped + ", so the task has one segment to the goal")
        if lost:
            parts.append(
                f"dropped {len(lost)} candidate region(s) that all but a few demos share: "
                + "; ".join(f"near step {d['time']:.0f}, {d['reason']}" for d in lost)
                + f" ({threshold}); if those demos differ from the others (another rate, a "
                "skipped phase), fix or drop them"
            )
        if not parts:
            return
        if n_transition_regions:
            parts.append(f"the task has {len(self.regions_)} segment(s)")
        message = ". ".join(p[0].upper() + p[1:] for p in parts) + f". To find more, {advice}"
        warnings.warn(message, SegmentationWarning, stacklevel=3)

    def _check_complete(self, segments: list[np.ndarray], x: list[np.ndarray]) -> None:
        """Raise unless enough demonstrations reach every region in order (after their start).

        Where the goal is the only region left, demonstrations that start inside it are not
        counted against the fit (with a warning) as long as at least half of them travel to
        it: the demos of a task of holding a state (balancing) end where a few of them begin.
        The error says when the demonstrations end far apart (a goal that changes per episode),
        the usual reason why they start inside the goal region.
        """
        problems: dict[int, str] = {}  # per incomplete demo, what it lacks
        at_goal = []
        for n, bounds in enumerate(segments):
            if bounds[0] == 0:
                problems[n] = f"demo {n} starts inside region 0"
                at_goal.append(n)
            elif bounds[-1] < 0:
                problems[n] = f"demo {n} never reaches region {int(np.argmax(bounds < 0))}"
        complete = len(segments) - len(problems)
        goal_only = self.include_goal and len(self.regions_) == 1
        excused = at_goal if goal_only and 2 * complete >= len(segments) else []
        need = self._min_demos(len(segments))
        if complete + len(excused) < need:
            shown = "; ".join(list(problems.values())[:5]) + ("; ..." if len(problems) > 5 else "")
            ends = np.array([s[-1] for s in x])
            end_spread = float(np.median(np.linalg.norm(ends - np.median(ends, axis=0), axis=1)))
            travel = float(np.median([np.linalg.norm(s[-1] - s[0]) for s in x]))
            walked = float(np.median([np.linalg.norm(np.diff(s, axis=0), axis=1).sum() for s in x]))
            # demos that head somewhere (not jitter in place) but not to one place
            if goal_only and at_goal and end_spread > 0.5 * travel and travel > 0.25 * walked:
                advice = (
                    f"The demonstrations end in different places (their last states lie a "
                    f"median {end_spread:.3g} from their middle, and they travel {travel:.3g}), "
                    "so the goal region, fitted to where they end, holds their starts. "
                    "SWIRL's last segment is one goal shared by every demonstration: where the "
                    "goal changes per episode, give the task a state relative to the goal (the "
                    "offset to it) or the state with the goal (on a Dict env, state_key="
                    "['observation', 'desired_goal'])"
                )
            elif goal_only and at_goal and travel <= 0.25 * walked:
                advice = (
                    f"The demonstrations end about where they start (a median {travel:.3g} "
                    f"from start to end over a path of {walked:.3g}): they wander in place, or "
                    "return to where they began, so the goal region, fitted to where they "
                    "end, holds their starts. SWIRL marks segments by regions of states: it "
                    "needs demos that end away from their start, or a state that tells the "
                    "two apart (a progress or time variable in the observation), and "
                    "transitions every demo shares. Otherwise lower min_demo_fraction or "
                    "change the indicator or window"
                )
            else:
                advice = (
                    "Do the demonstrations move? Otherwise lower min_demo_fraction or change "
                    "the indicator or window"
                )
            raise ValueError(
                f"only {complete} of {len(segments)} demonstrations reach "
                + (
                    "the region"
                    if len(self.regions_) == 1
                    else f"the {len(self.regions_)} regions in order"
                )
                + f", {need} needed ({shown}). {advice}"
            )
        short = [problem for n, problem in problems.items() if n not in excused]
        if short:
            warnings.warn(
                f"{len(short)} of {len(segments)} demonstrations do not reach every region in "
                f"order ({'; '.join(short[:5])}{'; ...' if len(short) > 5 else ''}): "
                f"min_demo_fraction={self.min_demo_fraction} keeps regions that at least "
                f"{need} of {len(segments)} demos pass. Such a demo stays in the segment "
                "before the region it misses to its end, so its later states shape that "
                "segment's reward and a BC start (SwirlDQN) clones its later actions under "
                "that segment. Fix or drop those demos, or raise min_demo_fraction",
                SegmentationWarning,
                stacklevel=4,
            )
        if excused:
            warnings.warn(
                f"Demos {excused} start inside the goal region (where the demos end), as in a "
                "task of holding a state such as balancing: it marks no transition for them, "
                "and an episode that starts there is complete from its first step. The task "
                "has one segment; if the demos have phases, fit without those that start at the "
                f"goal, or try another indicator ('auto' tries {', '.join(_AUTO_CANDIDATES)})",
                SegmentationWarning,
                stacklevel=4,
            )

    def _drop(
        self, times: np.ndarray, points: np.ndarray, reason: str, demos: list[int] | None = None
    ) -> None:
        """Record a dropped candidate region in ``dropped_regions_``."""
        self.dropped_regions_.append(
            {
                "time": float(np.median(times)),
                "centre": np.atleast_2d(points).mean(axis=0).tolist(),
                "reason": reason,
                "demos": demos or [],
            }
        )

    def _prune_unreached(
        self, x: list[np.ndarray], regions: list[Region], ids: list[int], times: list
    ) -> list[int]:
        """Drop regions until enough demonstrations reach every region in order.

        Algorithm 1 prunes clusters without a transition from every demonstration, but the
        agent is segmented by the Markov function (first entry into the *next* region), so a
        cluster can hold every demonstration and still be skipped by some: they pass through
        it before reaching the previous region (on a growing oscillation every place near the
        start is revisited later). Likewise a first region that holds a demonstration's start
        state marks no transition (the start state never counts as one). A demonstration is
        *complete* when it reaches every region in order, the first after its start. Greedily,
        the transition region whose removal makes the most demonstrations complete (after
        shrinking for disjointness) is removed until ``ceil(min_demo_fraction * n_demos)``
        are; the goal region is kept.
        """
        need = self._min_demos(len(x))
        removable = len(regions) - (1 if self.include_goal else 0)

        def incomplete(subset: list[int]) -> list[int]:
            """Position (in ``subset``) of the first region each demo misses; -1: none."""
            if not subset:
                return [0] * len(x)
            task = _regions_task(_make_disjoint([regions[j] for j in subset]))
            missed = []
            for b in task.reach_steps(x):
                b[0] = -1 if b[0] == 0 else b[0]  # the start state never counts
                missed.append(int(np.argmax(b < 0)) if (b < 0).any() else -1)
            return missed

        def n_complete(subset: list[int]) -> int:
            return incomplete(subset).count(-1)

        alive = list(range(len(regions)))
        missed = incomplete(alive)
        while missed.count(-1) < need and removable > 0:
            candidates = [j for j in alive if j < removable]
            if not candidates:
                break
            scores = [n_complete([j for j in alive if j != c]) for c in candidates]
            worst = candidates[int(np.argmax(scores))]
            position = alive.index(worst)
            demos = [n for n, m in enumerate(missed) if m == position]
            self._drop(
                times[ids[worst]],
                regions[worst].mean,
                "not reached in order (after the previous region, not at the start) by "
                f"demos {demos}",
                demos,
            )
            alive.remove(worst)
            missed = incomplete(alive)
        return [ids[j] for j in alive]

    def transform_states(self, states: np.ndarray) -> np.ndarray:
        """Map states (the same columns as given to ``fit``) into the regions' task space."""
        states = np.asarray(states, dtype=np.float64)
        return states if self.feature_map_ is None else self.feature_map_(states)

    @property
    def _window(self) -> int:
        """The window of the ``"gmm"`` and ``"velocity"`` indicators and the length checks."""
        return _DEFAULT_WINDOW if self.window is None else int(self.window)

    def _min_demos(self, n: int) -> int:
        return max(1, math.ceil(self.min_demo_fraction * n - 1e-9))

    def _fit_feature_map(self, states: list[np.ndarray], seed: int) -> RBFFeatures:
        rs = check_random_state(seed)
        pooled = np.concatenate(states)
        if len(pooled) > self.max_indicator_samples:
            pooled = pooled[rs.choice(len(pooled), self.max_indicator_samples, replace=False)]
        distinct = np.unique(pooled, axis=0)
        gamma = 1.0 / (2.0 * self.kernel_sigma**2)
        nystroem = Nystroem(
            kernel="rbf",
            gamma=gamma,
            n_components=min(self.n_landmarks, len(distinct)),
            random_state=rs.randint(_SEED_MAX),
        ).fit(distinct)
        phi = nystroem.transform(pooled)
        n_out = min(self.n_kernel_components, phi.shape[1], len(pooled))
        pca = PCA(n_components=n_out, random_state=rs.randint(_SEED_MAX)).fit(phi)
        projection = nystroem.normalization_.T @ pca.components_.T
        return RBFFeatures(
            landmarks=nystroem.components_,
            gamma=gamma,
            projection=projection,
            offset=pca.mean_ @ pca.components_.T,
        )

    def _named_indicator(self, name: str, x: list[np.ndarray], seed: int) -> list[np.ndarray]:
        if name == "gmm":
            return gmm_indicator(
                x,
                seed,
                window=self._window,
                n_components=self.n_indicator_components,
                max_samples=self.max_indicator_samples,
            )
        if name == "velocity":
            return velocity_indicator(x, seed, window=self._window)
        if name == "linear":
            return linear_indicator(x, seed, window=self.window)
        if name == "phases":
            return phases_indicator(
                x,
                seed,
                min_size=self._window,
                ignore_nuisance_dims=self.ignore_nuisance_dims,
                max_samples=self.max_indicator_samples,
            )
        return ruptures_indicator(x, seed, min_size=self._window)

    def _indicate(self, x: list[np.ndarray], seed: int) -> list[np.ndarray]:
        if callable(self.indicator):
            found = self.indicator(x, seed)
        else:
            # several indicators: the union of their candidates, those closer than a window
            # to an earlier one merged into it
            names = self.indicator.split("+")
            found = self._named_indicator(names[0], x, seed)
            for name in names[1:]:
                found = [
                    _merge_close(np.concatenate([a, b]), self._window)
                    for a, b in zip(found, self._named_indicator(name, x, seed), strict=True)
                ]
        if not isinstance(found, Sequence) or len(found) != len(x):
            raise ValueError(
                f"the transition indicator must return one index array per demonstration "
                f"({len(x)}), got {type(found).__name__}"
            )
        out = []
        for i, idx in enumerate(found):
            idx = np.asarray(idx)
            if idx.size and (idx.dtype.kind not in "iu" or idx.ndim != 1):
                raise ValueError(
                    f"the transition indicator returned non-integer or non-1-D indices for "
                    f"demo {i}: dtype {idx.dtype}, shape {idx.shape}"
                )
            n_states = len(x[i])
            outside = idx[(idx < 0) | (idx >= n_states)] if idx.size else idx
            if outside.size:
                raise ValueError(
                    f"the transition indicator returned steps outside demo {i} (its states are "
                    f"0 .. {n_states - 1}): {outside[:5].tolist()}"
                )
            out.append(_interior(idx.reshape(-1), n_states))
        return out

    def _dpgmm_labels(self, feats: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Labels and responsibilities of a Dirichlet-process GMM on standardised features."""
        feats = (feats - feats.mean(axis=0)) / _scale(feats)
        n_distinct = len(np.unique(feats, axis=0))
        if n_distinct < 2:
            return np.zeros(len(feats), dtype=np.int64), np.ones((len(feats), 1))
        dpgmm = BayesianGaussianMixture(
            n_components=min(self.n_regions_max, n_distinct),
            covariance_type=self.covariance_type,
            weight_concentration_prior_type="dirichlet_process",
            weight_concentration_prior=self.concentration,
            reg_covar=1e-3,
            max_iter=500,
            random_state=seed,
        ).fit(feats)
        proba = dpgmm.predict_proba(feats)
        return proba.argmax(axis=1), proba

    def _cluster(
        self, x: list[np.ndarray], seed: int, dims: np.ndarray | None = None
    ) -> tuple[list[tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]], bool]:
        """DP-GMM over the candidate transition states, then over time, then pruning.

        As in the authors' TSC code, transition states are clustered first in state, then in
        time within each state cluster. A state cluster is split by time only when every time
        sub-cluster survives pruning on its own (a place all demonstrations visit more than
        once); otherwise demonstrators' differing speeds would fragment one transition into
        sub-clusters each holding part of the demonstrations. With ``merge_fragments``, state
        clusters too small to survive are first merged by :func:`_merge_fragments`. With
        ``dims``, the state clustering uses those dimensions only.

        Returns (times, states, [(demo, step), ...]) of one representative transition per
        demonstration (its most probable member) for every surviving cluster, ordered by
        median time; and whether clusters too small to survive were dropped.
        """
        owner = np.concatenate(
            [np.full(len(t), i, dtype=np.int64) for i, t in enumerate(self.transitions_)]
        )
        steps = np.concatenate(self.transitions_).astype(np.int64)
        if len(steps) < 2:
            return [], False
        points = np.concatenate([s[t] for s, t in zip(x, self.transitions_, strict=True)])
        need = self._min_demos(len(x))
        rs = check_random_state(seed)
        state_labels, state_proba = self._dpgmm_labels(
            points if dims is None else points[:, dims], rs.randint(_SEED_MAX)
        )
        clusters, fragments = [], []
        for c in np.unique(state_labels):
            members = np.flatnonzero(state_labels == c)
            part = (members, state_proba[members, c])
            (clusters if len(np.unique(owner[members])) >= need else fragments).append(part)
        times = steps * self.time_scale_[owner]  # time-normalised
        if self.merge_fragments:
            fragments = _merge_fragments(fragments, owner, times, self._window)
        found, fragmented = [], False
        for members, score in fragments:
            here = np.unique(owner[members])
            if len(here) < need:
                fragmented = True
                without = sorted(set(range(len(x))) - set(here.tolist()))
                self._drop(
                    steps[members],
                    points[members],
                    f"only {len(here)} of {len(x)} demos have a transition there ({need} "
                    f"needed; none from demos {without})",
                    without,
                )
            else:  # merged fragments: one transition, not split by time again
                found.append(self._representatives(members, score, owner, steps, points))
        for members, score in clusters:
            groups = [(members, score)]
            if len(members) > 1:
                time_seed = rs.randint(_SEED_MAX)  # drawn even when unused: same later seeds
                # A split needs two parts of `need` demos each, so at least 2 * need members.
                if len(members) >= 2 * need:
                    time_labels, time_proba = self._dpgmm_labels(times[members][:, None], time_seed)
                    sub = [
                        (members[time_labels == u], time_proba[time_labels == u, u])
                        for u in np.unique(time_labels)
                    ]
                    if len(sub) > 1 and all(len(np.unique(owner[m])) >= need for m, _ in sub):
                        groups = sub
            for group, group_score in groups:
                found.append(self._representatives(group, group_score, owner, steps, points))
        found.sort(key=lambda item: float(np.median(item[0])))
        return found, fragmented

    @staticmethod
    def _representatives(
        group: np.ndarray,
        score: np.ndarray,
        owner: np.ndarray,
        steps: np.ndarray,
        points: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
        """(times, states, [(demo, step), ...]) of each demonstration's most probable member."""
        reps = []
        for demo in np.unique(owner[group]):
            mine = owner[group] == demo
            reps.append(int(group[mine][np.argmax(score[mine])]))
        reps = np.asarray(reps)
        return (
            steps[reps].astype(np.float64),
            points[reps],
            [(int(owner[r]), int(steps[r])) for r in reps],
        )

    def _region(
        self, points: np.ndarray, reg: np.ndarray, threshold: float, times: np.ndarray
    ) -> Region:
        mean = points.mean(axis=0)
        cov = np.cov(points, rowvar=False).reshape(len(mean), len(mean)) if len(points) > 1 else 0
        bounds = None
        if self.use_time:
            spread = max(float(times.max() - times.min()), float(self._window))
            bounds = (max(0.0, float(times.min()) - spread), float(times.max()) + spread)
        # A region holds the states it was built from: with few points the chi-square
        # quantile can leave one of them outside (and that demo would then miss the region).
        cov = cov + reg
        diff = points - mean
        d2 = np.einsum("ij,ij->i", diff, np.linalg.solve(cov, diff.T).T)
        threshold = max(threshold, float(d2.max()) * (1 + 1e-9))
        return Region(mean, cov, threshold, time_bounds=bounds)
