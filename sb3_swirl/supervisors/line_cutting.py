"""Kinesthetic-like supervisor for :class:`~sb3_swirl.envs.dvrk.DVRKLineCuttingEnv`."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_swirl.envs.dvrk.line_cutting import _DIRECTIONS, PLUS_X, DVRKLineCuttingEnv
from sb3_swirl.supervisors._shared import controlled_env, step_towards

#: The supervisor's phases: move to the line's start, then follow the line.
POSITION, FOLLOW = range(2)


class LineCuttingSupervisor:
    """Go to the start of the line, then follow it, in 2 mm steps.

    It plans on the commanded tool position (where the arm is being taken, as a person moving
    the arm by hand knows) and the line's geometry. The arm trails its commands by a few
    millimetres, so it first lines up ``approach`` behind the start, on the line's extension
    (across the line first, then along it), then moves in along the line; following steps
    towards the point of the line ``lookahead`` ahead of the tool's nearest point. It is
    deterministic: demos differ by their starts and lines.

    Parameters
    ----------
    env : DVRKLineCuttingEnv
        The environment to control (wrappers are looked through with ``env.unwrapped``).
    seed : int, optional
        Unused (taken like the other supervisors' seeds).
    lookahead : float, default 0.004
        How far ahead along the line (m) the follower aims.
    approach : float, default 0.012
        Length (m) of the straight run-in to the line's start.

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
    ) -> None:
        self.env = controlled_env(env, DVRKLineCuttingEnv, "LineCuttingSupervisor")
        self.lookahead = lookahead
        self.approach = approach
        self._stage = 0

    @property
    def phase(self) -> int:
        """0 while moving to the line's start, 1 while following the line."""
        return POSITION if self._stage < 2 else FOLLOW

    def reset(self, obs: np.ndarray) -> None:
        self._stage = 0

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
        _, s = env.line_distance(here)
        target = env.point_along(s + self.lookahead)
        action = self._step_towards(target - here)
        return PLUS_X if action is None else action

    def _step_towards(self, error: np.ndarray) -> int | None:
        return step_towards(_DIRECTIONS, error, self.env.step_size)
