"""The SWIRL proxy task on Stable-Baselines3 vector envs: ``SwirlVecEnv`` and ``make_swirl_env``."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    VecEnv,
    VecEnvWrapper,
    VecFrameStack,
    VecNormalize,
    unwrap_vec_wrapper,
)
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

from swirl_wrappers import Lifter, RewardConfig, SegmentTracker, SwirlWrapper, TaskModel
from swirl_wrappers._validation import check_int
from swirl_wrappers.wrappers import (
    SEGMENT_KEY,
    SEGMENT_REWARD_KEY,
    TASK_REWARD_KEY,
    StateKey,
    TrackedTask,
    _refuse_below,
)

__all__ = ["SwirlVecEnv", "get_swirl_attr", "make_swirl_env"]

#: What every SWIRL env answers to ``VecEnv.get_attr``: sub-envs wrapped with ``SwirlWrapper``
#: and a ``SwirlVecEnv`` alike.
SWIRL_ATTRIBUTES = ("task", "reward_config", "terminate_on_completion", "state_key")


class SwirlVecEnv(TrackedTask, VecEnvWrapper):
    """Track the SWIRL segment of every sub-environment and return the segment rewards.

    The Stable-Baselines3 counterpart of :class:`swirl_wrappers.SwirlWrapper`, computed for all
    sub-envs at once by one :class:`swirl_wrappers.SegmentTracker`, with the same observations,
    rewards and ``info`` keys (``"segment"``, ``"task_reward"``, ``"segment_reward"``). SB3
    vector envs reset a sub-env as soon as it is done: the transition's reward is computed on
    ``infos[i]["terminal_observation"]``, which is lifted with the index the episode ended with,
    and the returned observation starts the new episode. The env's own rewards are those the
    vector env returns: float32 in SB3's ``DummyVecEnv``, so ``info["task_reward"]`` (and a
    reward built on it) can differ from a ``SwirlWrapper``'s in the last float32 digit.

    Put it directly on the environments, below ``VecNormalize`` and ``VecFrameStack``: the
    task's regions live in the raw observation space (an error says so otherwise). A
    ``VecEnvWrapper`` cannot end one sub-env's episode: for ``terminate_on_completion``, wrap
    each env with ``SwirlWrapper`` instead (:func:`make_swirl_env`).

    ``get_attr`` of ``"task"``, ``"reward_config"``, ``"terminate_on_completion"``,
    ``"state_key"`` and ``"segment"`` (each sub-env's index) answers for every sub-env, as for
    sub-envs wrapped with ``SwirlWrapper``.

    Parameters
    ----------
    venv : VecEnv
        Sub-environments with a 1-D Box or a Dict observation space.
    task : TaskModel
    reward_config : RewardConfig or dict, optional
        Default: ``task.reward_config``; a dict changes only the fields it names.
    state_key : str or sequence of str, optional
        For Dict observations, the key(s) of the task state (default ``"observation"``; see
        :func:`swirl_wrappers.lift_observation_space`).

    Attributes
    ----------
    task : TaskModel
    reward_config : RewardConfig
    tracker : SegmentTracker
        Indices (``tracker.index``) and episode steps (``tracker.t``) of the sub-envs.

    Examples
    --------
    >>> import numpy as np
    >>> from stable_baselines3.common.env_util import make_vec_env
    >>> from swirl_wrappers import QuadraticReward, Region, TaskModel
    >>> task = TaskModel(
    ...     regions=[Region(mean=[0.0], covariance=[[0.05**2]], threshold=1.0)],
    ...     rewards=[QuadraticReward(target=[0.0], weight=[[100.0]])],
    ...     dims=[2],
    ... )
    >>> venv = SwirlVecEnv(make_vec_env("CartPole-v1", n_envs=4, seed=0), task)
    >>> obs = venv.reset()
    >>> obs.shape, venv.tracker.index.tolist()
    ((4, 6), [1, 1, 1, 1])
    >>> obs, rewards, dones, infos = venv.step(np.zeros(4, dtype=int))
    >>> bool(np.allclose(rewards, -100.0 * obs[:, 2] ** 2)), infos[0]["segment"]
    (True, 1)
    """

    def __init__(
        self,
        venv: VecEnv,
        task: TaskModel,
        reward_config: RewardConfig | dict[str, Any] | None = None,
        state_key: StateKey = None,
    ) -> None:
        if not isinstance(venv, VecEnv):
            raise ValueError(
                f"SwirlVecEnv wraps an SB3 VecEnv, got {type(venv).__name__}: vectorise the env "
                "first (DummyVecEnv), or wrap a gymnasium env with SwirlWrapper"
            )
        for below in (VecNormalize, VecFrameStack):
            if unwrap_vec_wrapper(venv, below) is not None:
                name = below.__name__
                raise ValueError(
                    f"SwirlVecEnv must sit below {name}: the task reads raw states. Wrap as "
                    f"{name}(SwirlVecEnv(venv, task)), not SwirlVecEnv({name}(venv), task)"
                )
        if unwrap_vec_wrapper(venv, SwirlVecEnv) is not None or any(
            venv.env_is_wrapped(SwirlWrapper)
        ):
            raise ValueError(
                "SwirlVecEnv over a vector env that is lifted already (a SwirlVecEnv below, or "
                "sub-envs wrapped with SwirlWrapper, as make_swirl_env makes them): lift the "
                "observations once"
            )
        _refuse_below(venv, "SwirlVecEnv")  # gymnasium's wrappers, in its sub-envs
        self.lifter = Lifter(venv.observation_space, task, state_key)
        self.tracker = SegmentTracker(task, reward_config, num_envs=venv.num_envs)
        super().__init__(venv, observation_space=self.lifter.observation_space)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        chosen = self._get_indices(indices)
        if attr_name == "segment":  # each sub-env's own, as a SwirlWrapper's
            return [int(self.tracker.index[i]) for i in chosen]
        if attr_name in SWIRL_ATTRIBUTES:
            return [getattr(self, attr_name)] * len(chosen)
        return self.venv.get_attr(attr_name, indices)

    def has_attr(self, attr_name: str) -> bool:
        return attr_name in (*SWIRL_ATTRIBUTES, "segment") or self.venv.has_attr(attr_name)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        if method_name == "compute_reward":  # the sub-envs' own would drop the segment reward
            raise ValueError(
                "SwirlVecEnv cannot relabel goals (HerReplayBuffer): the sub-envs' "
                "compute_reward knows nothing of the segment reward. Wrap each env with "
                "SwirlWrapper instead (make_swirl_env), whose compute_reward keeps it"
            )
        return self.venv.env_method(method_name, *method_args, indices=indices, **method_kwargs)

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        self._warn_overwritten(*self.venv.reset_infos)
        self.tracker.reset(self.lifter.state(obs))
        self.reset_infos = [
            {**info, SEGMENT_KEY: index}
            for info, index in zip(self.venv.reset_infos, self.tracker.index.tolist(), strict=True)
        ]
        return self.lifter.lift(obs, self.tracker.index)

    def step_wait(self) -> VecEnvStepReturn:
        obs, task_rewards, dones, infos = self.venv.step_wait()
        self._warn_overwritten(*infos)
        done = np.flatnonzero(dones).tolist()
        final = [infos[i]["terminal_observation"] for i in done]
        # SB3 marks a time-limit end with TimeLimit.truncated; every other done is a termination.
        truncated = np.array([info.get("TimeLimit.truncated", False) for info in infos])
        rewards, _ = self.tracker.step(
            self.lifter.state(obs),
            task_rewards,
            dones & ~truncated,
            restart=dones if done else None,
            final_states=np.array([self.lifter.state(o) for o in final]) if done else None,
        )
        ended = self.tracker.ended_index
        for i, obs_i in zip(done, final, strict=True):
            infos[i]["terminal_observation"] = self.lifter.lift(obs_i, ended[i])
        for info, index, task_reward, reward in zip(
            infos, ended.tolist(), task_rewards.tolist(), rewards.tolist(), strict=True
        ):
            info[SEGMENT_KEY] = index
            info[TASK_REWARD_KEY] = task_reward
            info[SEGMENT_REWARD_KEY] = reward
        for i in done:  # the new episodes' reset infos, as SB3's VecEnvs keep them
            self.reset_infos[i] = {
                **self.venv.reset_infos[i],
                SEGMENT_KEY: int(self.tracker.index[i]),
            }
        lifted = self.lifter.lift(obs, self.tracker.index)
        return lifted, rewards.astype(np.float32), dones, infos


def same_task(a: TaskModel, b: TaskModel) -> bool:
    """Whether two tasks have the same regions and rewards, their reward settings aside: those
    the env's wrapper pays by may differ (a model adopts them, with a warning); and their
    ``metadata`` aside, which records the fit (a later version records more)."""
    plain = RewardConfig()
    return (
        dataclasses.replace(a, reward_config=plain, metadata={}).to_json()
        == dataclasses.replace(b, reward_config=plain, metadata={}).to_json()
    )


def swirl_task(env: Any) -> TaskModel | None:
    """The task of a SWIRL env (a ``VecEnv`` whose ``get_attr("task")`` is a TaskModel), or
    ``None`` for any other env (a Fetch env's own ``task`` attribute is a name)."""
    # has_attr first: a get_attr that fails inside a SubprocVecEnv worker kills the worker
    if not (isinstance(env, VecEnv) and env.has_attr("task")):
        return None
    task = env.get_attr("task", indices=[0])[0]
    return task if isinstance(task, TaskModel) else None


def trained_task(env: VecEnv) -> TaskModel:
    """The SWIRL env's task with the reward settings it pays by: what to save beside a model
    that does not hold it (any algorithm but ``SwirlDQN``), to wrap an env with it again."""
    return dataclasses.replace(
        get_swirl_attr(env, "task"), reward_config=get_swirl_attr(env, "reward_config")
    )


def get_swirl_attr(env: VecEnv, name: str) -> Any:
    """``env.get_attr(name)`` of a SWIRL env's first sub-env: ``"task"``, ``"reward_config"`` or
    ``"terminate_on_completion"``.

    A SWIRL env is a ``SwirlVecEnv`` (possibly under other ``VecEnvWrapper`` s) or a ``VecEnv``
    whose sub-envs are wrapped with ``SwirlWrapper``; both answer SB3's ``get_attr``.

    Parameters
    ----------
    env : VecEnv
    name : str
        ``"task"``, ``"reward_config"``, ``"terminate_on_completion"`` or ``"state_key"``.

    Returns
    -------
    Any
        The attribute of the first sub-env (every sub-env carries the same).

    Raises
    ------
    ValueError
        If the env carries no SWIRL task, with a hint on how to wrap it.
    """
    task = swirl_task(env)
    if task is None:
        raise ValueError(
            "the environment carries no SWIRL proxy task: wrap it first, e.g. "
            "`SwirlWrapper(env, task)` in every sub-env, `make_swirl_env(env_id, task, "
            "n_envs=...)` or `SwirlVecEnv(venv, task)`"
        )
    return task if name == "task" else env.get_attr(name, indices=[0])[0]


@dataclass
class _SwirlEnvFactory:
    """Makes ``SwirlWrapper(base env, task, ...)``, picklable by reference (``make_vec_env``
    puts the ``Monitor`` outside).

    SB3's ``SubprocVecEnv`` sends env factories to fresh processes (``forkserver``, ``spawn``).
    Defined in this module, the factory is unpickled by importing sb3_swirl, which registers
    the ``sb3_swirl/`` env ids there before ``gym.make`` runs.
    """

    env: str | gym.Env | Callable[..., gym.Env]
    task: TaskModel
    wrapper_kwargs: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    def __call__(self) -> gym.Env:
        if isinstance(self.env, str):
            # as SB3's make_vec_env: rgb_array frames where the env can render (not asked of
            # an env whose metadata lists other modes: gymnasium would warn at every make)
            if _renders_rgb_array(self.env):
                try:
                    base = gym.make(self.env, **{"render_mode": "rgb_array", **self.env_kwargs})
                except TypeError:
                    base = gym.make(self.env, **self.env_kwargs)
            else:
                base = gym.make(self.env, **self.env_kwargs)
        elif isinstance(self.env, gym.Env):
            base = self.env
        else:
            base = self.env(**self.env_kwargs)
        return SwirlWrapper(base, self.task, **self.wrapper_kwargs)


def _renders_rgb_array(env_id: str) -> bool:
    """Whether the registered env may take ``render_mode="rgb_array"``: its class's metadata
    lists it, or says nothing of its modes (then it is tried, as SB3 does)."""
    try:
        entry = gym.spec(env_id).entry_point
        creator = entry if callable(entry) else gym.envs.registration.load_env_creator(entry)
    except (gym.error.Error, ImportError, AttributeError):  # gym.make then says why
        return True
    modes = getattr(creator, "metadata", {}).get("render_modes")
    return modes is None or "rgb_array" in modes


def make_swirl_env(
    env_id: str | gym.Env | Callable[..., gym.Env],
    task: TaskModel,
    n_envs: int = 1,
    seed: int | None = None,
    start_index: int = 0,
    monitor_dir: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
    wrapper_kwargs: dict[str, Any] | None = None,
    vec_env_cls: type[VecEnv] | None = None,
    vec_env_kwargs: dict[str, Any] | None = None,
    monitor_kwargs: dict[str, Any] | None = None,
) -> VecEnv:
    """SB3's ``make_vec_env`` with every sub-env ``Monitor(SwirlWrapper(env, task))``.

    The monitor sits outside the SWIRL wrapper, so it sees the episode as the agent does
    (including an early end with ``terminate_on_completion``); the env's own reward stays in
    ``info["task_reward"]``. The sub-envs can run in other processes (``SubprocVecEnv``, any
    start method): they find the ``sb3_swirl/`` env ids there. The arguments are
    ``make_vec_env``'s but ``wrapper_kwargs``, which go to :class:`SwirlWrapper` (give a factory
    for wrappers of your own).

    Parameters
    ----------
    env_id : str, gymnasium.Env or callable
        A registered id (made with ``gym.make(env_id, render_mode="rgb_array", **env_kwargs)``,
        without the render mode where the env takes none, as SB3 does), an env instance
        (``n_envs`` must then be 1) or a picklable factory (called with ``**env_kwargs``).
    task : TaskModel
        The proxy task.
    n_envs : int
        Number of sub-environments.
    seed : int, optional
        Seed of the first sub-env; the others get ``seed + i``.
    start_index : int
        Rank of the first sub-env (its seed offset and monitor file name).
    monitor_dir : str, optional
        Folder of the monitors' ``{rank}.monitor.csv`` files; default: none written.
    env_kwargs : dict, optional
        Passed to ``gym.make`` or to the factory (e.g. ``{"radius": 2.0}``); refused with an env
        instance.
    wrapper_kwargs : dict, optional
        ``reward_config``, ``terminate_on_completion`` or ``state_key`` of ``SwirlWrapper``.
    vec_env_cls : type, optional
        ``DummyVecEnv`` (default) or ``SubprocVecEnv``.
    vec_env_kwargs : dict, optional
        Passed to ``vec_env_cls`` (e.g. ``{"start_method": "spawn"}``).
    monitor_kwargs : dict, optional
        Passed to each ``Monitor`` (e.g. ``{"info_keywords": ("is_success",)}``).

    Returns
    -------
    VecEnv
        ``n_envs`` sub-envs, each ``Monitor(SwirlWrapper(gym.make(env_id), task))``.

    Examples
    --------
    >>> from swirl_wrappers import QuadraticReward, Region, TaskModel
    >>> task = TaskModel(  # hold the pole upright: one region around angle 0
    ...     regions=[Region(mean=[0.0], covariance=[[0.05**2]], threshold=1.0)],
    ...     rewards=[QuadraticReward(target=[0.0], weight=[[100.0]])],
    ...     dims=[2],
    ... )
    >>> venv = make_swirl_env("CartPole-v1", task, n_envs=2, seed=0)
    >>> venv.reset().shape, venv.get_attr("segment")
    ((2, 6), [1, 1])
    """
    n_envs = check_int("n_envs", n_envs, low=1)
    if isinstance(env_id, gym.Env) and n_envs != 1:
        raise ValueError(
            f"an env instance can back only one sub-env, got n_envs={n_envs}; "
            "pass an env id or a factory instead"
        )
    if env_kwargs and isinstance(env_id, gym.Env):
        raise TypeError(
            f"env_kwargs {sorted(env_kwargs)} are for gym.make or a factory; got an env "
            f"instance ({type(env_id).__name__}): give the settings to your env instead"
        )
    factory = _SwirlEnvFactory(env_id, task, dict(wrapper_kwargs or {}), dict(env_kwargs or {}))
    vec_env_cls = vec_env_cls or DummyVecEnv
    if vec_env_cls is not DummyVecEnv and not isinstance(env_id, gym.Env):
        factory().close()  # a bad id, task or setting fails here, not in a worker process
    return make_vec_env(
        factory,
        n_envs=n_envs,
        seed=seed,
        start_index=start_index,
        monitor_dir=monitor_dir,
        vec_env_cls=vec_env_cls,
        vec_env_kwargs=vec_env_kwargs,
        monitor_kwargs=monitor_kwargs,
    )
