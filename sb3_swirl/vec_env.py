"""The SWIRL proxy task as a Stable-Baselines3 ``VecEnvWrapper``."""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from swirl_wrappers import SegmentTracker, TaskModel
from swirl_wrappers.wrappers import SEGMENT_KEY

__all__ = ["SwirlVecEnv"]


class SwirlVecEnv(VecEnvWrapper):
    """Track the SWIRL segment of every sub-environment and return the segment rewards.

    The SB3 counterpart of :class:`swirl_wrappers.SwirlWrapper`, computed for all sub-envs at
    once (:meth:`swirl_wrappers.SegmentTracker.step_lift_infos`: with numba, one compiled call
    that also reads and writes the info dicts), with the same observations, rewards and
    ``info`` keys (``"segment"``, ``"task_reward"``, ``"segment_reward"``). SB3
    vector envs reset a sub-env as soon as it is done: the transition's reward is computed on
    ``infos[i]["terminal_observation"]``, which is lifted with the index the episode ended with,
    and the returned observation starts the new episode. The env's own rewards are those the
    vector env returns: float32 in SB3's ``DummyVecEnv``, so ``info["task_reward"]`` (and a
    ``task_reward_weight`` or ``"potential"`` reward built on it) can differ from a
    ``SwirlWrapper``'s in the last float32 digit.

    Put it directly on the environments (below ``VecNormalize`` or ``VecFrameStack``): the
    task's regions live in the raw observation space.

    ``terminate_on_completion`` needs the sub-environment to be reset, which a ``VecEnvWrapper``
    cannot do cleanly; wrap each env with ``SwirlWrapper(..., terminate_on_completion=True)``
    (``make_vec_env(..., wrapper_class=SwirlWrapper, wrapper_kwargs=...)``) instead.

    Parameters
    ----------
    venv : VecEnv
        Sub-environments with a 1-D Box or a Dict observation space.
    task : TaskModel
    reward_scale, region_bonus, state_key, reward_mode, task_reward_weight, gamma
        As in :class:`swirl_wrappers.SwirlWrapper`.

    Attributes
    ----------
    task : TaskModel
    tracker : SegmentTracker
        Indices (``tracker.index``) and episode steps (``tracker.t``) of the sub-envs.

    Examples
    --------
    >>> import numpy as np
    >>> from stable_baselines3.common.env_util import make_vec_env
    >>> from swirl_wrappers import QuadraticReward, Region, TaskModel
    >>> from sb3_swirl.vec_env import SwirlVecEnv
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
    >>> np.allclose(rewards, -100.0 * obs[:, 2] ** 2), infos[0]["segment"]
    (True, 1)
    """

    def __init__(
        self,
        venv: VecEnv,
        task: TaskModel,
        reward_scale: float = 1.0,
        region_bonus: float = 0.0,
        terminate_on_completion: bool = False,
        state_key: str | None = None,
        reward_mode: str = "quadratic",
        task_reward_weight: float | None = None,
        gamma: float = 0.99,
    ) -> None:
        if not isinstance(venv, VecEnv):
            raise ValueError(
                f"SwirlVecEnv wraps an SB3 VecEnv, got {type(venv).__name__}: vectorise the env "
                "first (DummyVecEnv), or wrap a gymnasium env with SwirlWrapper"
            )
        if terminate_on_completion:
            raise ValueError(
                "SwirlVecEnv cannot end one sub-environment's episode on completion; wrap each "
                "env with SwirlWrapper(..., terminate_on_completion=True) instead"
            )
        tracker = SegmentTracker(
            task,
            venv.num_envs,
            venv.observation_space,
            reward_scale,
            region_bonus,
            state_key,
            reward_mode=reward_mode,
            task_reward_weight=task_reward_weight,
            gamma=gamma,
        )
        super().__init__(venv, observation_space=tracker.observation_space)
        self.task = task
        self.tracker = tracker

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        self.tracker.reset(self.tracker.states(obs))
        self.reset_infos = [
            {**info, SEGMENT_KEY: index}
            for info, index in zip(self.venv.reset_infos, self.tracker.index.tolist(), strict=True)
        ]
        return self.tracker.lift(obs)

    def step_wait(self) -> VecEnvStepReturn:
        obs, task_rewards, dones, infos = self.venv.step_wait()
        terminated = None
        if self.tracker.reward_mode == "potential":  # the only mode that reads terminated
            # SB3 marks a time-limit end with TimeLimit.truncated; every other done is a
            # termination.
            truncated = [bool(info.get("TimeLimit.truncated")) for info in infos]
            terminated = dones & ~np.array(truncated)
        lifted, rewards = self.tracker.step_lift_infos(obs, dones, task_rewards, infos, terminated)
        return lifted, rewards, dones, infos
