"""SB3 callbacks that report progress on the *true* task of a SWIRL-wrapped env.

Both work with any SB3 algorithm. They read the step ``infos``: ``"segment"`` (the index after the
step, from the SWIRL wrapper), ``"task_reward"`` (the env's own reward) and ``"is_success"``. On an
env without the SWIRL wrapper the step reward *is* the task reward and is used instead, so a
baseline trained on the raw env is scored the same way.
"""

from __future__ import annotations

import os
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecEnv, sync_envs_normalization

from sb3_swirl.dqn import find_task


class _EpisodeTracker:
    """Per-env running sums of the true reward; a summary of each episode when it ends."""

    def __init__(self, n_envs: int) -> None:
        self.returns = np.zeros(n_envs)

    def step(self, i: int, reward: float, done: bool, info: dict[str, Any]) -> dict | None:
        self.returns[i] += float(info.get("task_reward", reward))
        if not done:
            return None
        summary = {
            "task_return": self.returns[i],
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
    * ``swirl/success_rate``: mean of ``info["is_success"]`` at the episode end;
    * ``swirl/task_return_mean``: mean undiscounted true return.

    Values are recorded when episodes end and written with SB3's normal log dumps.

    Parameters
    ----------
    window_size : int
        Number of recent episodes averaged over.
    n_segments : int, optional
        Number of segments ``k``; read from the training env's task when omitted.
    verbose : int

    Examples
    --------
    >>> model.learn(10_000, callback=SegmentProgressCallback())  # doctest: +SKIP
    """

    def __init__(self, window_size: int = 100, n_segments: int | None = None, verbose: int = 0):
        super().__init__(verbose=verbose)
        if window_size < 1:
            raise ValueError(f"window_size must be >= 1, got {window_size}")
        self.window_size = window_size
        self.n_segments = n_segments
        self.n_episodes = 0
        self._episodes: deque[dict] = deque(maxlen=window_size)

    def _init_callback(self) -> None:
        if self.n_segments is None:
            try:
                self.n_segments = find_task(self.training_env).n_segments
            except ValueError:
                self.n_segments = 0  # not a SWIRL env: success and return only
        self._tracker = _EpisodeTracker(self.training_env.num_envs)

    def _on_step(self) -> bool:
        ended = False
        rewards = self.locals.get("rewards", np.zeros(len(self.locals["dones"])))
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
        successes = [e["is_success"] for e in self._episodes if e["is_success"] is not None]
        if successes:
            self.logger.record("swirl/success_rate", float(np.mean(successes)))
        self.logger.record(
            "swirl/task_return_mean", float(np.mean([e["task_return"] for e in self._episodes]))
        )


class TaskEvalCallback(EvalCallback):
    """``EvalCallback`` scored on the true task: success rate first, then true return.

    Every ``eval_freq`` calls it runs ``n_eval_episodes`` episodes on ``eval_env`` and logs
    ``eval/success_rate``, ``eval/task_return`` (mean undiscounted ``info["task_reward"]``),
    ``eval/final_segment_mean`` (SWIRL envs) besides SB3's ``eval/mean_reward`` (the proxy
    return) and ``eval/mean_ep_length``. The best model (highest success rate, ties broken by
    true return) goes to ``best_model_save_path/best_model.zip``.

    History, one entry per evaluation: ``evaluations_timesteps``, ``evaluations_episodes``
    (training episodes finished so far: the paper's "rollouts"), ``success_rates``,
    ``task_returns``, ``evaluations_results`` / ``evaluations_length`` (proxy returns and
    lengths per episode) and ``evaluations_task_returns`` / ``evaluations_successes`` per
    episode. With ``log_path`` it is saved to ``log_path/evaluations.npz`` after every
    evaluation.

    Parameters
    ----------
    eval_env : gymnasium.Env or VecEnv
        Wrapped like the training env.
    n_eval_episodes, eval_freq, log_path, best_model_save_path, deterministic, render, verbose,
    callback_on_new_best, callback_after_eval :
        As in :class:`stable_baselines3.common.callbacks.EvalCallback`.
    warn : bool
        Warn when ``eval_env`` has no ``Monitor``; off by default because the scores here come
        from ``info``, not from a monitor.

    Examples
    --------
    >>> cb = TaskEvalCallback(eval_env, n_eval_episodes=20, eval_freq=1000)  # doctest: +SKIP
    >>> model.learn(30_000, callback=cb)  # doctest: +SKIP
    >>> cb.evaluations_episodes, cb.success_rates  # doctest: +SKIP
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
    ) -> None:
        super().__init__(
            eval_env,
            callback_on_new_best=callback_on_new_best,
            callback_after_eval=callback_after_eval,
            n_eval_episodes=n_eval_episodes,
            eval_freq=eval_freq,
            log_path=log_path,
            best_model_save_path=best_model_save_path,
            deterministic=deterministic,
            render=render,
            verbose=verbose,
            warn=warn,
        )
        self.best_score: tuple[float, float] = (-np.inf, -np.inf)
        self.n_training_episodes = 0
        self.evaluations_episodes: list[int] = []
        self.success_rates: list[float] = []
        self.task_returns: list[float] = []
        self.evaluations_task_returns: list[list[float]] = []
        self.evaluations_final_segments: list[list[int]] = []

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        summary = self._eval_tracker.step(
            locals_["i"], locals_["reward"], bool(locals_["done"]), locals_["info"]
        )
        if summary is not None:
            if summary["is_success"] is not None:
                self._is_success_buffer.append(bool(summary["is_success"]))
            self._task_returns.append(float(summary["task_return"]))
            if summary["segment"] is not None:
                self._final_segments.append(int(summary["segment"]))

    def _on_step(self) -> bool:
        self.n_training_episodes += int(np.sum(self.locals["dones"]))
        if not (self.eval_freq > 0 and self.n_calls % self.eval_freq == 0):
            return True
        if self.model.get_vec_normalize_env() is not None:
            sync_envs_normalization(self.training_env, self.eval_env)

        self._is_success_buffer, self._task_returns, self._final_segments = [], [], []
        self._eval_tracker = _EpisodeTracker(self.eval_env.num_envs)
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
        # NaN, not 0, when the env reports no success at all
        success_rate = (
            float(np.mean(self._is_success_buffer)) if self._is_success_buffer else np.nan
        )
        task_return = float(np.mean(self._task_returns))
        self.last_mean_reward = float(np.mean(episode_rewards))

        self.evaluations_timesteps.append(self.num_timesteps)
        self.evaluations_episodes.append(self.n_training_episodes)
        self.evaluations_results.append(list(episode_rewards))  # type: ignore[arg-type]
        self.evaluations_length.append(list(episode_lengths))  # type: ignore[arg-type]
        self.evaluations_successes.append(self._is_success_buffer)
        self.evaluations_task_returns.append(self._task_returns)
        self.evaluations_final_segments.append(self._final_segments)
        self.success_rates.append(success_rate)
        self.task_returns.append(task_return)
        if self.log_path is not None:
            np.savez(
                self.log_path,
                timesteps=self.evaluations_timesteps,
                episodes=self.evaluations_episodes,
                results=self.evaluations_results,
                ep_lengths=self.evaluations_length,
                successes=self.evaluations_successes,
                task_returns=self.evaluations_task_returns,
                success_rate=self.success_rates,
                task_return=self.task_returns,
            )

        if self.verbose >= 1:
            print(
                f"Eval num_timesteps={self.num_timesteps}, episodes={self.n_training_episodes}, "
                f"success_rate={success_rate:.2f}, task_return={task_return:.3f}"
            )
        self.logger.record("eval/mean_reward", self.last_mean_reward)
        self.logger.record("eval/mean_ep_length", float(np.mean(episode_lengths)))
        self.logger.record("eval/success_rate", success_rate)
        self.logger.record("eval/task_return", task_return)
        if self._final_segments:
            self.logger.record("eval/final_segment_mean", float(np.mean(self._final_segments)))
        self.logger.record("eval/training_episodes", self.n_training_episodes)
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(self.num_timesteps)

        continue_training = True
        score = (np.nan_to_num(success_rate, nan=-np.inf), task_return)
        if score > self.best_score:
            if self.verbose >= 1:
                print("New best success rate!")
            if self.best_model_save_path is not None:
                self.model.save(os.path.join(self.best_model_save_path, "best_model"))
            self.best_score = score
            self.best_mean_reward = self.last_mean_reward
            if self.callback_on_new_best is not None:
                continue_training = self.callback_on_new_best.on_step()
        if self.callback is not None:
            continue_training = continue_training and self._on_event()
        return continue_training
