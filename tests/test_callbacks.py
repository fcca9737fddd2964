"""SegmentProgressCallback and TaskEvalCallback with SwirlDQN, PPO and plain DQN."""

from __future__ import annotations

import csv
import dataclasses
import warnings

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecNormalize
from test_dqn import PointEnv, point_demos, point_env, point_task

from sb3_swirl.callbacks import SegmentProgressCallback, TaskEvalCallback
from sb3_swirl.dqn import SwirlDQN
from sb3_swirl.vec_env import make_swirl_env, same_task
from swirl_wrappers import QuadraticReward, Region, SwirlWrapper, TaskModel


def logged(path) -> dict[str, list[str]]:
    with open(path / "progress.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {key: [row[key] for row in rows if row[key] != ""] for key in rows[0]}


def test_segment_progress_keys_reach_the_logger(tmp_path):
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=point_demos(3), bc_epochs=100, seed=0,
        exploration_initial_eps=0.05, learning_starts=500,
    )  # fmt: skip
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = SegmentProgressCallback(window_size=10)
    model.learn(400, callback=callback, log_interval=1)
    log = logged(tmp_path)
    for key in (
        "swirl/reach_rate_seg0",
        "swirl/reach_rate_seg1",
        "swirl/final_segment_mean",
        "swirl/success_rate",
        "swirl/task_return_mean",
    ):
        assert log[key], key
    # the cloned policy walks the demos' route: it reaches the first corner and succeeds
    assert float(log["swirl/reach_rate_seg0"][-1]) > 0.5
    assert float(log["swirl/success_rate"][-1]) > 0.5
    assert float(log["swirl/task_return_mean"][-1]) == pytest.approx(
        float(log["swirl/success_rate"][-1])
    )
    assert callback.n_episodes >= 10


def test_task_eval_scores_true_success_and_saves_best(tmp_path):
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=point_demos(3), bc_epochs=100, seed=0,
        exploration_initial_eps=0.05, learning_starts=1000,
    )  # fmt: skip
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = TaskEvalCallback(
        point_env(),
        n_eval_episodes=5,
        eval_freq=100,
        best_model_save_path=str(tmp_path / "best"),
        log_path=str(tmp_path / "eval"),
        verbose=0,
    )
    model.learn(300, callback=callback)
    assert callback.evaluations_timesteps == [100, 200, 300]
    assert len(callback.evaluations_episodes) == 3
    assert callback.evaluations_episodes == sorted(callback.evaluations_episodes)
    assert callback.evaluations_episodes[-1] > 0
    # BC start, no learning yet: the greedy policy succeeds; the proxy return is not the score
    assert callback.success_rates[0] == 1.0
    assert callback.task_returns[0] == 1.0
    assert all(r < 0 for r in callback.evaluations_results[0])
    assert sorted(p.name for p in (tmp_path / "best").iterdir()) == [
        "best_model.zip"
    ]  # task inside
    saved = np.load(tmp_path / "eval" / "evaluations.npz")
    np.testing.assert_array_equal(saved["episodes"], callback.evaluations_episodes)
    np.testing.assert_array_equal(saved["success_rate"], callback.success_rates)
    np.testing.assert_array_equal(saved["final_segments"], callback.evaluations_final_segments)
    assert saved["final_segments"].shape == (3, 5)
    log = logged(tmp_path)
    assert log["eval/success_rate"] and log["eval/task_return"]


def test_eval_at_start_scores_the_bc_start_before_any_env_step():
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=point_demos(3), bc_epochs=100, seed=0,
        exploration_initial_eps=0.05, learning_starts=1000,
    )  # fmt: skip
    callback = TaskEvalCallback(
        point_env(), n_eval_episodes=3, eval_freq=100, eval_at_start=True, verbose=0
    )
    model.learn(200, callback=callback)
    assert callback.evaluations_timesteps == [0, 100, 200]
    assert callback.evaluations_episodes[0] == 0
    assert callback.success_rates[0] == 1.0  # the clone alone walks the demos' route
    untrained = DQN("MlpPolicy", point_env(), learning_starts=1000, seed=0)
    callback = TaskEvalCallback(
        point_env(), n_eval_episodes=3, eval_freq=100, eval_at_start=True, verbose=0
    )
    untrained.learn(100, callback=callback)
    assert callback.evaluations_timesteps == [0, 100]
    assert callback.success_rates[0] == 0.0


def test_callbacks_work_with_ppo_on_a_swirl_env(tmp_path):
    shaped = {"mode": "potential", "gamma": 0.99}
    model = PPO("MlpPolicy", point_env(reward_config=shaped), n_steps=64, batch_size=32, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    evaluation = TaskEvalCallback(
        point_env(), n_eval_episodes=2, eval_freq=64, best_model_save_path=str(tmp_path), verbose=0
    )
    model.learn(128, callback=[SegmentProgressCallback(), evaluation])
    assert len(evaluation.success_rates) == 2
    assert (tmp_path / "best_model.zip").is_file()
    # PPO's zip holds no task: it is saved beside, with the reward settings trained on
    saved = TaskModel.from_json(tmp_path / "task.json")
    assert same_task(saved, point_task()) and saved.reward_config.mode == "potential"
    loaded = PPO.load(tmp_path / "best_model.zip", env=point_env(reward_config=saved.reward_config))
    assert loaded.get_env().get_attr("reward_config")[0] == saved.reward_config
    log = logged(tmp_path)
    assert log["eval/success_rate"] and log["swirl/final_segment_mean"]
    # a gamma other than the shaping's is warned once a learn call, not once a callback
    other = PPO("MlpPolicy", point_env(reward_config=shaped), n_steps=64, batch_size=32, gamma=0.9)
    for _ in range(2):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            other.learn(64, callback=[SegmentProgressCallback(), TaskEvalCallback(point_env())])
        assert sum("discounts with gamma" in str(w.message) for w in caught) == 1


def test_plain_env_is_scored_on_its_own_reward(tmp_path):
    """A baseline on the raw env is evaluated the same way (no segment keys)."""
    env = gym.wrappers.TimeLimit(PointEnv(), 30)
    model = DQN("MlpPolicy", env, learning_starts=1000, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    evaluation = TaskEvalCallback(
        gym.wrappers.TimeLimit(PointEnv(), 30), n_eval_episodes=3, eval_freq=100, verbose=0
    )
    progress = SegmentProgressCallback()
    model.learn(200, callback=[progress, evaluation], log_interval=1)
    assert evaluation.success_rates == [0.0, 0.0]
    assert evaluation.task_returns == [0.0, 0.0]
    assert progress.n_segments == 0
    log = logged(tmp_path)
    assert "swirl/final_segment_mean" not in log
    assert log["swirl/success_rate"]


def scripted(model: DQN) -> DQN:
    """Evaluate ``model`` with the demos' route on PointEnv: right until x ~ 1, then up."""
    model.predict = lambda obs, state=None, episode_start=None, deterministic=False: (
        np.where(obs[:, 0] < 0.95, 0, 2),
        None,
    )
    return model


def test_segment_progress_logs_the_true_return_under_vec_normalize(tmp_path):
    """On a plain env the step reward is the task reward, but VecNormalize scales it."""
    env = VecNormalize(make_vec_env("CartPole-v1", n_envs=2, seed=0))
    model = DQN("MlpPolicy", env, learning_starts=1000, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = SegmentProgressCallback()
    model.learn(300, callback=callback, log_interval=1)
    monitor = [episode["r"] for episode in model.ep_info_buffer]
    assert callback.n_episodes == len(monitor) > 5
    assert float(logged(tmp_path)["swirl/task_return_mean"][-1]) == pytest.approx(np.mean(monitor))


def test_segment_progress_keeps_episodes_that_go_on_across_learn_calls(tmp_path):
    model = DQN("MlpPolicy", make_vec_env("CartPole-v1", n_envs=1, seed=0), seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = SegmentProgressCallback(window_size=1)  # logs each episode's own return
    model.learn(10, callback=callback, log_interval=1)
    assert callback.n_episodes == 0  # stopped mid-episode
    model.learn(150, callback=callback, log_interval=1, reset_num_timesteps=False)
    went_on = [episode["r"] for episode in model.ep_info_buffer]
    model.learn(150, callback=callback, log_interval=1)  # resets the env: a fresh start
    restarted = [episode["r"] for episode in model.ep_info_buffer]
    returns = [float(r) for r in logged(tmp_path)["swirl/task_return_mean"]]
    assert returns == went_on + restarted


def test_a_new_segment_progress_callback_skips_the_episode_already_running(tmp_path):
    model = DQN("MlpPolicy", make_vec_env("CartPole-v1", n_envs=1, seed=0), seed=0)
    model.learn(10)  # stopped mid-episode
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = SegmentProgressCallback(window_size=1)  # joins the run: it saw no episode start
    model.learn(150, callback=callback, log_interval=1, reset_num_timesteps=False)
    whole = [episode["r"] for episode in model.ep_info_buffer]
    assert callback.n_episodes == len(whole) - 1 > 0
    returns = [float(r) for r in logged(tmp_path)["swirl/task_return_mean"]]
    assert returns == whole[1:]  # not the first episode's last steps alone


class NoTermPoint(PointEnv):
    """Never terminates: completion or the time limit ends the episode; 300 steps at most."""

    steps = 0

    def step(self, action):
        self.steps += 1
        if self.steps > 300:
            raise RuntimeError("the evaluation does not stop")
        obs, reward, _, truncated, info = super().step(action)
        return obs, reward, False, truncated, info


def test_task_eval_counts_episodes_ended_by_completion():
    """Monitor outside the SWIRL wrapper (make_swirl_env) sees the episodes that end on
    completion; an inner Monitor (make_vec_env(..., wrapper_class=SwirlWrapper)) never would,
    and evaluate_policy would run on: the wrapper refuses it, saying where Monitor belongs."""

    def base():
        return gym.wrappers.TimeLimit(NoTermPoint(), 60)

    wrapper_kwargs = dict(terminate_on_completion=True)
    env = make_swirl_env(base, point_task(), seed=0, wrapper_kwargs=wrapper_kwargs)
    eval_env = make_swirl_env(base, point_task(), seed=1, wrapper_kwargs=wrapper_kwargs)
    model = scripted(DQN("MlpPolicy", env, learning_starts=1000, seed=0))
    callback = TaskEvalCallback(eval_env, n_eval_episodes=5, eval_freq=10, verbose=0)
    model.learn(10, callback=callback)
    assert callback.success_rates == [1.0]
    assert len(callback.evaluations_results[0]) == 5
    assert all(length < 60 for length in callback.evaluations_length[0])  # ended on completion

    with pytest.raises(ValueError, match=r"must sit below SB3's Monitor.*make_swirl_env"):
        make_vec_env(
            base,
            seed=0,
            wrapper_class=SwirlWrapper,
            wrapper_kwargs=dict(task=point_task(), **wrapper_kwargs),
        )

    class MyMonitor(Monitor):
        pass

    with pytest.raises(ValueError, match=r"must sit below SB3's Monitor"):
        SwirlWrapper(MyMonitor(base()), point_task(), **wrapper_kwargs)
    inner = make_vec_env(base, wrapper_class=SwirlWrapper, wrapper_kwargs=dict(task=point_task()))
    assert inner.num_envs == 1  # without terminate_on_completion the inner Monitor is fine


class SuccessOnlyAtGoal(PointEnv):
    """Reports ``is_success`` only when it succeeds; every other episode starts too far away."""

    episodes = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = np.zeros(2) if self.episodes % 2 == 0 else np.full(2, -0.5)
        self.episodes += 1
        return self.pos.astype(np.float32), {}

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        if not terminated:
            del info["is_success"]
        return obs, reward, terminated, truncated, info


def test_task_eval_counts_a_missing_is_success_as_a_failure(tmp_path):
    model = scripted(DQN("MlpPolicy", gym.wrappers.TimeLimit(PointEnv(), 21), seed=0))
    callback = TaskEvalCallback(
        gym.wrappers.TimeLimit(SuccessOnlyAtGoal(), 21),
        n_eval_episodes=4,
        eval_freq=10,
        log_path=str(tmp_path),
        verbose=0,
    )
    model.learn(20, callback=callback)
    # the near starts reach the goal in 19 steps, the far ones would need 30
    assert callback.success_rates == [0.5, 0.5]
    assert callback.task_returns == [0.5, 0.5]
    saved = np.load(tmp_path / "evaluations.npz")
    for key in ("results", "ep_lengths", "successes", "task_returns"):
        assert saved[key].shape == (2, 4), key


def test_task_eval_without_is_success_ranks_by_the_true_return(capsys, tmp_path):
    model = DQN("MlpPolicy", "CartPole-v1", learning_starts=1000, seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    callback = TaskEvalCallback(gym.make("CartPole-v1"), n_eval_episodes=2, eval_freq=50)
    model.learn(100, callback=callback)
    assert np.isnan(callback.success_rates).all() and len(callback.task_returns) == 2
    out = capsys.readouterr().out
    assert "New best true return!" in out and "New best success rate" not in out
    log = logged(tmp_path)
    assert len(log["eval/task_return"]) == 2 and "eval/success_rate" not in log  # not NaN


def test_sb3_stop_on_threshold_reads_the_true_return_of_the_best_model():
    """The proxy return of the BC start is negative; its true return is 1 (it parks)."""
    from stable_baselines3.common.callbacks import StopTrainingOnRewardThreshold

    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=point_demos(3), bc_epochs=100, seed=0,
        exploration_initial_eps=0.05, learning_starts=1000,
    )  # fmt: skip
    callback = TaskEvalCallback(
        point_env(),
        n_eval_episodes=3,
        eval_freq=100,
        verbose=0,
        callback_on_new_best=StopTrainingOnRewardThreshold(reward_threshold=0.5),
    )
    model.learn(300, callback=callback)
    assert callback.evaluations_timesteps == [100]  # stopped at once
    assert callback.best_mean_reward == callback.task_returns[0] == 1.0
    assert callback.last_mean_reward < 0  # the proxy return, which it does not compare


def test_task_eval_refuses_an_eval_env_with_another_task():
    model = PPO("MlpPolicy", point_env(), n_steps=64, batch_size=32, n_epochs=1, seed=0)
    task = point_task()
    moved = Region(mean=[0.5, 0.0], covariance=np.eye(2) * 0.01, threshold=1.0)
    other = dataclasses.replace(task, regions=[moved, *task.regions[1:]])
    for eval_env in (SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), other), PointEnv()):
        with pytest.raises(ValueError, match="eval_env must carry the training env's SWIRL task"):
            model.learn(64, callback=TaskEvalCallback(eval_env, eval_freq=64, verbose=0))
    # the reward settings may differ: only the proxy return evaluated changes
    model.learn(64, callback=TaskEvalCallback(point_env(reward_config={"scale": 2.0})))


def test_task_eval_refuses_a_file_as_its_folders(tmp_path):
    """SB3 failed in os.makedirs with a bare FileExistsError."""
    model = PPO("MlpPolicy", point_env(), n_steps=64, batch_size=32, n_epochs=1, seed=0)
    (tmp_path / "taken").write_text("a user's file")
    for name in ("best_model_save_path", "log_path"):
        callback = TaskEvalCallback(point_env(), eval_freq=64, **{name: str(tmp_path / "taken")})
        with pytest.raises(NotADirectoryError, match=f"TaskEvalCallback {name} .*taken' is a file"):
            model.learn(64, callback=callback)
    assert (tmp_path / "taken").read_text() == "a user's file"


def test_callbacks_warn_when_the_shaping_discounts_otherwise_than_the_agent():
    shaped = {"mode": "potential", "gamma": 0.99}
    model = PPO(
        "MlpPolicy", point_env(reward_config=shaped), gamma=0.9, n_steps=32, batch_size=32, seed=0
    )
    for callback in (SegmentProgressCallback(), TaskEvalCallback(point_env(), eval_freq=10**6)):
        with pytest.warns(UserWarning, match=r"shapes with gamma=0\.99 but PPO discounts with"):
            model.learn(32, callback=callback)
    model = PPO(
        "MlpPolicy", point_env(reward_config=shaped), gamma=0.99, n_steps=32, batch_size=32, seed=0
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.learn(32, callback=SegmentProgressCallback())


@pytest.mark.parametrize("n_segments", ["2", 2.5, 0, -1])
def test_segment_progress_refuses_a_bad_segment_count(n_segments):
    with pytest.raises(ValueError, match="n_segments"):
        SegmentProgressCallback(n_segments=n_segments)


@pytest.mark.parametrize(("kwargs", "match"), [({"n_eval_episodes": 0}, "n_eval_episodes"),
                                               ({"eval_freq": 1.5}, "eval_freq")])  # fmt: skip
def test_task_eval_refuses_no_episodes_and_a_fractional_frequency(kwargs, match):
    with pytest.raises(ValueError, match=f"{match} must be an integer"):
        TaskEvalCallback(point_env(), **kwargs)


def test_a_callback_class_or_a_wrong_segment_count_is_named():
    """learn(callback=SegmentProgressCallback), the class: SB3 called it with its locals, and
    the error spoke of a window_size holding them. n_segments other than the task's logged
    reach rates of segments that do not exist."""
    model = SwirlDQN("MlpPolicy", point_env(), bc_epochs=0, seed=0)
    for cls in (SegmentProgressCallback, TaskEvalCallback):
        with pytest.raises(TypeError, match=rf"callback={cls.__name__}\) passes the class"):
            model.learn(10, callback=cls)
    with pytest.raises(ValueError, match=r"n_segments=7\): the training env's task has 2"):
        model.learn(10, callback=SegmentProgressCallback(n_segments=7))
    model.learn(10, callback=SegmentProgressCallback(n_segments=2))
    # one callback, read afresh for a model whose task has another number of segments
    reused = SegmentProgressCallback()
    model.learn(10, callback=reused)
    one = TaskModel([Region([0.0], [[1.0]], 1.0)], [QuadraticReward([0.0], [[1.0]])], dims=[0])
    other = SwirlDQN("MlpPolicy", SwirlWrapper(PointEnv(), one), bc_epochs=0, seed=0)
    other.learn(10, callback=reused)
    assert reused.n_segments == 1
