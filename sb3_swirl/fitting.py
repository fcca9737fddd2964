"""The one-line path from demonstrations to a proxy task: :func:`fit_task`."""

from __future__ import annotations

import difflib
import functools
import inspect
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from sklearn.base import clone

from sb3_swirl.demos import Demonstration, as_demonstrations
from sb3_swirl.rewards import MaxEntIRLRewardLearner, QuadraticRewardLearner, RewardLearner
from sb3_swirl.segmentation import TransitionStateClustering
from swirl_wrappers import TaskModel
from swirl_wrappers._validation import check_int
from swirl_wrappers.task import angle_features, check_angles

Progress = Callable[[str], None]

#: ``fit_task(reward=NAME)``: the reward learners by name
REWARD_LEARNERS: dict[str, type[RewardLearner]] = {
    "quadratic": QuadraticRewardLearner,
    "maxent": MaxEntIRLRewardLearner,
}


def _jsonable(value: Any) -> Any:
    """A JSON-safe record of a hyperparameter value (callables by qualified name)."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, np.integer | np.floating):
        return value.item()
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, functools.partial):
        return {
            "partial": _jsonable(value.func),
            "args": _jsonable(list(value.args)),
            "kwargs": {k: _jsonable(v) for k, v in value.keywords.items()},
        }
    if callable(value):
        return f"{getattr(value, '__module__', '?')}.{getattr(value, '__qualname__', repr(value))}"
    if isinstance(value, np.random.RandomState | np.random.Generator):
        return f"<{type(value).__name__}>"  # its state is not recorded (a repr has an address)
    return repr(value)


class _TaskSpaceModel:
    """A known model of the env's observations, called on the rows of demos mapped by
    ``transform`` (``dims``, ``angles``): the row is looked up among the demos, the model steps
    its recorded observation, and the next observation is mapped the same way."""

    def __init__(self, model: Any, raw: list[Any], mapped: list[Any], transform: Any) -> None:
        self.model, self.transform = model, transform
        self.raw: dict[bytes, np.ndarray] = {}
        for r, m in zip(raw, mapped, strict=True):
            for row, obs in zip(m.observations, r.observations, strict=True):
                key = np.asarray(row, dtype=np.float64).tobytes()
                if key in self.raw and not np.array_equal(self.raw[key], obs):
                    raise ValueError(
                        f"demo states {self.raw[key]} and {obs} share their task-space values "
                        "(dims, angles) but differ in the observation entries left out, so a "
                        "known model of the observations cannot tell which one to step: give "
                        "the task the entries the model reads (dims), or the model in task space"
                    )
                self.raw[key] = obs

    def __call__(self, state: np.ndarray, action: Any) -> np.ndarray:
        key = np.asarray(state, dtype=np.float64).tobytes()
        if key not in self.raw:
            raise ValueError("a known model with dims/angles can only step the demos' states")
        return self.transform(np.asarray(self.model(self.raw[key], action))[None])[0]


def _record(estimator: Any) -> dict[str, Any]:
    params = {k: _jsonable(v) for k, v in estimator.get_params(deep=False).items()}
    return {"class": type(estimator).__name__, "params": params}


def _build(spec: Any, cls: type, kwargs: dict[str, Any], what: str, base: type) -> Any:
    """``cls(**kwargs)`` from None or a dict of parameters, or a clone of a ``base`` instance."""
    if spec is None:
        return cls(**kwargs)
    if isinstance(spec, dict):
        return cls(**{**spec, **kwargs})
    if not isinstance(spec, base):
        raise TypeError(
            f"{what} must be a {base.__name__}, a dict of parameters or None, "
            f"got {type(spec).__name__}"
        )
    if kwargs:
        raise TypeError(
            f"keyword arguments {sorted(kwargs)} cannot be combined with a {what} instance; "
            "set them on the instance"
        )
    return clone(spec)


def fit_task(
    demos: Any,
    *,
    dims: Any = None,
    angles: Any = None,
    segmentation: TransitionStateClustering | dict[str, Any] | None = None,
    reward: RewardLearner | dict[str, Any] | str | None = None,
    random_state: int | None = None,
    progress: Progress | bool | None = None,
    state_key: str | Sequence[str] | None = None,
    **kwargs: Any,
) -> TaskModel:
    """Learn a SWIRL proxy task (regions and local rewards) from demonstrations.

    Parameters
    ----------
    demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts
        Lists of arrays, :class:`~sb3_swirl.demos.Demonstration`, imitation trajectories,
        Minari episodes, or a ``.npz`` path.
    dims : sequence of int, optional
        Observation dimensions that form the state (e.g. ``(0, 1, 2)`` for x, y, theta);
        ``None`` uses all of them. Recorded in the task so the runtime selects them too.
        With ``angles``, the observation entries passed through besides the angle features
        (required; may be empty).
    angles : sequence of sequences of int, optional
        Observation entries holding wrapped angles: entry ``j`` defines ``phi_j``, the sum of
        the listed entries, and the state gets ``(cos phi_j, sin phi_j)`` in front of
        ``obs[dims]`` (see :class:`swirl_wrappers.TaskModel`). Regions and rewards are then
        continuous across ``±pi``. For the acrobot, ``angles=[[0], [0, 1]], dims=[2, 3]``
        gives the absolute link angles, in which the tip height is linear.
    segmentation : TransitionStateClustering or dict, optional
        The segmenter (cloned before fitting) or its keyword arguments.
    reward : RewardLearner, dict or {"quadratic", "maxent"}, optional
        The reward learner (cloned), keyword arguments of the model-free
        :class:`~sb3_swirl.rewards.QuadraticRewardLearner`, or a learner by name:
        ``"maxent"`` is :class:`~sb3_swirl.rewards.MaxEntIRLRewardLearner` (model-based, needs
        demos with actions; ``dynamics=model`` gives it a known model).
    random_state : int, optional
        Seed of the segmenter (overrides its own ``random_state`` when given).
    progress : callable or bool, optional
        ``progress(message)`` is called at each stage (e.g. to update a status line);
        ``True`` prints the stages.
    state_key : str or sequence of str, optional
        For demos of a ``Dict`` observation given as dicts of per-key arrays (Minari's
        episodes of a goal env, say): the keys joined into the state, in the order of the
        wrapper's ``state_key`` (:func:`~sb3_swirl.demos.as_demonstrations`).
    **kwargs
        Further hyperparameters, routed by name to the segmenter (e.g. ``window``,
        ``indicator``, ``min_demo_fraction``) or the reward learner (e.g. ``metric``).

    Returns
    -------
    TaskModel
        With ``metadata`` recording the estimators and their parameters, ``dims``, the
        number of demonstrations and their lengths, the indicator used (``"indicator"``, the
        one ``"auto"`` chose), each indicator's :func:`~sb3_swirl.dynamics_cv_error` and the
        number of segments each gave (``"indicator_scores"``, ``"indicator_segments"``).

    Examples
    --------
    >>> from sb3_swirl.demos import make_piecewise_linear_demos
    >>> demos, _ = make_piecewise_linear_demos(n_demos=8, random_state=0)
    >>> task = fit_task(demos, window=3, random_state=0)
    >>> task.n_segments
    3
    """
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise ValueError(f"progress must be True, False or a callable, got {progress!r}")
    if progress is True:

        def progress(message: str) -> None:
            print(message)

    report: Progress = progress if callable(progress) else (lambda message: None)

    seg_params = set(inspect.signature(TransitionStateClustering).parameters)
    if isinstance(reward, str):
        if reward not in REWARD_LEARNERS:
            raise ValueError(f"reward must be one of {sorted(REWARD_LEARNERS)}, got {reward!r}")
        reward_cls, reward = REWARD_LEARNERS[reward], None
    else:
        reward_cls = type(reward) if isinstance(reward, RewardLearner) else QuadraticRewardLearner
    reward_params = set(inspect.signature(reward_cls).parameters)
    unknown = set(kwargs) - seg_params - reward_params
    if unknown:
        known = sorted(seg_params | reward_params)
        close = {k: difflib.get_close_matches(k, known, n=1) for k in sorted(unknown)}
        guess = ", ".join(f"{m[0]!r} for {k!r}" for k, m in close.items() if m)
        raise TypeError(
            f"fit_task() got unexpected keyword arguments {sorted(unknown)}"
            + (f" (did you mean {guess}?)" if guess else "")
            + f"; segmentation takes {sorted(seg_params)}, the reward learner "
            f"{sorted(reward_params)}"
        )
    segmenter = _build(
        segmentation,
        TransitionStateClustering,
        {k: v for k, v in kwargs.items() if k in seg_params},
        "segmentation",
        TransitionStateClustering,
    )
    learner = _build(
        reward,
        reward_cls,
        {k: v for k, v in kwargs.items() if k in reward_params and k not in seg_params},
        "reward",
        RewardLearner,
    )
    if random_state is not None:
        if isinstance(random_state, np.random.Generator):
            raise ValueError(
                "random_state must be an integer or a numpy RandomState (sklearn takes no "
                "Generator), got a Generator: pass an integer drawn from it"
            )
        if not isinstance(random_state, np.random.RandomState):  # sklearn takes both
            random_state = check_int("random_state", random_state, low=0, high=2**32 - 1)
        segmenter.set_params(random_state=random_state)

    report("validating demonstrations")
    demos = as_demonstrations(demos, state_key=state_key)
    state_dim = demos[0].observations.shape[1]
    if angles is not None and dims is None:
        raise ValueError(
            "dims must be given with angles: the observation entries passed through besides "
            "the angle features (use () for none)"
        )
    if dims is not None:
        index = np.atleast_1d(dims)
        if index.ndim != 1 or (index.size and index.dtype.kind not in "iu"):
            raise ValueError(f"dims must be integer indices, got {dims!r}")
        dims = tuple(int(d) for d in index)
        if (
            (not dims and angles is None)
            or min(dims, default=0) < 0
            or max(dims, default=0) >= state_dim
        ):
            raise ValueError(
                f"dims must be indices into the {state_dim} observation dimensions, got {dims}"
            )
        if len(set(dims)) < len(dims):  # the task model refuses it, after the whole fit
            raise ValueError(f"dims lists an index more than once: {list(dims)}")
    if angles is not None:
        angles = check_angles(angles)

    def transform(observations: np.ndarray) -> np.ndarray:
        if angles is not None:
            return np.concatenate(
                [angle_features(observations, angles), observations[:, dims]], axis=1
            )
        return observations if dims is None else observations[:, dims]

    raw_demos = demos
    demos = [Demonstration(transform(d.observations), d.actions, d.rewards) for d in demos]

    report(f"learning transition regions from {len(demos)} demonstrations")
    segmenter.fit(demos)
    report(f"learning local rewards for {len(segmenter.regions_)} segments")
    model = getattr(learner, "dynamics", None)
    if callable(model) and (dims is not None or angles is not None):
        # a known model steps the env's observations: hand it the demo rows as recorded
        learner.set_params(dynamics=_TaskSpaceModel(model, raw_demos, demos, transform))
        try:
            learner.fit(demos, segmenter)
        finally:
            learner.set_params(dynamics=model)
    else:
        learner.fit(demos, segmenter)
    lengths = [len(d) for d in demos]
    metadata = {
        "fitted_by": "sb3_swirl.fit_task",
        "n_demos": len(demos),
        "demo_lengths": {"min": min(lengths), "max": max(lengths), "mean": float(np.mean(lengths))},
        "state_dim": state_dim,
        # each dimension's range over the demos' states, for the wrapper to compare with the
        # env's observation bounds (demos in other units or from another env)
        "state_range": {
            "low": np.min([d.observations.min(axis=0) for d in raw_demos], axis=0).tolist(),
            "high": np.max([d.observations.max(axis=0) for d in raw_demos], axis=0).tolist(),
        },
        # the Dict observation keys the demos' states join, in order (None: not recorded)
        "state_key": next((list(d.state_key) for d in raw_demos if d.state_key), None),
        "dims": None if dims is None else list(dims),
        "angles": None if angles is None else [list(a) for a in angles],
        "random_state": _jsonable(random_state),
        "segmentation": _record(segmenter),
        "indicator": _jsonable(segmenter.indicator_),
        "indicator_scores": {  # None: that indicator's fit failed
            name: error if np.isfinite(error) else None
            for name, error in segmenter.indicator_scores_.items()
        },
        "indicator_segments": segmenter.indicator_segments_,  # 0: that indicator's fit failed
        "indicator_failures": segmenter.indicator_failures_,
        "dropped_regions": segmenter.dropped_regions_,
        "cluster_dims": None
        if segmenter.cluster_dims_ is None
        else segmenter.cluster_dims_.tolist(),
        "transitions": [t.tolist() for t in segmenter.transitions_],
        "switches": [t.tolist() for t in segmenter.switches_],
        "reward": _record(learner),
    }
    task = TaskModel(
        regions=segmenter.regions_,
        rewards=learner.rewards_,
        dims=dims,
        features=segmenter.feature_map_,
        metadata=metadata,
        angles=angles,
    )
    report(f"done: {task.n_segments} segment{'s' * (task.n_segments != 1)}")
    return task
