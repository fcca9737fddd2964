"""Scripted supervisors for the discrete Fetch tasks (:class:`~sb3_swirl.envs.FetchDiscreteEnv`).

Each plans on where its steps take the gripper (the env's ``target``, as a person moving the
arm knows) and on the object and goal positions of the observation, and moves in the env's
end-effector steps, choosing at random (with its ``seed``) among equally useful steps now and
then so that demos from the same start differ (:func:`~sb3_swirl.supervisors._shared.step_towards`).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_swirl.envs.fetch import CLOSE, DIRECTIONS, OPEN, FetchDiscreteEnv
from sb3_swirl.supervisors._shared import controlled_env, step_towards

UP = 4
#: height (m) above the object's centre at which the gripper travels over it
_CLEARANCE = 0.08
#: height (m) above the object's centre under which push's gripper is down at the object
_LOWERED = 0.03
#: height (m) above the object's centre at which pick-and-place closes the fingers (fingers
#: that touch the table close slowly and let the object go)
_GRASP_HEIGHT = 0.005


class _FetchSupervisor:
    """Shared parts: the env, the rng, the phase and a step towards a point."""

    task = ""

    def __init__(self, env: gym.Env, seed: int | None = None) -> None:
        self.env = controlled_env(env, FetchDiscreteEnv, type(self).__name__)
        if self.env.task != self.task:
            raise ValueError(
                f"{type(self).__name__} controls Fetch{self.task}, got Fetch{self.env.task}"
            )
        self.rng = np.random.default_rng(seed)
        self._phase = 0

    @property
    def phase(self) -> int:
        """The phase of the plan the last action belongs to."""
        return self._phase

    def reset(self, obs: dict[str, np.ndarray]) -> None:
        self._phase = 0

    def _towards(self, error: np.ndarray, explore: bool = True) -> int | None:
        """The step that brings the gripper closer by ``error``; None within half a step."""
        return step_towards(DIRECTIONS, error, self.env.step_size, self.rng if explore else None)


class FetchReachSupervisor(_FetchSupervisor):
    """Move the gripper straight to the goal (one phase).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/FetchReachDiscrete-v0")
    >>> sup = FetchReachSupervisor(env.unwrapped, seed=0)
    >>> obs, info = env.reset(seed=0)
    >>> sup.reset(obs)
    >>> while True:
    ...     obs, reward, terminated, truncated, info = env.step(sup.act(obs))
    ...     if terminated or truncated:
    ...         break
    >>> info["is_success"]
    True
    """

    task = "Reach"

    def act(self, obs: dict[str, np.ndarray]) -> int:
        action = self._towards(obs["desired_goal"] - self.env.target)
        return UP if action is None else action


#: FetchPushSupervisor's phases
LIFT, ALIGN, LOWER, PUSH = range(4)


class FetchPushSupervisor(_FetchSupervisor):
    """Push the object to the goal in two straight legs, one along x and one along y.

    Each action follows from what the supervisor sees now (the gripper, the object and the
    goal), not from a plan it remembers, so that a clone, which sees the same, can learn it:
    with a remembered phase, alike states got opposite actions (up while lifting, down while
    lowering), and clones went back and forth between them until the time limit (most of
    SwirlDQN's failures on tuning seeds 0 and 1). Along the longer open leg first: lowered
    behind the object on its centre line, push along the leg's axis until the object is within
    ``done`` of the goal on that axis; over the spot ``behind`` the object, lower; elsewhere,
    low, back off and lift clear of the object; high, go over the spot. The discrete steps
    push straight only along an axis, so the legs are axis-aligned; an object that slid
    sideways by more than ``tolerance`` is lined up again, and a leg that the other undid is
    pushed again. :attr:`phase` names the branch taken (lift, align, lower, push).

    Parameters
    ----------
    env : FetchDiscreteEnv
        A ``FetchPushDiscrete`` env (wrappers are looked through).
    seed : int, optional
        Seeds the choice among equally useful steps.
    behind : float, default 0.05
        How far behind the object's centre (m) the gripper lowers to push.
    tolerance : float, default 0.015
        How far (m) the gripper may be off the object's centre line while pushing.
    done : float, default 0.025
        A leg ends when the object is this close to the goal (m) along its axis. The object
        slides on by a step or so after the last push (the arm lags its command): with 0.015,
        an object pushed towards a goal near the table's edge slid off it (1 of 151 starts).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/FetchPushDiscrete-v0")
    >>> sup = FetchPushSupervisor(env.unwrapped, seed=0)
    >>> obs, info = env.reset(seed=0)
    >>> sup.reset(obs)
    >>> while True:
    ...     obs, reward, terminated, truncated, info = env.step(sup.act(obs))
    ...     if terminated or truncated:
    ...         break
    >>> info["is_success"]
    True
    """

    task = "Push"

    def __init__(
        self,
        env: gym.Env,
        seed: int | None = None,
        behind: float = 0.05,
        tolerance: float = 0.015,
        done: float = 0.025,
    ) -> None:
        super().__init__(env, seed)
        self.behind = behind
        self.tolerance = tolerance
        self.done = done

    def act(self, obs: dict[str, np.ndarray]) -> int:
        grip, cube, goal = self.env.target, self.env.fetch_observation[3:6], obs["desired_goal"]
        error = goal[:2] - cube[:2]
        signs = np.where(error > 0, 1.0, -1.0)
        legs = [axis for axis in (0, 1) if abs(error[axis]) >= self.done]
        for axis in legs:
            # pushed past the goal, the object is no longer ahead of the (observed) gripper
            ahead = (cube[axis] - self.env.fetch_observation[axis]) * signs[axis]
            lined_up = abs(grip[1 - axis] - cube[1 - axis]) <= self.tolerance
            lowered = grip[2] < cube[2] + _LOWERED
            if lowered and lined_up and 0 < ahead <= self.behind + self.tolerance:
                self._phase = PUSH
                return self._push(axis, signs[axis])
        axis = max(legs, key=lambda a: abs(error[a])) if legs else int(np.argmax(abs(error)))
        place = cube.copy()
        place[axis] -= signs[axis] * self.behind
        action = self._towards(np.append(place[:2] - grip[:2], 0.0))
        if action is None:  # over the spot: down to the table, then push
            self._phase = LOWER
            down = self._towards(np.array([0.0, 0.0, place[2] - grip[2]]), explore=False)
            return self._push(axis, signs[axis]) if down is None else down
        if grip[2] < cube[2] + _CLEARANCE - self.env.step_size / 2:
            self._phase = LIFT
            away = grip[:2] - cube[:2]
            if grip[2] < cube[2] + _LOWERED and np.linalg.norm(away) < self.behind + 0.01:
                # back off before lifting: a gripper that rises against the object drags it
                return int(np.argmax(DIRECTIONS[:4, :2] @ away))
            return UP
        self._phase = ALIGN
        return action

    @staticmethod
    def _push(axis: int, sign: float) -> int:
        return 2 * axis + (0 if sign > 0 else 1)  # +x, -x, +y or -y


#: FetchPickAndPlaceSupervisor's phases
OVER, DESCEND, GRASP, CARRY = range(4)


class FetchPickAndPlaceSupervisor(_FetchSupervisor):
    """Open over the object, go down, close, carry it to the goal.

    Parameters
    ----------
    env : FetchDiscreteEnv
        A ``FetchPickAndPlaceDiscrete`` env (wrappers are looked through).
    seed : int, optional
        Seeds the choice among equally useful steps.
    grasp_steps : int, default 8
        Close actions at most before carrying: it carries as soon as the fingers have stopped
        closing (moved less than 1 mm in a step).
    """

    task = "PickAndPlace"

    def __init__(self, env: gym.Env, seed: int | None = None, grasp_steps: int = 8) -> None:
        super().__init__(env, seed)
        self.grasp_steps = grasp_steps
        self._closing = 0
        self._width = np.inf

    def reset(self, obs: dict[str, np.ndarray]) -> None:
        super().reset(obs)
        self._closing = 0
        self._width = np.inf

    def act(self, obs: dict[str, np.ndarray]) -> int:
        grip, cube, goal = self.env.target, self.env.fetch_observation[3:6], obs["desired_goal"]
        if self._phase == OVER:
            if not self.env.gripper_open:
                return OPEN
            action = self._towards(cube + np.array([0.0, 0.0, _CLEARANCE]) - grip)
            if action is not None:
                return action
            self._phase = DESCEND
        if self._phase == DESCEND:  # to just above the object's centre: clear of the table
            height = cube[2] + _GRASP_HEIGHT - grip[2]
            action = self._towards(np.array([0.0, 0.0, height]), explore=False)
            if action is not None:
                return action
            self._phase = GRASP
        if self._phase == GRASP:
            width = float(self.env.fetch_observation[9:11].sum())
            closing, self._width = self._width - width > 0.001, width
            if self._closing < self.grasp_steps and (closing or self._closing == 0):
                self._closing += 1
                return CLOSE
            self._phase = CARRY
        action = self._towards(goal - cube)
        return UP if action is None else action
