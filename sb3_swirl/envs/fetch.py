"""gymnasium-robotics' Fetch tasks with the dVRK tasks' discrete end-effector actions.

:class:`FetchDiscreteEnv` drives a gymnasium-robotics Fetch env (``FetchReach-v4``,
``FetchPush-v4``, ``FetchPickAndPlace-v4``) in fixed end-effector steps, as the dVRK tasks
drive their arm (:mod:`sb3_swirl.envs.dvrk`):

- actions ``0..5`` move the gripper by ``step_size`` (default 2 cm) along +x, -x, +y, -y, +z,
  -z; on pick-and-place, ``6`` opens and ``7`` closes the gripper, which stays as last
  commanded while the arm moves. Reach and push keep gymnasium-robotics' blocked (closed)
  gripper, so they have the 6 moves only;
- the steps add up exactly: Fetch moves its gripper towards a point ahead of it and covers
  about two thirds of the way in one step, so the adapter keeps the target the steps lead to
  and commands the way to it (``target``; kept within two steps of a gripper that the table
  or an object holds back);
- the goal-conditioned ``Dict`` observation (``observation``, ``achieved_goal``,
  ``desired_goal``) and the sparse reward (-1 until the goal is within 5 cm, then 0) are
  gymnasium-robotics' own, and so is ``compute_reward``: the env is a goal env for SB3's
  ``HerReplayBuffer``;
- the episode ends (``terminated``) when the goal is reached, as the paper's tasks do, so that
  a return counts the steps to the goal; ``terminate_on_success=False`` keeps Fetch's
  behaviour (never terminated, only truncated by the time limit);
- a start whose goal is closer than ``min_goal_distance`` (default 10 cm, twice Fetch's
  success distance) is redrawn: Fetch draws goals near enough to be reached in a step or two
  (already reached in about 9% of push starts), and such episodes teach nothing and give
  demos too short to segment.

gymnasium-robotics (the ``fetch`` extra) is imported when an env is made, not on import.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Sequence
from typing import Any, ClassVar, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from swirl_wrappers._validation import check_bool, check_real

#: +x, -x, +y, -y, +z, -z: the end-effector moves (unit vectors, world frame)
DIRECTIONS = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
)
#: the gripper actions of pick-and-place
OPEN, CLOSE = 6, 7
#: gymnasium-robotics scales a unit action to this end-effector move (m)
_FETCH_ACTION_SCALE = 0.05


class FetchDiscreteEnv(gym.Env):
    """A gymnasium-robotics Fetch task with discrete end-effector steps.

    Parameters
    ----------
    task : {"Reach", "Push", "PickAndPlace"}
        The Fetch task (gymnasium-robotics' ``Fetch<task>-v4``).
    step_size : float, default 0.02
        The end-effector move of one action (m), at most 0.05 (Fetch's largest step).
    terminate_on_success : bool, default True
        End the episode when the goal is reached.
    min_goal_distance : float, default 0.1
        Starts whose achieved goal lies closer than this (m) to the desired one are redrawn
        (from the same seeded stream). 0 keeps Fetch's distribution.
    goal_offset : bool, default False
        Add a ``"goal_offset"`` key, ``desired_goal - achieved_goal``: a goal-relative state
        for SWIRL, whose phases look alike across demos only in coordinates relative to the
        object and the goal. Leave it out for ``HerReplayBuffer``, which relabels
        ``desired_goal`` but not the keys computed from it.
    observation_dims : sequence of int, optional
        Keep only these entries of Fetch's ``observation`` vector (push and pick-and-place:
        0-2 gripper position, 3-5 object position, 6-8 the object's offset from the gripper,
        9-10 finger widths, 11-13 object rotation, 14-16 and 17-19 object velocities, 20-22
        gripper velocity, 23-24 finger velocities; reach: 0-2 gripper position, 3-4 finger
        widths, 5-7 and 8-9 velocities). Entries that a task does not need make a policy
        learned from few demos generalise worse. Default: all.
    render_mode : {"rgb_array"}, optional
        For looking at the scene; never needed for training.
    **fetch_kwargs
        Passed to gymnasium-robotics' env (e.g. ``reward_type="dense"``).

    Attributes
    ----------
    fetch : gymnasium.Env
        The unwrapped gymnasium-robotics env.
    gripper_open : bool
        The gripper command in force (pick-and-place; always False on reach and push).
    target : array of shape (3,)
        Where the steps so far take the gripper (m, world frame).
    fetch_observation : array
        Fetch's whole ``observation`` vector at the last reset or step (``observation_dims``
        selects from it).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/FetchReachDiscrete-v0")
    >>> env.action_space, sorted(env.observation_space.spaces)
    (Discrete(6), ['achieved_goal', 'desired_goal', 'observation'])
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(0)  # 2 cm along +x
    >>> float(reward), bool(info["is_success"])
    (-1.0, False)
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 25}
    #: the observation keys computed from the desired goal (a SWIRL task that reads one
    #: refuses hindsight relabelling: :meth:`swirl_wrappers.SwirlWrapper.compute_reward`)
    goal_keys: ClassVar[tuple[str, ...]] = ("desired_goal", "goal_offset")
    TASKS: ClassVar[tuple[str, ...]] = ("Reach", "Push", "PickAndPlace")

    def __init__(
        self,
        task: str = "Reach",
        step_size: float = 0.02,
        terminate_on_success: bool = True,
        min_goal_distance: float = 0.1,
        goal_offset: bool = False,
        observation_dims: Sequence[int] | None = None,
        render_mode: str | None = None,
        **fetch_kwargs: Any,
    ) -> None:
        if task not in self.TASKS:
            raise ValueError(f"task must be one of {self.TASKS}, got {task!r}")
        step_size = check_real("step_size", step_size)
        if not 0.0 < step_size <= _FETCH_ACTION_SCALE:
            raise ValueError(
                f"step_size must be in (0, {_FETCH_ACTION_SCALE}] m (Fetch moves at most "
                f"{_FETCH_ACTION_SCALE} m per step), got {step_size}"
            )
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.task = task
        self.step_size = step_size
        self.terminate_on_success = check_bool("terminate_on_success", terminate_on_success)
        self.min_goal_distance = check_real("min_goal_distance", min_goal_distance)
        if not 0.0 <= self.min_goal_distance <= 0.2:
            raise ValueError(
                f"min_goal_distance must be in [0, 0.2] m (Fetch's goals lie within about "
                f"0.3 m), got {min_goal_distance}"
            )
        self.render_mode = render_mode
        self.fetch = _make_fetch(task, render_mode, fetch_kwargs)
        self.goal_offset = check_bool("goal_offset", goal_offset)
        keys = dict(self.fetch.observation_space.spaces)
        size = keys["observation"].shape[0]
        self.observation_dims = _check_dims(observation_dims, size)
        if self.observation_dims is not None:
            whole = keys["observation"]
            keys["observation"] = spaces.Box(
                whole.low[self.observation_dims],
                whole.high[self.observation_dims],
                dtype=whole.dtype,
            )
        if self.goal_offset:
            goal = keys["desired_goal"]
            keys["goal_offset"] = spaces.Box(-np.inf, np.inf, goal.shape, goal.dtype)
        self.observation_space = spaces.Dict(keys)
        self.action_space = spaces.Discrete(6 if self.fetch.block_gripper else 8)
        self.gripper_open = False
        self.target = self._gripper = np.zeros(3)
        self.fetch_observation = np.zeros(size)

    @property
    def distance_threshold(self) -> float:
        """How close (m) the achieved goal must come to the desired one."""
        return float(self.fetch.distance_threshold)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        """gymnasium-robotics' reward (vectorised): -1 if the goals are farther apart than
        :attr:`distance_threshold`, else 0."""
        return self.fetch.compute_reward(achieved_goal, desired_goal, info)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        obs, info = self.fetch.reset(seed=seed, options=options)
        # a start whose goal is too near is redrawn (from the same seeded stream)
        while (
            np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"]) < self.min_goal_distance
            or self.fetch.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == 0
        ):
            obs, info = self.fetch.reset(options=options)
        self.gripper_open = False
        self._gripper = obs["observation"][:3].copy()  # Fetch's grip_pos
        self.target = self._gripper.copy()
        return self._observe(obs), info

    def _observe(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.fetch_observation = obs["observation"].copy()
        if self.observation_dims is not None:
            obs["observation"] = obs["observation"][self.observation_dims]
        if self.goal_offset:
            obs["goal_offset"] = obs["desired_goal"] - obs["achieved_goal"]
        return obs

    def step(
        self, action: Any
    ) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool, dict[str, Any]]:
        action = int(action)
        if not self.action_space.contains(action):
            raise ValueError(f"action must be in 0..{self.action_space.n - 1}, got {action}")
        gripper = self._gripper
        if action < len(DIRECTIONS):
            self.target = self.target + DIRECTIONS[action] * self.step_size
        else:
            self.gripper_open = action == OPEN
        # the target stays within two steps of a gripper that something holds back
        reach = 2.0 * self.step_size
        self.target = gripper + np.clip(self.target - gripper, -reach, reach)
        command = np.zeros(4)
        move = np.clip(self.target - gripper, -_FETCH_ACTION_SCALE, _FETCH_ACTION_SCALE)
        command[:3] = move / _FETCH_ACTION_SCALE
        command[3] = 1.0 if self.gripper_open else -1.0
        obs, reward, terminated, truncated, info = self.fetch.step(command)
        success = bool(info["is_success"])
        info["is_success"] = success
        terminated = terminated or (self.terminate_on_success and success)
        self._gripper = obs["observation"][:3].copy()
        return self._observe(obs), float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        return self.fetch.render()

    def close(self) -> None:
        self.fetch.close()


def _check_dims(dims: Sequence[int] | None, size: int) -> np.ndarray | None:
    """``observation_dims`` as an index array, or a clear error."""
    if dims is None:
        return None
    arr = np.asarray(dims)
    if arr.ndim != 1 or arr.size == 0 or not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"observation_dims must be a non-empty list of ints, got {dims!r}")
    if arr.min() < 0 or arr.max() >= size or len(set(arr.tolist())) != arr.size:
        raise ValueError(
            f"observation_dims must be distinct entries of Fetch's {size}-dim observation "
            f"(0..{size - 1}), got {list(dims)}"
        )
    return arr


def _make_fetch(task: str, render_mode: str | None, kwargs: dict[str, Any]) -> gym.Env:
    """The unwrapped ``Fetch<task>-v4``; a one-line error without gymnasium-robotics."""
    try:
        # gymnasium-robotics prints a notice on import about Adroit rewards (not used here)
        with contextlib.redirect_stderr(io.StringIO()):
            import gymnasium_robotics
    except ImportError:
        raise ImportError(
            "the Fetch tasks need gymnasium-robotics: pip install 'sb3-swirl[fetch]'"
        ) from None
    gym.register_envs(gymnasium_robotics)
    return gym.make(f"Fetch{task}-v4", render_mode=render_mode, **kwargs).unwrapped
