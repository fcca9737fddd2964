"""Reward learning (§6 of the paper, Algorithm 2): one local quadratic reward per segment.

Every reward learner follows the :class:`RewardLearner` protocol: hyperparameters in
``__init__``, ``fit(demos, segmentation)`` learns ``rewards_``, a list of
:class:`swirl_wrappers.QuadraticReward` (one per segment, segment ``i`` leading to region ``i``).
:func:`segment_states` cuts the demonstrations into segments with the same Markov segmentation
function the runtime uses (:func:`segment_transitions` with the actions), so every learner (the
model-free :class:`QuadraticRewardLearner`, the model-based :class:`MaxEntIRLRewardLearner`)
sees exactly the segments an agent will be rewarded on.
"""

from __future__ import annotations

import contextlib
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval, StrOptions
from threadpoolctl import threadpool_limits

from sb3_swirl.demos import Demonstration, as_demonstrations
from sb3_swirl.segmentation import (
    StrictParamsMixin,
    TransitionStateClustering,
    _constant_columns,
    segment_boundaries,
)
from swirl_wrappers import QuadraticReward, RBFFeatures, Region, TaskModel


def _resolve(
    segmentation: Any, features: RBFFeatures | None
) -> tuple[list[Region], Callable[[np.ndarray], np.ndarray]]:
    """Regions and the state -> task-space map of a fitted segmenter, task model or regions."""
    if isinstance(segmentation, TransitionStateClustering):
        if not hasattr(segmentation, "regions_"):
            raise ValueError("the TransitionStateClustering is not fitted; call fit(demos) first")
        return list(segmentation.regions_), segmentation.transform_states
    if isinstance(segmentation, TaskModel):
        return list(segmentation.regions), segmentation.featurize
    regions = list(segmentation) if isinstance(segmentation, Iterable) else []
    if not regions or not all(isinstance(r, Region) for r in regions):
        raise ValueError(
            "segmentation must be a fitted TransitionStateClustering, a TaskModel or a "
            f"non-empty sequence of Region, got {type(segmentation).__name__}"
        )
    if features is None:
        return regions, lambda s: s
    return regions, features


def segment_states(
    demos: Sequence[Demonstration],
    segmentation: Any,
    features: RBFFeatures | None = None,
) -> tuple[list[list[np.ndarray]], list[Region]]:
    """Cut every demonstration into the segments of a learned segmentation.

    Segment ``i`` of a demonstration holds the states after region ``i - 1`` was reached up to
    and including the first state in region ``i`` (Markov segmentation function, as
    :meth:`swirl_wrappers.TaskModel.segment_indices`). A demonstration that never reaches
    region ``i`` puts all its remaining states in segment ``i`` and none in later segments.

    Parameters
    ----------
    demos : list of Demonstration
    segmentation : fitted TransitionStateClustering, TaskModel or sequence of Region
    features : RBFFeatures, optional
        Feature map of a bare sequence of regions (ignored otherwise).

    Returns
    -------
    segments : list (per segment) of lists (per demonstration) of task-space state arrays
    regions : list of Region
    """
    regions, featurize = _resolve(segmentation, features)
    segments: list[list[np.ndarray]] = [[] for _ in regions]
    for i, demo in enumerate(demos):
        x = featurize(demo.observations)
        if x.shape[-1] != regions[0].mean.size:
            raise ValueError(
                f"demo {i}: states map to {x.shape[-1]} task-space dims but the regions live "
                f"in {regions[0].mean.size}"
            )
        bounds = segment_boundaries(x, regions)
        start = 0
        for j, b in enumerate(bounds):
            end = len(x) if b < 0 else int(b) + 1
            segments[j].append(x[start:end])
            if b < 0:
                break
            start = end
    return segments, regions


def _mean_cost(x: np.ndarray, target: np.ndarray, weight: np.ndarray) -> float:
    """Mean of ``(x - target)^T weight (x - target)`` over the rows of ``x``."""
    diff = x - target
    return float(np.mean(np.einsum("ij,jk,ik->i", diff, weight, diff)))


def _constant_dims(pooled: np.ndarray) -> np.ndarray:
    """The task-space dimensions no demonstration moves in, with a warning that the rewards
    ignore them: the demos say nothing of how far off such a dimension may be (its inverse
    variance would be a floor's, 1e12 times the others')."""
    constant = _constant_columns(pooled)
    if constant.any():
        warnings.warn(
            f"task-space dimensions {np.flatnonzero(constant).tolist()} are constant in every "
            "demonstration: the rewards ignore them (pass dims= to leave them out of the task "
            "space)",
            stacklevel=3,
        )
    return constant


def _inverse_covariance(x: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """The symmetric inverse of the covariance of the rows of ``x`` plus ``floor``."""
    p = x.shape[1]
    cov = np.cov(x, rowvar=False).reshape(p, p) if len(x) > 1 else np.zeros((p, p))
    weight = np.linalg.inv(cov + floor)
    return (weight + weight.T) / 2


class RewardLearner(BaseEstimator, ABC):
    """Protocol of the reward learners: ``fit(demos, segmentation)`` sets ``rewards_``.

    Subclasses (the model-free :class:`QuadraticRewardLearner`; :class:`MaxEntIRLRewardLearner`
    for demonstrations with actions) implement :meth:`fit` and may use :func:`segment_states`
    or :func:`segment_transitions`.
    """

    rewards_: list[QuadraticReward]

    @abstractmethod
    def fit(
        self, demos: Any, segmentation: Any, features: RBFFeatures | None = None
    ) -> RewardLearner:
        """Learn one :class:`swirl_wrappers.QuadraticReward` per segment into ``rewards_``."""


class QuadraticRewardLearner(StrictParamsMixin, RewardLearner):
    """Model-free local rewards for state-only demonstrations (§6.1, eq. 1).

    For segment ``i`` the reward is ``R_i(x) = -(x - mu_i)^T Psi_i (x - mu_i)`` where ``mu_i``
    is the centre of region ``i`` (the region the segment leads to) and

    * ``metric="mahalanobis"``: ``Psi_i`` is the regularised inverse covariance of the
      segment's task-space states over all demonstrations (eq. 1 writes the uncentred second
      moment; the text means the covariance, which is used here), so deviation along
      directions the demonstrator kept steady costs more;
    * ``metric="euclidean"``: ``Psi_i = I``.

    Parameters
    ----------
    metric : {"mahalanobis", "euclidean"}, default "mahalanobis"
    regularization : float, default 1e-3
        Added to the segment covariance before inversion, relative to the variance of all
        demonstration states along each axis (plus a tiny absolute floor), so segments with
        few states or a coordinate constant in the segment still give a finite ``Psi``. A
        coordinate constant in every demonstration gets weight 0 (with a warning).
    normalize : bool, default True
        Scale each ``Psi_i`` so the mean reward over the demonstrations' states in segment
        ``i`` is ``-1``. Raw Mahalanobis rewards range over orders of magnitude between
        segments and tasks; normalised, a reward of ``-1`` means "as far from the next region
        as a demonstrator typically was", a sane scale for RL.

    Attributes
    ----------
    rewards_ : list of QuadraticReward
    segment_sizes_ : list of int
        Number of demonstration states used for each segment.

    Examples
    --------
    >>> from sb3_swirl.demos import make_piecewise_linear_demos
    >>> from sb3_swirl.segmentation import TransitionStateClustering
    >>> demos, _ = make_piecewise_linear_demos(n_demos=8, random_state=0)
    >>> tsc = TransitionStateClustering(random_state=0).fit(demos)
    >>> learner = QuadraticRewardLearner().fit(demos, tsc)
    >>> len(learner.rewards_) == len(tsc.regions_)
    True
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "metric": [StrOptions({"mahalanobis", "euclidean"})],
        "regularization": [Interval(Real, 0, np.inf, closed="neither")],
        "normalize": ["boolean"],
    }

    def __init__(
        self, metric: str = "mahalanobis", regularization: float = 1e-3, normalize: bool = True
    ) -> None:
        self.metric = metric
        self.regularization = regularization
        self.normalize = normalize

    def fit(
        self, demos: Any, segmentation: Any, features: RBFFeatures | None = None
    ) -> QuadraticRewardLearner:
        """Learn the local rewards.

        Parameters
        ----------
        demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts
            The same states the segmentation was fitted on (or full observations when
            ``segmentation`` is a TaskModel with ``dims``).
        segmentation : fitted TransitionStateClustering, TaskModel or sequence of Region
        features : RBFFeatures, optional
            Feature map of a bare sequence of regions.

        Returns
        -------
        self
        """
        self._validate_params()
        demos = as_demonstrations(demos)
        segments, regions = segment_states(demos, segmentation, features)
        pooled = np.concatenate([s for seg in segments for s in seg])
        p = pooled.shape[1]
        floor = self.regularization * np.diag(pooled.var(axis=0)) + 1e-12 * np.eye(p)
        constant = _constant_dims(pooled) if self.metric == "mahalanobis" else np.zeros(p, bool)
        rewards, sizes = [], []
        for seg, region in zip(segments, regions, strict=True):
            # A segment no demonstration entered falls back on the statistics of all states.
            x = np.concatenate(seg) if seg else pooled
            sizes.append(sum(len(s) for s in seg))
            weight = np.eye(p) if self.metric == "euclidean" else _inverse_covariance(x, floor)
            weight[constant] = 0.0
            weight[:, constant] = 0.0
            if self.normalize:
                mean_cost = _mean_cost(x, region.mean, weight)
                if mean_cost > 1e-12:
                    weight = weight / mean_cost
            rewards.append(QuadraticReward(target=region.mean, weight=weight))
        self.rewards_ = rewards
        self.segment_sizes_ = sizes
        return self


def segment_transitions(
    demos: Sequence[Demonstration],
    segmentation: Any,
    features: RBFFeatures | None = None,
) -> tuple[list[dict[str, np.ndarray]], list[Region]]:
    """The demonstrated transitions ``(s_t, a_t, s_{t+1})`` of every segment.

    A transition belongs to the segment of its first state (the same Markov segmentation as
    :func:`segment_states`). Demonstrations need actions.

    Returns
    -------
    transitions : list (per segment) of dicts with ``states`` and ``next_states`` (the demos'
        own rows, shape (n, d)), ``x`` and ``next_x`` (their task-space features, (n, p)) and
        ``actions`` ((n,) or (n, m)); empty arrays for a segment no demo entered
    regions : list of Region
    """
    regions, featurize = _resolve(segmentation, features)
    parts: list[list[tuple[np.ndarray, ...]]] = [[] for _ in regions]
    for demo in demos:
        x = featurize(demo.observations)
        bounds = segment_boundaries(x, regions)
        label = np.full(len(x), -1)
        start = 0
        for j, b in enumerate(bounds):
            end = len(x) if b < 0 else int(b) + 1
            label[start:end] = j
            if b < 0:
                break
            start = end
        actions = np.asarray(demo.actions)
        for j in range(len(regions)):
            t = np.flatnonzero(label[:-1] == j)
            obs = demo.observations
            parts[j].append((obs[t], obs[t + 1], x[t], x[t + 1], actions[t]))
    out = []
    for seg in parts:
        names = ("states", "next_states", "x", "next_x", "actions")
        out.append({n: np.concatenate([p[i] for p in seg]) for i, n in enumerate(names)})
    return out, regions


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """Torch's and the BLAS libraries' work on one thread, as before afterwards."""
    import torch as th

    threads = th.get_num_threads()
    th.set_num_threads(1)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        th.set_num_threads(threads)


class MaxEntIRLRewardLearner(StrictParamsMixin, RewardLearner):
    """Model-based local rewards by maximum-entropy IRL on each segment (§6.2).

    For segment ``i`` the reward is ``R_i(x) = -(x - mu_i)^T Psi_i (x - mu_i)``, ``mu_i`` the
    centre of region ``i`` (as in :class:`QuadraticRewardLearner`) and ``Psi_i = L L^T +
    floor`` positive semi-definite by construction, fitted by maximising the likelihood of the
    demonstrated actions under the soft-optimal (maximum causal entropy) policy of the
    segment's dynamics. That is MaxEnt IRL's maximum-likelihood problem: the dynamics terms of a
    trajectory's log-probability do not depend on the reward. The dynamics are a linear model
    ``x' = A x + B u + c`` fitted by least squares on the segment's transitions (§6.2.2), or the
    known model ``dynamics`` (Fig. 5, "the benefit of models").

    * **Continuous actions** (2-D float action arrays): the action cost ``u^T R u`` with
      ``R = action_cost * I`` is fixed (it sets the scale of ``Psi``) and the problem is a
      soft LQR: a discounted Riccati recursion on ``(x, 1)`` gives the Gaussian policy
      ``u ~ N(-K (x, 1), (2 (R + gamma B^T P B))^-1)``. ``dynamics`` is then a linear model
      ``(A, B)`` or ``(A, B, c)`` in task space.
    * **Discrete actions** (integer actions): soft value iteration with a quadratic value
      function fitted by least squares on the segment's states, ``Q(x, a) = R_i(x) + gamma
      V(x'_a)`` and ``pi(a | x) = softmax_a Q(x, a)``; ``x'_a`` comes from the linear model
      (``B`` acting on the one-hot action) or from ``dynamics(state, action) -> next state``,
      called on the demonstrations' own rows (the states ``fit`` is given).

    Parameters
    ----------
    gamma : float, default 0.9
        Discount of the soft Bellman recursion (the horizon a segment's demonstrator plans for).
    action_cost : float, default 1.0
        ``R = action_cost * I`` (continuous actions only).
    dynamics : callable or tuple, optional
        The known model (see above); ``None`` estimates a linear model per segment.
    max_iter : int, default 100
        L-BFGS iterations (strong Wolfe line search) on the likelihood.
    value_function : {"quadratic", "tabular"}, default "quadratic"
        Discrete actions: soft value iteration with a quadratic value function fitted on the
        segment's states (any number of dims), or on a grid (``n_bins`` per task-space axis
        over the segment's range, ``P(s' | s, a)`` counted from the demonstrated transitions or
        from the known model; at most 50 000 cells).
    n_bins : int, default 6
        Bins per axis of ``value_function="tabular"``.
    n_value_iterations : int, default 60
        Soft Bellman iterations per likelihood evaluation (discrete actions; the Riccati
        recursion of the continuous case runs as many).
    regularization : float, default 1e-3
        Floor added to ``Psi`` (relative to the inverse variance of the segment's states along
        each axis) and ridge of the linear model's least squares.
    weight_decay : float, default 1e-3
        Penalty ``weight_decay * ||S Psi S||_F^2`` with ``S`` the segment states' standard
        deviations (unit-free): where a segment's demonstrations are deterministic, the
        likelihood grows without bound with the scale of ``Psi``, and this keeps it finite.
    normalize : bool, default True
        Scale each ``Psi_i`` so the mean reward over the segment's demonstration states is
        ``-1``, the scale of :class:`QuadraticRewardLearner` (the shape of ``Psi_i`` is the
        MaxEnt estimate; ``raw_scales_`` keeps the factor).

    Attributes
    ----------
    rewards_ : list of QuadraticReward
    segment_sizes_ : list of int
        Demonstrated transitions per segment.
    log_likelihoods_ : list of float
        Mean log-likelihood of the demonstrated actions per segment at the optimum.
    raw_scales_ : list of float
        The factor ``normalize`` divided each ``Psi_i`` by (1 without it).
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "gamma": [Interval(Real, 0, 1, closed="left")],
        "action_cost": [Interval(Real, 0, np.inf, closed="neither")],
        "dynamics": [callable, tuple, None],
        "max_iter": [Interval(Integral, 1, None, closed="left")],
        "value_function": [StrOptions({"quadratic", "tabular"})],
        "n_bins": [Interval(Integral, 2, None, closed="left")],
        "n_value_iterations": [Interval(Integral, 1, None, closed="left")],
        "regularization": [Interval(Real, 0, np.inf, closed="neither")],
        "weight_decay": [Interval(Real, 0, np.inf, closed="left")],
        "normalize": ["boolean"],
    }

    def __init__(
        self,
        gamma: float = 0.9,
        action_cost: float = 1.0,
        dynamics: Callable[[np.ndarray, Any], np.ndarray] | tuple | None = None,
        max_iter: int = 100,
        value_function: str = "quadratic",
        n_bins: int = 6,
        n_value_iterations: int = 60,
        regularization: float = 1e-3,
        weight_decay: float = 1e-3,
        normalize: bool = True,
    ) -> None:
        self.gamma = gamma
        self.action_cost = action_cost
        self.dynamics = dynamics
        self.max_iter = max_iter
        self.value_function = value_function
        self.n_bins = n_bins
        self.n_value_iterations = n_value_iterations
        self.regularization = regularization
        self.weight_decay = weight_decay
        self.normalize = normalize

    def fit(
        self, demos: Any, segmentation: Any, features: RBFFeatures | None = None
    ) -> MaxEntIRLRewardLearner:
        """Learn the local rewards from demonstrations *with actions*.

        Raises
        ------
        ValueError
            If a demonstration has no actions (MaxEnt IRL needs them; label state-only demos
            with :class:`sb3_swirl.InverseDynamics` or use :class:`QuadraticRewardLearner`).
        """
        self._validate_params()
        demos = as_demonstrations(demos)
        for i, demo in enumerate(demos):
            if demo.actions is None:
                raise ValueError(
                    f"demo {i} has no actions: MaxEnt IRL (reward='maxent', "
                    "MaxEntIRLRewardLearner) needs states and actions; label state-only demos "
                    "of discrete actions with sb3_swirl.InverseDynamics, or use the model-free "
                    "reward"
                )
        discrete = all(np.asarray(d.actions).ndim == 1 for d in demos)
        for i, demo in enumerate(demos if discrete else ()):
            fractional = np.flatnonzero(np.asarray(demo.actions) != np.round(demo.actions))
            if fractional.size:
                step = int(fractional[0])
                raise ValueError(
                    f"demo {i}: action {demo.actions[step]:g} at step {step}; actions of shape "
                    "(T,) are discrete labels (integers). For continuous actions (one value a "
                    "step, e.g. Pendulum's torque) give shape (T, 1): actions[:, None]"
                )
            if len(demo) and np.min(demo.actions) < 0:
                raise ValueError(
                    f"demo {i}: action {int(np.min(demo.actions))} at step "
                    f"{int(np.argmin(demo.actions))}; actions of shape (T,) are discrete labels, "
                    "numbered 0 .. n - 1 as a Discrete action space numbers them (shift labels "
                    "such as -1/0/+1). For continuous actions (one value a step) give shape "
                    "(T, 1): actions[:, None]"
                )
        floats = [i for i, d in enumerate(demos) if np.asarray(d.actions).dtype.kind == "f"]
        if discrete and floats:
            warnings.warn(
                f"demos {floats} have float actions of shape (T,): they are read as discrete "
                "labels 0 .. n - 1. If they are the values of a continuous action of one "
                "dimension, give shape (T, 1): actions[:, None]",
                stacklevel=2,
            )
        if (
            not discrete
            and self.dynamics is not None
            and (callable(self.dynamics) or len(self.dynamics) not in (2, 3))
        ):
            raise ValueError(
                "continuous actions: dynamics must be a linear model (A, B) or (A, B, c) in "
                "task space"
            )
        segments, regions = segment_transitions(demos, segmentation, features)
        _, featurize = _resolve(segmentation, features)
        n_actions = 1 + max(int(np.max(d.actions)) for d in demos if len(d)) if discrete else 0
        used = len(np.unique(np.concatenate([d.actions for d in demos]))) if discrete else 0
        if n_actions > max(16, 2 * used):
            warnings.warn(
                f"the demos' action labels reach {n_actions - 1} but only {used} distinct ones "
                f"are used: MaxEnt IRL models every label 0 .. {n_actions - 1}, which is slow; "
                f"number the actions 0 .. {used - 1}",
                stacklevel=2,
            )
        pooled = np.concatenate([s["x"] for s in segments if len(s["x"])])
        var = pooled.var(axis=0) + 1e-12
        constant = _constant_dims(pooled)
        rewards, sizes, loglik, scales = [], [], [], []
        # one thread: the tensors are small, and the fit then does not depend on the machine's
        # cores (with 2 threads one of 15 parking demos' segments got a 100x smaller Psi)
        with _one_thread():
            for seg, region in zip(segments, regions, strict=True):
                x = seg["x"] if len(seg["x"]) else pooled
                sizes.append(len(seg["x"]))
                if not len(seg["x"]):  # no demo entered: no evidence, an isotropic reward
                    weight, ll = np.diag(1.0 / var), float("nan")
                elif discrete:
                    weight, ll = self._fit_discrete(seg, region.mean, n_actions, featurize, var)
                else:
                    weight, ll = self._fit_continuous(seg, region.mean, var)
                weight[constant] = 0.0
                weight[:, constant] = 0.0
                scale = _mean_cost(x, region.mean, weight) if self.normalize else 1.0
                scale = scale if scale > 1e-12 else 1.0
                rewards.append(QuadraticReward(target=region.mean, weight=weight / scale))
                loglik.append(ll)
                scales.append(scale)
        self.rewards_ = rewards
        self.segment_sizes_ = sizes
        self.log_likelihoods_ = loglik
        self.raw_scales_ = scales
        return self

    # ---------------------------------------------------------------- shared pieces
    def _linear_model(
        self, x: np.ndarray, u: np.ndarray, next_x: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ridge least squares ``x' = A x + B u + c`` (§6.2.2)."""
        design = np.hstack([x, u, np.ones((len(x), 1))])
        scale = design.std(axis=0) + 1e-8
        scale[-1] = 1.0
        z = design / scale
        # the ridge also settles actions a segment never shows (their effect estimate is 0)
        # and the one-hot columns' collinearity with the intercept
        ridge = self.regularization * len(x) * np.eye(z.shape[1])
        ridge[-1, -1] = 1e-9 * len(x)
        p = x.shape[1]
        try:
            coef = np.linalg.solve(z.T @ z + ridge, z.T @ next_x)
        except np.linalg.LinAlgError:
            # Singular where the segment holds a state coordinate constant beside an action it
            # always takes: that coordinate is the intercept again, its effect cannot be told
            # apart and is estimated as 0. Still singular with constant collinear action
            # columns: the least-squares solution settles them
            z[:, :p][:, _constant_columns(x)] = 0.0
            try:
                coef = np.linalg.solve(z.T @ z + ridge, z.T @ next_x)
            except np.linalg.LinAlgError:
                coef = np.linalg.lstsq(z.T @ z + ridge, z.T @ next_x, rcond=None)[0]
        coef = coef / scale[:, None]
        return coef[:p].T, coef[p : p + u.shape[1]].T, coef[-1]

    def _optimise(
        self, loss_of_psi: Callable[[Any], Any], x: np.ndarray, var: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """Minimise ``loss_of_psi(Psi)`` over ``Psi = L L^T + floor`` (L-BFGS on ``L``, started
        at the model-free estimate of the segment ``x``); ``var`` is the variance of all the
        demonstrations' states per axis (a segment may hold an axis constant). Returns ``Psi``
        and ``-loss``."""
        import torch as th

        start = _inverse_covariance(x, self.regularization * np.diag(var))
        start /= max(_mean_cost(x, x.mean(axis=0), start), 1e-12)
        chol = th.tensor(np.linalg.cholesky(start), requires_grad=True)
        floor = th.tensor(self.regularization * np.diag(1.0 / var))
        std = th.tensor(np.sqrt(var))
        optimiser = th.optim.LBFGS(
            [chol], lr=1.0, max_iter=self.max_iter, line_search_fn="strong_wolfe"
        )

        def closure() -> Any:
            optimiser.zero_grad()
            low = th.tril(chol)
            psi = low @ low.T + floor
            penalty = self.weight_decay * ((std[:, None] * psi * std[None, :]) ** 2).sum()
            loss = loss_of_psi(psi) + penalty
            loss.backward()
            return loss

        optimiser.step(closure)
        with th.no_grad():
            low = th.tril(chol)
            psi = low @ low.T + floor
            final = float(loss_of_psi(psi))
        weight = psi.numpy()
        return (weight + weight.T) / 2, -final

    # ---------------------------------------------------------------- continuous actions
    def _fit_continuous(
        self, seg: dict[str, np.ndarray], target: np.ndarray, var: np.ndarray
    ) -> tuple[np.ndarray, float]:
        import torch as th

        x, u, nx = seg["x"], np.asarray(seg["actions"], dtype=float), seg["next_x"]
        if self.dynamics is None:
            a, b, c = self._linear_model(x, u, nx)
        else:
            a, b, *rest = (np.asarray(m, dtype=float) for m in self.dynamics)
            c = rest[0] if rest else np.zeros(a.shape[0])
            want = {"A": (x.shape[1],) * 2, "B": (x.shape[1], u.shape[1]), "c": (x.shape[1],)}
            for name, matrix in zip("ABc", (a, b, c), strict=True):
                if matrix.shape != want[name]:
                    raise ValueError(
                        f"dynamics {name} has shape {matrix.shape}; the task space has "
                        f"{x.shape[1]} dims (after dims/angles) and the actions {u.shape[1]}, "
                        f"so s' = A s + B u + c needs {name} of shape {want[name]}"
                    )
        p, m = b.shape
        t = lambda v: th.tensor(v, dtype=th.float64)  # noqa: E731
        abar = t(np.block([[a, c[:, None]], [np.zeros((1, p)), np.ones((1, 1))]]))
        bbar = t(np.vstack([b, np.zeros((1, m))]))
        z = t(np.hstack([x, np.ones((len(x), 1))]))
        uu, mu = t(u), t(target)
        r = self.action_cost * th.eye(m, dtype=th.float64)
        gamma = self.gamma

        def loss(psi: Any) -> Any:
            qbar = th.zeros((p + 1, p + 1), dtype=th.float64)
            qbar[:p, :p] = psi
            qbar[:p, p] = -psi @ mu
            qbar[p, :p] = -psi @ mu
            qbar[p, p] = mu @ psi @ mu
            pbar = qbar
            for _ in range(self.n_value_iterations):
                mmat = r + gamma * bbar.T @ pbar @ bbar
                gain = gamma * th.linalg.solve(mmat, bbar.T @ pbar @ abar)
                pbar = qbar + gamma * abar.T @ pbar @ abar - gamma * abar.T @ pbar @ bbar @ gain
                pbar = (pbar + pbar.T) / 2
            mmat = r + gamma * bbar.T @ pbar @ bbar
            gain = gamma * th.linalg.solve(mmat, bbar.T @ pbar @ abar)
            mean = -z @ gain.T
            precision = 2 * mmat
            err = uu - mean
            quad = th.einsum("ni,ij,nj->n", err, precision, err)
            logdet = th.linalg.slogdet(precision)[1]
            return (0.5 * quad - 0.5 * logdet).mean()

        return self._optimise(loss, x, var)

    # ---------------------------------------------------------------- discrete actions
    def _fit_discrete(
        self,
        seg: dict[str, np.ndarray],
        target: np.ndarray,
        n_actions: int,
        featurize: Callable[[np.ndarray], np.ndarray],
        var: np.ndarray,
    ) -> tuple[np.ndarray, float]:
        import torch as th

        x, actions = seg["x"], np.asarray(seg["actions"]).astype(int)
        known = None  # the known model's next state under every action, (n, actions, p)
        if callable(self.dynamics):
            states = seg["states"]
            raw = [[self.dynamics(s, a) for a in range(n_actions)] for s in states]
            flat = np.asarray(raw, dtype=float).reshape(len(states) * n_actions, -1)
            known = featurize(flat).reshape(len(states), n_actions, x.shape[1])
        elif self.dynamics is not None:
            raise ValueError("discrete actions: dynamics must be a callable model")
        if self.value_function == "tabular":
            loss = self._tabular_loss(x, actions, seg["next_x"], known, target, n_actions)
            return self._optimise(loss, x, var)
        if known is not None:
            nxt = known
        else:
            onehot = np.eye(n_actions)[actions]
            a, b, c = self._linear_model(x, onehot, seg["next_x"])
            nxt = (x @ a.T + c)[:, None, :] + b.T[None, :, :]  # (n, actions, p)
        p = x.shape[1]
        iu = np.triu_indices(p)

        def quad_features(v: Any) -> Any:
            outer = v[..., :, None] * v[..., None, :]
            ones = th.ones((*v.shape[:-1], 1), dtype=th.float64)
            return th.cat([outer[..., iu[0], iu[1]], v, ones], dim=-1)

        # centred and scaled coordinates keep the least squares well conditioned
        centre, spread = x.mean(axis=0), np.sqrt(var)
        zx = th.tensor((x - centre) / spread, dtype=th.float64)
        znext = th.tensor((nxt - centre) / spread, dtype=th.float64)
        phi, phi_next = quad_features(zx), quad_features(znext)
        ridge = 1e-6 * th.eye(phi.shape[1], dtype=th.float64)
        fit_v = th.linalg.solve(phi.T @ phi + ridge, phi.T)  # V's weights from its targets
        xs, mu = th.tensor(x, dtype=th.float64), th.tensor(target, dtype=th.float64)
        acts = th.tensor(actions)
        gamma = self.gamma

        def loss(psi: Any) -> Any:
            diff = xs - mu
            reward = -th.einsum("ni,ij,nj->n", diff, psi, diff)
            w = th.zeros(phi.shape[1], dtype=th.float64)
            for _ in range(self.n_value_iterations):
                q = reward[:, None] + gamma * phi_next @ w
                w = fit_v @ th.logsumexp(q, dim=1)
            q = reward[:, None] + gamma * phi_next @ w
            logp = q - th.logsumexp(q, dim=1, keepdim=True)
            return -logp[th.arange(len(acts)), acts].mean()

        return self._optimise(loss, x, var)

    def _tabular_loss(
        self,
        x: np.ndarray,
        actions: np.ndarray,
        next_x: np.ndarray,
        known: np.ndarray | None,
        target: np.ndarray,
        n_actions: int,
    ) -> Callable[[Any], Any]:
        """The negative log-likelihood of the demonstrated actions under tabular soft value
        iteration: the segment's task space cut into ``n_bins`` equal bins per axis over the
        range of its states, ``P(s' | s, a)`` counted from the demonstrated transitions (or
        from the known model's next states under every action), an unseen ``(s, a)`` staying
        in ``s``; the reward of a bin is ``R_i`` at its centre."""
        import torch as th

        p, n = x.shape[1], self.n_bins
        n_states = n**p
        if n_states > 50_000:
            raise ValueError(
                f"value_function='tabular' with {p} task-space dims and n_bins={n} makes "
                f"{n_states} states (at most 50000): use fewer bins or dims, or "
                "value_function='quadratic'"
            )
        low, high = x.min(axis=0), x.max(axis=0)
        width = np.where(high > low, (high - low) / n, 1.0)

        def cell(v: np.ndarray) -> np.ndarray:
            index = np.clip(np.floor((v - low) / width), 0, n - 1).astype(int)
            return np.ravel_multi_index(tuple(np.moveaxis(index, -1, 0)), (n,) * p)

        here = cell(x)
        if known is None:
            rows, there = here * n_actions + actions, cell(next_x)
        else:
            rows = (here[:, None] * n_actions + np.arange(n_actions)).ravel()
            there = cell(known.reshape(-1, p))
        counts: dict[tuple[int, int], float] = {}
        for r, t in zip(rows.tolist(), there.tolist(), strict=True):
            counts[r, t] = counts.get((r, t), 0.0) + 1.0
        seen = np.zeros(n_states * n_actions, dtype=bool)
        seen[rows] = True
        unseen = np.flatnonzero(~seen)
        src = np.concatenate([np.array([k[0] for k in counts], dtype=int), unseen])
        dst = np.concatenate([np.array([k[1] for k in counts], dtype=int), unseen // n_actions])
        mass = np.concatenate([np.array(list(counts.values())), np.ones(len(unseen))])
        total = np.bincount(src, weights=mass, minlength=n_states * n_actions)
        src_t, dst_t = th.tensor(src), th.tensor(dst)
        prob = th.tensor(mass / total[src])
        axes = [low[j] + width[j] * (np.arange(n) + 0.5) for j in range(p)]
        grids = np.meshgrid(*axes, indexing="ij")
        centres = th.tensor(np.stack([g.ravel() for g in grids], axis=1) - target)
        cells, acts = th.tensor(here), th.tensor(actions)
        gamma = self.gamma

        def loss(psi: Any) -> Any:
            reward = -th.einsum("ni,ij,nj->n", centres, psi, centres)
            value = th.zeros(n_states, dtype=th.float64)
            for _ in range(self.n_value_iterations + 1):
                expected = th.zeros(n_states * n_actions, dtype=th.float64)
                expected = expected.index_add(0, src_t, prob * value[dst_t])
                q = reward[:, None] + gamma * expected.view(n_states, n_actions)
                value = th.logsumexp(q, dim=1)
            logp = q[cells] - value[cells, None]
            return -logp[th.arange(len(acts)), acts].mean()

        return loss
