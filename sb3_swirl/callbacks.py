"""SB3 callbacks that report progress on the *true* task of a SWIRL-wrapped env.

Both work with any SB3 algorithm. They read the step ``infos``: ``"segment"`` (the index after the
step, from the SWIRL wrapper), ``"task_reward"`` (the env's own reward) and ``"is_success"``. On an
env without the SWIRL wrapper the step reward *is* the task reward and is used instead, so a
baseline trained on the raw env is scored the same way; under ``VecNormalize`` that is the
original, unnormalised reward. An episode end without ``"is_success"`` counts as a failure.
"""

from __future__ import annotations

import os
import warnings
import weakref
from collections import deque
from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import (
    VecEnv,
    VecNormalize,
    sync_envs_normalization,
    unwrap_vec_normalize,
)

from sb3_swirl.vec_env import get_swirl_attr, same_task, swirl_task, trained_task
from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_int


def _original_rewards(env: VecNormalize | None, rewards: np.ndarray) -> np.ndarray:
    """The rewards of the last step before ``env`` normalised them (``rewards`` without it)."""
    return rewards if env is None else env.get_original_reward()


def _success_rate(episodes: Iterable[dict]) -> float:
    """Mean success, a missing ``is_success`` counting as False; NaN if no episode reports it."""
    flags = [e["is_success"] for e in episodes]
    if all(flag is None for flag in flags):
        return np.nan
    return float(np.mean([bool(flag) for flag in flags]))


def _check_discount(model: Any, env: VecEnv) -> None:
    """Warn when a SWIRL env's potential shaping discounts otherwise than ``model`` (SwirlDQN
    checks it itself, when it takes the env)."""
    from sb3_swirl.dqn import SwirlDQN

    gamma = getattr(model, "gamma", None)
    if gamma is None or isinstance(model, SwirlDQN) or swirl_task(env) is None:
        return
    mismatch = get_swirl_attr(env, "reward_config").discount_mismatch(gamma, type(model).__name__)
    # once a learn call (SB3 stamps each with start_time), not once a callback
    started = getattr(model, "start_time", None)
    if mismatch and (started is None or _DISCOUNT_WARNED.get(model) != started):
        _DISCOUNT_WARNED[model] = started
        warnings.warn(mismatch, stacklevel=2)


_DISCOUNT_WARNED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _refuse_sb3_locals(cls: type, first: Any) -> None:
    """``learn(callback=SomeCallback)``, the class not an instance: SB3 calls a callable with
    its ``locals()`` and ``globals()`` at every step, which land in the first parameters."""
    if isinstance(first, dict) and "self" in first and "total_timesteps" in first:
        raise TypeError(
            f"learn(callback={cls.__name__}) passes the class: give an instance, "
            f"callback={cls.__name__}(...)"
        )


class _EpisodeTracker:
    """Per-env running sums of the true reward; a summary of each finished episode."""

    def __init__(self, n_envs: int, running: bool = False) -> None:
        self.returns = np.zeros(n_envs)
        # episodes that began before the tracker: their summaries would be partial
        self.partial = np.full(n_envs, running)

    def step(self, i: int, reward: float, done: bool, info: dict[str, Any]) -> dict | None:
        """Add a step of sub-env ``i``; ``reward`` is the true reward where ``info`` has no
        ``"task_reward"``. Returns the episode's summary when ``done`` ends it (``None`` for an
        episode that began before the tracker)."""
        self.returns[i] += float(info.get("task_reward", reward))
        if not done:
            return None
        if self.partial[i]:
            self.partial[i], self.returns[i] = False, 0.0
            return None
        summary = {
            "task_return": float(self.returns[i]),
            "segment": info.get("segment"),
            "is_success": info.get("is_success"),
        }
        self.returns[i] = 0.0
        return summary


class SegmentProgressCallback(BaseCallback):
    """Log how far training episodes get through the proxy task.

    Over the last ``window_size`` finished training episodes it records

    * ``swirl/reach_rate_seg{i}``: fraction whose final segment index is above ``i``
      (region ``i`` was reached), for every segment ``i``;
    * ``swirl/final_segment_mean``: mean final segment index;
    * ``swirl/success_rate``: mean of ``info["is_success"]`` at the episode end (missing:
      False; not logged when no episode reports it);
    * ``swirl/task_return_mean``: mean undiscounted true return.

    Values are recorded when episodes end and written with SB3's normal log dumps. Episodes
    that run on across ``learn(..., reset_num_timesteps=False)`` calls are summed whole; a new
    callback given to such a call skips the episodes already running, which began before it.

    Parameters
    ----------
    window_size : int
        Number of recent episodes averaged over.
    n_segments : int, optional
        Number of segments ``k``; read from the training env's task when omitted.
    verbose : int

    Examples
    --------
    ::

        model.learn(10_000, callback=SegmentProgressCallback())
    """

    def __init__(self, window_size: int = 100, n_segments: int | None = None, verbose: int = 0):
        _refuse_sb3_locals(type(self), window_size)
        super().__init__(verbose=verbose)
        self.window_size = check_int("window_size", window_size, low=1)
        self.n_segments = None if n_segments is None else check_int("n_segments", n_segments, low=1)
        self._given_segments = self.n_segments  # None: read from each model's env
        self.n_episodes = 0
        self._episodes: deque[dict] = deque(maxlen=window_size)
        self._tracker: _EpisodeTracker | None = None
        self._final_obs: Any = None  # the model's last observation when training last ended

    def _init_callback(self) -> None:
        _check_discount(self.model, self.training_env)
        task = swirl_task(self.training_env)  # none: success and return only
        if self._given_segments is None:
            self.n_segments = 0 if task is None else task.n_segments
        elif task is not None and self._given_segments != task.n_segments:
            k = task.n_segments
            raise ValueError(
                f"SegmentProgressCallback(n_segments={self._given_segments}): the training "
                f"env's task has {k} segment{'s' * (k != 1)} (leave n_segments out to read them)"
            )

    def _on_training_start(self) -> None:
        # learn() resets the env (a new _last_obs) unless it goes on with reset_num_timesteps=False:
        # then the running episodes go on too, and a new tracker skips them (it saw no start);
        # so does one after the steps SwirlDQN takes to label state-only demos, in learn's set-up
        n_envs = self.training_env.num_envs
        going_on = self._final_obs is not None and self.model._last_obs is self._final_obs
        if self._tracker is None or len(self._tracker.returns) != n_envs or not going_on:
            self._tracker = _EpisodeTracker(n_envs, running=self.model.num_timesteps > 0)

    def _on_training_end(self) -> None:
        self._final_obs = self.model._last_obs

    def _on_step(self) -> bool:
        ended = False
        rewards = self.locals.get("rewards", np.zeros(len(self.locals["dones"])))
        rewards = _original_rewards(self.model.get_vec_normalize_env(), rewards)
        for i, (done, info) in enumerate(
            zip(self.locals["dones"], self.locals["infos"], strict=True)
        ):
            summary = self._tracker.step(i, rewards[i], bool(done), info)
            if summary is not None:
                self._episodes.append(summary)
                self.n_episodes += 1
                ended = True
        if ended:
            self._record()
        return True

    def _record(self) -> None:
        segments = [e["segment"] for e in self._episodes if e["segment"] is not None]
        if segments and self.n_segments:
            final = np.asarray(segments)
            for i in range(self.n_segments):
                self.logger.record(f"swirl/reach_rate_seg{i}", float(np.mean(final > i)))
            self.logger.record("swirl/final_segment_mean", float(final.mean()))
        success_rate = _success_rate(self._episodes)
        if not np.isnan(success_rate):
            self.logger.record("swirl/success_rate", success_rate)
        self.logger.record(
            "swirl/task_return_mean", float(np.mean([e["task_return"] for e in self._episodes]))
        )


class TaskEvalCallback(EvalCallback):
    """SB3's ``EvalCallback`` scored on the true task: success rate first, then true return.

    Every ``eval_freq`` calls it runs :func:`~stable_baselines3.common.evaluation.evaluate_policy`
    for ``n_eval_episodes`` episodes on ``eval_env`` and logs ``eval/success_rate``,
    ``eval/task_return`` (mean undiscounted ``info["task_reward"]``, the env's own reward) and
    ``eval/final_segment_mean`` (SWIRL envs) besides SB3's ``eval/mean_reward`` and
    ``eval/mean_ep_length``. ``eval/mean_reward`` is the return ``evaluate_policy`` reads: the
    proxy return with ``Monitor`` outside the SWIRL wrapper (``make_swirl_env``), the env's
    own with a ``Monitor`` inside it (the zoo). The best model (highest success rate, ties broken by
    true return) goes to ``best_model_save_path/best_model.zip``, with the task (and the reward
    settings it paid by) as ``task.json`` beside it for an algorithm whose model file does not hold
    it (any but ``SwirlDQN``), and ``best_mean_reward`` is its
    true return: SB3's ``StopTrainingOnRewardThreshold`` compares the threshold with it, and
    ``StopTrainingOnNoModelImprovement`` counts an evaluation as an improvement when it rises
    (not when only the success rate does). Episodes are counted as ``evaluate_policy`` counts
    them (by ``Monitor`` when the env has one).

    History, one entry per evaluation: ``evaluations_timesteps``, ``evaluations_episodes``
    (training episodes finished so far: the paper's "rollouts"), ``success_rates``,
    ``task_returns``, ``evaluations_results`` / ``evaluations_length`` (those returns and
    lengths per episode), ``evaluations_successes`` / ``evaluations_task_returns`` /
    ``evaluations_final_segments`` per episode (an episode end without ``info["is_success"]``
    is a failure; the success rate is NaN, and not logged, when no episode reports it). With
    ``log_path`` they are saved to ``log_path/evaluations.npz`` after every evaluation, the
    per-episode ones as ``results``, ``ep_lengths``, ``successes``, ``task_returns`` and
    ``final_segments``.

    Parameters
    ----------
    eval_env : gymnasium.Env or VecEnv
        Wrapped like the training env, with the same SWIRL task (checked when training starts).
    n_eval_episodes, eval_freq, log_path, best_model_save_path, deterministic, render, verbose,
    warn, callback_on_new_best, callback_after_eval :
        As in :class:`stable_baselines3.common.callbacks.EvalCallback`.
    eval_at_start : bool, default False
        Also evaluate when training starts, before the first env step: after SwirlDQN's
        behavioural cloning, so the history starts at what the demos alone give (entry 0, at 0
        timesteps and 0 episodes).

    Examples
    --------
    ::

        cb = TaskEvalCallback(eval_env, n_eval_episodes=20, eval_freq=1000)
        model.learn(30_000, callback=cb)
        cb.evaluations_episodes, cb.success_rates  # rollouts run, and the success at each
    """

    def __init__(
        self,
        eval_env: gym.Env | VecEnv,
        n_eval_episodes: int = 20,
        eval_freq: int = 10000,
        best_model_save_path: str | None = None,
        log_path: str | None = None,
        deterministic: bool = True,
        render: bool = False,
        verbose: int = 1,
        warn: bool = False,
        callback_on_new_best: BaseCallback | None = None,
        callback_after_eval: BaseCallback | None = None,
        eval_at_start: bool = False,
    ) -> None:
        _refuse_sb3_locals(type(self), eval_env)
        super().__init__(
            eval_env,  # eval_freq <= 0 never evaluates, as SB3's EvalCallback
            callback_on_new_best=callback_on_new_best,
            callback_after_eval=callback_after_eval,
            n_eval_episodes=check_int("n_eval_episodes", n_eval_episodes, low=1),
            eval_freq=check_int("eval_freq", eval_freq),
            log_path=log_path,
            best_model_save_path=best_model_save_path,
            deterministic=deterministic,
            render=render,
            verbose=verbose,
            warn=warn,
        )
        self.best_score: tuple[float, float] = (-np.inf, -np.inf)
        self.eval_at_start = eval_at_start
        self.n_training_episodes = 0
        self.evaluations_episodes: list[int] = []
        self.success_rates: list[float] = []
        self.task_returns: list[float] = []
        self.evaluations_task_returns: list[list[float]] = []
        self.evaluations_final_segments: list[list[int]] = []
        self._episodes: list[dict] = []
        self._sums = _EpisodeTracker(self.eval_env.num_envs)

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        """Called by ``evaluate_policy`` for every sub-env after every step: sums the true
        reward and records each episode that ``evaluate_policy`` counts."""
        i, info, done = locals_["i"], locals_["info"], bool(locals_["done"])
        # Read where info has no "task_reward" (not a SWIRL env): the step reward is the task's.
        rewards = _original_rewards(unwrap_vec_normalize(self.eval_env), locals_["rewards"])
        counted = done and (not locals_["is_monitor_wrapped"] or "episode" in info)
        summary = self._sums.step(i, float(rewards[i]), counted, info)
        if summary is not None:
            self._episodes.append(summary)

    def _init_callback(self) -> None:
        _check_discount(self.model, self.training_env)
        trained, evaluated = swirl_task(self.training_env), swirl_task(self.eval_env)
        if (trained is None) != (evaluated is None) or (
            trained is not None and not same_task(trained, evaluated)
        ):
            raise ValueError(
                "TaskEvalCallback's eval_env must carry the training env's SWIRL task (the "
                "policy reads the segment index of its regions): wrap it as the training env, "
                "with the same task"
            )
        folders = {
            "best_model_save_path": self.best_model_save_path,
            "log_path": None if self.log_path is None else os.path.dirname(self.log_path),
        }
        for name, folder in folders.items():
            if folder and os.path.exists(folder) and not os.path.isdir(folder):
                raise NotADirectoryError(
                    f"TaskEvalCallback {name} {folder!r} is a file, not a folder: give the "
                    "folder to write into"
                )
        super()._init_callback()  # after the checks: it makes the log folders

    def _on_training_start(self) -> None:
        model = self.model
        if model.num_timesteps and getattr(model, "_labelled_at", None) == model.num_timesteps:
            # SwirlDQN labelled state-only demos in this learn's set-up, before any step a
            # callback sees: those random-action episodes are rollouts too
            self.n_training_episodes += model.inverse_dynamics_episodes_
        if self.eval_at_start and not self.evaluations_timesteps:
            self.evaluate()

    def _on_step(self) -> bool:
        self.n_training_episodes += int(np.sum(self.locals["dones"]))
        if not (self.eval_freq > 0 and self.n_calls % self.eval_freq == 0):
            return True
        return self.evaluate()

    def evaluate(self) -> bool:
        """Evaluate the model now and record it, as every ``eval_freq`` calls.

        Call it after ``learn`` to score the final policy when the budget is not a multiple of
        ``eval_freq``. Returns whether training should go on (``callback_on_new_best``).
        """
        if self.model.get_vec_normalize_env() is not None:
            sync_envs_normalization(self.training_env, self.eval_env)
        self._episodes = []
        self._sums = _EpisodeTracker(self.eval_env.num_envs)
        episode_rewards, episode_lengths = evaluate_policy(
            self.model,
            self.eval_env,
            n_eval_episodes=self.n_eval_episodes,
            render=self.render,
            deterministic=self.deterministic,
            return_episode_rewards=True,
            warn=self.warn,
            callback=self._log_success_callback,
        )
        episodes = self._episodes
        successes = [bool(e["is_success"]) for e in episodes]
        task_returns = [e["task_return"] for e in episodes]
        final_segments = [int(e["segment"]) for e in episodes if e["segment"] is not None]
        success_rate = _success_rate(episodes)
        task_return = float(np.mean(task_returns))
        self.last_mean_reward = float(np.mean(episode_rewards))

        self.evaluations_timesteps.append(self.num_timesteps)
        self.evaluations_episodes.append(self.n_training_episodes)
        self.evaluations_results.append([float(r) for r in episode_rewards])
        self.evaluations_length.append([int(n) for n in episode_lengths])
        self.evaluations_successes.append(successes)
        self.evaluations_task_returns.append(task_returns)
        self.evaluations_final_segments.append(final_segments)
        self.success_rates.append(success_rate)
        self.task_returns.append(task_return)
        if self.log_path is not None:
            with atomic_write(self.log_path + ".npz", "wb") as fh:
                np.savez(
                    fh,
                    timesteps=self.evaluations_timesteps,
                    episodes=self.evaluations_episodes,
                    results=self.evaluations_results,
                    ep_lengths=self.evaluations_length,
                    successes=self.evaluations_successes,
                    task_returns=self.evaluations_task_returns,
                    final_segments=self.evaluations_final_segments,
                    success_rate=self.success_rates,
                    task_return=self.task_returns,
                )

        if self.verbose >= 1:
            print(
                f"Eval num_timesteps={self.num_timesteps}, "
                f"training_episodes={self.n_training_episodes}, success_rate={success_rate:.2f} "
                f"over {len(episode_lengths)} episodes, task_return={task_return:.3f}"
            )
        self.logger.record("eval/mean_reward", self.last_mean_reward)
        self.logger.record("eval/mean_ep_length", float(np.mean(episode_lengths)))
        if np.isfinite(success_rate):  # as SB3's EvalCallback: only where the env reports it
            self.logger.record("eval/success_rate", success_rate)
        self.logger.record("eval/task_return", task_return)
        if final_segments:
            self.logger.record("eval/final_segment_mean", float(np.mean(final_segments)))
        self.logger.record("eval/training_episodes", self.n_training_episodes)
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(self.num_timesteps)

        continue_training = True
        score = (np.nan_to_num(success_rate, nan=-np.inf), task_return)
        if score > self.best_score:
            if self.verbose >= 1:
                print(
                    "New best success rate!"
                    if np.isfinite(success_rate)
                    else "New best true return! (the env reports no is_success)"
                )
            if self.best_model_save_path is not None:
                self.model.save(os.path.join(self.best_model_save_path, "best_model"))
                if getattr(self.model, "task_json", None) is None:  # PPO, SAC...: not inside
                    trained_task(self.training_env).to_json(
                        os.path.join(self.best_model_save_path, "task.json")
                    )
            self.best_score = score
            self.best_mean_reward = task_return
            if self.callback_on_new_best is not None:
                continue_training = self.callback_on_new_best.on_step()
        if self.callback is not None:
            continue_training = continue_training and self._on_event()
        return continue_training
