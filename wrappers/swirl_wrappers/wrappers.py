"""Gymnasium wrappers that put a SWIRL proxy task on an environment.

The agent of SWIRL (paper §7, Algorithm 3) learns in a lifted state: the observation plus a one-hot
segment index. Each wrapper here tracks that index with the task's Markov segmentation function
and replaces the reward with the current segment's local reward.

Timing, the same in every wrapper (and in :meth:`TaskModel.segment_indices`):

* on reset, ``t = 0`` and the index starts at 0, then the segmentation function is applied to the
  initial state once, so an episode that starts inside region 0 starts at index 1;
* on each step, ``t`` grows by one, the reward is ``reward_scale * R_i(s')`` with ``i`` the index
  *before* the step (Algorithm 3: observe ``R_i``, update the state, then advance if
  ``s' in rho_i``), plus ``region_bonus`` when ``s'`` reaches region ``i``; then the index
  advances and the returned observation carries the new index;
* after the last region (index ``k``), the reward stays that of segment ``k - 1``.

Reward modes (``reward_mode``), the same in every wrapper:

* ``"quadratic"`` (default; the paper's proxy reward): ``reward_scale * R_i(s')``
  (+ ``region_bonus`` on a step that reaches region ``i``). ``R_i <= 0``, so when episodes can
  end early (a crash) a negative per-step reward makes ending them early look good.
* ``"potential"``: potential-based shaping of the environment's own reward (Ng et al., 1999),
  ``task_reward_weight * r_env + reward_scale * (gamma * Phi(s', i') - Phi(s, i))``
  (+ ``region_bonus``) with the SWIRL progress potential ``Phi(s, i) = i + 1 / (1 - R_i(s))``
  (segments done plus closeness to the next region, in ``(i, i + 1]``) and ``Phi = 0`` after a
  termination. Over an episode the shaping telescopes, so every policy's shaped return is its
  discounted task return times ``task_reward_weight`` minus ``reward_scale * Phi(s_0)``: the
  optimal policies are the true task's (with ``region_bonus = 0`` and ``gamma`` equal to the
  agent's discount), while the segment rewards give a dense signal towards the next region.

In both modes ``task_reward_weight`` adds the environment's own reward (default 0 for
``"quadratic"``, 1 for ``"potential"``, where it must be positive: shaping alone has no goal).

``info`` gets ``"segment"`` (index after the step), ``"task_reward"`` (the environment's own
reward) and ``"segment_reward"`` (the reward the wrapper returns); the reset ``info`` gets
``"segment"``. The environment's own info keys pass through.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

from swirl_wrappers import _compiled
from swirl_wrappers._checks import is_bool, is_integer
from swirl_wrappers.task import TaskModel

__all__ = [
    "REWARD_MODES",
    "SegmentTracker",
    "SwirlVectorWrapper",
    "SwirlWrapper",
    "lift_observation",
    "lift_observation_space",
    "progress_potential",
]

SEGMENT_KEY = "segment"
TASK_REWARD_KEY, SEGMENT_REWARD_KEY = "task_reward", "segment_reward"
# Where an SB3 vector env puts the last observation of an episode it reset in the same step.
TERMINAL_OBSERVATION_KEY = "terminal_observation"
# The addresses ``_compiled.step_infos`` stores with (its ``addresses`` layout): module
# constants, alive as long as the module. An argument, not a global of the kernel: numba would
# bake a global array into its on-disk cache, and addresses change from process to process.
_INFO_ADDRESSES = np.array(
    [
        id(dict),
        id(TERMINAL_OBSERVATION_KEY),
        id(SEGMENT_KEY),
        id(TASK_REWARD_KEY),
        id(SEGMENT_REWARD_KEY),
    ]
)
_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))
_BOOL = np.dtype(bool)
# Compared with an array's dtype: several times cheaper than comparing with np.float32 (and
# np.empty takes a dtype faster than a type).
_FLOAT32, _INT64 = np.dtype(np.float32), np.dtype(np.int64)


def lift_observation_space(
    space: gym.Space, task: TaskModel, state_key: str | None = None
) -> tuple[spaces.Box | spaces.Dict, str | None]:
    """Check that ``task`` fits observations from ``space`` and build the lifted space.

    Parameters
    ----------
    space : gymnasium.spaces.Box or gymnasium.spaces.Dict
        The environment's (single) observation space. A Box must be 1-D; a Dict must hold a
        1-D Box under ``state_key`` and no ``"segment"`` key.
    task : TaskModel
    state_key : str, optional
        For Dict spaces, the key of the state the task reads; default ``"observation"``.

    Returns
    -------
    lifted : Box or Dict
        Box: ``low``/``high`` extended with ``task.n_indices`` zeros/ones, same dtype. Dict: the
        same keys plus ``"segment"``, a ``Box(0, 1, (task.n_indices,), float32)``.
    state_key : str or None
        The key to read the task state from (``None`` for Box spaces).

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
        if state_key is not None:
            raise ValueError(
                f"state_key={state_key!r} is only for Dict observation spaces; this one is a Box"
            )
        _check_state_space(space, task, "observation space")
        lifted = spaces.Box(
            low=np.concatenate([space.low, np.zeros(n, dtype=space.dtype)]),
            high=np.concatenate([space.high, np.ones(n, dtype=space.dtype)]),
            dtype=space.dtype,
        )
        return lifted, None
    if isinstance(space, spaces.Dict):
        if state_key is None:
            if "observation" not in space.spaces:
                raise ValueError(
                    "Dict observation space has no 'observation' key; pass state_key= naming "
                    f"the task state, one of {sorted(space.spaces)}"
                )
            state_key = "observation"
        if state_key not in space.spaces:
            raise ValueError(
                f"state_key {state_key!r} is not in the observation space; keys are "
                f"{sorted(space.spaces)}"
            )
        if SEGMENT_KEY in space.spaces:
            raise ValueError(f"Dict observation space already has a {SEGMENT_KEY!r} key")
        _check_state_space(space.spaces[state_key], task, f"observation space[{state_key!r}]")
        segment = spaces.Box(0.0, 1.0, (n,), dtype=np.float32)
        return spaces.Dict({**space.spaces, SEGMENT_KEY: segment}), state_key
    raise ValueError(
        f"SWIRL wrappers need a Box or Dict observation space, got {type(space).__name__}"
    )


def _check_state_space(space: gym.Space, task: TaskModel, name: str) -> None:
    if not isinstance(space, spaces.Box) or len(space.shape) != 1:
        raise ValueError(
            f"{name} must be a 1-D Box to hold the task state, got {space}; flatten it first "
            "(gymnasium.wrappers.FlattenObservation)"
        )
    try:
        task.check_state_dim(space.shape[0])
    except ValueError as exc:
        raise ValueError(f"task does not fit the {name} {space}: {exc}") from exc


def _check_scalars(
    first: float, second: float, names: tuple[str, str] = ("reward_scale", "region_bonus")
) -> tuple[float, float]:
    """The two settings as floats, each a finite real number >= 0 (a negative one would
    reward moving away from the regions or penalise the task)."""
    values = []
    for name, value in zip(names, (first, second), strict=True):
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            raise ValueError(f"{name} must be a number, got {value!r}")
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        values.append(float(value))
    return values[0], values[1]


REWARD_MODES = ("quadratic", "potential")


def _check_reward_options(
    reward_mode: str, task_reward_weight: float | None, gamma: float
) -> tuple[str, float, float]:
    if reward_mode not in REWARD_MODES:
        raise ValueError(f"reward_mode must be one of {REWARD_MODES}, got {reward_mode!r}")
    if task_reward_weight is None:
        task_reward_weight = 1.0 if reward_mode == "potential" else 0.0
    weight, gamma = _check_scalars(task_reward_weight, gamma, ("task_reward_weight", "gamma"))
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must be in [0, 1], got {gamma}")
    if reward_mode == "potential" and weight <= 0.0:
        raise ValueError(
            "reward_mode='potential' shapes the environment's own reward and needs "
            f"task_reward_weight > 0 (shaping alone leaves every policy equal), got {weight}"
        )
    return reward_mode, weight, gamma


def progress_potential(index: np.ndarray | int, segment_reward: np.ndarray | float) -> Any:
    """The progress potential ``Phi(s, i) = i + 1 / (1 - R_i(s))`` of ``reward_mode="potential"``.

    ``segment_reward`` is ``R_i(s)`` (at most 0) of the segment ``index`` the state is in; the
    result lies in ``(i, i + 1]`` and grows as the state nears region ``i``.

    Examples
    --------
    >>> from swirl_wrappers.wrappers import progress_potential
    >>> progress_potential(2, 0.0), progress_potential(0, -3.0)
    (3.0, 0.25)
    """
    return index + 1.0 / (1.0 - np.minimum(segment_reward, 0.0))


def _one_hot_table(lifted: spaces.Box | spaces.Dict, state_key: str | None, n: int) -> np.ndarray:
    dtype = lifted.dtype if state_key is None else lifted[SEGMENT_KEY].dtype
    table = np.eye(n, dtype=dtype)
    table.flags.writeable = False
    return table


def lift_observation(obs: Any, one_hot: np.ndarray, state_key: str | None) -> Any:
    """Append one-hot segment rows to an observation or a batch of observations.

    ``one_hot`` has shape (n_indices,) for one observation, (n, n_indices) for a batch; Box
    observations get it concatenated on the last axis, Dict observations as a ``"segment"`` key.
    """
    if state_key is None:
        return np.concatenate((obs, one_hot), axis=-1)
    return {**obs, SEGMENT_KEY: np.array(one_hot)}


class SwirlWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Track the segment of a SWIRL proxy task and reward the agent with its local reward.

    The observation gets a one-hot segment index appended (Box observations) or a ``"segment"``
    key (Dict observations); the reward becomes ``reward_scale * R_i(s')`` (+ ``region_bonus``
    on the step a region is reached), with ``i`` the index before the step. See the module
    docstring for the exact timing and the ``info`` keys.

    Parameters
    ----------
    env : gymnasium.Env
        Environment with a 1-D Box or a Dict observation space.
    task : TaskModel
        The proxy task; its ``dims`` / features must fit the observation.
    reward_scale : float
        Multiplies the segment reward (>= 0).
    region_bonus : float
        Added to the reward of a step that reaches the next region (>= 0).
    terminate_on_completion : bool
        End the episode (``terminated=True``) when the last region is reached.
    state_key : str, optional
        For Dict observations, the key holding the task state (default ``"observation"``).
    reward_mode : {"quadratic", "potential"}
        ``"quadratic"``: the paper's segment reward; ``"potential"``: potential-based shaping of
        the environment's reward by segment progress (see the module docstring).
    task_reward_weight : float, optional
        Weight (>= 0) of the environment's own reward in the returned reward; default 0 for
        ``"quadratic"``, 1 for ``"potential"``.
    gamma : float
        Discount of the shaping term in ``"potential"`` mode; set it to the agent's ``gamma``.

    Attributes
    ----------
    task : TaskModel
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
    >>> env = SwirlWrapper(gym.make("CartPole-v1"), task, region_bonus=1.0)
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
        task: TaskModel,
        reward_scale: float = 1.0,
        region_bonus: float = 0.0,
        terminate_on_completion: bool = False,
        state_key: str | None = None,
        reward_mode: str = "quadratic",
        task_reward_weight: float | None = None,
        gamma: float = 0.99,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            task=task,
            reward_scale=reward_scale,
            region_bonus=region_bonus,
            terminate_on_completion=terminate_on_completion,
            state_key=state_key,
            reward_mode=reward_mode,
            task_reward_weight=task_reward_weight,
            gamma=gamma,
        )
        gym.Wrapper.__init__(self, env)
        self.observation_space, self._state_key = lift_observation_space(
            env.observation_space, task, state_key
        )
        self.task = task
        self.reward_scale, self.region_bonus = _check_scalars(reward_scale, region_bonus)
        self.reward_mode, self.task_reward_weight, self.gamma = _check_reward_options(
            reward_mode, task_reward_weight, gamma
        )
        if not is_bool(terminate_on_completion):
            raise ValueError(
                f"terminate_on_completion must be True or False, got {terminate_on_completion!r}"
            )
        self.terminate_on_completion = bool(terminate_on_completion)
        self._one_hot = _one_hot_table(self.observation_space, self._state_key, task.n_indices)
        self.segment = 0
        self.potential = 0.0
        self._t = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        state = obs if self._state_key is None else obs[self._state_key]
        self._t = 0
        reward, self.segment = self.task.reward_and_next(state, 0, 0)
        if self.reward_mode == "potential":
            self.potential = self._potential(state, reward, 0)
        info[SEGMENT_KEY] = self.segment
        return lift_observation(obs, self._one_hot[self.segment], self._state_key), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, task_reward, terminated, truncated, info = self.env.step(action)
        state = obs if self._state_key is None else obs[self._state_key]
        self._t += 1
        before = self.segment
        reward, self.segment = self.task.reward_and_next(state, self._t, before)
        if self.terminate_on_completion and self.segment == self.task.n_segments:
            terminated = True  # also on the first step of an episode complete at reset
        if self.reward_mode == "potential":
            # Phi = 0 after a termination keeps the shaping policy-invariant; a truncation
            # keeps Phi(s'), which the agent bootstraps from.
            potential = 0.0 if terminated else self._potential(state, reward, before)
            reward = self.reward_scale * (self.gamma * potential - self.potential)
            self.potential = potential
        else:
            reward *= self.reward_scale
        if self.segment != before:
            reward += self.region_bonus
        if self.task_reward_weight != 0.0:
            reward += self.task_reward_weight * float(task_reward)
        info[SEGMENT_KEY] = self.segment
        info[TASK_REWARD_KEY] = task_reward
        info[SEGMENT_REWARD_KEY] = reward
        lifted = lift_observation(obs, self._one_hot[self.segment], self._state_key)
        return lifted, reward, terminated, truncated, info

    def _potential(self, state: np.ndarray, reward: float, before: int) -> float:
        """``Phi(s, i)`` for the current index, given ``reward = R_before(s)``."""
        if self.segment != before:
            reward = self.task.reward_and_next(state, None, self.segment)[0]
        return float(progress_potential(self.segment, reward))


class SegmentTracker:
    """Segment indices and time steps of ``num_envs`` parallel episodes, updated in one pass.

    The vectorised core of :class:`SwirlVectorWrapper` and of sb3-swirl's ``SwirlVecEnv``: it
    validates the task against the observation space, holds one index and one step counter per
    sub-environment, applies the timing described in the module docstring to all of them at
    once, and lifts batches of observations.

    Parameters
    ----------
    task : TaskModel
    num_envs : int
    observation_space : gymnasium.spaces.Box or gymnasium.spaces.Dict
        The observation space of *one* sub-environment.
    reward_scale, region_bonus, state_key, reward_mode, task_reward_weight, gamma
        As in :class:`SwirlWrapper`. With ``reward_mode="potential"`` or a nonzero
        ``task_reward_weight``, :meth:`step` needs the environment's ``task_rewards`` and
        ``terminated`` flags.

    Attributes
    ----------
    observation_space : Box or Dict
        The lifted observation space of one sub-environment.
    state_key : str or None
        Key of the task state in Dict observations.
    index : ndarray of int64, shape (num_envs,)
        Current segment index of each sub-environment.
    t : ndarray of int64, shape (num_envs,)
        Steps taken in each sub-environment's current episode.
    potential : ndarray of float64, shape (num_envs,)
        ``Phi`` of each sub-environment's current lifted state (``"potential"`` mode).
    compiled : bool
        Whether :meth:`step` and :meth:`step_lift` run as one numba-compiled call (when numba
        is installed: ``pip install swirl-wrappers[numba]``; sb3-swirl installs it) instead of
        a few dozen small numpy calls. The results are the same up to floating-point rounding;
        set it to ``False`` to use numpy.

    Examples
    --------
    >>> import numpy as np
    >>> from gymnasium import spaces
    >>> from swirl_wrappers import QuadraticReward, Region, SegmentTracker, TaskModel
    >>> task = TaskModel([Region([1.0], [[0.01]], 1.0)], [QuadraticReward([1.0], [[1.0]])])
    >>> space = spaces.Box(-10.0, 10.0, (1,))
    >>> tracker = SegmentTracker(task, 2, space, region_bonus=10.0)
    >>> tracker.reset(np.array([[0.0], [0.0]]))
    >>> tracker.step(np.array([[0.5], [1.0]])).tolist(), tracker.index.tolist()
    ([-0.25, 10.0], [0, 1])
    >>> tracker.step(np.array([[0.7], [7.0]]), restart=np.array([True, False])).tolist()
    [0.0, -36.0]
    >>> tracker.index.tolist(), tracker.t.tolist()
    ([0, 1], [0, 2])
    >>> tracker.lift(np.array([[0.7], [7.0]], dtype=np.float32))
    array([[0.7, 1. , 0. ],
           [7. , 0. , 1. ]], dtype=float32)
    """

    def __init__(
        self,
        task: TaskModel,
        num_envs: int,
        observation_space: gym.Space,
        reward_scale: float = 1.0,
        region_bonus: float = 0.0,
        state_key: str | None = None,
        *,
        reward_mode: str = "quadratic",
        task_reward_weight: float | None = None,
        gamma: float = 0.99,
    ) -> None:
        self.observation_space, self.state_key = lift_observation_space(
            observation_space, task, state_key
        )
        if not is_integer(num_envs, 1):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        self.task = task
        self.num_envs = int(num_envs)
        state_space = (
            observation_space if self.state_key is None else observation_space[self.state_key]
        )
        self._batch_shape = (self.num_envs, *state_space.shape)
        self.reward_scale, self.region_bonus = _check_scalars(reward_scale, region_bonus)
        self.reward_mode, self.task_reward_weight, self.gamma = _check_reward_options(
            reward_mode, task_reward_weight, gamma
        )
        self.index = np.zeros(self.num_envs, dtype=np.int64)
        self.ended_index = self.index
        self.potential = np.zeros(self.num_envs, dtype=np.float64)
        self._one_hot = _one_hot_table(self.observation_space, self.state_key, task.n_indices)
        # Episode steps are a clock minus each episode's start: no per-step array update, and
        # `t` is only built where a region has a time window (or on request).
        self._clock = 0
        self._start = np.zeros(self.num_envs, dtype=np.int64)
        self._timed = task.timed
        self._zeros = np.zeros(self.num_envs, dtype=np.int64)
        # Inputs of the task's product, reused every step (a restart step evaluates up to
        # 2 num_envs rows: the transitions, then the new episodes' first states).
        self._inputs = task.input_buffer(2 * self.num_envs)
        # With numba installed, step() and step_lift() are one compiled call
        # (swirl_wrappers._compiled) on these settings; `compiled = False` selects numpy.
        self.compiled = _compiled.step is not None
        self._potential_mode = self.reward_mode == "potential"
        self._uses_task_rewards = self.task_reward_weight != 0.0
        tables = task._tables
        self._weights = np.ascontiguousarray(tables.weights.T)  # a row per output
        self._linear = tables.linear
        self._t_bounds = np.vstack((tables.t_lo_array, tables.t_hi_array))
        self._settings = _compiled.settings(
            self.reward_scale, self.region_bonus, self.task_reward_weight, self.gamma, self._timed
        )
        self._index_shape = (2, self.num_envs)
        self._rows_shape = (self.num_envs,)
        self._state_shape = state_space.shape
        # Modes whose step reads the environment's signals (checked on every step).
        self._checks_signals = self._potential_mode or self._uses_task_rewards
        self._lifted_dim = state_space.shape[0] + task.n_indices
        self._lifted_shape = (self.num_envs, self._lifted_dim)
        self._lift_dtype = self._one_hot.dtype
        # step_lift_infos's kernel: Box observations of a task without features, whose final
        # observations it copies into a scratch buffer (replaced for another dtype).
        self._infos_kernel = self.state_key is None and self._linear
        self._final_obs = np.empty(self._batch_shape, self._lift_dtype)
        self._rewards64 = np.empty(self.num_envs)

    @property
    def t(self) -> np.ndarray:
        """Steps taken in each sub-environment's current episode (a new int64 array)."""
        return self._clock - self._start

    def states(self, obs: Any) -> np.ndarray:
        """The task states in a batch of (unlifted) observations."""
        return obs if self.state_key is None else obs[self.state_key]

    def reset(self, states: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Start new episodes from ``states`` (num_envs, state_dim) where ``mask`` is true.

        ``t`` becomes 0 and the index ``M(s_0, 0, 0)`` (1 if ``s_0`` is already in region 0).
        """
        self._check_batch(states, mask, "mask")
        if mask is None:
            mask = np.ones(self.num_envs, dtype=bool)
        zeros = self._zeros[: int(np.count_nonzero(mask))]
        # New arrays, not in-place writes: earlier infos may hold the old ones.
        self.index = self.index.copy()
        self._start[mask] = self._clock
        reward, self.index[mask] = self.task.reward_and_next_batch(
            states[mask], zeros, zeros, self._inputs
        )
        self.ended_index = self.index
        if self.reward_mode == "potential":
            self.potential = self.potential.copy()
            self.potential[mask] = self._potentials(states[mask], reward, zeros, self.index[mask])

    def step(
        self,
        states: np.ndarray,
        restart: np.ndarray | None = None,
        final_states: np.ndarray | None = None,
        task_rewards: np.ndarray | None = None,
        terminated: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance every episode to ``states`` and return the float64 segment rewards.

        Parameters
        ----------
        states : array of shape (num_envs, state_dim)
        restart : bool array of shape (num_envs,), optional
            Rows whose ``states`` start a new episode (an autoreset). They are reset as by
            :meth:`reset`, in the same numpy pass as the other rows.
        final_states : array of shape (restart.sum(), state_dim), optional
            The last states of the episodes that ended at the ``restart`` rows, when the
            environment resets in the step that ends an episode (SB3, gymnasium ``SAME_STEP``):
            the reward of those rows is that of the final transition. Without it (gymnasium
            ``NEXT_STEP``) the ``restart`` rows made no transition and get reward 0.
        task_rewards : array of shape (num_envs,), optional
            The environment's own rewards of this step; needed when ``task_reward_weight`` is
            not 0.
        terminated : bool array of shape (num_envs,), optional
            Which transitions ended their episode by a termination (not a truncation); needed
            by ``reward_mode="potential"``, where a terminal state has potential 0.

        After the call :attr:`index` holds the indices of the current episodes and
        ``ended_index`` the index each row's transition ended with (they differ only at
        ``restart`` rows with ``final_states``).
        """
        if self.compiled:
            return self._compiled_step(states, restart, final_states, task_rewards, terminated)[1]
        self._check_step(states, restart, task_rewards, terminated)
        if restart is not None and final_states is not None:
            self._check_final(states, int(np.count_nonzero(restart)), final_states)
        before = self.index
        self._clock += 1
        t = self.t if self._timed else None
        # count_nonzero: a fraction of the cost of ndarray.any() on small arrays.
        if restart is None or not np.count_nonzero(restart):
            reward, self.index = self.task.reward_and_next_batch(states, t, before, self._inputs)
            self.ended_index = self.index
            return self._shape(reward, before, self.index, states, task_rewards, terminated)
        rows = restart.nonzero()[0]
        zeros = self._zeros[: len(rows)]
        if final_states is None:
            # Index 0 at t = 0 makes the restart rows compute exactly reset's M(s_0, 0, 0).
            index = before.copy()
            index[rows] = 0
            self._start[rows] = self._clock
            reward, self.index = self.task.reward_and_next_batch(
                states, self.t if self._timed else None, index, self._inputs
            )
            # A restart row made no transition: its potential restarts from Phi(s_0).
            not_terminal = None
            if self.reward_mode == "potential":  # the only mode that reads terminated
                not_terminal = np.where(restart, False, terminated)
            reward = self._shape(reward, index, self.index, states, task_rewards, not_terminal)
            reward[rows] = 0.0
            self.ended_index = self.index
            return reward
        # One pass: the num_envs transitions (ending in the final states at the restart rows),
        # then the first states of the new episodes (index 0 at t = 0, as in reset).
        n = self.num_envs
        x = np.concatenate((states, states[rows]))
        x[rows] = final_states
        if self._timed:
            t = np.concatenate((t, zeros))
        reward, nxt = self.task.reward_and_next_batch(
            x, t, np.concatenate((before, zeros)), self._inputs
        )
        self.ended_index = nxt[:n]
        self.index = nxt[:n].copy()
        self.index[rows] = nxt[n:]
        self._start[rows] = self._clock  # in place: `t` hands out new arrays
        shaped = self._shape(reward[:n], before, self.ended_index, x[:n], task_rewards, terminated)
        if self.reward_mode == "potential":
            self.potential[rows] = self._potentials(states[rows], reward[n:], zeros, nxt[n:])
        return shaped

    def step_lift(
        self,
        obs: Any,
        restart: np.ndarray | None = None,
        final_states: np.ndarray | None = None,
        task_rewards: np.ndarray | None = None,
        terminated: np.ndarray | None = None,
        *,
        float32_rewards: np.ndarray | None = None,
    ) -> tuple[Any, np.ndarray, np.ndarray | None]:
        """:meth:`step` on a batch of observations, then :meth:`lift` them: the wrappers' step.

        The arguments are :meth:`step`'s, with the observations in place of the states, and
        ``float32_rewards``: a float32 array of shape (num_envs,) that also receives the rewards
        (SB3 vector envs return float32 rewards), written in the same pass.

        Returns ``(lifted_obs, rewards, lifted_final)``: ``lifted_final`` is ``final_states``
        lifted with the indices their episodes ended with, for Box observations (where the
        final states are the final observations); ``None`` for Dict observations or without
        ``final_states``.
        """
        if float32_rewards is not None and (
            not isinstance(float32_rewards, np.ndarray)
            or float32_rewards.shape != self._rows_shape
            or float32_rewards.dtype != _FLOAT32
        ):
            raise ValueError(
                f"float32_rewards must be a float32 array of shape ({self.num_envs},), got "
                f"{type(float32_rewards).__name__} {np.shape(float32_rewards)} of "
                f"{np.asarray(float32_rewards).dtype}"
            )
        if not self.compiled or self.state_key is not None:
            rewards = self.step(self.states(obs), restart, final_states, task_rewards, terminated)
            if float32_rewards is not None:
                float32_rewards[...] = rewards
            lifted_final = None
            if final_states is not None and restart is not None and self.state_key is None:
                lifted_final = self.lift(final_states, self.ended_index[restart])
            return self.lift(obs), rewards, lifted_final
        return self._compiled_step(
            obs, restart, final_states, task_rewards, terminated, float32_rewards, True
        )

    def step_lift_infos(
        self,
        obs: Any,
        restart: np.ndarray,
        task_rewards: np.ndarray,
        infos: list[dict[str, Any]],
        terminated: np.ndarray | None = None,
    ) -> tuple[Any, np.ndarray]:
        """:meth:`step_lift` on a step of an SB3 vector env, reading and writing its ``infos``.

        An SB3 vector env resets a sub-env in the step that ends its episode: a ``restart``
        row's observation starts the next episode, and the transition ends in
        ``infos[i]["terminal_observation"]``, which is replaced by its lifted form (with the
        index the episode ended with). Every info then gets ``"segment"`` (the index the
        transition ended with), ``"task_reward"`` and ``"segment_reward"`` as Python numbers.

        Parameters
        ----------
        obs : array of shape (num_envs, obs_dim), or a dict of arrays
            The observations of the step (for Dict observation spaces, a dict).
        restart : bool array of shape (num_envs,)
            The step's ``dones``.
        task_rewards : array of shape (num_envs,)
            The environment's own rewards.
        infos : list of dict
            One info dict per sub-env, changed in place.
        terminated : bool array of shape (num_envs,), optional
            As in :meth:`step`.

        Returns
        -------
        lifted_obs : array or dict of arrays
            As from :meth:`step_lift`.
        rewards : float32 ndarray of shape (num_envs,)
            SB3's reward dtype; ``info["segment_reward"]`` holds the float64 value.

        Notes
        -----
        Reading and writing the info dicts in Python costs more per sub-env than the tracker's
        whole compiled step. With numba, for Box observations of float32 or float64 and a task
        without features, one compiled call (``swirl_wrappers._compiled.step_infos``) makes the
        same reads and stores through CPython's C API. Anything else it meets (a tuple of infos,
        a dict subclass, a final observation of another dtype or shape) leaves the step to
        the Python path, which gives the same results.
        """
        if len(infos) != self.num_envs:
            raise ValueError(
                f"infos must hold one dict per environment ({self.num_envs}), got {len(infos)}"
            )
        if (
            self.compiled
            and self._infos_kernel
            and type(obs) is np.ndarray
            and obs.shape == self._batch_shape
            and obs.dtype in _FLOATS
            and type(restart) is np.ndarray
            and restart.shape == self._rows_shape
            and restart.dtype == _BOOL
            and type(infos) is list
            and type(task_rewards) is np.ndarray
            and task_rewards.shape == self._rows_shape
            and task_rewards.dtype in _FLOATS
        ):
            stepped = self._compiled_step_infos(obs, restart, task_rewards, infos, terminated)
            if stepped is not None:
                return stepped
        restart = np.asarray(restart)
        self._check_rows(restart, "restart")
        done = restart.nonzero()[0].tolist()
        final = [infos[i][TERMINAL_OBSERVATION_KEY] for i in done]
        final_states = None
        if done:
            # np.array: one C call, where np.stack loops over the rows in Python.
            final_states = np.array(
                final if self.state_key is None else [self.states(o) for o in final]
            )
        rewards32 = np.empty(self.num_envs, dtype=np.float32)
        lifted, rewards, lifted_final = self.step_lift(
            obs, restart, final_states, task_rewards, terminated, float32_rewards=rewards32
        )
        if done and lifted_final is None:  # Dict observations
            lifted_final = [
                self.lift(o, self.ended_index[i]) for o, i in zip(final, done, strict=True)
            ]
        self._write_infos(infos, done, lifted_final, task_rewards, rewards)
        return lifted, rewards32

    def _compiled_step_infos(
        self,
        obs: np.ndarray,
        restart: np.ndarray,
        task_rewards: np.ndarray,
        infos: list[dict[str, Any]],
        terminated: Any,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`step_lift_infos` in one compiled call; ``None`` (nothing changed) where the
        kernel leaves the step to Python."""
        if self._checks_signals:
            self._check_step(obs, restart, task_rewards, terminated)
        n = self.num_envs
        dtype = self._lifted_dtype(obs)
        final_obs = self._final_obs
        if final_obs.dtype != obs.dtype:
            # C order: the kernel copies into its rows.
            final_obs = self._final_obs = np.empty(obs.shape, obs.dtype)
        lifted = np.empty(self._lifted_shape, dtype)
        lifted_final = np.empty(self._lifted_shape, dtype)  # the first restart.sum() rows
        rewards32 = np.empty(self._rows_shape, _FLOAT32)
        reward = self._rewards64  # read back only into the infos
        index = np.empty(self._index_shape, _INT64)
        potential = np.empty(n) if self._potential_mode else None
        result = _compiled.step_infos(
            _INFO_ADDRESSES,
            id(infos),
            ord(obs.dtype.char),
            obs,
            restart,
            final_obs,
            *self._kernel_state(task_rewards, terminated),
            reward,
            rewards32,
            index,
            potential,
            lifted,
            lifted_final,
            id(lifted_final),
            task_rewards,
        )
        if result == _compiled.NOT_HANDLED:
            return None
        self._commit(index, potential)
        if result == _compiled.INFOS_UNFINISHED:  # a failed allocation: Python stores them all
            done = restart.nonzero()[0].tolist()
            self._write_infos(infos, done, lifted_final, task_rewards, reward)
        return lifted, rewards32

    def _write_infos(
        self,
        infos: list[dict[str, Any]],
        done: list[int],
        lifted_final: Any,
        task_rewards: np.ndarray,
        rewards: np.ndarray,
    ) -> None:
        """The stores of :meth:`step_lift_infos` into ``infos``."""
        # Indexing, not iteration: cheaper on a row or two of an array.
        for k, i in enumerate(done):
            infos[i][TERMINAL_OBSERVATION_KEY] = lifted_final[k]
        for info, index, task_reward, reward in zip(
            infos,
            self.ended_index.tolist(),
            np.asarray(task_rewards).tolist(),
            rewards.tolist(),
            strict=True,
        ):
            info[SEGMENT_KEY] = index
            info[TASK_REWARD_KEY] = task_reward
            info[SEGMENT_REWARD_KEY] = reward

    def _compiled_step(
        self,
        states: Any,
        restart: Any,
        final_states: Any,
        task_rewards: Any,
        terminated: Any,
        float32_rewards: np.ndarray | None = None,
        lift: bool = False,
    ) -> tuple[Any, np.ndarray, np.ndarray | None]:
        """:meth:`step` (and :meth:`lift`, for Box observations) in one compiled call.

        The same results as the numpy path, up to floating-point rounding. The checks are
        :meth:`step`'s, written for speed: this runs on every step of every vector env.
        """
        states = np.asarray(states)
        n = self.num_envs
        final = None
        if restart is not None:
            restart = np.asarray(restart)
            if final_states is not None:
                final = np.asarray(final_states)
        if (
            states.shape != self._batch_shape
            or (restart is not None and restart.shape != self._rows_shape)
            or self._checks_signals
        ):
            self._check_step(states, restart, task_rewards, terminated)
        if final is not None and final.shape[1:] != self._state_shape:
            self._check_final(states, int(np.count_nonzero(restart)), final)
        lifted = lifted_final = None
        if lift:
            lifted = np.empty(self._lifted_shape, self._lifted_dtype(states))
            if final is not None:
                lifted_final = np.empty((len(final), self._lifted_dim), self._lifted_dtype(final))
        reward = np.empty(n)
        # New arrays, not in-place writes: earlier infos may hold the old ones.
        index = np.empty(self._index_shape, _INT64)
        potential = np.empty(n) if self._potential_mode else None
        # The kernel reads the leading columns of its task inputs: a linear task's are the
        # observations themselves.
        linear = self._linear
        try:
            _compiled.step(
                states,
                states if linear else self.task._task_input(states),
                final,
                final if linear or final is None else self.task._task_input(final),
                restart,
                *self._kernel_state(task_rewards, terminated),
                reward,
                float32_rewards,
                index,
                potential,
                lifted,
                lifted_final,
            )
        except ValueError:  # the kernel counts the restart rows before it changes anything
            if final is not None:
                self._check_final(states, int(np.count_nonzero(restart)), final)
            raise
        self._commit(index, potential)
        return lifted, reward, lifted_final

    def _kernel_state(self, task_rewards: Any, terminated: Any) -> tuple:
        """The compiled kernels' arguments from ``before`` to ``potential``: the tracker's state
        and settings, and the signals of the step, passed only when the mode reads them (the
        checks made sure they were given)."""
        potential_mode = self._potential_mode
        return (
            self.index,
            self._start,
            self._clock + 1,
            self._weights,
            self._t_bounds,
            self._settings,
            np.asarray(task_rewards, dtype=np.float64) if self._uses_task_rewards else None,
            np.asarray(terminated, dtype=bool) if potential_mode else None,
            self.potential if potential_mode else None,
        )

    def _commit(self, index: np.ndarray, potential: np.ndarray | None) -> None:
        """Take a compiled step's results: ``index`` (2, num_envs) and the new potentials."""
        self._clock += 1
        self.index = index[0]
        self.ended_index = index[1]
        if self._potential_mode:
            self.potential = potential

    def _lifted_dtype(self, obs: np.ndarray) -> np.dtype:
        """The dtype of ``obs`` lifted (that of concatenating it with the one-hot rows)."""
        if obs.dtype == self._lift_dtype:
            return self._lift_dtype
        return np.promote_types(obs.dtype, self._lift_dtype)

    def _check_step(
        self,
        states: Any,
        restart: Any,
        task_rewards: Any,
        terminated: Any,
    ) -> None:
        if self._potential_mode and terminated is None:
            raise ValueError("reward_mode='potential' needs the terminated flags of each step")
        if self._uses_task_rewards and task_rewards is None:
            raise ValueError("task_reward_weight != 0 needs the environment's task_rewards")
        self._check_batch(states, restart, "restart")
        # Checked only where read: the default mode ignores them.
        if self._uses_task_rewards:
            self._check_rows(task_rewards, "task_rewards")
        if self._potential_mode:
            self._check_rows(terminated, "terminated")

    def _check_final(self, states: np.ndarray, n_rows: int, final_states: Any) -> None:
        if final_states is not None and np.shape(final_states) != (n_rows, *states.shape[1:]):
            raise ValueError(
                f"final_states must hold one state per restart row, shape "
                f"{(n_rows, *states.shape[1:])}, got {np.shape(final_states)}"
            )

    def _check_batch(self, states: Any, rows: Any, name: str) -> None:
        if np.shape(states) != self._batch_shape:
            raise ValueError(
                f"states must have shape {self._batch_shape} (num_envs, state_dim), "
                f"got {np.shape(states)}"
            )
        if rows is not None:
            self._check_rows(rows, name)

    def _check_rows(self, rows: Any, name: str) -> None:
        if np.shape(rows) != self._rows_shape:
            raise ValueError(f"{name} must have shape ({self.num_envs},), got {np.shape(rows)}")

    def _potentials(
        self, states: np.ndarray, reward: np.ndarray, before: np.ndarray, after: np.ndarray
    ) -> np.ndarray:
        """``Phi(s, after)`` given ``reward = R_before(s)``, re-evaluated where the index moved."""
        moved = after != before
        if moved.any():
            reward = reward.copy()
            reward[moved] = self.task.reward_and_next_batch(
                states[moved], None, after[moved], self._inputs
            )[0]
        return progress_potential(after, reward)

    def _shape(
        self,
        reward: np.ndarray,
        before: np.ndarray,
        after: np.ndarray,
        states: np.ndarray | None,
        task_rewards: np.ndarray | None,
        terminated: np.ndarray | None,
    ) -> np.ndarray:
        # ``states`` is read only in "potential" mode (callers may pass None otherwise).
        if self.reward_mode == "potential":
            potential = self._potentials(states, reward, before, after)
            potential[np.asarray(terminated, dtype=bool)] = 0.0
            reward = self.reward_scale * (self.gamma * potential - self.potential)
            self.potential = potential
        elif self.reward_scale != 1.0:
            reward = reward * self.reward_scale
        if self.region_bonus != 0.0:
            reward = reward + self.region_bonus * (after != before)
        if self.task_reward_weight != 0.0:
            reward = reward + self.task_reward_weight * np.asarray(task_rewards, dtype=np.float64)
        return reward

    def lift(self, obs: Any, index: np.ndarray | int | None = None) -> Any:
        """Append segment one-hots to a batch of observations (or to one, with an int ``index``).

        ``index`` defaults to the current indices of all sub-environments.
        """
        index = self.index if index is None else index
        return lift_observation(obs, self._one_hot.take(index, axis=0), self.state_key)


class SwirlVectorWrapper(VectorWrapper, gym.utils.RecordConstructorArgs):
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
    The results are those of the :class:`SwirlWrapper` s, in one numpy pass over the sub-envs,
    up to floating-point rounding (the batched product sums in another order, so a state within
    about 1e-15 of a region's boundary may be inside for one and outside for the other).

    ``terminate_on_completion`` needs the sub-environment to be reset, which a vector wrapper
    cannot do; wrap each sub-env with :class:`SwirlWrapper` instead (``gymnasium.make_vec(...,
    wrappers=[...])``).

    Parameters
    ----------
    env : gymnasium.vector.VectorEnv
    task, reward_scale, region_bonus, state_key, reward_mode, task_reward_weight, gamma
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
        task: TaskModel,
        reward_scale: float = 1.0,
        region_bonus: float = 0.0,
        terminate_on_completion: bool = False,
        state_key: str | None = None,
        reward_mode: str = "quadratic",
        task_reward_weight: float | None = None,
        gamma: float = 0.99,
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self,
            task=task,
            reward_scale=reward_scale,
            region_bonus=region_bonus,
            terminate_on_completion=terminate_on_completion,
            state_key=state_key,
            reward_mode=reward_mode,
            task_reward_weight=task_reward_weight,
            gamma=gamma,
        )
        VectorWrapper.__init__(self, env)
        if terminate_on_completion:
            raise ValueError(
                "SwirlVectorWrapper cannot end one sub-environment's episode on completion; wrap "
                "each sub-env with SwirlWrapper(..., terminate_on_completion=True) instead"
            )
        self.autoreset_mode = AutoresetMode(
            env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        )
        self.tracker = SegmentTracker(
            task,
            self.num_envs,
            env.single_observation_space,
            reward_scale,
            region_bonus,
            state_key,
            reward_mode=reward_mode,
            task_reward_weight=task_reward_weight,
            gamma=gamma,
        )
        self.single_observation_space = self.tracker.observation_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.task = task
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._all = np.ones(self.num_envs, dtype=bool)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        mask = None if options is None else options.get("reset_mask")
        obs, infos = self.env.reset(seed=seed, options=options)
        mask = self._all if mask is None else np.asarray(mask, dtype=bool)
        self.tracker.reset(self.tracker.states(obs), mask)
        self._autoreset[mask] = False
        infos[SEGMENT_KEY] = self.tracker.index.copy()
        infos["_" + SEGMENT_KEY] = mask.copy()  # the rows that were reset
        return self.tracker.lift(obs), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, task_rewards, terminations, truncations, infos = self.env.step(actions)
        done = np.logical_or(terminations, truncations)
        env_signals = {"task_rewards": task_rewards, "terminated": terminations}
        # Rows whose top-level info is a step's (None: all). As from independent SwirlWrappers,
        # a row that was reset holds the reset info: "segment" only.
        stepped = None
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            if np.count_nonzero(self._autoreset):
                stepped = ~self._autoreset
            lifted, rewards, _ = self.tracker.step_lift(obs, self._autoreset, **env_signals)
            self._autoreset = done
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and np.count_nonzero(done):
            # A done row holds the next episode's first observation; the transition ends in
            # infos["final_obs"], which is lifted with the index the episode ended with.
            final = np.flatnonzero(done)
            final_obs = infos["final_obs"]
            lifted, rewards, lifted_final = self.tracker.step_lift(
                obs,
                done,
                np.stack([self.tracker.states(final_obs[i]) for i in final]),
                **env_signals,
            )
            for j, i in enumerate(final):
                final_obs[i] = (
                    self.tracker.lift(final_obs[i], self.tracker.ended_index[i])
                    if lifted_final is None
                    else lifted_final[j]
                )
            # The ended transitions' keys go with their final_info, as the sub-envs' would.
            final_info = infos.setdefault("final_info", {})
            for key, values in (
                (SEGMENT_KEY, self.tracker.ended_index),
                (TASK_REWARD_KEY, task_rewards),
                (SEGMENT_REWARD_KEY, rewards),
            ):
                final_info[key] = np.array(values)
                final_info["_" + key] = done
            stepped = ~done
        else:
            lifted, rewards, _ = self.tracker.step_lift(obs, **env_signals)
        # The tracker never writes into an index array it has published: no copy needed.
        infos[SEGMENT_KEY] = self.tracker.index
        infos[TASK_REWARD_KEY] = np.array(task_rewards)  # the sub-envs reuse their reward buffer
        infos[SEGMENT_REWARD_KEY] = rewards.copy()
        # Masks shared between keys (a copy each costs more than the keys).
        infos["_" + SEGMENT_KEY] = self._all.copy()
        infos["_task_reward"] = infos["_segment_reward"] = (
            infos["_" + SEGMENT_KEY] if stepped is None else stepped
        )
        return lifted, rewards, terminations, truncations, infos
