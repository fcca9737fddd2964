"""Gymnasium wrappers that put a SWIRL proxy task on an environment.

The agent of SWIRL (paper §7, Algorithm 3) learns in a lifted state: the observation plus a one-hot
segment index. Each wrapper here steps its episodes through a
:class:`~swirl_wrappers.SegmentTracker` (the timing and reward rules, written once) and a
:class:`Lifter` (reading the task state from observations and appending the one-hot).

``info`` gets ``"segment"`` (index after the step), ``"task_reward"`` (the environment's own
reward) and ``"segment_reward"`` (the reward the wrapper returns), and on a goal env
``"segment_goal"`` (the desired goal of the step, for :meth:`SwirlWrapper.compute_reward`); the
reset ``info`` gets ``"segment"``. The environment's own info keys pass through.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

from swirl_wrappers.task import RewardConfig, TaskModel
from swirl_wrappers.tracker import SegmentTracker

__all__ = [
    "Lifter",
    "SwirlVectorWrapper",
    "SwirlWrapper",
    "lift_observation_space",
    "observation_state",
    "state_space",
]

SEGMENT_KEY = "segment"
TASK_REWARD_KEY, SEGMENT_REWARD_KEY = "task_reward", "segment_reward"
#: info key of a goal env's step: the desired goal the segment reward was computed with
GOAL_KEY = "segment_goal"


StateKey = str | Sequence[str] | None


def lift_observation_space(
    space: gym.Space, task: TaskModel, state_key: StateKey = None
) -> tuple[spaces.Box | spaces.Dict, str | tuple[str, ...] | None]:
    """Check that ``task`` fits observations from ``space`` and build the lifted space.

    Parameters
    ----------
    space : gymnasium.spaces.Box or gymnasium.spaces.Dict
        The environment's (single) observation space. A Box must be 1-D; a Dict must hold a
        1-D Box under each ``state_key`` and no ``"segment"`` key.
    task : TaskModel
    state_key : str or sequence of str, optional
        For Dict spaces, the key of the state the task reads; default ``"observation"``. With
        several keys, the task reads their 1-D Boxes concatenated in that order (e.g.
        ``["observation", "desired_goal"]`` on a goal-conditioned env).

    Returns
    -------
    lifted : Box or Dict
        Box: ``low``/``high`` extended with ``task.n_indices`` zeros/ones, same dtype. Dict: the
        same keys plus ``"segment"``, a ``Box(0, 1, (task.n_indices,), float32)``.
    state_key : str, tuple of str or None
        The key(s) to read the task state from (``None`` for Box spaces).

    Examples
    --------
    >>> import numpy as np
    >>> from gymnasium import spaces
    >>> from swirl_wrappers import QuadraticReward, Region, TaskModel, lift_observation_space
    >>> region, reward = Region([0.5], [[0.01]], 4.0), QuadraticReward([0.5], [[1.0]])
    >>> task = TaskModel([region], [reward], dims=[2])
    >>> lifted, key = lift_observation_space(spaces.Box(-1.0, 1.0, (3,)), task)
    >>> lifted.low, key
    (array([-1., -1., -1.,  0.,  0.], dtype=float32), None)
    """
    if not isinstance(task, TaskModel):
        raise ValueError(f"task must be a swirl_wrappers.TaskModel, got {type(task).__name__}")
    n = task.n_indices
    if isinstance(space, spaces.Box):
        check_state_key_space(space, state_key)
        _check_state_space(space, task, "observation space")
        _warn_other_layout(task, space, None)
        lifted = spaces.Box(
            low=np.concatenate([space.low, np.zeros(n, dtype=space.dtype)]),
            high=np.concatenate([space.high, np.ones(n, dtype=space.dtype)]),
            dtype=space.dtype,
        )
        return lifted, None
    if isinstance(space, spaces.Dict):
        given = state_key
        state, state_key = state_space(space, state_key)
        if SEGMENT_KEY in space.spaces:
            raise ValueError(f"Dict observation space already has a {SEGMENT_KEY!r} key")
        if isinstance(state_key, str):
            name = f"observation space[{state_key!r}]"
        else:
            name = f"observation spaces {list(state_key)} joined"
        try:
            _check_state_space(state, task, name)
        except ValueError as exc:
            recorded = _recorded_keys(task, space)
            if given is None and recorded is not None and recorded != state_key:
                raise ValueError(
                    f"{exc}. The task was fitted on demos that join the keys "
                    f"{list(_key_tuple(recorded))}: pass state_key={list(_key_tuple(recorded))}"
                ) from exc
            raise
        _warn_other_layout(task, state, state_key)
        segment = spaces.Box(0.0, 1.0, (n,), dtype=np.float32)
        return spaces.Dict({**space.spaces, SEGMENT_KEY: segment}), state_key
    if isinstance(space, spaces.MultiDiscrete):
        how = (
            "give the env a Box view of its integers, which keeps their order (e.g. "
            "gymnasium.wrappers.TransformObservation(env, lambda o: o.astype(np.float64), "
            "Box(0, space.nvec - 1, dtype=np.float64)))"
        )
    else:
        how = (
            "wrap the env in gymnasium.wrappers.FlattenObservation first (a Discrete state "
            "becomes one-hot)"
        )
    raise ValueError(
        f"SWIRL wrappers need a Box or Dict observation space, got {type(space).__name__}; "
        f"{how} and record the demos' states the same way"
    )


def check_state_key_space(space: gym.Space, state_key: StateKey) -> None:
    """Refuse a ``state_key`` for an observation space that is not a Dict (a ValueError)."""
    if state_key is not None and not isinstance(space, spaces.Dict):
        raise ValueError(
            f"state_key={state_key!r} is only for Dict observation spaces; this one is a "
            f"{type(space).__name__}"
        )


def state_space(
    space: spaces.Dict, state_key: StateKey = None
) -> tuple[spaces.Box, str | tuple[str, ...]]:
    """The space of the task state in a Dict observation space, and ``state_key`` checked.

    Parameters
    ----------
    space : gymnasium.spaces.Dict
    state_key : str or sequence of str, optional
        As in :func:`lift_observation_space` (default ``"observation"``).

    Returns
    -------
    state : Box
        The 1-D Box under ``state_key``, or those under several keys joined (float64).
    state_key : str or tuple of str
        One key as a str, several as a tuple.

    Raises
    ------
    ValueError
        A key that is missing or not a 1-D Box, or no key at all.
    """
    if state_key is None:
        if "observation" not in space.spaces:
            raise ValueError(
                "Dict observation space has no 'observation' key; pass state_key= naming "
                f"the task state, one of {sorted(space.spaces)}"
            )
        state_key = "observation"
    keys = _key_tuple(state_key)
    for key in keys:
        if key not in space.spaces:
            raise ValueError(
                f"state_key {key!r} is not in the observation space; keys are "
                f"{sorted(space.spaces)}"
            )
    if len(keys) == 1:
        return space.spaces[keys[0]], keys[0]
    for key in keys:
        _check_state_space(space.spaces[key], None, f"observation space[{key!r}]")
    joined = spaces.Box(  # float64 bounds: float32 infinities cast without a warning
        np.concatenate([space.spaces[key].low.astype(np.float64) for key in keys]),
        np.concatenate([space.spaces[key].high.astype(np.float64) for key in keys]),
        dtype=np.float64,
    )
    return joined, keys


def _recorded_keys(task: TaskModel, space: spaces.Dict) -> str | tuple[str, ...] | None:
    """The Dict keys the task's demos were recorded with (``metadata["state_key"]``), where the
    fit recorded them and ``space`` holds them all; else ``None`` (named where the default
    ``"observation"`` does not fit the task)."""
    keys = task.metadata.get("state_key")
    if not isinstance(keys, list | tuple) or not keys:
        return None
    if not all(isinstance(key, str) and key in space.spaces for key in keys):
        return None
    return keys[0] if len(keys) == 1 else tuple(keys)


def _key_tuple(state_key: Any, what: str = "state_key") -> tuple[str, ...]:
    """``state_key``, one key or several, as a tuple of keys; anything else is a ``ValueError``
    (``what`` names it)."""
    keys = (
        (state_key,)
        if isinstance(state_key, str)
        else tuple(state_key)
        if isinstance(state_key, Iterable)
        else ()
    )
    if not keys or not all(isinstance(key, str) for key in keys):
        raise ValueError(f"{what} must be a key or a list of keys, got {state_key!r}")
    twice = sorted({key for key in keys if keys.count(key) > 1})
    if twice:
        raise ValueError(f"{what} names {twice} more than once, got {state_key!r}")
    return keys


def _warn_other_layout(task: TaskModel, state: spaces.Box, state_key: StateKey) -> None:
    """Warn when the wrapper's task state is laid out otherwise than the states the task was
    fitted on, where the fit recorded them (``metadata``): another width, another order of
    the Dict keys (two keys of one width swapped pass every check of the spaces), or demo
    states far outside the state's bounds (other units, another env)."""
    state_dim = state.shape[0]
    fitted_dim, fitted_keys = task.metadata.get("state_dim"), task.metadata.get("state_key")
    if isinstance(fitted_dim, int) and fitted_dim != state_dim and task.state_entries is not None:
        warnings.warn(
            f"the task was fitted on states of {fitted_dim} values and is given states of "
            f"{state_dim}: it reads their entries {list(task.state_entries)}. If the two are "
            "laid out otherwise (another state_key, observation_dims or env), its regions and "
            "rewards read other quantities than the demos'; fit it on demos recorded as these "
            "states are",
            stacklevel=4,
        )
    keys = [] if state_key is None else list(_key_tuple(state_key))
    if isinstance(fitted_keys, list | tuple) and keys and list(fitted_keys) != keys:
        warnings.warn(
            f"the task was fitted on states that join the keys {list(fitted_keys)}, in that "
            f"order; this wrapper's join {keys}: its regions and rewards then read other "
            "quantities than the demos' (pass state_key as the demos were recorded)",
            stacklevel=4,
        )
    if fitted_dim == state_dim:
        _warn_out_of_bounds(task.metadata.get("state_range"), state)


def _warn_out_of_bounds(fitted: Any, state: spaces.Box) -> None:
    """Warn where the demos' states (``metadata["state_range"]``) reach beyond a finite bound of
    ``state`` by over a quarter of its width: a demo in cm for an env in m never enters the
    task's regions, and nothing else tells."""
    try:
        low, high = (np.asarray(fitted[end], dtype=np.float64) for end in ("low", "high"))
    except (TypeError, KeyError, ValueError):
        return  # not recorded (an older fit, a hand-made task)
    far = far_outside_bounds(low, high, state)
    if far:
        warnings.warn(
            f"the task was fitted on states far outside this env's observation bounds ({far}): "
            "were the demos recorded in other units, or on another env? Its regions are then "
            "never entered and its rewards read other quantities: fit it on demos of this "
            "env's states",
            stacklevel=5,
        )


def far_outside_bounds(low: np.ndarray, high: np.ndarray, space: spaces.Box) -> str:
    """The dims bounded on both sides in ``space`` where states ranging over ``low .. high``
    reach beyond a bound by over a quarter of the width, as ``"dim 0: [lo, hi] against [a, b],
    ..."``; ``""`` where none does (or the shapes differ)."""
    if low.shape != space.shape or high.shape != space.shape:
        return ""
    bound_low, bound_high = space.low.astype(np.float64), space.high.astype(np.float64)
    width = bound_high - bound_low
    finite = np.isfinite(width) & (width > 0)
    margin = np.where(finite, 0.25 * width, np.inf)
    far = np.flatnonzero(finite & ((low < bound_low - margin) | (high > bound_high + margin)))
    if not far.size:
        return ""
    shown = ", ".join(
        f"{i}: [{low[i]:.4g}, {high[i]:.4g}] against [{bound_low[i]:.4g}, {bound_high[i]:.4g}]"
        for i in far[:4]
    )
    return f"dim {shown}" + (f" and {far.size - 4} more" if far.size > 4 else "")


def _check_state_space(space: gym.Space, task: TaskModel | None, name: str) -> None:
    if isinstance(space, spaces.Box) and len(space.shape) > 1 and space.dtype == np.uint8:
        raise ValueError(
            f"{name} is an image, {space}: SWIRL's regions and rewards are Gaussians and "
            "quadratics over a low-dimensional state, not pixels. Give the task such a state "
            "(positions, angles, features you compute from the image), e.g. as a key of a "
            "Dict observation beside the image (state_key=...)"
        )
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise ValueError(
            f"{name} must be a 1-D Box to hold the task state, got {space}; flatten it first "
            "(gymnasium.wrappers.FlattenObservation)"
        )
    if task is None:
        return
    try:
        task.check_state_dim(space.shape[0])
    except ValueError as exc:
        raise ValueError(f"task does not fit the {name} {space}: {exc}") from exc


def observation_state(obs: Any, state_key: StateKey = None) -> np.ndarray:
    """The task state in an observation (or a batch): ``obs`` itself (Box observations), the
    value under ``state_key``, or the values under several keys concatenated in order.

    Parameters
    ----------
    obs : array or dict of arrays
        One observation or a batch (leading axis).
    state_key : str or sequence of str, optional
        The Dict key(s) of the task state; ``None`` for Box observations.

    Returns
    -------
    numpy.ndarray
        The state, of shape (state_dim,) or (n, state_dim).

    Examples
    --------
    >>> import numpy as np
    >>> obs = {"observation": np.zeros(2), "desired_goal": np.ones(1)}
    >>> observation_state(obs, ["observation", "desired_goal"])
    array([0., 0., 1.])
    """
    if state_key is None:
        return obs
    if isinstance(state_key, str):
        return obs[state_key]
    return np.concatenate([obs[key] for key in state_key], axis=-1)


def _real(value: Any) -> bool:
    """Whether ``value`` reads as one real number: numpy's scalars (booleans too) and arrays
    of one numeric value, as some envs return their reward."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        return False
    return array.size == 1 and array.dtype.kind in "biuf"


def _keys_read(space: gym.Space, task: TaskModel, state_key: StateKey) -> list[str]:
    """The keys of a Dict observation whose values the task reads: those of ``state_key``
    that hold one of the task's ``state_entries`` in the joined state."""
    if state_key is None:
        return []
    keys = list(_key_tuple(state_key))
    entries = task.state_entries
    if entries is None:
        return keys
    read, start = [], 0
    for key in keys:
        stop = start + int(np.prod(space[key].shape))
        if any(start <= i < stop for i in entries):
            read.append(key)
        start = stop
    return read


class Lifter:
    """Reads the task state from observations and appends the one-hot segment index.

    Parameters
    ----------
    space : Box or Dict
        The (single) observation space of the environment.
    task : TaskModel
    state_key : str or sequence of str, optional
        As in :func:`lift_observation_space`.

    Attributes
    ----------
    observation_space : Box or Dict
        The lifted space (:func:`lift_observation_space`).
    state_key : str, tuple of str or None
    """

    def __init__(self, space: gym.Space, task: TaskModel, state_key: StateKey = None) -> None:
        self.observation_space, self.state_key = lift_observation_space(space, task, state_key)
        lifted = self.observation_space
        dtype = lifted.dtype if self.state_key is None else lifted[SEGMENT_KEY].dtype
        self._one_hot = np.eye(task.n_indices, dtype=dtype)
        self._one_hot.flags.writeable = False
        state = space if self.state_key is None else state_space(space, self.state_key)[0]
        self._width = int(state.shape[-1])  # the values of a state

    def state(self, obs: Any) -> np.ndarray:
        """The task state in an (unlifted) observation or batch of observations.

        Raises
        ------
        ValueError
            An observation of another width than the env's observation space declares (an env
            that breaks its own space: the task's regions would read other quantities).
        """
        state = observation_state(obs, self.state_key)
        try:  # an array's last axis, at every step: kept cheap
            wide = state.shape[-1] != self._width
        except (AttributeError, IndexError):  # a list, a 0-d value
            wide = np.shape(state)[-1:] != (self._width,)
        if wide:
            raise ValueError(
                f"the env returned an observation of shape {np.shape(state)}"
                + ("" if self.state_key is None else f" under {self.state_key!r}")
                + f" where its observation space declares {self._width} value"
                + "s" * (self._width != 1)
            )
        return state

    def lift(self, obs: Any, index: Any) -> Any:
        """``obs`` with the one-hot of ``index`` appended: an int for one observation, an array
        for a batch. Box observations get it concatenated on the last axis, Dict observations
        as a ``"segment"`` key."""
        one_hot = self._one_hot[index]
        if self.state_key is None:
            return np.concatenate((obs, one_hot), axis=-1)
        return {**obs, SEGMENT_KEY: one_hot.copy()}


class TrackedTask:
    """The task and settings of a wrapper's :class:`SegmentTracker` (``self.tracker``), as the
    attributes every SWIRL wrapper exposes."""

    tracker: SegmentTracker
    _warned_overwritten: bool = False  # _warn_overwritten's warning, once per wrapper

    @property
    def task(self) -> TaskModel:
        return self.tracker.task

    @property
    def reward_config(self) -> RewardConfig:
        return self.tracker.config

    @property
    def terminate_on_completion(self) -> bool:
        return self.tracker.terminate_on_completion

    @property
    def state_key(self) -> str | tuple[str, ...] | None:
        """The observation key(s) the task state is read from (``None``: Box observations)."""
        return self.lifter.state_key

    def _warn_overwritten(self, *infos: Mapping[str, Any]) -> None:
        """Warn, once, where the env's own infos hold a key the wrapper writes."""
        if self._warned_overwritten:
            return
        keys = (SEGMENT_KEY, TASK_REWARD_KEY, SEGMENT_REWARD_KEY)
        taken = sorted({k for info in infos for k in keys if k in info}, key=keys.index)
        if taken:
            self._warned_overwritten = True
            warnings.warn(
                f"the env's info holds {taken}, which {type(self).__name__} writes (the segment "
                "index, the env's reward, the segment reward): the env's values are overwritten. "
                "Rename those keys in the env to keep them",
                stacklevel=3,
            )


def _refuse_below(env: Any, wrapper: str) -> None:
    """Raise if a wrapper that breaks a SWIRL wrapper sits below it: observation normalisation
    (the task's regions live in the raw observation space, so normalised states would be
    segmented wrongly), gymnasium's ``Autoreset`` (it starts a new episode inside a step, which
    the tracker would take for a step of the old one, in its segment), or another SWIRL
    wrapper (the observations would be lifted twice, by two trackers)."""
    normalisers = (gym.wrappers.NormalizeObservation, gym.wrappers.vector.NormalizeObservation)
    while isinstance(env, gym.Wrapper | VectorWrapper):
        name = type(env).__name__
        if isinstance(env, TrackedTask):
            raise ValueError(
                f"{wrapper} over {name}: the env's observations are lifted already (they "
                "carry a segment); wrap the env with one SWIRL wrapper"
            )
        if isinstance(env, normalisers):
            raise ValueError(
                f"{wrapper} must sit below {name}: the task reads raw states. Wrap as "
                f"{name}({wrapper}(env, task)), not {wrapper}({name}(env), task)"
            )
        if isinstance(env, gym.wrappers.Autoreset):
            raise ValueError(
                f"{wrapper} must sit below Autoreset, which starts a new episode inside a step: "
                "the tracker would score its first state as a step of the old episode, in the "
                f"old segment. Wrap as Autoreset({wrapper}(env, task))"
            )
        env = env.env
    for i, sub in enumerate(getattr(env, "envs", ())):  # a SyncVectorEnv's (an async one's
        try:  # sub-envs live in other processes, out of reach)
            _refuse_below(sub, wrapper)
        except ValueError as exc:
            if "lifted already" in str(exc):
                raise ValueError(
                    f"{wrapper} over a vector env whose sub-env {i} is wrapped with a SWIRL "
                    "wrapper already: lift the observations once, with the sub-envs' wrapper "
                    f"or with {wrapper} over plain sub-envs"
                ) from None
            if "Autoreset" in str(exc):
                raise
            on_top = (
                "SB3's VecNormalize(SwirlVecEnv(venv, task))"
                if wrapper == "SwirlVecEnv"
                else f"gymnasium.wrappers.vector.NormalizeObservation({wrapper}(envs, task))"
            )
            raise ValueError(
                f"{wrapper} must sit below observation normalisation, but sub-env {i} "
                "normalises its observations: the task reads raw states. Normalise the "
                f"vector env on top instead: {on_top}"
            ) from None


def _refuse_monitor_below(env: Any) -> None:
    """Raise if an episode recorder (SB3's ``Monitor``, gymnasium's
    ``RecordEpisodeStatistics``) sits below a SwirlWrapper that ends episodes itself: it would
    never see those episodes end, and record none of them (only the failed ones)."""
    while isinstance(env, gym.Wrapper):
        if any(  # by name: this package does not depend on SB3; subclasses count
            kind.__name__ == "Monitor" and kind.__module__.startswith("stable_baselines3")
            for kind in type(env).__mro__
        ):
            raise ValueError(
                "SwirlWrapper(terminate_on_completion=True) must sit below SB3's Monitor, which "
                "would never see the episodes it ends: wrap as Monitor(SwirlWrapper(env, task, "
                "...)), as sb3_swirl.make_swirl_env(env_id, task, wrapper_kwargs=...) does. "
                "make_vec_env(..., wrapper_class=SwirlWrapper) and the zoo put Monitor first"
            )
        if isinstance(env, gym.wrappers.RecordEpisodeStatistics):
            raise ValueError(
                "SwirlWrapper(terminate_on_completion=True) must sit below "
                "RecordEpisodeStatistics, which would never see the episodes it ends (it would "
                "record only the failed ones): wrap as RecordEpisodeStatistics(SwirlWrapper(env, "
                "task, ...))"
            )
        env = env.env


def _as_task(task: Any) -> TaskModel:
    """``task``, or the task of a mapping of its fields (as ``TaskModel.to_dict`` writes it, and
    as a wrapper's ``env.spec`` records it)."""
    if isinstance(task, Mapping):
        return TaskModel.from_dict(task)
    if not isinstance(task, TaskModel):
        raise ValueError(
            "task must be a TaskModel (TaskModel.from_json reads a file), got "
            f"{type(task).__name__}"
        )
    return task


def _recorded(reward_config: Any) -> Any:
    """``reward_config`` as ``env.spec`` records it: a RewardConfig as its fields."""
    return reward_config.to_dict() if isinstance(reward_config, RewardConfig) else reward_config


def relabelling_refused(keys: list[str]) -> str:
    """Why hindsight relabelling (``HerReplayBuffer``) cannot work when the task reads ``keys``."""
    return (
        f"SwirlWrapper refuses relabelled goals (HerReplayBuffer): its task reads {keys}, so "
        "the segment reward follows the path under the episode's own goal and cannot be "
        "recomputed for another one. Give the task a state without the goal (e.g. "
        "state_key='observation') to use hindsight relabelling, or train without "
        "HerReplayBuffer"
    )


class SwirlWrapper(TrackedTask, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Track the segment of a SWIRL proxy task and reward the agent with its local reward.

    The observation gets a one-hot segment index appended (Box observations) or a ``"segment"``
    key (Dict observations); the reward is the segment reward as the
    :class:`~swirl_wrappers.RewardConfig` says (default: the task's own, the paper's
    ``R_i(s')`` of the segment ``i`` in force before the step). See
    :mod:`swirl_wrappers.tracker` for the exact timing. The infos get ``"segment"``, and the
    step infos ``"task_reward"`` (the env's own reward) and ``"segment_reward"``; an env's own
    info keys of these names are overwritten, with a warning the first time.

    Parameters
    ----------
    env : gymnasium.Env
        Environment with a 1-D Box or a Dict observation space.
    task : TaskModel or dict
        The proxy task (or its fields, ``TaskModel.to_dict``); its ``dims`` / features must fit
        the observation.
    reward_config : RewardConfig or dict, optional
        How the agent is rewarded; default ``task.reward_config``. A dict changes only the
        fields it names (:meth:`RewardConfig.updated`).
    terminate_on_completion : bool
        End the episode (``terminated=True``) when the last region is reached. With SB3,
        ``Monitor`` must be outside this wrapper, to record such episodes (``make_swirl_env``
        puts it there); an SB3 ``Monitor`` inside is refused.
    state_key : str or sequence of str, optional
        For Dict observations, the key holding the task state (default ``"observation"``), or
        keys whose values the task reads concatenated (:func:`lift_observation_space`).

    Attributes
    ----------
    task : TaskModel
    reward_config : RewardConfig
    tracker : SegmentTracker
    segment : int
        The current segment index, in ``0 .. task.n_segments``.
    potential : float
        ``Phi`` of the current lifted state (``"potential"`` mode; 0 after a termination).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> from swirl_wrappers import QuadraticReward, Region, SwirlWrapper, TaskModel
    >>> task = TaskModel(  # region 0: the pole within 0.05 rad of upright; reward: keep it at 0
    ...     regions=[Region(mean=[0.0], covariance=[[0.05**2]], threshold=1.0)],
    ...     rewards=[QuadraticReward(target=[0.0], weight=[[100.0]])],
    ...     dims=[2],
    ... )
    >>> env = SwirlWrapper(gym.make("CartPole-v1"), task, reward_config={"region_bonus": 1.0})
    >>> env.observation_space.shape
    (6,)
    >>> obs, info = env.reset(seed=0)
    >>> obs[4:], info["segment"]
    (array([0., 1.], dtype=float32), 1)
    >>> obs, reward, terminated, truncated, info = env.step(0)
    >>> sorted(k for k in info if k != "episode")
    ['segment', 'segment_reward', 'task_reward']
    >>> info["task_reward"], reward == info["segment_reward"]
    (1.0, True)
    >>> bool(np.isclose(reward, -100.0 * float(obs[2]) ** 2))  # R_1 = R_0 once all are reached
    True
    """

    def __init__(
        self,
        env: gym.Env,
        task: TaskModel | Mapping[str, Any],
        reward_config: RewardConfig | dict[str, Any] | None = None,
        terminate_on_completion: bool = False,
        state_key: StateKey = None,
    ) -> None:
        task = _as_task(task)
        gym.utils.RecordConstructorArgs.__init__(  # as JSON-able values: env.spec.to_json()
            self,
            task=task.to_dict(),
            reward_config=_recorded(reward_config),
            terminate_on_completion=terminate_on_completion,
            state_key=state_key,
        )
        if isinstance(env, VectorEnv) or hasattr(env, "step_async"):  # gymnasium's, SB3's
            raise ValueError(
                f"SwirlWrapper wraps one env, got the vector env {type(env).__name__}: wrap it "
                "with SwirlVectorWrapper (gymnasium's vector envs) or sb3_swirl.SwirlVecEnv "
                "(SB3's VecEnv), or wrap each sub-env with SwirlWrapper"
            )
        gym.Wrapper.__init__(self, env)
        _refuse_below(env, "SwirlWrapper")
        self.lifter = Lifter(env.observation_space, task, state_key)
        self.observation_space = self.lifter.observation_space
        self.tracker = SegmentTracker(
            task, reward_config, terminate_on_completion=terminate_on_completion
        )
        if self.tracker.terminate_on_completion:
            _refuse_monitor_below(env)
        # a goal env as HER sees one: compute_reward and Dict observations with the goal (a
        # goal env flattened to a Box is a plain env here)
        self._goal_env = (
            hasattr(env.unwrapped, "compute_reward")
            and isinstance(env.observation_space, spaces.Dict)
            and "desired_goal" in env.observation_space.spaces
        )
        goal_keys = getattr(env.unwrapped, "goal_keys", ("desired_goal",))
        self._reads_goal = [
            key
            for key in _keys_read(env.observation_space, task, self.lifter.state_key)
            if key in goal_keys
        ]
        self._warned_unweighted = False  # compute_reward's warning, once

    @property
    def segment(self) -> int:
        return int(self.tracker.index)

    @property
    def reads_goal(self) -> list[str]:
        """The env's goal keys (``goal_keys``, default ``("desired_goal",)``) that the task
        state reads: where any is, hindsight relabelling is refused."""
        return list(self._reads_goal)

    @property
    def potential(self) -> float:
        return float(self.tracker.potential)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._warn_overwritten(info)
        self.tracker.reset(self.lifter.state(obs))
        segment = int(self.tracker.index)
        info[SEGMENT_KEY] = segment
        return self.lifter.lift(obs, segment), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, task_reward, terminated, truncated, info = self.env.step(action)
        self._warn_overwritten(info)
        if type(task_reward) is not float and not _real(task_reward):  # float: the fast path
            raise ValueError(f"the env's step returned the reward {task_reward!r}, not a number")
        reward, terminated = self.tracker.step(self.lifter.state(obs), task_reward, terminated)
        reward, segment = float(reward), int(self.tracker.index)
        info[SEGMENT_KEY] = segment
        info[TASK_REWARD_KEY] = task_reward
        info[SEGMENT_REWARD_KEY] = reward
        if self._goal_env:
            info[GOAL_KEY] = np.array(obs["desired_goal"])
        return self.lifter.lift(obs, segment), reward, bool(terminated), truncated, info

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        """The reward of recorded steps for other desired goals, on a goal env (vectorised, as
        ``HerReplayBuffer`` and SB3's ``check_env`` call it).

        The agent's reward is the segment part plus ``task_reward_weight`` times the env's own
        reward. Only the latter depends on the goal when the task state does not read it, so
        it is recomputed with the env's ``compute_reward`` and the segment part is kept from
        ``info``: hindsight relabelling works with SWIRL on the goal-independent states.

        Raises
        ------
        AttributeError
            If the wrapped env is not a goal env (has no ``compute_reward``, or its
            observations are not a Dict with a ``"desired_goal"`` key).
        ValueError
            For a goal other than the step's when the task reads the goal (its
            ``state_entries`` fall in a key among the env's ``goal_keys``, default
            ``("desired_goal",)``): the segment, and so
            the segment reward, follows the whole path under the goal the episode was run
            with, and relabelling one transition cannot redo that.
        """
        if not self._goal_env:
            raise AttributeError(
                f"{type(self.env.unwrapped).__name__} is not a goal env here (it needs "
                "compute_reward and Dict observations with a 'desired_goal' key)"
            )
        infos = [info] if isinstance(info, dict) else list(info)
        weight = self.reward_config.task_reward_weight
        if self._reads_goal or (weight == 0.0 and not self._warned_unweighted):
            recorded = [i.get(GOAL_KEY) for i in infos]
            relabelled = any(goal is None for goal in recorded) or not np.array_equal(
                np.reshape(recorded, np.shape(desired_goal)), desired_goal
            )
            if self._reads_goal and relabelled:
                raise ValueError(relabelling_refused(self._reads_goal))
            if weight == 0.0 and relabelled:
                self._warned_unweighted = True  # once per wrapper
                warnings.warn(
                    "relabelled goals change no reward here: the agent's reward does not "
                    "depend on the goal, as the task's reward settings weigh the env's own "
                    "reward by task_reward_weight=0. Give it a weight (e.g. reward_config="
                    "{'mode': 'potential'}) for the relabelled goals to count",
                    stacklevel=2,
                )
        if any(SEGMENT_REWARD_KEY not in i or TASK_REWARD_KEY not in i for i in infos):
            raise ValueError(
                "SwirlWrapper.compute_reward needs each step's info (its 'segment_reward' and "
                "'task_reward'); with HerReplayBuffer pass "
                "replay_buffer_kwargs=dict(copy_info_dict=True)"
            )
        segment_rewards = np.array([i[SEGMENT_REWARD_KEY] for i in infos], dtype=np.float64)
        task_rewards = np.array([i[TASK_REWARD_KEY] for i in infos], dtype=np.float64)
        env_rewards = np.asarray(
            self.env.get_wrapper_attr("compute_reward")(achieved_goal, desired_goal, info),
            dtype=np.float64,
        ).reshape(task_rewards.shape)
        rewards = segment_rewards + weight * (env_rewards - task_rewards)
        return float(rewards[0]) if isinstance(info, dict) else rewards


class SwirlVectorWrapper(TrackedTask, VectorWrapper, gym.utils.RecordConstructorArgs):
    """:class:`SwirlWrapper` for gymnasium vector environments, vectorised across sub-envs.

    Handles the three autoreset modes of gymnasium 1.x: ``NEXT_STEP`` (the default: the step
    after a done returns the reset observation, with reward 0 here too), ``SAME_STEP`` (the
    reward of a done sub-env is that of its final transition, the final observation in
    ``infos["final_obs"]`` is lifted with the index it ended with, and ``infos["segment"]`` is
    the new episode's index, as a reset info would say) and ``DISABLED`` (reset sub-envs with
    ``reset(options={"reset_mask": mask})``). ``infos`` gets ``"segment"``, ``"task_reward"``
    and ``"segment_reward"`` arrays with their ``"_"`` masks, as from a vector env of
    :class:`SwirlWrapper` s: a sub-env that was reset holds a reset's info (``"segment"``
    only), and in ``SAME_STEP`` mode the ended transitions' keys are in ``infos["final_info"]``.
    Observations, rewards and indices are those of independent :class:`SwirlWrapper` s, bit for
    bit (one tracker, the same arithmetic per sub-env).

    A vector wrapper cannot end one sub-env's episode: for ``terminate_on_completion``, wrap
    each sub-env with :class:`SwirlWrapper` instead (``gymnasium.make_vec(...,
    wrappers=[...])``).

    Parameters
    ----------
    env : gymnasium.vector.VectorEnv
    task, reward_config, state_key
        As in :class:`SwirlWrapper`.

    Examples
    --------
    >>> import gymnasium as gym
    >>> from swirl_wrappers import QuadraticReward, Region, SwirlVectorWrapper, TaskModel
    >>> task = TaskModel(
    ...     regions=[Region(mean=[0.0], covariance=[[0.01**2]], threshold=9.0)],
    ...     rewards=[QuadraticReward(target=[0.0], weight=[[100.0]])],
    ...     dims=[2],
    ... )
    >>> envs = SwirlVectorWrapper(gym.make_vec("CartPole-v1", num_envs=3), task)
    >>> obs, infos = envs.reset(seed=0)
    >>> obs.shape, infos["segment"].tolist()
    ((3, 6), [1, 1, 1])
    >>> obs, rewards, terminations, truncations, infos = envs.step(envs.action_space.sample())
    >>> bool((rewards == -100.0 * obs[:, 2].astype(float) ** 2).all())
    True
    >>> envs.close()
    """

    def __init__(
        self,
        env: VectorEnv,
        task: TaskModel | Mapping[str, Any],
        reward_config: RewardConfig | dict[str, Any] | None = None,
        state_key: StateKey = None,
    ) -> None:
        task = _as_task(task)
        gym.utils.RecordConstructorArgs.__init__(  # as JSON-able values
            self, task=task.to_dict(), reward_config=_recorded(reward_config), state_key=state_key
        )
        VectorWrapper.__init__(self, env)
        _refuse_below(env, "SwirlVectorWrapper")
        self.autoreset_mode = AutoresetMode(
            env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        )
        self.lifter = Lifter(env.single_observation_space, task, state_key)
        self.tracker = SegmentTracker(task, reward_config, num_envs=self.num_envs)
        self.single_observation_space = self.lifter.observation_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        mask = None if options is None else options.get("reset_mask")  # before env.reset pops it
        mask = np.ones(self.num_envs, dtype=bool) if mask is None else np.asarray(mask, bool)
        obs, infos = self.env.reset(seed=seed, options=options)
        self._warn_overwritten(infos)
        self.tracker.reset(self.lifter.state(obs), mask)
        self._autoreset = self._autoreset & ~mask
        infos[SEGMENT_KEY] = self.tracker.index.copy()  # not the tracker's own array
        infos["_" + SEGMENT_KEY] = mask  # the rows that were reset
        return self.lifter.lift(obs, self.tracker.index), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, task_rewards, terminations, truncations, infos = self.env.step(actions)
        self._warn_overwritten(infos)
        done = terminations | truncations
        restart = final_states = None
        stepped = np.ones(self.num_envs, dtype=bool)  # rows whose info is a step's
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            # The rows done last step hold reset observations: no transition, a reset's info.
            if self._autoreset.any():
                restart, stepped = self._autoreset, ~self._autoreset
            self._autoreset = done
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            # A done row holds the next episode's first observation; the transition ended in
            # infos["final_obs"].
            restart, stepped = done, ~done
            final_obs = infos["final_obs"]
            final_states = np.array([self.lifter.state(final_obs[i]) for i in np.flatnonzero(done)])
        rewards, _ = self.tracker.step(
            self.lifter.state(obs),
            task_rewards,
            terminations,
            restart=restart,
            final_states=final_states,
        )
        if final_states is not None:
            for i in np.flatnonzero(done):
                final_obs[i] = self.lifter.lift(final_obs[i], self.tracker.ended_index[i])
            # The ended transitions' keys go with their final_info, as the sub-envs' would.
            final_info = infos.setdefault("final_info", {})
            for key, values in (
                (SEGMENT_KEY, self.tracker.ended_index.copy()),
                (TASK_REWARD_KEY, np.array(task_rewards)),
                (SEGMENT_REWARD_KEY, rewards.copy()),
            ):
                final_info[key], final_info["_" + key] = values, done
        # copies: an agent that edits its rewards or infos must not edit the tracker's state
        infos[SEGMENT_KEY] = self.tracker.index.copy()
        infos["_" + SEGMENT_KEY] = np.ones(self.num_envs, dtype=bool)
        infos[TASK_REWARD_KEY] = np.array(task_rewards)  # the sub-envs reuse their buffer
        infos[SEGMENT_REWARD_KEY] = rewards.copy()
        infos["_" + TASK_REWARD_KEY] = infos["_" + SEGMENT_REWARD_KEY] = stepped
        return self.lifter.lift(obs, self.tracker.index), rewards, terminations, truncations, infos
