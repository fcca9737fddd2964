"""gymnasium-robotics' Fetch tasks in discrete steps, SWIRL on goal envs and on Dict
observations, and hindsight relabelling (HER) with the SWIRL wrapper."""

from __future__ import annotations

import dataclasses
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3 import DQN, HerReplayBuffer
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.utils import set_random_seed

import sb3_swirl.envs  # noqa: F401  (registers the ids)
from sb3_swirl import KeysExtractor, SwirlDQN, as_demonstrations, collect_demos, fit_task
from sb3_swirl.baselines import run_method
from sb3_swirl.buffers import DictNStepReplayBuffer
from sb3_swirl.demos import Demonstration
from sb3_swirl.envs.fetch import FetchDiscreteEnv
from sb3_swirl.experiments import PRESETS
from sb3_swirl.supervisors import _run_episode
from sb3_swirl.supervisors.fetch import PUSH, FetchPushSupervisor
from swirl_wrappers import QuadraticReward, Region, SwirlWrapper, TaskModel

pytestmark = pytest.mark.filterwarnings("ignore:.*GoalEnv.*", "ignore:.*compute_reward.*")

TASKS = ("Reach", "Push", "PickAndPlace")
KEYS = ["observation", "achieved_goal", "desired_goal", "goal_offset"]


def _ids(task: str) -> str:
    return f"sb3_swirl/Fetch{task}Discrete-v0"


def _goal_task(dims: list[int]) -> TaskModel:
    """One region at the origin of ``dims`` (a goal offset of zero)."""
    size = len(dims)
    return TaskModel(
        [Region(np.zeros(size), np.eye(size) * 1e-3, 9.0)],
        [QuadraticReward(np.zeros(size), np.eye(size))],
        dims=dims,
    )


@pytest.mark.parametrize("task", TASKS)
def test_env_checkers_and_seeding(task):
    env = gym.make(_ids(task), goal_offset=True)
    gym_check_env(env.unwrapped, skip_render_check=True)
    check_env(env.unwrapped)
    assert env.action_space.n == (8 if task == "PickAndPlace" else 6)

    def rollout(seed: int) -> np.ndarray:
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        states = [np.concatenate([obs["observation"], obs["desired_goal"]])]
        for _ in range(10):
            obs, *_ = env.step(int(rng.integers(env.action_space.n)))
            states.append(np.concatenate([obs["observation"], obs["desired_goal"]]))
        return np.array(states)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.array_equal(rollout(3), rollout(4))
    obs, _ = env.reset(seed=5)
    np.testing.assert_array_equal(obs["goal_offset"], obs["desired_goal"] - obs["achieved_goal"])
    assert np.linalg.norm(obs["goal_offset"]) >= 0.1  # starts too near the goal are redrawn


def test_steps_add_up_exactly():
    env = gym.make(_ids("Reach"))
    obs, _ = env.reset(seed=0)
    start = obs["observation"][:3].copy()
    for action in (2, 2, 2, 0, 0, 1):  # +y three times, +x twice, -x
        obs, *_ = env.step(action)
    np.testing.assert_allclose(env.unwrapped.target - start, [0.02, 0.06, 0.0], atol=1e-9)
    # the arm trails the target by about a third of a step
    assert np.abs(obs["observation"][:3] - env.unwrapped.target).max() < 0.012


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"task": "Slide"}, "task must be one of"),
        ({"step_size": 0.1}, r"step_size must be in \(0, 0.05\]"),
        ({"min_goal_distance": 0.5}, r"min_goal_distance must be in \[0, 0.2\]"),
        ({"render_mode": "human"}, "render_mode must be None or 'rgb_array'"),
        ({"observation_dims": []}, "observation_dims must be a non-empty list of ints"),
        ({"observation_dims": [0.5]}, "observation_dims must be a non-empty list of ints"),
        ({"observation_dims": [3, 10]}, r"distinct entries of Fetch's 10-dim observation"),
        ({"observation_dims": [1, 1]}, r"distinct entries of Fetch's 10-dim observation"),
        # a string read as true, or failed in float() without the setting's name
        ({"goal_offset": "false"}, "goal_offset must be True or False, got 'false'"),
        ({"terminate_on_success": "no"}, "terminate_on_success must be True or False"),
        ({"step_size": "big"}, "step_size must be a finite number, got 'big'"),
    ],
)
def test_bad_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        FetchDiscreteEnv(**kwargs)


def test_observation_dims_keep_those_entries_and_the_supervisor_still_succeeds():
    kwargs = {"observation_dims": [6, 7, 8], "goal_offset": True}
    env = gym.make(_ids("Push"), **kwargs)
    check_env(env.unwrapped)
    assert env.observation_space["observation"].shape == (3,)
    obs, _ = env.reset(seed=2)
    whole = env.unwrapped.fetch_observation
    assert whole.shape == (25,)
    np.testing.assert_array_equal(obs["observation"], whole[6:9])  # object minus gripper
    np.testing.assert_allclose(obs["observation"], whole[3:6] - whole[0:3], atol=1e-12)
    # the supervisor reads the whole observation, not the agent's: same demos either way
    demos = collect_demos(_ids("Push"), 2, seed=1, state_key=KEYS, **kwargs)
    whole_demos = collect_demos(_ids("Push"), 2, seed=1, state_key=KEYS, goal_offset=True)
    for short, full in zip(demos, whole_demos, strict=True):
        np.testing.assert_array_equal(short.actions, full.actions)
        np.testing.assert_array_equal(short.observations[:, :3], full.observations[:, 6:9])
        np.testing.assert_array_equal(short.observations[:, 3:], full.observations[:, 25:])


def test_push_supervisor_pushes_the_longer_leg_first():
    """The order of the legs follows from the start, so alike starts get alike demos."""
    demos, phases = collect_demos(
        _ids("Push"), 4, seed=3, return_phases=True, state_key=KEYS, goal_offset=True
    )
    for demo, phase in zip(demos, phases, strict=True):
        longer = int(np.argmax(np.abs(demo.observations[0, -3:-1])))  # goal minus object
        first_push = demo.actions[np.flatnonzero(phase == PUSH)[0]]
        assert first_push // 2 == longer  # 0, 1: along x; 2, 3: along y


@pytest.mark.parametrize("supervisor_seed", [1, 2])
def test_push_supervisor_keeps_the_object_on_the_table(supervisor_seed):
    """From this start, legs that ended 1.5 cm from the goal let the object slide over the
    table's edge (it slides on after the last push)."""
    env = gym.make(_ids("Push"))
    demo, _ = _run_episode(env, FetchPushSupervisor, 906654279, supervisor_seed, "observation")
    assert demo is not None and env.unwrapped.fetch_observation[5] > 0.4  # on the table


@pytest.mark.parametrize("task", TASKS)
def test_supervisors_succeed_and_demos_record_the_state_keys(task):
    demos, phases = collect_demos(
        _ids(task), 3, seed=1, return_phases=True, state_key=KEYS, goal_offset=True
    )
    width = {"Reach": 10, "Push": 25, "PickAndPlace": 25}[task] + 9
    assert [d.observations.shape[1] for d in demos] == [width] * 3
    assert all(len(p) == len(d) for p, d in zip(phases, demos, strict=True))
    # the last recorded goal offset is within Fetch's 5 cm
    assert all(np.linalg.norm(d.observations[-1, -3:]) < 0.05 for d in demos)
    if task != "Reach":
        assert all(len(set(p)) >= 3 for p in phases)  # the plans go through their phases


def test_state_key_is_for_dict_observations():
    with pytest.raises(ValueError, match="state_key is for Dict observations"):
        collect_demos("sb3_swirl/ParallelParking-v0", 1, state_key="observation")
    # an unknown key is named before an episode runs (it was a KeyError after the first)
    with pytest.raises(ValueError, match="state_key 'goal' is not in the observation space"):
        collect_demos(_ids("Push"), 1, state_key=["observation", "goal"])


# ------------------------------------------------------------------ goal envs and HER
def test_swirl_on_gymnasium_robotics_fetch_reach_passes_sb3_check_env():
    """The user's case of the issue: SB3's checker sees a goal env under the wrapper."""
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    env = SwirlWrapper(
        gym.make("FetchReach-v4"),
        _goal_task([0, 1, 2]),
        state_key="observation",
        reward_config={"task_reward_weight": 2.0},
    )
    check_env(env)
    env.reset(seed=0)
    obs, reward, *_, info = env.step(env.action_space.sample())
    with warnings.catch_warnings():  # the env's reward has a weight: relabelling counts
        warnings.simplefilter("error")
        assert env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == reward
        # another goal: the segment part is kept, the env's part recomputed (-1 -> 0, weight 2)
        relabelled = env.compute_reward(obs["achieved_goal"], obs["achieved_goal"], info)
    assert info["task_reward"] == -1.0 and relabelled == pytest.approx(reward + 2.0)


def test_her_works_with_a_goal_free_task_and_is_refused_when_the_task_reads_the_goal():
    def make(state_key, dims):
        env = gym.make(_ids("Reach"), goal_offset=True)
        return SwirlWrapper(env, _goal_task(dims), state_key=state_key)

    def her(env, **kwargs):
        model = DQN(
            "MultiInputPolicy",
            env,
            replay_buffer_class=HerReplayBuffer,
            replay_buffer_kwargs=kwargs,
            learning_starts=60,
            seed=0,
        )
        model.learn(120)

    # the default reward settings weigh the env's own reward 0: HER changes nothing, and says so
    with pytest.warns(UserWarning, match="relabelled goals change no reward here"):
        her(make("observation", [0, 1, 2]), copy_info_dict=True)
    # what counts is the entries the task reads, not the keys the state joins
    her(make(KEYS, [0, 1, 2]), copy_info_dict=True)
    with pytest.raises(ValueError, match="pass replay_buffer_kwargs=dict\\(copy_info_dict=True\\)"):
        her(make("observation", [0, 1, 2]))
    with pytest.raises(ValueError, match=r"refuses relabelled goals .* reads \['goal_offset'\]"):
        her(make(["observation", "goal_offset"], [10, 11, 12]), copy_info_dict=True)
    with pytest.raises(ValueError, match=r"refuses relabelled goals .* reads \['goal_offset'\]"):
        her(make(KEYS, [0, 16]), copy_info_dict=True)
    # SwirlDQN refuses it when it is built, not at its first update
    with pytest.raises(ValueError, match=r"refuses relabelled goals .* reads \['goal_offset'\]"):
        SwirlDQN(
            "MultiInputPolicy",
            make(["observation", "goal_offset"], [10, 11, 12]),
            replay_buffer_class=HerReplayBuffer,
            replay_buffer_kwargs=dict(copy_info_dict=True),
            learning_starts=10**6,
        )
    SwirlDQN(  # a task without the goal: fine
        "MultiInputPolicy",
        make("observation", [0, 1, 2]),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs=dict(copy_info_dict=True),
        buffer_size=1000,
    )


def test_swirl_vec_env_refuses_to_relabel_goals():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from sb3_swirl import SwirlVecEnv

    venv = SwirlVecEnv(
        DummyVecEnv([lambda: gym.make(_ids("Reach"))]), _goal_task([0, 1, 2]), state_key=KEYS[:3]
    )
    with pytest.raises(ValueError, match="SwirlVecEnv cannot relabel goals"):
        venv.env_method("compute_reward", np.zeros(3), np.zeros(3), {}, indices=[0])
    assert venv.env_method("get_wrapper_attr", "step_size") == [0.02]


def test_swirl_dqn_with_her_prefills_demos_that_relabel_as_its_own_steps():
    """SwirlDQN's demo transitions carry the infos HER's relabelling reads: for the episode's
    own goal the recomputed reward is the stored one, for a reached goal it gains the weight."""
    keys = KEYS[:3]
    demos = collect_demos(_ids("Push"), 3, seed=0, state_key=keys)
    weight = 10.0
    env = SwirlWrapper(
        gym.make(_ids("Push")),
        fit_task(demos, dims=[6, 7, 8], indicator="velocity", random_state=0),
        state_key=keys,
        reward_config={"mode": "potential", "task_reward_weight": weight},
    )
    model = SwirlDQN(
        "MultiInputPolicy",
        env,
        demonstrations=demos,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs=dict(copy_info_dict=True),
        prefill_replay=True,
        learning_starts=0,
        bc_epochs=5,
        seed=0,
    )
    model.pretrain()
    buffer, n = model.replay_buffer, sum(len(d) for d in demos)
    assert buffer.pos == n and buffer.ep_length[:n, 0].tolist() == [
        len(d) for d in demos for _ in range(len(d))
    ]
    rows = np.arange(n)
    infos = list(buffer.infos[rows, 0])
    achieved = buffer.next_observations["achieved_goal"][rows, 0]
    own = env.compute_reward(achieved, buffer.next_observations["desired_goal"][rows, 0], infos)
    np.testing.assert_allclose(own, buffer.rewards[rows, 0], rtol=1e-6, atol=1e-5)
    reached = env.compute_reward(achieved, achieved, infos)
    missed = np.array([info["task_reward"] for info in infos]) < 0
    assert missed.sum() == n - len(demos)  # every demo reaches the goal on its last step
    np.testing.assert_allclose(reached[missed], own[missed] + weight, rtol=1e-6, atol=1e-4)
    model.learn(200)  # HER samples demo episodes and relabels them


def test_dict_n_step_buffer_samples_as_sb3s_n_step_buffer():
    box = gym.spaces.Box(-10.0, 10.0, (2,), dtype=np.float32)
    spaces = {"box": box, "dict": gym.spaces.Dict({"observation": box})}
    action_space = gym.spaces.Discrete(3)
    buffers = {
        "box": NStepReplayBuffer(50, box, action_space, n_steps=4, gamma=0.9),
        "dict": DictNStepReplayBuffer(50, spaces["dict"], action_space, n_steps=4, gamma=0.9),
    }
    rng = np.random.default_rng(0)
    for t in range(40):
        obs, next_obs = rng.normal(size=(2, 1, 2)).astype(np.float32)
        done, cut = t % 7 == 6, t % 11 == 10
        for name, buffer in buffers.items():
            wrap = (lambda x: {"observation": x}) if name == "dict" else (lambda x: x)
            buffer.add(
                wrap(obs),
                wrap(next_obs),
                np.array([[t % 3]]),
                np.array([float(t)]),
                np.array([done]),
                [{"TimeLimit.truncated": cut}],
            )
    batch = np.arange(40)
    set_random_seed(0)  # both buffers draw the env column from numpy's global generator
    box_samples = buffers["box"]._get_samples(batch)
    set_random_seed(0)  # both buffers draw the env column from numpy's global generator
    dict_samples = buffers["dict"]._get_samples(batch)
    for field in ("actions", "dones", "rewards", "discounts"):
        np.testing.assert_allclose(getattr(dict_samples, field), getattr(box_samples, field))
    for field in ("observations", "next_observations"):
        np.testing.assert_array_equal(
            getattr(dict_samples, field)["observation"], getattr(box_samples, field)
        )


# ------------------------------------------------------------------ SwirlDQN on Dict obs
def test_swirl_dqn_needs_every_key_in_the_task_state():
    demos = collect_demos(_ids("Reach"), 2, seed=0, state_key="observation")
    env = SwirlWrapper(gym.make(_ids("Reach")), _goal_task([0, 1, 2]), state_key="observation")
    with pytest.raises(ValueError, match=r"leaves out \['achieved_goal', 'desired_goal'\]"):
        SwirlDQN("MultiInputPolicy", env, demonstrations=demos)


def test_swirl_dqn_clones_and_prefills_dict_demos_and_saves_them(tmp_path):
    demos = collect_demos(_ids("Reach"), 3, seed=0, state_key=KEYS, goal_offset=True)
    env = SwirlWrapper(
        gym.make(_ids("Reach"), goal_offset=True), _goal_task([16, 17, 18]), state_key=KEYS
    )
    model = SwirlDQN(
        "MultiInputPolicy", env, demonstrations=demos, n_steps=5, prefill_replay=True, seed=0
    )
    assert isinstance(model.replay_buffer, DictNStepReplayBuffer)
    info = model.pretrain()
    assert info["n_pairs"] == sum(len(d) for d in demos) and info["accuracy"] > 0.5
    stored = model.replay_buffer.observations
    assert model.replay_buffer.pos == -(-info["n_pairs"] // model.n_envs)
    np.testing.assert_array_equal(stored["goal_offset"][0, 0], demos[0].observations[0, -3:])
    assert set(stored) == {*KEYS, "segment"}
    model.save(tmp_path / "model")
    with warnings.catch_warnings():  # not SB3's "n_steps is ignored": the buffer carries it
        warnings.filterwarnings("error", message="`n_steps=")
        loaded = SwirlDQN.load(tmp_path / "model", env=env)
    assert loaded.replay_buffer.n_steps == 5
    obs, _ = env.reset(seed=0)
    assert loaded.predict(obs, deterministic=True)[0] == model.predict(obs, deterministic=True)[0]


def test_state_only_demos_on_dict_observations_are_refused_when_the_model_is_built():
    demos = collect_demos(_ids("Reach"), 2, seed=0, state_key=KEYS, goal_offset=True)
    env = SwirlWrapper(
        gym.make(_ids("Reach"), goal_offset=True), _goal_task([16, 17, 18]), state_key=KEYS
    )
    states = [demos[0], demos[1].observations]  # the second without actions
    with pytest.raises(ValueError, match=r"demonstrations \[1\] have no actions.*flat Box"):
        SwirlDQN("MultiInputPolicy", env, demonstrations=states)  # was: inside learn()
    model = SwirlDQN("MultiInputPolicy", env, demonstrations=states, infer_actions="none")
    assert model.pretrain()["n_pairs"] == len(demos[0])
    # demos recorded under other keys: the message breaks the env's state down by key
    fewer = collect_demos(_ids("Reach"), 2, seed=0, state_key=KEYS[:2], goal_offset=True)
    with pytest.raises(ValueError, match=r"joins the keys \['observation', 'achieved_goal'\], in"):
        SwirlDQN("MultiInputPolicy", env, demonstrations=fewer)
    unrecorded = [Demonstration(d.observations, d.actions) for d in fewer]  # plain arrays
    with pytest.raises(ValueError, match=r"have 13 dims.* have 19 \(observation 10 \+ "):
        SwirlDQN("MultiInputPolicy", env, demonstrations=unrecorded)


def test_demos_and_tasks_recorded_under_another_key_order_are_caught():
    """The two goals have one width: swapped, they pass every width check."""
    swapped = ["observation", "desired_goal", "achieved_goal", "goal_offset"]
    demos = collect_demos(_ids("Reach"), 2, seed=0, state_key=swapped, goal_offset=True)
    assert demos[0].state_key == tuple(swapped)
    env = SwirlWrapper(
        gym.make(_ids("Reach"), goal_offset=True), _goal_task([16, 17, 18]), state_key=KEYS
    )
    with pytest.raises(
        ValueError, match=r"demo 0 joins the keys \['observation', 'desired.*the env's\)"
    ):
        SwirlDQN("MultiInputPolicy", env, demonstrations=demos)
    task = fit_task(demos, dims=[16, 17, 18], indicator="gmm", random_state=0)
    assert task.metadata["state_key"] == swapped
    with pytest.warns(UserWarning, match="fitted on states that join the keys"):
        SwirlWrapper(gym.make(_ids("Reach"), goal_offset=True), task, state_key=KEYS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the demos' own order: no warning
        SwirlWrapper(gym.make(_ids("Reach"), goal_offset=True), task, state_key=swapped)


def test_dict_demos_are_joined_in_the_wrappers_key_order():
    demos = collect_demos(_ids("Reach"), 2, seed=0, state_key=KEYS, goal_offset=True)
    env = SwirlWrapper(
        gym.make(_ids("Reach"), goal_offset=True), _goal_task([16, 17, 18]), state_key=KEYS
    )
    widths = {"observation": 10, "achieved_goal": 3, "desired_goal": 3, "goal_offset": 3}
    bounds = np.cumsum([0, *widths.values()])
    as_dicts = [  # as Minari would store them: per key, in no particular order
        {
            "observations": {
                key: d.observations[:, a:b]
                for key, a, b in reversed(list(zip(widths, bounds[:-1], bounds[1:], strict=True)))
            },
            "actions": d.actions,
        }
        for d in demos
    ]
    model = SwirlDQN("MultiInputPolicy", env, demonstrations=as_dicts, seed=0)
    for joined, demo in zip(model.demonstrations, demos, strict=True):
        np.testing.assert_array_equal(joined.observations, demo.observations)
        assert joined.state_key == tuple(KEYS)
    task = fit_task(as_dicts, state_key=KEYS, dims=[16, 17, 18], indicator="gmm", random_state=0)
    assert task.metadata["state_key"] == KEYS
    # one dict a step, as env.step returns them
    per_step = [
        {
            "observations": [{k: v[t] for k, v in d["observations"].items()} for t in range(n)],
            "actions": d["actions"],
        }
        for d, n in ((d, len(d["actions"]) + 1) for d in as_dicts)
    ]
    for joined, demo in zip(as_demonstrations(per_step, state_key=KEYS), demos, strict=True):
        np.testing.assert_array_equal(joined.observations, demo.observations)


def test_keys_extractor_reads_only_its_keys_and_saves(tmp_path):
    """The network reads the offsets and the segment, not the absolute goals, which the env
    keeps for compute_reward and the supervisor."""
    demos = collect_demos(_ids("Reach"), 2, seed=0, state_key=KEYS, goal_offset=True)
    env = SwirlWrapper(
        gym.make(_ids("Reach"), goal_offset=True), _goal_task([16, 17, 18]), state_key=KEYS
    )
    kwargs = {"features_extractor_class": KeysExtractor}
    kwargs["features_extractor_kwargs"] = {"keys": ["observation", "goal_offset"]}
    model = SwirlDQN("MultiInputPolicy", env, demonstrations=demos, policy_kwargs=kwargs, seed=0)
    model.pretrain()
    assert model.q_net.features_extractor.keys == ["goal_offset", "observation", "segment"]
    obs, _ = env.reset(seed=0)
    q = model.q_net(model.policy.obs_to_tensor(obs)[0])
    moved = {
        **obs,
        "desired_goal": obs["desired_goal"] + 1,
        "achieved_goal": obs["achieved_goal"] * 0,
    }
    assert th.equal(model.q_net(model.policy.obs_to_tensor(moved)[0]), q)
    shifted = {**obs, "goal_offset": obs["goal_offset"] + 0.1}
    assert not th.equal(model.q_net(model.policy.obs_to_tensor(shifted)[0]), q)
    model.save(tmp_path / "model")
    loaded = SwirlDQN.load(tmp_path / "model", env=env)
    assert th.equal(loaded.q_net(loaded.policy.obs_to_tensor(obs)[0]), q)
    with pytest.raises(ValueError, match=r"\['goal'\] not among the observation's keys"):
        KeysExtractor(env.observation_space, keys=["goal"])
    with pytest.raises(TypeError, match="Dict observation"):
        KeysExtractor(gym.spaces.Box(0, 1, (2,)), keys=["observation"])


def test_swirl_dqn_learns_fetch_reach_within_a_small_budget():
    """10 demos, 2000 env steps: the preset's SwirlDQN succeeds on 8 or more of the 10 final
    evaluation episodes (it reads 10; measured once, its BC start alone reached 5 of 10 at best,
    and the same agent with neither BC nor updates 2)."""
    preset = dataclasses.replace(PRESETS["fetchreach"], eval_freq=1_000, n_eval_episodes=10)
    demos = collect_demos(
        preset.env_id, 10, seed=0, state_key=preset.state_key, **preset.demo_env_kwargs
    )
    result = run_method("swirl", preset, demos, seed=0, total_timesteps=2_000)
    assert result["final_success"] >= 0.8
    assert result["n_segments"] == fit_task(demos, random_state=0, **preset.fit_kwargs).n_segments


def test_comparison_methods_run_on_fetch():
    preset = dataclasses.replace(PRESETS["fetchreach"], eval_freq=250, n_eval_episodes=2)
    demos = collect_demos(
        preset.env_id, 3, seed=0, state_key=preset.state_key, **preset.demo_env_kwargs
    )
    her = run_method("dqn_her", preset, [], seed=0, total_timesteps=300)
    assert her["curve"][-1]["timesteps"] >= 300
    with pytest.raises(ValueError, match=r"reads the goal's offset .* swirl_her needs a task"):
        run_method("swirl_her", preset, demos, seed=0, total_timesteps=300)
    push = dataclasses.replace(PRESETS["fetchpush"], eval_freq=300, n_eval_episodes=1)
    pushes = collect_demos(push.env_id, 3, seed=0, state_key=push.state_key, **push.demo_env_kwargs)
    swirl_her = run_method("swirl_her", push, pushes, seed=0, total_timesteps=300)
    assert swirl_her["curve"][-1]["timesteps"] >= 300 and swirl_her["n_segments"] >= 1
    # the one-segment methods keep the entry's state_key (a Dict observation)
    for method in ("qinit", "global_irl"):
        result = run_method(method, push, pushes, seed=0, total_timesteps=300)
        assert result["curve"][-1]["timesteps"] >= 300, method
    bc = run_method("bc_rbf_svm", preset, demos, seed=0, total_timesteps=300)
    assert bc["curve"][-1]["timesteps"] == 0 and 0.0 <= bc["final_success"] <= 1.0


def test_zoo_names_a_state_key_that_leaves_keys_out_before_training(tmp_path, monkeypatch, capsys):
    from sb3_swirl import zoo

    monkeypatch.chdir(tmp_path)
    spec = {"demos": {"n_demos": 2, "seed": 0}, "state_key": "observation"}
    entry = {
        "n_timesteps": 100,
        "policy": "MultiInputPolicy",
        "env_wrapper": [{"sb3_swirl.zoo.SwirlTaskWrapper": spec | {"fit": {"indicator": "gmm"}}}],
    }
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({_ids("Reach"): entry}))
    args = ["train", "--algo", "swirl_dqn", "--env", _ids("Reach"), "-conf", "mine.yml"]
    assert zoo.main([*args, "-f", "logs"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "mine.yml, entry 'sb3_swirl/FetchReachDiscrete-v0': SwirlDQN clones" in err
    assert "leaves out ['achieved_goal', 'desired_goal']" in err
    assert not (tmp_path / "logs").exists()  # nothing started


def test_zoo_trains_and_enjoys_swirl_dqn_on_fetch_reach(tmp_path, zoo_cli):
    """The entry's env_kwargs (goal_offset) reach the zoo's evaluation env and `enjoy` too
    (rl_zoo3 gives them to the training env only), and VecNormalize's statistics are saved."""

    common = ["--env", "sb3_swirl/FetchReachDiscrete-v0", "-f", "logs", "--seed", "0"]
    zoo_cli("train", "--algo", "swirl_dqn", "-n", "600", "--eval-freq", "300", *common)
    params = tmp_path / "logs/swirl_dqn/sb3_swirl-FetchReachDiscrete-v0_1"
    params = params / "sb3_swirl-FetchReachDiscrete-v0"
    args = yaml.load((params / "args.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert args["env_kwargs"] == {"goal_offset": True}
    assert (params / "vecnormalize.pkl").is_file()
    assert "true return" in zoo_cli(
        "enjoy", "--algo", "swirl_dqn", "-n", "60", "--no-render", *common
    )
