"""Teleoperation-like supervisor for :class:`~sb3_swirl.envs.dvrk.DVRKTensioningEnv`."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_swirl.envs.dvrk._robosuite import TABLE_TOP
from sb3_swirl.envs.dvrk.tensioning import (
    _DIRECTIONS,
    CLOSE,
    FREE_EDGE,
    GRID,
    MINUS_Z,
    PIN_HEIGHT,
    PLUS_Z,
    DVRKTensioningEnv,
)
from sb3_swirl.supervisors._shared import controlled_env, step_towards
from swirl_wrappers._validation import check_int, check_real

#: The supervisor's phases.
REACH, GRASP, LIFT, TENSION = range(4)


class TensioningSupervisor:
    """Reach the gauze's free edge, grasp it, lift it and pull it flat, one key press a step.

    Like a person at a keyboard it moves one axis at a time on the commanded tool position:

    1. *reach*: over the middle of the free edge (a point up to ``aim_spread`` to either side,
       drawn with ``seed``), horizontally first (along either useful axis, chosen at random with
       ``seed``), then down to the lowest tool height;
    2. *grasp*: once the tool has come down to within 1 mm of that height (pressing "down"
       again, at most ``max_wait`` times), close the gripper for ``grasp_steps`` steps;
    3. *lift*: up to the height of the pinned corners;
    4. *tension*: pull away from the pins, with the grasped part centred on the sheet and
       5 mm above the pins, until the disparity is at most ``target_disparity`` or the
       workspace ends; then hold (``close`` again).

    Parameters
    ----------
    env : DVRKTensioningEnv
        The environment to control (wrappers are looked through with ``env.unwrapped``).
    seed : int, optional
        Seeds the aim point and the choice of axes while reaching.
    aim_spread : float, default 0.01
        How far (m) from the middle of the free edge the aim point may be.
    target_disparity : float, default 0.02
        Disparity (cm²) at which pulling stops.
    grasp_steps : int, default 2
        Steps the gripper is closed for before lifting (at least 1).
    max_wait : int, default 5
        The most "down" steps pressed while the tool settles to its lowest height.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/DVRKTensioning-v0")
    >>> sup = TensioningSupervisor(env.unwrapped, seed=0)
    >>> obs, info = env.reset(seed=0)
    >>> sup.reset(obs)
    >>> while True:
    ...     obs, reward, terminated, truncated, info = env.step(sup.act(obs))
    ...     if terminated or truncated:
    ...         break
    >>> info["is_success"]
    True
    """

    def __init__(
        self,
        env: gym.Env,
        seed: int | None = None,
        aim_spread: float = 0.01,
        target_disparity: float = 0.02,
        grasp_steps: int = 2,
        max_wait: int = 5,
    ) -> None:
        self.env = controlled_env(env, DVRKTensioningEnv, "TensioningSupervisor")
        self.aim_spread = check_real("aim_spread (m)", aim_spread, low=0.0, high=0.05)
        self.target_disparity = check_real(
            "target_disparity", target_disparity, low=0.0, low_open=True
        )
        self.grasp_steps = check_int("grasp_steps", grasp_steps, low=1)
        self.max_wait = check_int("max_wait", max_wait, low=0)
        self.rng = np.random.default_rng(seed)
        self._phase = REACH
        self._aim_y = 0.0
        self._waited = 0
        self._offset_y = 0.0

    @property
    def phase(self) -> int:
        """The phase of the last action: 0 reach, 1 grasp, 2 lift, 3 tension."""
        return self._phase

    def reset(self, obs: np.ndarray) -> None:
        self._phase = REACH
        self._aim_y = self.rng.uniform(-self.aim_spread, self.aim_spread)
        self._waited = 0
        self._offset_y = 0.0

    def act(self, obs: np.ndarray) -> int:
        env = self.env
        here = env.commanded_position
        if self._phase == REACH:
            edge = env.vertices[FREE_EDGE[GRID // 2]]
            error = np.array([edge[0], self._aim_y, TABLE_TOP + env.min_height]) - here
            action = self._step_towards(error * [1.0, 1.0, 0.0], explore=True)
            if action is None and error[2] < -env.step_size / 2:
                action = MINUS_Z
            if action is not None:
                return action
            # at the lowest command, wait (pressing "down" again) for the tool to arrive
            if obs[2] > 100.0 * env.min_height + 0.1 and self._waited < self.max_wait:
                self._waited += 1
                return MINUS_Z
            self._waited = 0
            self._phase = GRASP
        if self._phase == GRASP:
            if self._waited < self.grasp_steps:
                self._waited += 1
                return CLOSE
            # centre what was grasped on the sheet's middle line while pulling
            held = env.held_vertices
            if len(held):
                self._offset_y = float(env.vertices[held, 1].mean() - env.tool_position[1])
            self._phase = LIFT
        if self._phase == LIFT:
            if here[2] < TABLE_TOP + PIN_HEIGHT - env.step_size / 2:
                return PLUS_Z
            self._phase = TENSION
        if obs[5] <= self.target_disparity:
            return CLOSE
        target = np.array([env.workspace_low[0], -self._offset_y, TABLE_TOP + PIN_HEIGHT + 0.005])
        action = self._step_towards(target - here, explore=False)
        return CLOSE if action is None else action

    def _step_towards(self, error: np.ndarray, explore: bool) -> int | None:
        rng = self.rng if explore else None
        return step_towards(_DIRECTIONS, error, self.env.step_size, rng)
