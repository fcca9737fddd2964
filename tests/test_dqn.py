"""SwirlDQN: BC start, inverse dynamics, replay prefill, save/load, RBF features, learning."""

from __future__ import annotations

import dataclasses
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize

import sb3_swirl.envs  # noqa: F401  (registers the envs)
from sb3_swirl.demos import Demonstration, DemoWarning, save_demos
from sb3_swirl.dqn import SwirlDQN
from sb3_swirl.experiments import PRESETS
from sb3_swirl.features import RBFFeaturesExtractor
from sb3_swirl.vec_env import get_swirl_attr, make_swirl_env
from swirl_wrappers import QuadraticReward, Region, RewardConfig, SwirlWrapper, TaskModel

PARKING = "sb3_swirl/ParallelParking-v0"
# tiny networks: extra threads only contend for the CPU cores


class PointEnv(gym.Env):
    """A point on a plane moved by +-0.1 in x or y; reach (1, 1). Actions are identifiable."""

    def __init__(self) -> None:
        self.observation_space = spaces.Box(-0.5, 1.5, shape=(2,), dtype=np.float32)
        self.action_space = spaces.Discrete(4)
        self._moves = np.array([[0.1, 0.0], [-0.1, 0.0], [0.0, 0.1], [0.0, -0.1]])

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = self.np_random.uniform(-0.05, 0.05, size=2)
        return self.pos.astype(np.float32), {"is_success": False}

    def step(self, action):
        self.pos = np.clip(self.pos + self._moves[int(action)], -0.5, 1.5)
        success = bool(np.linalg.norm(self.pos - 1.0) < 0.15)
        return self.pos.astype(np.float32), float(success), success, False, {"is_success": success}


def point_task() -> TaskModel:
    corners = ([1.0, 0.0], [1.0, 1.0])
    return TaskModel(
        regions=[Region(mean=c, covariance=np.eye(2) * 0.01, threshold=1.0) for c in corners],
        rewards=[QuadraticReward(target=c, weight=np.eye(2)) for c in corners],
    )


def point_env(**wrapper_kwargs) -> gym.Env:
    return SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), point_task(), **wrapper_kwargs)


def point_demos(n: int, seed: int = 0) -> list[Demonstration]:
    """A scripted supervisor: right until x ~ 1, then up."""
    env = gym.wrappers.TimeLimit(PointEnv(), 60)
    demos = []
    for k in range(n):
        obs, _ = env.reset(seed=seed + k)
        states, actions, done = [obs], [], False
        while not done:
            action = 0 if obs[0] < 0.95 else 2
            obs, _, terminated, truncated, _ = env.step(action)
            states.append(obs)
            actions.append(action)
            done = terminated or truncated
        demos.append(Demonstration(np.array(states), np.array(actions)))
    return demos


@pytest.fixture(scope="module")
def parking():
    from sb3_swirl.fitting import fit_task
    from sb3_swirl.supervisors import collect_demos

    demos = collect_demos(PARKING, 5, seed=0)
    return demos, fit_task(demos, random_state=0, **PRESETS["parking"].fit_kwargs)


def q_values(model, obs: np.ndarray) -> np.ndarray:
    with th.no_grad():
        return model.q_net(th.as_tensor(obs, device=model.device)).cpu().numpy()


def success_count(model, env: gym.Env, n_episodes: int, seed: int) -> int:
    successes = 0
    for k in range(n_episodes):
        obs, _ = env.reset(seed=seed + k)
        done, info = False, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(int(action))
            done = terminated or truncated
        successes += bool(info["is_success"])
    return successes


def test_continuous_actions_are_refused_with_what_to_train_instead():
    task = TaskModel(
        [Region([0.0], [[0.01]], 1.0)], [QuadraticReward([0.0], [[1.0]])], dims=(2,)
    )  # Pendulum's angular velocity
    env = SwirlWrapper(gym.make("Pendulum-v1"), task)
    with pytest.raises(ValueError, match=r"needs discrete actions.*Box.*SAC, TD3, PPO"):
        SwirlDQN("MlpPolicy", env)  # was SB3's AssertionError


def test_discrete_actions_from_another_start_are_refused_with_how_to_shift_them():
    env = SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), point_task())
    env.action_space = gym.spaces.Discrete(4, start=1)  # DQN would pick 0 .. 3
    with pytest.raises(ValueError, match=r"actions 0 \.\. n-1 .*start=1.*a \+ 1"):
        SwirlDQN("MlpPolicy", env)


def test_double_q_scores_the_online_nets_action_with_the_target_net():
    model = SwirlDQN("MlpPolicy", point_env(), demonstrations=point_demos(2), seed=0)
    obs = th.as_tensor(np.stack([model.observation_space.sample() for _ in range(16)]))
    with th.no_grad():
        for p in model.q_net_target.parameters():  # a target net that disagrees
            p.add_(th.randn_like(p))
        online, target = model.q_net(obs), model.q_net_target(obs)
    np.testing.assert_allclose(model._td_target(obs), target.max(dim=1).values)
    model.double_q = True
    pick = online.argmax(dim=1)
    np.testing.assert_allclose(model._td_target(obs), target[th.arange(16), pick])
    assert (model._td_target(obs) <= target.max(dim=1).values + 1e-6).all()


def test_plain_env_is_rejected_with_a_hint():
    with pytest.raises(ValueError, match=r"SwirlWrapper\(.*make_swirl_env"):
        SwirlDQN("MlpPolicy", gym.make(PARKING))


def test_task_is_found_in_sub_envs_and_must_match():
    venv = make_swirl_env(lambda: gym.wrappers.TimeLimit(PointEnv(), 60), point_task(), n_envs=2)
    for n_envs in (0, "2", 1.0):
        with pytest.raises(ValueError, match=f"n_envs must be an integer >= 1, got {n_envs!r}"):
            make_swirl_env(lambda: PointEnv(), point_task(), n_envs=n_envs)
    assert get_swirl_attr(venv, "task").to_json() == point_task().to_json()
    other = TaskModel(
        regions=[Region(mean=[0.0, 0.0], covariance=np.eye(2), threshold=1.0)],
        rewards=[QuadraticReward(target=[0.0, 0.0], weight=np.eye(2))],
    )
    with pytest.raises(ValueError, match="differs"):
        SwirlDQN("MlpPolicy", venv, task=other)


def test_set_env_and_load_refuse_a_different_task(tmp_path):
    model = SwirlDQN("MlpPolicy", point_env(), seed=0)
    model.set_env(point_env())  # the same task: fine
    moved = TaskModel(
        regions=[Region(mean=[0.5, 0.0], covariance=np.eye(2) * 0.01, threshold=1.0)] * 2,
        rewards=[QuadraticReward(target=[0.5, 0.0], weight=np.eye(2))] * 2,
    )
    kept = model.env
    with pytest.raises(ValueError, match="differs"):
        model.set_env(SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), moved))
    assert model.env is kept  # the refused env was not taken
    model.save(tmp_path / "model.zip")
    assert SwirlDQN.load(tmp_path / "model.zip", env=point_env()).task.to_json() == model.task_json
    with pytest.raises(ValueError, match=r"differs .* load without env="):
        SwirlDQN.load(
            tmp_path / "model.zip", env=SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), moved)
        )


def test_set_env_and_load_take_the_envs_reward_settings_with_a_warning(tmp_path):
    potential = {"mode": "potential", "task_reward_weight": 10.0, "gamma": 0.9}
    paid = SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 60), point_task(), potential)
    model = SwirlDQN("MlpPolicy", paid, demonstrations=point_demos(2), gamma=0.9, seed=0)
    model.save(tmp_path / "model.zip")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the same settings (gamma 0.9, saved): no warning
        assert SwirlDQN.load(tmp_path / "model.zip", env=paid).reward_config.potential
        # a task file that carries the reward settings (the zoo's task.json) is the same task
        carried = dataclasses.replace(point_task(), reward_config=RewardConfig(**potential))
        SwirlDQN.load(tmp_path / "model.zip", env=SwirlWrapper(PointEnv(), carried))
        # model.task carries them: an env wrapped with it (the advice on a refused env) too
        for source in (model, SwirlDQN.load(tmp_path / "model.zip")):
            assert source.task.reward_config == RewardConfig(**potential)
            SwirlDQN.load(tmp_path / "model.zip", env=SwirlWrapper(PointEnv(), source.task))
    with pytest.warns(UserWarning, match="trained with RewardConfig") as caught:
        loaded = SwirlDQN.load(tmp_path / "model.zip", env=point_env(terminate_on_completion=True))
    assert not loaded.reward_config.potential  # the env's, as set_env takes them
    assert loaded.terminate_on_completion and caught[0].filename == __file__
    ended = "terminate_on_completion=True, but this model was trained with False: its episodes"
    assert any(ended in str(w.message) for w in caught)  # it was taken without a word
    with pytest.warns(UserWarning, match="trained with True: its episodes now go on past"):
        loaded.set_env(point_env(reward_config=potential))
    with pytest.warns(UserWarning, match="trained with RewardConfig") as caught:
        model.set_env(point_env())
    assert not model.reward_config.potential and caught[0].filename == __file__
    # a later version records more about the fit: the task is still the same
    recorded = dataclasses.replace(point_task(), metadata={"state_range": {"low": [0.0]}})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwirlDQN.load(tmp_path / "model.zip", env=SwirlWrapper(PointEnv(), recorded, potential))
    shaped = SwirlWrapper(PointEnv(), point_task(), {"mode": "potential", "gamma": 0.99})
    with pytest.warns(
        UserWarning, match="shapes with gamma=0.99 but SwirlDQN discounts with gamma=0.9"
    ):
        model.set_env(shaped)


def test_a_batch_larger_than_the_demo_pairs_is_all_of_them():
    model = SwirlDQN(
        "MlpPolicy",
        point_env(),
        demonstrations=point_demos(2),
        bc_epochs=2,
        seed=0,
        bc_batch_size=10**9,
    )
    model.pretrain()
    assert model._bc_done and 0 < model.bc_n_pairs_ < 10**9


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(bc_lr=-1.0), "bc_lr"),
        (dict(demo_loss_coef=float("nan")), "demo_loss_coef"),
        (dict(inverse_dynamics_kwargs={"batch_size": 0}), "batch_size"),
        (dict(inverse_dynamics_kwargs={"net_arch": 64}), "net_arch"),
        (dict(inverse_dynamics_kwargs={"lr": -1}), "lr"),
        (dict(inverse_dynamics_kwargs={"layers": [8]}), "unknown"),
        (dict(bc_epochs=2.7), "bc_epochs must be an integer"),
        (dict(bc_batch_size="64"), "bc_batch_size must be an integer"),
        (dict(task="task.json"), "task must be a swirl_wrappers.TaskModel, got str"),
        (dict(double_q=1), "double_q"),
        (dict(pretrain_td_steps=100), "set prefill_replay=True"),
        (dict(pretrain_td_steps=-1, prefill_replay=True), "pretrain_td_steps"),
        (
            dict(prefill_replay=True, optimize_memory_usage=True, replay_buffer_kwargs={}),
            "optimize_memory_usage",
        ),
        # DQN's: SB3 failed inside learn() (batch_size), in torch or not at all
        (dict(batch_size=0), "batch_size must be an integer >= 1, got 0"),
        (dict(gamma=1.5), r"gamma must be a finite number in \[0, 1\]"),
        (dict(exploration_final_eps=2.0), "exploration_final_eps"),
        (dict(max_grad_norm=-1), "max_grad_norm must be a finite number > 0"),
        (dict(learning_rate=-1e-3), "learning_rate must be a finite number > 0"),
        (dict(seed=1.5), "seed must be an integer"),
        (dict(train_freq=0), "train_freq must be an integer >= 1, got 0"),
        (dict(train_freq=(0, "episode")), r"train_freq\[0\] must be an integer >= 1"),
        (dict(train_freq=(1, "epoch")), r"train_freq\[1\] must be one of \['episode', 'step'\]"),
        (dict(verbose="2"), "verbose must be an integer >= 0, got '2'"),
        (dict(tensorboard_log=123), "tensorboard_log must be a folder path or None, got 123"),
    ],
)
def test_bad_settings_fail_at_construction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SwirlDQN("MlpPolicy", point_env(), demonstrations=point_demos(2), **kwargs)


def test_train_freq_takes_what_sb3_takes():
    from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

    for freq in (1, (2, "step"), (1, "episode"), TrainFreq(3, TrainFrequencyUnit.EPISODE)):
        SwirlDQN("MlpPolicy", point_env(), train_freq=freq, bc_epochs=0, seed=0).learn(5)


def test_a_task_that_is_not_a_task_model_is_named_before_the_env_is_read():
    # A path given as the task, with an env that is not wrapped: the task is what to fix first.
    with pytest.raises(ValueError, match=r"task must be a swirl_wrappers\.TaskModel, got str"):
        SwirlDQN("MlpPolicy", "CartPole-v1", task="task.json")


def test_a_model_saved_before_learning_keeps_its_demonstrations(tmp_path):
    model = SwirlDQN("MlpPolicy", point_env(), demonstrations=point_demos(2), bc_epochs=2, seed=0)
    model.save(tmp_path / "fresh.zip")
    loaded = SwirlDQN.load(tmp_path / "fresh.zip", env=point_env())
    loaded.learn(10)
    assert loaded._bc_done and loaded.bc_n_pairs_ > 0


def test_save_is_atomic_and_refuses_a_folder_and_load_a_plain_dqn(tmp_path, monkeypatch):
    """A save cut short (Ctrl-C, a full disk) leaves the model it replaces; a folder is an
    error, not PATH_2; a zip that holds no SWIRL task is refused at load, naming it."""
    from stable_baselines3 import DQN, PPO

    model = SwirlDQN("MlpPolicy", point_env(), bc_epochs=0, seed=0)
    model.save(tmp_path / "models" / "model")  # as in SB3: .zip added, the folder made
    path = tmp_path / "models" / "model.zip"
    before = path.read_bytes()
    other = SwirlDQN("MlpPolicy", point_env(), bc_epochs=0, seed=1)

    def cut(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(th, "save", cut)  # the policy's weights are written with torch.save
    with pytest.raises(KeyboardInterrupt):
        other.save(path)
    monkeypatch.undo()
    assert path.read_bytes() == before and sorted(p.name for p in path.parent.iterdir()) == [
        "model.zip"
    ]
    obs = point_env().observation_space.sample()
    assert SwirlDQN.load(path).predict(obs)[0] == model.predict(obs)[0]
    (tmp_path / "folder.zip").mkdir()
    with pytest.raises(IsADirectoryError, match=r"folder\.zip: it is a folder"):
        model.save(tmp_path / "folder.zip")
    with pytest.raises(IsADirectoryError, match="it is a folder"):
        model.save_replay_buffer(tmp_path / "folder.zip")
    assert not (tmp_path / "folder.zip_2").exists()
    model.save_replay_buffer(tmp_path / "buffer")
    model.load_replay_buffer(tmp_path / "buffer.pkl")
    two = SwirlDQN("MlpPolicy", DummyVecEnv([point_env, point_env]), bc_epochs=0, seed=0)
    own = two.replay_buffer
    with pytest.raises(ValueError, match=r"buffer\.pkl: the replay buffer does not fit.*n_envs 1"):
        two.load_replay_buffer(tmp_path / "buffer.pkl")
    assert two.replay_buffer is own
    (tmp_path / "task.pkl").write_text("{}")  # a JSON by mistake: SB3 "invalid load key"
    (tmp_path / "cut.pkl").write_bytes((tmp_path / "buffer.pkl").read_bytes()[:100])
    with open(tmp_path / "list.pkl", "wb") as fh:
        pickle.dump([1, 2], fh)
    for name, why in [("task", "invalid load key"), ("cut", "data was truncated")]:
        with pytest.raises(ValueError, match=rf"{name}\.pkl: not a replay buffer .*{why}"):
            two.load_replay_buffer(tmp_path / f"{name}.pkl")
    with pytest.raises(ValueError, match=r"list\.pkl: .*it holds no replay buffer"):
        two.load_replay_buffer(tmp_path / "list.pkl")
    assert two.replay_buffer is own
    with pytest.raises(ValueError, match=r"env= carries no SWIRL task: wrap it with the one"):
        SwirlDQN.load(path, env=PointEnv())  # SB3 said the spaces differ, in array dumps
    assert SwirlDQN.load(path, DummyVecEnv([point_env])).task_json == model.task_json
    DQN("MlpPolicy", "CartPole-v1").save(tmp_path / "plain.zip")
    with pytest.raises(ValueError, match=r"plain.zip holds no SWIRL task: not a SwirlDQN model"):
        SwirlDQN.load(tmp_path / "plain.zip")
    # another algorithm's model, the demos file, a task JSON: SB3 failed deep inside on them
    # (a policy without q_net, "No data found in the saved file", "wasn't a zip-file")
    PPO("MlpPolicy", "CartPole-v1", n_steps=16, batch_size=16).save(tmp_path / "ppo")
    save_demos(point_demos(2), tmp_path / "demos.npz")
    (tmp_path / "task.json").write_text(model.task.to_json())
    for file, said in [
        ("ppo", r"ppo holds no SWIRL task: .*stable_baselines3.common.policies"),
        ("demos.npz", r"demos.npz is not a model saved by SwirlDQN.save: .* load_demos"),
        ("task.json", r"task.json is not a model saved by SwirlDQN.save \(not a zip file\)"),
    ]:
        with pytest.raises(ValueError, match=said):
            SwirlDQN.load(tmp_path / file)


def test_bc_under_vec_normalize_updates_the_statistics_with_the_demo_states():

    venv = VecNormalize(DummyVecEnv([point_env]), norm_reward=False)
    model = SwirlDQN("MlpPolicy", venv, demonstrations=point_demos(3), bc_epochs=30, seed=0)
    model.learn(1)
    demo_obs = model._demo_data["obs"]
    assert venv.obs_rms.count > len(demo_obs)  # the demo states went into the statistics
    # and the cloned policy survives the statistics of the first rollouts
    with th.no_grad():
        q = model.q_net(th.as_tensor(venv.normalize_obs(demo_obs), dtype=th.float32))
    accuracy = float((q.argmax(dim=1).numpy() == model._demo_data["actions"]).mean())
    assert accuracy >= 0.9


@pytest.mark.parametrize(
    ("demo", "match"),
    [
        (Demonstration(np.zeros((5, 3)), np.zeros(4, dtype=int)), r"demonstration 0: .*3 dims"),
        (Demonstration(np.zeros((5, 2)), [0, 1, 4, 2]), r"1: .*Discrete\(4\).*0 \.\. 3"),
        (Demonstration(np.zeros((5, 2)), np.array([0, 1, -1, 2])), r"1: .*Discrete\(4\)"),
        (
            Demonstration(np.zeros((5, 2)), np.array([0, 1, 0.5, 2])),
            r"1: actions must be integers .*got 0\.5 at step 2",
        ),
        (
            Demonstration(np.zeros((5, 2)), np.array([[0], [1], [0], [2]])),
            r"0: .*shape \(4,\) .*got shape \(4, 1\) \(one action a step: pass actions\.ravel",
        ),
    ],
    ids=["state dims", "action too large", "negative action", "fractional action", "column"],
)
def test_demos_that_do_not_fit_the_env_are_refused_when_the_model_is_built(demo, match):
    """Not deep inside learn(): the message names the demo and the space."""
    with pytest.raises(ValueError, match=match):
        # the same demo twice where every demo would share its form (state dims, a column)
        same = demo.observations.shape[1] == 3 or np.ndim(demo.actions) == 2
        first = demo if same else point_demos(1)[0]
        SwirlDQN("MlpPolicy", point_env(), demonstrations=[first, demo], seed=0)


def test_demos_are_refused_on_a_frame_stacked_env_with_the_reason():
    stacked = VecFrameStack(DummyVecEnv([point_env]), 2)
    with pytest.raises(ValueError, match=r"frame-stacked env \(VecFrameStack\): a demo holds"):
        SwirlDQN("MlpPolicy", stacked, demonstrations=point_demos(2), seed=0)
    SwirlDQN("MlpPolicy", stacked, seed=0)  # without demos it is DQN on the proxy task


@pytest.mark.parametrize(
    "wrapper_kwargs",
    [
        dict(reward_config=dict(scale=0.5, region_bonus=2.0), terminate_on_completion=True),
        dict(reward_config=dict(mode="potential", scale=0.5, task_reward_weight=2.0, gamma=0.9)),
        dict(
            reward_config=dict(mode="potential", task_reward_weight=3.0),
            terminate_on_completion=True,
        ),
    ],
    ids=["quadratic", "potential", "potential-completion"],
)
def test_prefill_matches_what_the_wrapper_shows(wrapper_kwargs):
    """Lifted demo transitions in the buffer equal a replay of the demo through the wrapper."""
    demos = point_demos(2)
    model = SwirlDQN(
        "MlpPolicy",
        point_env(**wrapper_kwargs),
        demonstrations=demos,
        prefill_replay=True,
        bc_epochs=1,
        seed=0,
        gamma=wrapper_kwargs["reward_config"].get("gamma", 0.99),
    )
    model.pretrain()
    buffer = model.replay_buffer
    env = point_env(**wrapper_kwargs)
    row = 0
    for k, demo in enumerate(demos):
        obs, _ = env.reset(seed=k)
        for action in demo.actions:
            next_obs, reward, terminated, truncated, _ = env.step(int(action))
            np.testing.assert_allclose(buffer.observations[row, 0], obs, atol=1e-6)
            np.testing.assert_allclose(buffer.next_observations[row, 0], next_obs, atol=1e-6)
            assert buffer.actions[row, 0, 0] == action
            assert buffer.rewards[row, 0] == pytest.approx(reward, abs=1e-5)
            assert buffer.dones[row, 0] == terminated
            obs, row = next_obs, row + 1
            if terminated or truncated:
                break
    assert buffer.size() == row


@pytest.mark.parametrize("n_envs", [1, 2])
def test_prefill_bootstraps_from_the_end_of_a_truncated_demo(n_envs):
    """A demo cut by a time limit ends in the buffer as the wrapper's episode ends at that
    limit: a truncation (SB3's timeouts), paid as a step that does not terminate (potential
    shaping keeps the last state's potential); not as a terminal state."""
    config = dict(mode="potential", task_reward_weight=1.0, gamma=0.9)
    cut = [
        Demonstration(d.observations[:6], d.actions[:5], np.zeros(5), truncated=True)
        for d in point_demos(2)
    ]
    model = SwirlDQN(
        "MlpPolicy",
        DummyVecEnv([lambda: point_env(reward_config=config)] * n_envs),
        demonstrations=cut,
        prefill_replay=True,
        bc_epochs=1,
        gamma=0.9,
        seed=0,
    )
    model.pretrain()
    data, buffer = model._demo_data, model.replay_buffer
    assert not data["done"].any() and data["end"].sum() == 2
    env = SwirlWrapper(gym.wrappers.TimeLimit(PointEnv(), 5), point_task(), reward_config=config)
    rewards, ends = [], []
    for k, demo in enumerate(cut):
        env.reset(seed=k)
        for action in demo.actions:
            _, reward, terminated, truncated, _ = env.step(int(action))
            assert not terminated
            rewards.append(reward)
            ends.append(truncated)
    np.testing.assert_allclose(data["reward"], rewards, atol=1e-6)
    # each env column holds a contiguous run of the transitions, in order
    slots = buffer.timeouts[: buffer.pos].T.ravel()[: len(ends)]
    np.testing.assert_array_equal(slots, ends)
    np.testing.assert_array_equal(buffer.dones[: buffer.pos].T.ravel()[: len(ends)], ends)


def test_prefill_warns_of_demos_without_rewards_where_the_env_reward_counts():
    """TD learning on such demos reads an env reward of 0 a step and 1 at the end: not the
    env's own (MountainCar pays -1 a step)."""
    counted = {"mode": "potential", "task_reward_weight": 1.0}
    kwargs = dict(prefill_replay=True, bc_epochs=1, seed=0)
    kwargs["demonstrations"] = point_demos(2)
    model = SwirlDQN("MlpPolicy", point_env(reward_config=counted), **kwargs)
    with pytest.warns(DemoWarning, match=r"demos \[0, 1\] hold no rewards: .*weight=1 adds"):
        model.pretrain()
    rewarded = [Demonstration(d.observations, d.actions, np.zeros(len(d))) for d in point_demos(2)]
    ignored = {"mode": "quadratic", "task_reward_weight": 0.0}
    for demos, config in [(rewarded, counted), (point_demos(2), ignored)]:
        kwargs["demonstrations"] = demos
        model = SwirlDQN("MlpPolicy", point_env(reward_config=config), **kwargs)
        with warnings.catch_warnings():
            warnings.simplefilter("error", DemoWarning)
            model.pretrain()


def test_demos_without_rewards_succeed_at_the_end_unless_truncated():
    """A rewardless demo is taken to end in success (task reward 1 on its last step); one
    that a time limit cut short pays 0 on every step."""
    demos = point_demos(2)
    cut = Demonstration(demos[1].observations, demos[1].actions, truncated=True)
    model = SwirlDQN("MlpPolicy", point_env(), demonstrations=[demos[0], cut], seed=0)
    done, truncated = model._demo_transitions()
    assert done["task_reward"][-1] == 1.0 and done["task_reward"][:-1].sum() == 0
    assert truncated["task_reward"].sum() == 0


@pytest.mark.parametrize("handle_timeout_termination", [True, False])
def test_prefill_lays_demos_out_in_order_for_n_step_returns(handle_timeout_termination):
    """With 3 envs and 3-step returns, each buffer column reads the demos in order, and a
    column's last row is a demo's end or ends an episode as a truncation: the n-step return of
    every demo transition equals its return computed from the demo alone (also where SB3
    stores no truncations)."""

    demos = point_demos(4)
    model = SwirlDQN(
        "MlpPolicy",
        DummyVecEnv([point_env] * 3),
        demonstrations=demos,
        replay_buffer_kwargs={"handle_timeout_termination": handle_timeout_termination},
        n_steps=3,
        gamma=0.9,
        prefill_replay=True,
        bc_epochs=1,
        seed=0,
    )
    model.pretrain()
    data, buffer = model._demo_data, model.replay_buffer
    n, rows = len(data["reward"]), buffer.pos
    assert rows == -(-n // 3)
    assert data["done"].sum() == len(demos)
    for _ in range(2):  # online steps follow in every column: no return may read into them
        obs = data["obs"][:3]
        buffer.add(obs, obs, np.zeros((3, 1)), np.full(3, 100.0), np.zeros(3, bool), [{}] * 3)

    def n_step(k: int, stop: int) -> tuple[float, float]:
        """Return and bootstrap discount of demo transition k read up to transition stop."""
        total, steps = 0.0, 0
        for j in range(k, k + 3):
            if j == stop:
                break
            total += 0.9**steps * data["reward"][j]
            steps += 1
            if data["done"][j]:
                break
        return total, 0.9**steps

    for _ in range(20):  # the buffer draws each sample's env column at random
        samples = buffer._get_samples(np.arange(rows))
        for row in range(rows):
            obs = samples.observations[row].numpy()
            k = int(np.flatnonzero(np.all(np.isclose(data["obs"], obs), axis=1))[0])
            # slot j = column * rows + row holds transition j % n; the column ends at a cut
            placements = [n_step(k, k + rows - j % rows) for j in (k, k + n) if j < 3 * rows]
            got = (samples.rewards[row, 0].item(), samples.discounts[row, 0].item())
            assert any(got == pytest.approx(p, abs=1e-5) for p in placements)


def test_pretrain_td_steps_start_q_at_the_demos_returns_and_keep_the_clone():
    """DQfD's pre-training moves Q(s, a_E) from about 0 towards the demos' discounted returns
    (here a cost at every step: the quadratic segment reward) without losing the clone."""
    demos = point_demos(3)
    errors = {}
    for steps in (0, 4000):
        model = SwirlDQN(
            "MlpPolicy",
            point_env(),
            demonstrations=demos,
            prefill_replay=steps > 0,
            pretrain_td_steps=steps,
            target_update_interval=250,
            gamma=0.9,
            bc_epochs=100,
            seed=0,
        )
        model.pretrain()
        data = model._demo_data
        q = q_values(model, data["obs"])
        returns, future = np.zeros(len(data["reward"])), 0.0
        for k in range(len(returns) - 1, -1, -1):
            future = data["reward"][k] + 0.9 * (0.0 if data["done"][k] else future)
            returns[k] = future
        assert returns.max() <= 0.0 and returns.mean() < -1.0  # a cost at every step
        assert np.mean(q.argmax(axis=1) == data["actions"]) > 0.95
        errors[steps] = np.abs(q[np.arange(len(q)), data["actions"]] - returns).mean()
    assert errors[4000] < 0.3 * errors[0]


def test_verbose_says_what_runs_before_the_first_env_step(capsys):
    model = SwirlDQN(
        "MlpPolicy",
        point_env(),
        demonstrations=point_demos(2),
        prefill_replay=True,
        pretrain_td_steps=20,
        bc_epochs=2,
        verbose=1,
        seed=0,
    )
    model.pretrain()
    out = " ".join(capsys.readouterr().out.split())
    assert "over 2 epochs (behavioural cloning)" in out and "BC accuracy" in out
    assert "20 TD updates on the demo transitions before the first env step" in out


def test_potential_shaping_with_another_gamma_warns():
    with pytest.warns(UserWarning, match="policy-invariant only when they are equal"):
        SwirlDQN("MlpPolicy", point_env(reward_config={"mode": "potential", "gamma": 0.9}))


def test_inverse_dynamics_labels_state_only_demos(tmp_path):
    demos = point_demos(3)
    state_only = [Demonstration(d.observations) for d in demos]
    model = SwirlDQN(
        "MlpPolicy",
        point_env(),
        demonstrations=state_only,
        inverse_dynamics_steps=1500,
        bc_epochs=30,
        seed=0,
    )
    labels = model.infer_demo_actions([d.observations for d in state_only])
    agreement = np.mean(np.concatenate(labels) == np.concatenate([d.actions for d in demos]))
    assert agreement >= 0.9
    # the random-action steps were kept for Q-learning
    assert model.replay_buffer.size() == 1500
    # the labeller is saved with the model (it was dropped): a loaded one labels alike
    model.save(tmp_path / "model.zip")
    loaded = SwirlDQN.load(tmp_path / "model.zip")
    for d in state_only:
        s, s_next = d.observations[:-1], d.observations[1:]
        np.testing.assert_array_equal(
            loaded.inverse_dynamics_.predict(s, s_next), model.inverse_dynamics_.predict(s, s_next)
        )


@pytest.mark.parametrize("by_hand", [False, True])
def test_the_labelling_steps_count_as_the_agents_own(by_hand):
    """The random-action steps that label state-only demos are env steps and rollouts: learn's
    budget, SB3's episode statistics and TaskEvalCallback's episodes count them (they did not:
    learn(N) took N + inverse_dynamics_steps steps), also after pretrain() called by hand."""
    from stable_baselines3.common.monitor import Monitor

    from sb3_swirl.callbacks import SegmentProgressCallback, TaskEvalCallback

    state_only = [Demonstration(d.observations) for d in point_demos(3)]
    env = DummyVecEnv([lambda: Monitor(point_env())])
    model = SwirlDQN(
        "MlpPolicy", env, demonstrations=state_only, inverse_dynamics_steps=300, seed=0
    )
    evaluation = TaskEvalCallback(DummyVecEnv([point_env]), eval_freq=10_000, eval_at_start=True)
    progress = SegmentProgressCallback()
    if by_hand:
        model.pretrain()
    model.learn(400, callback=[evaluation, progress])
    assert model.num_timesteps == 400 == model.replay_buffer.size()
    assert model.inverse_dynamics_episodes_ > 0
    assert evaluation.evaluations_timesteps[0] == 300  # evaluated after the labelling steps
    assert evaluation.evaluations_episodes[0] == model.inverse_dynamics_episodes_
    assert evaluation.n_training_episodes == model._episode_num
    assert len(model.ep_info_buffer) == min(model._episode_num, 100)
    # the episode running when the labelling ended is not scored: it began unseen
    assert progress.n_episodes <= model._episode_num - model.inverse_dynamics_episodes_ - 1


def test_a_budget_smaller_than_the_labelling_steps_is_said():
    """learn(100) with 300 labelling steps ran 300 steps and no Q-learning, without a word."""
    state_only = [Demonstration(d.observations) for d in point_demos(2)]
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=state_only, inverse_dynamics_steps=300, seed=0
    )
    with pytest.warns(UserWarning, match=r"took 300 env steps .* ends at 300 steps"):
        model.learn(100)
    assert model.num_timesteps == 300
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.learn(100, reset_num_timesteps=False)  # labelled once: an ordinary learn


def test_bad_settings_and_an_unlifted_observation_are_named():
    """n_steps was unchecked (0 ran as 1, 2.5 failed inside the buffer), max_grad_norm=inf
    (DQN's "no clipping") was refused, and predicting on the env's own observation gave SB3's
    shape error."""
    for bad in (0, -2, 2.5, "3"):
        with pytest.raises(ValueError, match="n_steps must be an integer"):
            SwirlDQN("MlpPolicy", point_env(), n_steps=bad)
    model = SwirlDQN("MlpPolicy", point_env(), max_grad_norm=float("inf"), seed=0)
    lifted, _ = point_env().reset(seed=0)
    model.predict(lifted)
    with pytest.raises(ValueError, match=r"no segment: .*SwirlWrapper\(env, model.task\)"):
        model.predict(lifted[: -model.task.n_indices])
    with pytest.raises(ValueError, match="no segment"):
        model.predict(np.zeros((4, len(lifted) - model.task.n_indices)))


def test_one_demo_is_enough_once_the_task_is_fitted():
    """Fitting needs two demos; cloning into a fitted task's agent does not (it refused one)."""
    model = SwirlDQN("MlpPolicy", point_env(), demonstrations=point_demos(1), bc_epochs=50, seed=0)
    assert model.pretrain()["accuracy"] >= 0.9


def test_demos_that_overflow_the_replay_buffer_are_warned_of():
    demos = point_demos(3)
    n = sum(len(d) for d in demos)
    kwargs = dict(demonstrations=demos, prefill_replay=True, bc_epochs=1, seed=0)
    model = SwirlDQN("MlpPolicy", point_env(), buffer_size=n - 1, **kwargs)
    with pytest.warns(DemoWarning, match=f"the {n} demo transitions do not fit the replay"):
        model.pretrain()
    model = SwirlDQN("MlpPolicy", point_env(), buffer_size=n, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DemoWarning)
        model.pretrain()


def test_inverse_dynamics_refuses_bad_transitions_naming_the_problem():
    from sklearn.exceptions import NotFittedError

    from sb3_swirl import InverseDynamics

    rng = np.random.default_rng(0)
    s, a = rng.normal(size=(50, 2)), rng.integers(3, size=50)
    with pytest.raises(NotFittedError):
        InverseDynamics().predict(s, s)
    nan = s.copy()
    nan[7, 1] = np.nan
    for args, match in (
        ((s, s[:, :1], a), r"one shape .* got \(50, 2\) and \(50, 1\)"),
        ((nan, s, a), "transition 7 holds NaN"),
        ((s, s, a[:-1]), r"actions must have shape \(50,\)"),
        ((s, s, a * 0.5), "is not an integer in 0 .. 2"),
        ((s, s, a + 1), "is not an integer in 0 .. 2"),
        ((s[:0], s[:0], a[:0]), "n >= 1"),
    ):
        with pytest.raises(ValueError, match=match):
            InverseDynamics(epochs=1).fit(*args, n_actions=3)
    for seed in ("a", -1, 1.5):  # numpy's SeedSequence said it, at fit
        with pytest.raises(ValueError, match=rf"seed must be an integer .*got {seed!r}"):
            InverseDynamics(seed=seed)
    fitted = InverseDynamics(epochs=1, seed=0).fit(s, s + 0.1, a, n_actions=3)
    with pytest.raises(ValueError, match="states have 3 dims; the model was fitted on 2"):
        fitted.predict(np.zeros((2, 3)), np.zeros((2, 3)))


def test_demos_left_out_of_bc_for_lack_of_actions_are_named():
    demos = point_demos(3)
    mixed = [demos[0], Demonstration(demos[1].observations), demos[2]]
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=mixed, infer_actions="none", bc_epochs=2
    )
    with pytest.warns(UserWarning, match=r"demos \[1\] have no actions .* clones the other 2"):
        model.pretrain()


def test_bc_only_with_state_only_demos_and_no_inference_is_skipped():
    state_only = [Demonstration(d.observations) for d in point_demos(2)]
    model = SwirlDQN("MlpPolicy", point_env(), demonstrations=state_only, infer_actions="none")
    before = q_values(model, np.zeros((1, 5), dtype=np.float32))
    with pytest.warns(UserWarning, match="skipping BC"):
        info = model.pretrain()
    assert info["n_pairs"] == 0
    np.testing.assert_array_equal(before, q_values(model, np.zeros((1, 5), dtype=np.float32)))


def test_bc_agrees_with_parking_demos(parking):
    demos, task = parking
    model = SwirlDQN(
        "MlpPolicy", SwirlWrapper(gym.make(PARKING), task), demonstrations=demos, seed=0
    )
    info = model.pretrain()
    assert info["accuracy"] >= 0.9
    # the target network starts from the cloned one
    obs = np.random.default_rng(0).normal(size=(8, model.observation_space.shape[0]))
    with th.no_grad():
        x = th.as_tensor(obs, dtype=th.float32)
        np.testing.assert_array_equal(model.q_net(x).numpy(), model.q_net_target(x).numpy())


def test_q_learning_on_the_proxy_reward_learns_what_no_demo_showed():
    """No demos, so no BC start: DQN on the SWIRL proxy reward (potential shaping) goes from
    never reaching the goal to reaching it, in 4000 steps. (On 12 seeds: 10 of 10 on 11 of them,
    7 of 10 on one.)"""
    shaped = {"mode": "potential", "task_reward_weight": 10.0}
    model = SwirlDQN(
        "MlpPolicy",
        point_env(reward_config=shaped),
        seed=0,
        learning_starts=200,
        learning_rate=1e-3,
        exploration_fraction=0.3,
        target_update_interval=250,
        buffer_size=10_000,
    )
    assert success_count(model, point_env(), 10, seed=100) == 0
    model.learn(4_000)
    assert success_count(model, point_env(), 10, seed=100) >= 8


def test_tuned_swirl_dqn_keeps_what_its_bc_start_parks(parking):
    """The shipped pipeline (preset task, tuned zoo config): the BC start parks, and 2000 steps
    of Q-learning keep it (on parking the clone of 5 demos already parks in most episodes; the
    test above shows the Q-learning itself learn)."""
    from sb3_swirl.experiments import _algo_kwargs, _swirl_wrapper_kwargs, load_hyperparams

    demos, task = parking
    hyperparams = load_hyperparams("swirl_dqn", PARKING)
    kwargs = _algo_kwargs(hyperparams)
    env = SwirlWrapper(gym.make(PARKING), task, **_swirl_wrapper_kwargs(hyperparams))
    model = SwirlDQN(hyperparams["policy"], env, demonstrations=demos, seed=0, **kwargs)
    assert success_count(model, env, 20, seed=100) == 0  # the untrained network
    model.pretrain()
    cloned = success_count(model, env, 20, seed=100)
    model.learn(2_000)
    trained = success_count(model, env, 20, seed=100)
    assert cloned >= 16 and trained >= 16, (cloned, trained)


def test_zoo_linear_learning_rate_schedule_and_a_bad_one():
    """An entry's ``learning_rate: lin_1e-3`` means what it means in rl-zoo: 1e-3 falling to 0."""
    from sb3_swirl.experiments import load_hyperparams, train_and_evaluate

    hyperparams = load_hyperparams("dqn", PARKING) | {"learning_rate": "lin_1e-3"}
    budget = dict(total_timesteps=400, seed=0, progress=False, hyperparams=hyperparams)
    record = train_and_evaluate("dqn", PRESETS["parking"], keep_model=True, **budget)
    model = record["model"]
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)
    assert model.lr_schedule(0.0) == 0.0
    assert model.policy.optimizer.param_groups[0]["lr"] < 1e-4  # decayed to 0 by the last update
    with pytest.raises(ValueError, match="learning_rate 'cos_1e-3'"):
        train_and_evaluate(
            "dqn",
            PRESETS["parking"],
            **budget | {"hyperparams": hyperparams | {"learning_rate": "cos_1e-3"}},
        )


@pytest.mark.slow
def test_swirl_dqn_learns_parking_where_dqn_does_not(parking):
    from sb3_swirl.experiments import train_and_evaluate

    demos, task = parking
    budget = dict(total_timesteps=10_000, seed=0, progress=False)
    swirl = train_and_evaluate("swirl_dqn", PRESETS["parking"], task=task, demos=demos, **budget)
    plain = train_and_evaluate("dqn", PRESETS["parking"], **budget)
    assert swirl["rollouts_to_target"] is not None and swirl["final_success"] >= 0.8
    assert plain["best_success"] == 0.0


def test_save_load_round_trip_keeps_the_demo_loss_and_no_second_bc(tmp_path, monkeypatch):
    demos = point_demos(2)
    model = SwirlDQN(
        "MlpPolicy", point_env(), demonstrations=demos, bc_epochs=20, learning_starts=50, seed=0
    )
    model.learn(100)
    assert model._bc_done
    model.save(tmp_path / "model.zip")
    obs = np.stack([point_env().reset(seed=i)[0] for i in range(6)])

    loaded = SwirlDQN.load(tmp_path / "model.zip", env=point_env())
    assert loaded.task.to_json() == model.task.to_json()
    assert loaded._bc_done
    np.testing.assert_array_equal(q_values(loaded, obs), q_values(model, obs))
    np.testing.assert_array_equal(
        loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0]
    )
    # also without an env (prediction only): the task comes from the file
    assert SwirlDQN.load(tmp_path / "model.zip").task.to_json() == model.task.to_json()

    # the supervised demo loss goes on after load, on the same demo pairs
    assert set(loaded._demo) == set(model._demo)
    for key, tensor in model._demo.items():
        assert th.equal(loaded._demo[key], tensor), key
    loaded.demonstrations = demos

    def fail():
        raise AssertionError("pretrain ran again after load")

    supervised = []
    monkeypatch.setattr(loaded, "pretrain", fail)
    monkeypatch.setattr(
        loaded, "_supervised_loss", lambda *a: supervised.append(1) or model._supervised_loss(*a)
    )
    loaded.learn(20, reset_num_timesteps=False)
    assert supervised, "no demo loss in the updates after load"


def test_demo_loss_normalises_demo_obs_with_the_current_vec_normalize_stats(monkeypatch):

    venv = VecNormalize(DummyVecEnv([point_env]), norm_reward=False)
    model = SwirlDQN(
        "MlpPolicy", venv, demonstrations=point_demos(2), bc_epochs=2, learning_starts=50, seed=0
    )
    model.learn(60)  # BC, then a few updates while the statistics move
    venv.obs_rms.mean = venv.obs_rms.mean + 0.5  # statistics unlike those at BC time
    seen = []
    forward = model.q_net.forward
    monkeypatch.setattr(model.q_net, "forward", lambda obs: seen.append(obs) or forward(obs))
    model.train(gradient_steps=1, batch_size=8)
    raw = model._demo["obs"].numpy()
    demo_batch = seen[-1].numpy()  # the last Q-network call is the demo batch's
    normalised = venv.normalize_obs(raw)
    matches = [
        np.where(np.isclose(normalised, row, atol=1e-6).all(axis=1))[0] for row in demo_batch
    ]
    assert all(len(m) for m in matches), "demo obs not normalised with the current statistics"


def test_rbf_features_shape_range_and_gradient():
    space = spaces.Box(low=np.array([0, -1, 0, 0, 0]), high=np.array([1, 1, 1, 1, 1]))
    fe = RBFFeaturesExtractor(space, n_centers_per_dim=4, sigma=0.1, n_indices=3)
    assert fe.features_dim == 16 * 3
    obs = th.tensor([[0.3, 0.2, 0.0, 1.0, 0.0], [5.0, -7.0, 1.0, 0.0, 0.0]], requires_grad=True)
    out = fe(obs)
    assert out.shape == (2, 48)
    assert th.all(out >= 0) and th.all(out <= 1)
    # a partition of unity inside the active segment's block, zeros in the others
    blocks = out.reshape(2, 16, 3)
    np.testing.assert_allclose(
        blocks.sum(dim=1).detach().numpy(), [[0, 1, 0], [1, 0, 0]], atol=1e-6
    )
    (out * th.arange(48.0)).sum().backward()
    assert obs.grad is not None and th.any(obs.grad[:, :2] != 0)


def test_rbf_features_need_a_finite_box():
    space = spaces.Box(-np.inf, np.inf, shape=(3,))
    with pytest.raises(ValueError, match=r"low=\.\.\. and high="):
        RBFFeaturesExtractor(space, n_centers_per_dim=3, sigma=0.1)
    assert RBFFeaturesExtractor(space, 3, 0.1, low=[0, 0, 0], high=[1, 1, 1]).features_dim == 27


def test_rbf_q_function_inside_swirl_dqn():
    model = SwirlDQN(
        "MlpPolicy",
        point_env(),
        demonstrations=point_demos(3),
        policy_kwargs=dict(
            features_extractor_class=RBFFeaturesExtractor,
            features_extractor_kwargs=dict(n_centers_per_dim=9, sigma=0.1),
            net_arch=[],
        ),
        bc_epochs=100,
        bc_lr=0.05,
        seed=0,
    )
    # n_indices filled from the task: one linear Q per segment
    assert model.q_net.features_extractor.n_indices == 3
    assert model.q_net.features_dim == 81 * 3
    assert model.pretrain()["accuracy"] >= 0.9


def test_a_plain_subprocess_env_is_a_clear_error_not_a_dead_worker():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    venv = make_vec_env("CartPole-v1", n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        with pytest.raises(ValueError, match="carries no SWIRL proxy task"):
            SwirlDQN("MlpPolicy", venv)
        assert venv.get_attr("spec")[0].id == "CartPole-v1"  # the workers are still alive
    finally:
        venv.close()


def test_demos_far_outside_the_observation_bounds_are_warned_about():
    """Demos in cm for an env in m: the clone would learn at states the agent never sees."""

    demos = point_demos(2)
    in_cm = [Demonstration(d.observations * 100, d.actions) for d in demos]
    with pytest.warns(DemoWarning, match=r"far outside the env's observation bounds \(dim 0: "):
        SwirlDQN("MlpPolicy", point_env(), demonstrations=in_cm, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwirlDQN("MlpPolicy", point_env(), demonstrations=demos, seed=0)


def test_prefill_without_demonstrations_is_said():
    """A zoo entry with a fitted task and no demos, and prefill_replay: it skipped BC and the
    prefill without a word."""
    with pytest.warns(UserWarning, match="prefill_replay / pretrain_td_steps without demonst"):
        SwirlDQN("MlpPolicy", point_env(), prefill_replay=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwirlDQN("MlpPolicy", point_env(), demonstrations=point_demos(2), prefill_replay=True)
