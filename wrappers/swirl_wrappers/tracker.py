"""The rules of a SWIRL proxy task at run time, written once for every wrapper.

:class:`SegmentTracker` holds the segment index, the episode step and the progress potential of
one episode (:class:`~swirl_wrappers.SwirlWrapper`) or of ``num_envs`` parallel ones (the vector
wrappers, and sb3-swirl's demo relabelling), and applies the same rules to both:

* **reset**: ``t = 0``; the index starts at 0 and the segmentation function is applied to the
  first state once, so an episode that starts inside region 0 starts at index 1;
* **advance**: on each step ``t`` grows by one and the index ``i`` moves on by one when the new
  state ``s'`` lies in region ``i`` (the paper's Markov segmentation function); after the last
  region (index ``k``) it stays;
* **reward**: from the segment reward ``R_i(s')`` of the index *before* the step (Algorithm 3:
  observe ``R_i``, move to ``s'``, then advance), as :class:`~swirl_wrappers.RewardConfig`
  says; in ``"potential"`` mode through :func:`progress_potential`, which is 0 after a
  termination (a truncated episode keeps it: the agent bootstraps from it);
* **autoreset**: a vector env may start a new episode in a row during a step; the row's
  transition is scored first (on the episode's final state, when the env reports it), then the
  row is reset as above.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from swirl_wrappers._validation import check_bool, check_int
from swirl_wrappers.task import RewardConfig, TaskModel


def progress_potential(index: Any, segment_reward: Any) -> Any:
    """The progress potential ``Phi(s, i) = i + 1 / (1 - R_i(s))`` of ``"potential"`` mode.

    ``segment_reward`` is ``R_i(s)`` of the segment ``index`` the state is in (at most 0, as
    every segment reward is); the result lies in ``(i, i + 1]`` and grows as the state nears
    region ``i``.

    Parameters
    ----------
    index : int or int array
        The segment index(es) ``i``.
    segment_reward : float or array
        ``R_i(s)`` for each, at most 0.

    Returns
    -------
    float or array
        ``Phi(s, i)``, of the broadcast shape of the two.

    Examples
    --------
    >>> progress_potential(2, 0.0), progress_potential(0, -3.0)
    (3.0, 0.25)
    """
    return index + 1.0 / (1.0 - segment_reward)


class SegmentTracker:
    """Segment index, episode step and potential of one episode or of ``num_envs`` episodes.

    Parameters
    ----------
    task : TaskModel
    reward_config : RewardConfig or dict, optional
        Default: the task's own ``task.reward_config``; a dict changes only the fields it
        names (:meth:`RewardConfig.updated`).
    num_envs : int, optional
        ``None`` (default): one episode, whose state attributes are scalars. An int: that many
        episodes, whose state attributes are arrays of shape (num_envs,).
    terminate_on_completion : bool
        End an episode (``terminated``) on the step that reaches the last region.

    Attributes
    ----------
    index : int or ndarray of int64
        The current segment index of each episode, in ``0 .. task.n_segments``.
    ended_index : int or ndarray of int64
        The index each episode's last transition ended with (differs from ``index`` in a row
        that a :meth:`step` with ``restart`` reset).
    t : int or ndarray of int64
        Steps taken in each current episode.
    potential : float or ndarray of float64
        ``Phi`` of each current state (``"potential"`` mode; 0 otherwise).

    Examples
    --------
    >>> import numpy as np
    >>> from swirl_wrappers import QuadraticReward, Region, SegmentTracker, TaskModel
    >>> task = TaskModel([Region([1.0], [[0.01]], 1.0)], [QuadraticReward([1.0], [[1.0]])])
    >>> tracker = SegmentTracker(task, {"region_bonus": 10.0}, num_envs=2)
    >>> tracker.reset(np.array([[0.0], [0.0]]))
    >>> rewards, _ = tracker.step(np.array([[0.5], [1.0]]), 0.0, False)
    >>> rewards.tolist(), tracker.index.tolist()
    ([-0.25, 10.0], [0, 1])
    >>> restart = np.array([True, False])  # row 0 starts a new episode at 0.7
    >>> rewards, _ = tracker.step(np.array([[0.7], [7.0]]), 0.0, False, restart=restart)
    >>> rewards.tolist(), tracker.index.tolist(), tracker.t.tolist()
    ([0.0, -36.0], [0, 1], [0, 2])
    """

    def __init__(
        self,
        task: TaskModel,
        reward_config: RewardConfig | dict[str, Any] | None = None,
        num_envs: int | None = None,
        terminate_on_completion: bool = False,
    ) -> None:
        if not isinstance(task, TaskModel):
            raise ValueError(f"task must be a swirl_wrappers.TaskModel, got {type(task).__name__}")
        self.task = task
        self.config = task.reward_config.updated(reward_config)
        self.num_envs = None if num_envs is None else check_int("num_envs", num_envs, low=1)
        self.terminate_on_completion = check_bool(
            "terminate_on_completion", terminate_on_completion
        )
        zero = 0 if num_envs is None else np.zeros(self.num_envs, dtype=np.int64)
        self.index = self.ended_index = self.t = zero
        self.potential = 0.0 if num_envs is None else np.zeros(self.num_envs)
        self._warned_not_finite = False

    def reset(self, states: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Start new episodes from ``states`` (one state, or one per episode where ``mask``).

        ``t`` becomes 0 and the index ``M(s_0, 0, 0)``: 1 if ``s_0`` is already in region 0.
        """
        self._check(states, mask=mask)
        x = self.task.featurize(states)
        index = 0 + self.task.evaluate(x, 0, 0)[1]
        potential = self._potential(x, index, False)
        if mask is None:
            self.index, self.t, self.potential = index, 0 * index, potential
        else:  # new arrays, never writes into old ones: earlier infos may hold them
            self.index = np.where(mask, index, self.index)
            self.t = np.where(mask, 0, self.t)
            self.potential = np.where(mask, potential, self.potential)
        self.ended_index = self.index

    def step(
        self,
        states: np.ndarray,
        task_rewards: Any,
        terminated: Any,
        *,
        restart: np.ndarray | None = None,
        final_states: np.ndarray | None = None,
    ) -> tuple[Any, Any]:
        """Advance every episode to its next state; return the rewards and the terminations.

        Parameters
        ----------
        states : array of shape (state_dim,) or (num_envs, state_dim)
            The states the step reached (unlifted, under the task's ``dims``).
        task_rewards : float or array of shape (num_envs,)
            The environment's own rewards of the step.
        terminated : bool or bool array of shape (num_envs,)
            Which transitions ended their episode by a termination (not a truncation).
        restart : bool array of shape (num_envs,), optional
            Vector envs only: rows whose ``states`` start a new episode (an autoreset). With
            ``final_states`` (SB3, gymnasium's ``SAME_STEP``) their transition ends in those
            states; without (gymnasium's ``NEXT_STEP``) they made no transition and get
            reward 0. Then they are reset as by :meth:`reset`.
        final_states : array of shape (restart.sum(), state_dim), optional
            The states the ended episodes' last transitions reached.

        Returns
        -------
        rewards : float or float64 array of shape (num_envs,)
        terminated : bool or bool array
            ``terminated``, or also where the last region was reached when the tracker ends
            episodes on completion.
        """
        if self.num_envs is None and restart is None and getattr(states, "ndim", None) == 1:
            return self._transition(states, task_rewards, terminated)  # one episode's step
        self._check(states, task_rewards=task_rewards, terminated=terminated, restart=restart)
        task_rewards = np.asarray(task_rewards, dtype=np.float64)  # rewards are float64 sums
        if restart is None:
            return self._transition(states, task_rewards, terminated)
        restart = np.asarray(restart, dtype=bool)
        want = (np.count_nonzero(restart), *np.shape(states)[1:])
        if final_states is not None and np.shape(final_states) != want:
            raise ValueError(
                f"final_states must hold one state per restart row, shape {want}, "
                f"got {np.shape(final_states)}"
            )
        ended = states
        if final_states is not None:
            ended = np.array(states)
            ended[restart] = final_states
        rewards, terminated = self._transition(ended, task_rewards, terminated)
        if final_states is None:
            rewards = np.where(restart, 0.0, rewards)
        ended = self.index
        self.reset(states, restart)
        self.ended_index = ended
        return rewards, terminated

    def _check(self, states: Any, **signals: Any) -> None:
        """Raise unless ``states`` is one state (one episode) or one per episode, and each
        per-episode signal is a scalar or one value per episode."""
        n = self.num_envs
        if n is None:
            if getattr(states, "ndim", None) != 1:
                kind = "" if isinstance(states, np.ndarray) else f"a {type(states).__name__} of "
                raise ValueError(
                    f"states must be one state, a numpy array of shape (d,), got {kind}shape "
                    f"{np.shape(states)}"
                )
            if signals.get("restart") is not None or signals.get("mask") is not None:
                raise ValueError("restart and mask are for a tracker of num_envs episodes")
            return
        if np.ndim(states) != 2 or len(states) != n:
            raise ValueError(
                f"states must have shape ({n}, state_dim) (num_envs, state_dim), "
                f"got {np.shape(states)}"
            )
        for name, value in signals.items():
            if value is not None and np.shape(value) not in ((), (n,)):
                raise ValueError(f"{name} must have shape ({n},), got {np.shape(value)}")

    def _transition(self, states: np.ndarray, task_rewards: Any, terminated: Any) -> tuple:
        task, config = self.task, self.config
        x = task.featurize(states)
        t = self.t + 1
        before = self.index
        segment_reward, entered = task.evaluate(x, t, before)
        index = before + entered  # the Markov segmentation function
        if self.terminate_on_completion:
            terminated = terminated | (index == task.n_segments)
        if config.potential:
            potential = self._potential(x, index, terminated, segment_reward, entered)
            reward = config.scale * (config.gamma * potential - self.potential)
            self.potential = potential
        else:
            reward = config.scale * segment_reward
        reward = reward + config.region_bonus * entered + config.task_reward_weight * task_rewards
        finite = math.isfinite(reward) if self.num_envs is None else np.isfinite(reward).all()
        if not finite and not self._warned_not_finite:
            self._warned_not_finite = True
            self._warn_not_finite(states, task_rewards, reward)
        self.index = self.ended_index = index
        self.t = t
        return reward, terminated

    def _warn_not_finite(self, states: Any, task_rewards: Any, reward: Any) -> None:
        if self.num_envs is None:
            where, state, task_reward, value = "", states, task_rewards, reward
        else:
            i = int(np.flatnonzero(~np.isfinite(reward))[0])
            where = f" in env {i}"
            state, value = states[i], reward[i]
            task_reward = np.broadcast_to(task_rewards, np.shape(reward))[i]
        warnings.warn(
            f"the proxy reward is {value}{where} (said once): the state "
            f"{np.asarray(state).tolist()} or the env's reward {task_reward} is not a finite "
            "number, or the state is so large that the quadratic reward overflows; the agent "
            "would learn from it (SB3's VecCheckNan wrapper, raise_exception=True, stops at "
            "the step that gives one)",
            stacklevel=5,
        )

    def _potential(
        self, x: np.ndarray, index: Any, terminated: Any, reward: Any = None, moved: Any = True
    ) -> Any:
        """``Phi(s, index)``, 0 where the episode terminated (and when not in potential mode).

        ``reward`` is ``R`` of ``s`` at the index before the step: the same number as at
        ``index`` for one episode whose index did not move (``moved`` False), so it is reused.
        """
        if not self.config.potential:
            return 0.0 if self.num_envs is None else np.zeros(self.num_envs)
        if self.num_envs is not None or moved:
            reward = self.task.evaluate(x, None, index)[0]
        phi = progress_potential(index, reward)
        if self.num_envs is None:
            return 0.0 if terminated else phi
        return np.where(terminated, 0.0, phi)
