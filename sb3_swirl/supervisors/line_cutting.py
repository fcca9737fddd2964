"""Kinesthetic-like supervisor for :class:`~sb3_swirl.envs.dvrk.DVRKLineCuttingEnv`."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_swirl.envs.dvrk.line_cutting import _DIRECTIONS, PLUS_X, DVRKLineCuttingEnv
from sb3_swirl.supervisors._shared import controlled_env, step_towards
from swirl_wrappers._validation import check_int, check_real

#: The supervisor's phases: move to the line's start, then follow the line.
POSITION, FOLLOW = range(2)


class LineCuttingSupervisor:
    """Go to the start of the line, then follow it, in 2 mm steps.

    It plans on the commanded tool position (where the arm is being taken, as a person moving
    the arm by hand knows) and the line's geometry. The arm trails its commands by a few
    millimetres, so it first lines up ``approach`` behind the start, on the line's extension
    (across the line first, then along it), then moves in along the line; following steps
    towards the point of the line ``lookahead`` ahead of the tool's nearest point.

    A hand that moves the arm is not exact: while following, at each step on the line (within
    ``slack``) the hand slips with probability ``slip``, 1 to ``max_slip`` steps across the line
    to a random side, and once the tool is more than ``slack`` off the line the next steps take
    it back. These corrections are what a clone of straight-line demos learns
    to follow an arc from: where the line bends away, step back towards it (with the env's
    signed offset, which says on which side the line is). Positioning is deterministic, one
    action per place, which a clone can learn.

    Parameters
    ----------
    env : DVRKLineCuttingEnv
        The environment to control (wrappers are looked through with ``env.unwrapped``).
    seed : int, optional
        Seeds the slips.
    lookahead : float, default 0.004
        How far ahead along the line (m) the follower aims.
    approach : float, default 0.012
        Length (m) of the straight run-in to the line's start.
    slip : float, default 0.15
        Probability that a step of the cut on the line starts a slip (0: none).
    slack : float, default 0.0015
        Distance from the line (m) beyond which the follower steps back to it.
    max_slip : int, default 3
        The longest slip, in steps (a slip's length is drawn uniformly from 1 to this).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/DVRKLineCutting-v0")
    >>> sup = LineCuttingSupervisor(env.unwrapped, seed=0)
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
        lookahead: float = 0.004,
        approach: float = 0.012,
        slip: float = 0.15,
        slack: float = 0.0015,
        max_slip: int = 3,
    ) -> None:
        self.env = controlled_env(env, DVRKLineCuttingEnv, "LineCuttingSupervisor")
        # in metres, as the env's positions (its radius and line settings are in cm)
        self.lookahead = check_real("lookahead (m)", lookahead, low=0.0, high=0.05, low_open=True)
        self.approach = check_real("approach (m)", approach, low=0.0, high=0.05, low_open=True)
        self.slip = check_real("slip", slip, low=0.0, high=1.0)
        self.slack = check_real("slack (m)", slack, low=0.0, high=0.01)
        self.max_slip = check_int("max_slip", max_slip, low=1)
        self._rng = np.random.default_rng(seed)
        self._stage = 0
        self._slipping = 0
        self._slip_action = PLUS_X

    @property
    def phase(self) -> int:
        """0 while moving to the line's start, 1 while following the line."""
        return POSITION if self._stage < 2 else FOLLOW

    def reset(self, obs: np.ndarray) -> None:
        self._stage = 0
        self._slipping = 0

    def act(self, obs: np.ndarray) -> int:
        env = self.env
        here = env.commanded_position[:2]
        line = env.line
        # the arm trails its commands by a few mm: line up behind the start (stage 0), then
        # move in along the line's direction (stage 1) so that the tool meets it at its start
        if self._stage == 0:
            tangent = (line[1] - line[0]) / np.linalg.norm(line[1] - line[0])
            normal = np.array([-tangent[1], tangent[0]])
            error = line[0] - self.approach * tangent - here
            # across the line first, then along it: one action per place, which a clone can
            # learn (choosing between the axes at random gave clones that cut 10-20% of lines)
            action = self._step_towards(np.dot(error, normal) * normal)
            if action is None:
                action = self._step_towards(error)
            if action is not None:
                return action
            self._stage = 1
        if self._stage == 1:
            action = self._step_towards(line[0] - here)
            if action is not None:
                return action
            self._stage = 2
        d, s = env.line_distance(here)
        if not self._slipping and d <= self.slack and self._rng.random() < self.slip:
            ahead = env.point_along(s + self.lookahead) - env.point_along(s)
            across = np.array([-ahead[1], ahead[0]]) * self._rng.choice([1.0, -1.0])
            self._slipping = int(self._rng.integers(1, self.max_slip + 1))
            self._slip_action = int(np.argmax(_DIRECTIONS @ across))  # the hand slips across
        if self._slipping:
            self._slipping -= 1
            return self._slip_action
        if d > self.slack:  # back to the line
            action = self._step_towards(env.point_along(s) - here)
            if action is not None:
                return action
        target = env.point_along(s + self.lookahead)
        action = self._step_towards(target - here)
        return PLUS_X if action is None else action

    def _step_towards(self, error: np.ndarray) -> int | None:
        return step_towards(_DIRECTIONS, error, self.env.step_size)
