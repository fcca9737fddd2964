"""SwirlWrapper, SwirlVectorWrapper and SwirlVecEnv: exact values, checkers, equivalence."""

from __future__ import annotations

import dataclasses
import pickle
import subprocess
import sys
import warnings
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack, VecNormalize

from sb3_swirl.vec_env import SwirlVecEnv
from swirl_wrappers import (
    QuadraticReward,
    Region,
    RewardConfig,
    SegmentTracker,
    SwirlVectorWrapper,
    SwirlWrapper,
    TaskModel,
)


class PointEnv(gym.Env):
    """A point moved by ``step_size`` along one axis per action; the observation is its position.

    Action 0 stays, action ``2 j + 1`` / ``2 j + 2`` moves along axis ``j`` up / down. The env's
    own reward is the first coordinate (so ``task_reward`` is checkable); the episode terminates
    when that coordinate leaves ``[-limit, limit]`` and is truncated after ``max_steps``.
    """

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(
        self,
        dim: int = 1,
        step_size: float = 0.5,
        jitter: float = 0.0,
        limit: float = 10.0,
        max_steps: int = 50,
        as_dict: bool = False,
    ) -> None:
        self.dim, self.step_size, self.jitter = dim, step_size, jitter
        self.limit, self.max_steps, self.as_dict = limit, max_steps, as_dict
        box = spaces.Box(-20.0, 20.0, (dim,), dtype=np.float32)
        if as_dict:
            self.observation_space = spaces.Dict(
                {"observation": box, "goal": spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)}
            )
        else:
            self.observation_space = box
        self.action_space = spaces.Discrete(2 * dim + 1)
        self.pos = np.zeros(dim, dtype=np.float32)
        self.steps = 0

    def _obs(self):
        if self.as_dict:
            return {"observation": self.pos.copy(), "goal": np.full(2, 0.5, dtype=np.float32)}
        return self.pos.copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        start = self.np_random.uniform(-self.jitter, self.jitter, self.dim)
        self.pos = start.astype(np.float32)
        if options and "start" in options:
            self.pos = np.asarray(options["start"], dtype=np.float32)
        self.steps = 0
        return self._obs(), {"from_env": True}

    def step(self, action):
        action = int(action)
        if action:
            axis, sign = (action - 1) // 2, 1.0 if action % 2 else -1.0
            self.pos[axis] += sign * self.step_size
        self.steps += 1
        terminated = bool(abs(self.pos[0]) > self.limit)
        truncated = self.steps >= self.max_steps
        return self._obs(), float(self.pos[0]), terminated, truncated, {"is_success": False}


UP, DOWN, STAY = 1, 2, 0


def line_task(scale_cov: float = 0.01) -> TaskModel:
    """Two regions on a line, at x = 1 and x = 2 (radius 0.3); rewards pull to them (Psi = 2)."""
    regions = [Region([c], [[scale_cov]], 9.0) for c in (1.0, 2.0)]
    rewards = [QuadraticReward([c], [[2.0]]) for c in (1.0, 2.0)]
    return TaskModel(regions, rewards)


def plane_task(timed: bool = False) -> TaskModel:
    """A 2-D task on a 2-D point env: two regions reachable by a random walk in a few steps.

    ``timed``: the regions only count from step 2 to step 6 of an episode.
    """
    bounds = (2, 6) if timed else None
    regions = [
        Region([0.5, 0.0], np.eye(2) * 0.1, 2.0, time_bounds=bounds),
        Region([1.0, 0.5], [[0.2, 0.05], [0.05, 0.1]], 2.0, time_bounds=bounds),
        Region([0.0, 1.0], np.eye(2) * 0.2, 2.0, time_bounds=bounds),
    ]
    rewards = [QuadraticReward(r.mean, [[1.0, 0.2], [0.2, 0.5]]) for r in regions]
    return TaskModel(regions, rewards)


# ----------------------------------------------------------------------- exact single-env values
def test_rewards_indices_bonus_and_info_on_a_line():
    env = SwirlWrapper(PointEnv(), line_task(), {"scale": 3.0, "region_bonus": 10.0})
    obs, info = env.reset(seed=0)
    assert info == {"from_env": True, "segment": 0}
    np.testing.assert_array_equal(obs, [0.0, 1.0, 0.0, 0.0])
    assert obs.dtype == np.float32
    # (action, position after it, index used for the reward, index after, bonus?)
    plan = [
        (UP, 0.5, 0, 0, False),
        (UP, 1.0, 0, 1, True),  # enters region 0: reward R_0(s') plus the bonus, then advance
        (UP, 1.5, 1, 1, False),
        (DOWN, 1.0, 1, 1, False),  # back in region 0: no second bonus
        (UP, 1.5, 1, 1, False),
        (UP, 2.0, 1, 2, True),  # the last region: index k = 2
        (UP, 2.5, 1, 2, False),  # after completion the last segment's reward stays
    ]
    for action, x, used, after, bonus in plan:
        obs, reward, terminated, truncated, info = env.step(action)
        target = (1.0, 2.0)[used]
        want = 3.0 * -2.0 * (x - target) ** 2 + (10.0 if bonus else 0.0)
        assert reward == pytest.approx(want, abs=1e-12)
        assert info["segment"] == after == env.segment
        assert info["segment_reward"] == reward
        assert info["task_reward"] == x  # the env's own reward passes through in info
        assert info["is_success"] is False
        np.testing.assert_array_equal(obs, np.r_[x, np.eye(3)[after]].astype(np.float32))
        assert not terminated and not truncated


class _SegmentInfoEnv(PointEnv):
    """An env of its own that reports a ``segment`` in its step infos."""

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "segment": "the env's own"}


@pytest.mark.parametrize("kind", ["wrapper", "vector", "sb3"])
def test_an_env_info_key_the_wrapper_writes_is_warned_of_once(kind):
    """The env's own info["segment"] is overwritten by the wrapper's: said once, not silently;
    an env without such keys gets no warning."""

    def run(make_env):
        if kind == "wrapper":
            env = SwirlWrapper(make_env(), line_task())
            env.reset(seed=0)
            return [env.step(UP)[4]["segment"] for _ in range(3)]
        if kind == "vector":
            env = SwirlVectorWrapper(SyncVectorEnv([make_env] * 2), line_task())
            env.reset(seed=0)
            return [env.step(np.full(2, UP))[4]["segment"][0] for _ in range(3)]
        env = SwirlVecEnv(DummyVecEnv([make_env] * 2), line_task())
        env.reset()
        return [env.step(np.full(2, UP))[3][0]["segment"] for _ in range(3)]

    with pytest.warns(UserWarning, match=r"holds \['segment'\], which Swirl\w+ writes") as caught:
        segments = run(_SegmentInfoEnv)
    assert len([w for w in caught if "holds ['segment']" in str(w.message)]) == 1
    assert segments == [0, 1, 1]  # the wrapper's index
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run(PointEnv)


def test_regions_must_be_reached_in_order():
    env = SwirlWrapper(PointEnv(), line_task())
    env.reset(options={"start": [2.0]})  # starts in region 1, which is not next
    assert env.segment == 0
    indices = [env.step(a)[4]["segment"] for a in (STAY, DOWN, DOWN, UP, UP)]
    # x: 2.0, 1.5, 1.0 (region 0 -> 1), 1.5, 2.0 (region 1 -> 2)
    assert indices == [0, 0, 1, 1, 2]


def test_initial_state_inside_region_zero_advances_on_reset():
    env = SwirlWrapper(PointEnv(), line_task(), {"region_bonus": 5.0})
    obs, info = env.reset(options={"start": [1.1]})
    assert info["segment"] == 1 and env.segment == 1
    np.testing.assert_array_equal(obs[1:], [0.0, 1.0, 0.0])
    # The reset is not a transition: no reward, and the next step earns no bonus either.
    _, reward, *_ = env.step(STAY)
    assert reward == pytest.approx(-2.0 * (1.1 - 2.0) ** 2, rel=1e-6)


def test_terminate_on_completion():
    env = SwirlWrapper(PointEnv(), line_task(), terminate_on_completion=True)
    env.reset()
    flags = [env.step(UP)[2] for _ in range(4)]  # x = 0.5, 1.0, 1.5, 2.0
    assert flags == [False, False, False, True]
    plain = SwirlWrapper(PointEnv(), line_task())
    plain.reset()
    assert not any(plain.step(UP)[2] for _ in range(4))


def test_terminate_on_completion_when_complete_at_reset():
    task = TaskModel([Region([0.0], [[0.01]], 9.0)], [QuadraticReward([0.0], [[1.0]])])
    env = SwirlWrapper(PointEnv(), task, terminate_on_completion=True)
    assert env.reset()[1]["segment"] == task.n_segments  # the start is inside the only region
    assert env.step(STAY)[2]


def test_env_termination_and_truncation_pass_through():
    env = SwirlWrapper(PointEnv(limit=0.9, max_steps=3), line_task())
    env.reset()
    assert env.step(UP)[2:4] == (False, False)
    assert env.step(UP)[2:4] == (True, False)
    env.reset()
    for _ in range(2):
        env.step(STAY)
    assert env.step(STAY)[2:4] == (False, True)


def test_counter_resets_with_the_episode():
    task = TaskModel(
        [Region([0.0], [[1.0]], 1.0, time_bounds=(2, 3))], [QuadraticReward([0.0], [[1.0]])]
    )
    env = SwirlWrapper(PointEnv(), task)
    for _ in range(2):
        env.reset()
        assert [env.step(STAY)[4]["segment"] for _ in range(3)] == [0, 1, 1]


def test_wrapper_follows_segment_indices_of_the_trajectory():
    task = plane_task()
    env = SwirlWrapper(PointEnv(dim=2, step_size=0.25, jitter=0.1), task)
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=3)
    states, segments = [obs[:2]], [info["segment"]]
    for _ in range(40):
        obs, *_, info = env.step(int(rng.integers(5)))
        states.append(obs[:2])
        segments.append(info["segment"])
    assert segments[-1] > 0
    np.testing.assert_array_equal(segments, task.segment_indices(np.array(states)))


def test_dict_observations_get_a_segment_key():
    env = SwirlWrapper(PointEnv(as_dict=True), line_task(), {"region_bonus": 1.0})
    assert set(env.observation_space.spaces) == {"observation", "goal", "segment"}
    assert env.observation_space["segment"] == spaces.Box(0.0, 1.0, (3,), dtype=np.float32)
    obs, _ = env.reset()
    np.testing.assert_array_equal(obs["segment"], [1.0, 0.0, 0.0])
    env.step(UP)
    obs, reward, *_, info = env.step(UP)
    np.testing.assert_array_equal(obs["segment"], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(obs["goal"], [0.5, 0.5])
    assert reward == 1.0 and info["segment"] == 1
    obs["segment"][:] = 7.0  # the returned one-hot is the caller's to keep
    assert env.step(STAY)[0]["segment"].tolist() == [0.0, 1.0, 0.0]


def test_dict_state_key_picks_the_state():
    env = PointEnv(as_dict=True)
    task = TaskModel([Region([0.5], [[0.01]], 1.0)], [QuadraticReward([0.5], [[1.0]])], dims=[1])
    wrapped = SwirlWrapper(env, task, state_key="goal")
    wrapped.reset()
    assert wrapped.segment == 1  # goal is (0.5, 0.5): dims=[1] of it is in the region


def test_several_state_keys_are_read_joined_in_order():
    env = PointEnv(as_dict=True)
    # dims 1 and 2: the goal's two coordinates after the position (observation, goal)
    task = TaskModel(
        [Region([0.5, 0.5], np.eye(2) * 0.01, 1.0)],
        [QuadraticReward([0.5, 0.5], np.eye(2))],
        dims=[1, 2],
    )
    wrapped = SwirlWrapper(env, task, state_key=["observation", "goal"])
    assert wrapped.state_key == ("observation", "goal")
    obs, _ = wrapped.reset()
    assert wrapped.segment == 1
    np.testing.assert_array_equal(
        wrapped.lifter.state(obs), np.concatenate([obs["observation"], obs["goal"]])
    )
    with pytest.raises(ValueError, match=r"state_key names \['goal'\] more than once"):
        SwirlWrapper(env, task, state_key=["goal", "goal"])
    with pytest.raises(ValueError, match="state_key must be a key or a list of keys"):
        SwirlWrapper(env, task, state_key=[])
    # without state_key the task reads "observation"; where that does not fit a task whose
    # demos joined other keys, the error names them
    recorded = TaskModel(
        task.regions, task.rewards, dims=[1, 2], metadata={"state_key": ["observation", "goal"]}
    )
    with pytest.raises(ValueError, match=r"pass state_key=\['observation', 'goal'\]"):
        SwirlWrapper(env, recorded)
    assert SwirlWrapper(env, recorded, state_key=["observation", "goal"]).state_key == (
        "observation",
        "goal",
    )


# ----------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: SwirlWrapper(gym.make("FrozenLake-v1"), line_task()),
            "Box or Dict .*FlattenObservation",
        ),
        (lambda: SwirlWrapper(PointEnv(dim=2), line_task()), "task expects 1"),
        (
            lambda: SwirlWrapper(
                PointEnv(),
                TaskModel(
                    [Region([0.0], [[1.0]], 1.0)], [QuadraticReward([0.0], [[1.0]])], dims=[3]
                ),
            ),
            "uses index 3",
        ),
        (lambda: SwirlWrapper(PointEnv(), line_task(), state_key="observation"), "only for Dict"),
        (lambda: SwirlWrapper(PointEnv(as_dict=True), line_task(), state_key="x"), "not in the"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"scale": np.nan}), "reward scale"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"region_bonus": "1"}), "finite number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"scale": True}), "finite number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"scale": np.ones(1)}), "finite number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"scale": -1.0}), r"scale .* >= 0"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), {"reward_scale": 2}), "unknown key"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), "potential"), "RewardConfig or a dict"),
        (
            lambda: SwirlWrapper(PointEnv(), line_task(), terminate_on_completion="no"),
            "terminate_on_completion must be True or False",
        ),
        (lambda: SwirlWrapper(PointEnv(), "task.json"), "TaskModel"),
    ],
)
def test_invalid_construction(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_invalid_observation_spaces():
    task = line_task()
    with pytest.raises(ValueError, match=r"is an image.*low-dimensional state"):
        SwirlWrapper(_ImageEnv(), task)
    with pytest.raises(ValueError, match=r"1-D Box.*FlattenObservation"):
        SwirlWrapper(_ImageEnv(space=spaces.Box(-1.0, 1.0, (2, 2))), task)
    with pytest.raises(ValueError, match="Box view of its integers"):
        SwirlWrapper(_ImageEnv(space=spaces.MultiDiscrete([4, 4])), task)
    with pytest.raises(ValueError, match=r"FlattenObservation.*one-hot"):
        SwirlWrapper(_ImageEnv(space=spaces.Discrete(4)), task)
    no_obs_key = _ImageEnv(dict_keys=("state",))
    with pytest.raises(ValueError, match="no 'observation' key"):
        SwirlWrapper(no_obs_key, task)
    with pytest.raises(ValueError, match="already has a 'segment'"):
        SwirlWrapper(_ImageEnv(dict_keys=("observation", "segment")), task)


class _ImageEnv(gym.Env):
    def __init__(self, dict_keys=(), space=None):
        box = spaces.Box(0, 255, (4, 4), dtype=np.uint8) if space is None else space
        self.observation_space = (
            spaces.Dict({k: spaces.Box(-1.0, 1.0, (1,)) for k in dict_keys}) if dict_keys else box
        )
        self.action_space = spaces.Discrete(2)


class _FlatGoalEnv(PointEnv):
    """A goal env (it has ``compute_reward``) whose observations were flattened to a Box."""

    def compute_reward(self, achieved_goal, desired_goal, info):
        return -np.linalg.norm(np.subtract(achieved_goal, desired_goal), axis=-1)


def test_a_goal_env_flattened_to_a_box_is_a_plain_env():
    env = SwirlWrapper(_FlatGoalEnv(), line_task())
    env.reset(seed=0)
    obs, *_, info = env.step(1)
    assert obs.shape == env.observation_space.shape and "segment_goal" not in info
    with pytest.raises(AttributeError, match="not a goal env here"):
        env.compute_reward(np.zeros(1), np.zeros(1), info)


# ----------------------------------------------------------------------- checkers, pickling
def _acrobot_task() -> TaskModel:
    # cos/sin of the two angles: hanging down, then the first link horizontal.
    regions = [Region([1.0, 0.0], np.eye(2) * 0.01, 9.0), Region([0.0, 1.0], np.eye(2) * 0.05, 9.0)]
    rewards = [QuadraticReward(r.mean, np.eye(2)) for r in regions]
    return TaskModel(regions, rewards, dims=(0, 1))


def _cartpole_task() -> TaskModel:
    regions = [Region([0.0, 0.0], np.eye(2) * 0.05**2, 1.0), Region([1.0, 0.0], np.eye(2), 1.0)]
    rewards = [QuadraticReward(r.mean, np.eye(2)) for r in regions]
    return TaskModel(regions, rewards, dims=(0, 2))


@pytest.mark.parametrize(
    "make",
    [
        lambda: SwirlWrapper(gym.make("Acrobot-v1"), _acrobot_task(), {"region_bonus": 1.0}),
        lambda: SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), {"scale": 0.1}),
        lambda: SwirlWrapper(PointEnv(as_dict=True, jitter=0.5), line_task()),
    ],
    ids=["acrobot", "cartpole", "point-dict"],
)
def test_env_checkers_pass(make):
    with warnings.catch_warnings():
        # gymnasium recommends checking the unwrapped env; checking the wrapper is the point here.
        warnings.filterwarnings("error", message=".*WARN.*")
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        warnings.filterwarnings("ignore", message=".*infinity")  # CartPole's own unbounded Box
        gym_check_env(make(), skip_render_check=True)
    sb3_check_env(make(), warn=False)


def test_pickle_round_trip_continues_identically():
    env = SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), {"region_bonus": 2.0})
    env.reset(seed=1)
    for _ in range(3):
        env.step(1)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.segment == env.segment and clone.task.to_dict() == env.task.to_dict()
    for action in (0, 0, 1, 0):
        a, b = env.step(action), clone.step(action)
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4] and a[4]["segment"] == b[4]["segment"]


def test_recreatable_from_spec():
    config = RewardConfig(scale=0.5)
    env = SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), config)
    spec = env.spec
    assert spec.additional_wrappers[-1].kwargs["reward_config"] == config.to_dict()
    for again in (gym.make(spec), gym.make(EnvSpec.from_json(spec.to_json()))):  # also as JSON
        assert isinstance(again, SwirlWrapper) and again.reward_config == config
        assert again.task.to_dict() == env.task.to_dict()
        again.reset(seed=0), env.reset(seed=0)
        for action in (0, 1, 1, 0):
            a, b = again.step(action), env.step(action)
            np.testing.assert_array_equal(a[0], b[0])
            assert a[1:4] == b[1:4]
    with pytest.raises(ValueError, match="task must be a TaskModel"):
        SwirlWrapper(gym.make("CartPole-v1"), "task.json")


def test_sb3_dummy_and_subproc_vec_envs():
    task = _cartpole_task()
    kwargs = {"task": task, "reward_config": {"region_bonus": 1.0}}
    for cls in (DummyVecEnv, SubprocVecEnv):
        venv = make_vec_env(
            "CartPole-v1",
            n_envs=2,
            seed=0,
            wrapper_class=SwirlWrapper,
            wrapper_kwargs=kwargs,
            vec_env_cls=cls,
        )
        try:
            obs = venv.reset()
            assert obs.shape == (2, 7)
            assert venv.get_attr("segment") == [int(np.argmax(o[4:])) for o in obs]
            for _ in range(3):
                obs, rewards, _, infos = venv.step(np.array([0, 1]))
                for o, r, info in zip(obs, rewards, infos, strict=True):
                    assert info["task_reward"] == 1.0
                    assert r == pytest.approx(info["segment_reward"], rel=1e-6)
                    assert o[4 + info["segment"]] == 1.0 and o[4:].sum() == 1.0
        finally:
            venv.close()


# ----------------------------------------------------------------------- vector equivalence
N_ENVS = 4


def _make_point(as_dict: bool):
    def make():
        # Short episodes and a wall at |x| = 1 give both truncations and terminations.
        return PointEnv(dim=2, step_size=0.25, jitter=0.2, limit=1.0, max_steps=9, as_dict=as_dict)

    return make


SWIRL_KWARGS = {"reward_config": RewardConfig(scale=2.0, region_bonus=3.0)}


def _actions(steps: int) -> np.ndarray:
    return np.random.default_rng(42).integers(0, 5, size=(steps, N_ENVS))


def _assert_obs_equal(a, b):
    if isinstance(a, dict):
        assert set(a) == set(b)
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    else:
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("timed", [False, True], ids=["untimed", "timed"])
@pytest.mark.parametrize("kwargs", ["quadratic", "potential"])
@pytest.mark.parametrize("as_dict", [False, True], ids=["box", "dict"])
def test_swirl_vec_env_matches_independent_wrappers(as_dict, kwargs, timed):
    kwargs = SWIRL_KWARGS if kwargs == "quadratic" else POTENTIAL_KWARGS
    task = plane_task(timed)
    make = _make_point(as_dict)
    reference = DummyVecEnv([lambda: SwirlWrapper(make(), task, **kwargs)] * N_ENVS)
    vectorised = SwirlVecEnv(DummyVecEnv([make] * N_ENVS), task, **kwargs)
    reference.seed(7)
    vectorised.seed(7)
    _assert_obs_equal(vectorised.reset(), reference.reset())
    assert [i["segment"] for i in vectorised.reset_infos] == reference.get_attr("segment")
    n_done, segments = 0, set()
    for actions in _actions(60):
        ref = reference.step(actions)
        got = vectorised.step(actions)
        _assert_obs_equal(got[0], ref[0])
        np.testing.assert_allclose(got[1], ref[1], rtol=1e-6)
        np.testing.assert_array_equal(got[2], ref[2])
        for g, r in zip(got[3], ref[3], strict=True):
            assert g["segment"] == r["segment"] and g["task_reward"] == r["task_reward"]
            assert g["segment_reward"] == pytest.approx(r["segment_reward"], rel=1e-12)
            assert g.get("TimeLimit.truncated") == r.get("TimeLimit.truncated")
            if "terminal_observation" in r:
                _assert_obs_equal(g["terminal_observation"], r["terminal_observation"])
            segments.add(g["segment"])
        n_done += int(np.sum(got[2]))
    # resets and region entries were exercised (fewer entries when regions expire)
    assert n_done >= 10 and segments >= ({0, 1} if timed else {0, 1, 2})


POTENTIAL_KWARGS = {
    "reward_config": RewardConfig(mode="potential", scale=2.0, task_reward_weight=0.5, gamma=0.9)
}


@pytest.mark.parametrize("kwargs", [SWIRL_KWARGS, POTENTIAL_KWARGS], ids=["quadratic", "potential"])
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("as_dict", [False, True], ids=["box", "dict"])
@pytest.mark.parametrize("timed", [False, True], ids=["untimed", "timed"])
def test_swirl_vector_wrapper_matches_independent_wrappers(mode, as_dict, kwargs, timed):
    task = plane_task(timed)
    make = _make_point(as_dict)
    reference = SyncVectorEnv(
        [lambda: SwirlWrapper(make(), task, **kwargs)] * N_ENVS, autoreset_mode=mode
    )
    vectorised = SwirlVectorWrapper(
        SyncVectorEnv([make] * N_ENVS, autoreset_mode=mode), task, **kwargs
    )
    assert vectorised.single_observation_space == reference.single_observation_space
    assert vectorised.observation_space == reference.observation_space
    got_obs, got_info = vectorised.reset(seed=11)
    ref_obs, ref_info = reference.reset(seed=11)
    _assert_obs_equal(got_obs, ref_obs)
    np.testing.assert_array_equal(got_info["segment"], ref_info["segment"])
    n_done = 0
    for actions in _actions(60):
        got = vectorised.step(actions)
        ref = reference.step(actions)
        _assert_obs_equal(got[0], ref[0])
        assert got[0] in vectorised.observation_space
        np.testing.assert_allclose(got[1], ref[1], rtol=1e-12)
        np.testing.assert_array_equal(got[2], ref[2])
        np.testing.assert_array_equal(got[3], ref[3])
        np.testing.assert_array_equal(got[4]["segment"], ref[4]["segment"])
        # the info keys, their masks (reset rows hold a reset's info) and final_info's keys
        for got_info, ref_info in (
            (got[4], ref[4]),
            (got[4].get("final_info"), ref[4].get("final_info")),
        ):
            if ref_info is None:
                continue
            for key in ("segment", "task_reward", "segment_reward"):
                mask = ref_info.get("_" + key, np.zeros(N_ENVS, dtype=bool))
                np.testing.assert_array_equal(got_info["_" + key], mask, err_msg=key)
                if mask.any():
                    np.testing.assert_allclose(got_info[key][mask], ref_info[key][mask], rtol=1e-12)
        if "final_obs" in ref[4]:
            for i in np.flatnonzero(ref[4]["_final_obs"]):
                _assert_obs_equal(got[4]["final_obs"][i], ref[4]["final_obs"][i])
        n_done += int(np.sum(got[2] | got[3]))
    assert n_done >= 10
    vectorised.close()
    reference.close()


def test_swirl_vec_env_needs_a_vec_env():
    with pytest.raises(ValueError, match="wraps an SB3 VecEnv"):
        SwirlVecEnv(PointEnv(), line_task())


@pytest.mark.parametrize(
    "make",
    [
        lambda: SwirlVecEnv(VecNormalize(DummyVecEnv([PointEnv])), line_task()),
        lambda: SwirlVecEnv(VecFrameStack(DummyVecEnv([PointEnv]), 1), line_task()),
        lambda: SwirlWrapper(gym.wrappers.NormalizeObservation(PointEnv()), line_task()),
        lambda: SwirlVectorWrapper(
            gym.wrappers.vector.NormalizeObservation(SyncVectorEnv([PointEnv])), line_task()
        ),
    ],
    ids=["VecNormalize", "VecFrameStack", "NormalizeObservation", "vector NormalizeObservation"],
)
def test_normalised_states_below_the_wrapper_are_refused_with_the_right_order(make):
    """The regions live in raw states: normalisation below the wrapper would silently pick
    the wrong segment."""
    with pytest.raises(ValueError, match=r"must sit below (\w+).*Wrap as \1\(Swirl"):
        make()
    # the right order works
    VecNormalize(SwirlVecEnv(DummyVecEnv([PointEnv]), line_task()))
    gym.wrappers.NormalizeObservation(SwirlWrapper(PointEnv(), line_task()))


def test_sub_envs_that_normalise_their_observations_are_refused():
    """CleanRL's make_env normalises each sub-env: the vector wrapper looks into them."""

    def normalised():
        return gym.wrappers.NormalizeObservation(PointEnv())

    for make, on_top in (
        (
            lambda: SwirlVectorWrapper(SyncVectorEnv([normalised, normalised]), line_task()),
            "vector",
        ),
        (lambda: SwirlVecEnv(DummyVecEnv([normalised, normalised]), line_task()), "VecNormalize"),
    ):
        with pytest.raises(ValueError, match=f"sub-env 0 normalises its observations.*{on_top}"):
            make()


@pytest.mark.parametrize(
    "make, match",
    [
        (
            lambda: SwirlWrapper(gym.wrappers.Autoreset(PointEnv()), line_task()),
            r"must sit below Autoreset.*Wrap as Autoreset\(SwirlWrapper",
        ),
        (
            lambda: SwirlWrapper(SwirlWrapper(PointEnv(), line_task()), line_task()),
            "SwirlWrapper over SwirlWrapper: the env's observations are lifted already",
        ),
        (
            lambda: SwirlVectorWrapper(
                SwirlVectorWrapper(SyncVectorEnv([PointEnv]), line_task()), line_task()
            ),
            "SwirlVectorWrapper over SwirlVectorWrapper: .* lifted already",
        ),
        (
            lambda: SwirlVectorWrapper(
                SyncVectorEnv([lambda: SwirlWrapper(PointEnv(), line_task())]), line_task()
            ),
            "sub-env 0 is wrapped with a SWIRL wrapper already",
        ),
        (
            lambda: SwirlVecEnv(SwirlVecEnv(DummyVecEnv([PointEnv]), line_task()), line_task()),
            "SwirlVecEnv over a vector env that is lifted already",
        ),
        (
            lambda: SwirlVecEnv(
                DummyVecEnv([lambda: SwirlWrapper(PointEnv(), line_task())]), line_task()
            ),
            "SwirlVecEnv over a vector env that is lifted already",
        ),
        (
            lambda: SwirlWrapper(SyncVectorEnv([PointEnv]), line_task()),
            "SwirlWrapper wraps one env, got the vector env SyncVectorEnv: .*SwirlVectorWrapper",
        ),
        (
            lambda: SwirlWrapper(DummyVecEnv([PointEnv]), line_task()),
            "got the vector env DummyVecEnv: .*SwirlVecEnv",
        ),
        (
            lambda: SwirlWrapper(
                gym.wrappers.RecordEpisodeStatistics(PointEnv()),
                line_task(),
                terminate_on_completion=True,
            ),
            r"must sit below RecordEpisodeStatistics.*only the failed ones",
        ),
    ],
    ids=[
        "Autoreset",
        "twice",
        "vector twice",
        "vector over lifted sub-envs",
        "SB3 twice",
        "SB3 over lifted sub-envs",
        "vector env",
        "SB3 vector env",
        "episode statistics",
    ],
)
def test_wrappers_that_would_break_the_tracker_are_refused(make, match):
    """Each of these ran silently: Autoreset below scored a new episode's first state as a
    step of the old one, in its segment; a second wrapper lifted the observations twice;
    RecordEpisodeStatistics below never saw the episodes the wrapper ends."""
    with pytest.raises(ValueError, match=match):
        make()
    # the right orders work
    env = gym.wrappers.Autoreset(SwirlWrapper(PointEnv(max_steps=2), line_task()))
    env.reset(seed=0)
    for _ in range(3):  # the third step resets (gymnasium's Autoreset: the next step)
        env.step(UP)
    assert env.get_wrapper_attr("tracker").t == 0
    gym.wrappers.RecordEpisodeStatistics(
        SwirlWrapper(PointEnv(), line_task(), terminate_on_completion=True)
    )
    SwirlWrapper(gym.wrappers.RecordEpisodeStatistics(PointEnv()), line_task())  # no ending


def test_swirl_vec_env_keeps_the_new_episodes_reset_infos():
    """After an autoreset, reset_infos holds the sub-env's new reset info and segment, as
    make_swirl_env's SB3 VecEnv does; it kept the first reset's."""

    class CountingResets(PointEnv):
        resets = 0

        def reset(self, *, seed=None, options=None):
            obs, info = super().reset(seed=seed, options=options)
            self.resets += 1
            return obs, info | {"resets": self.resets}

    venv = SwirlVecEnv(DummyVecEnv([lambda: CountingResets(max_steps=2)] * 2), line_task())
    venv.reset()
    assert [info["resets"] for info in venv.reset_infos] == [1, 1]
    for _ in range(2):
        venv.step(np.array([UP, UP]))
    assert [info["resets"] for info in venv.reset_infos] == [2, 2]
    assert [info["segment"] for info in venv.reset_infos] == venv.tracker.index.tolist()


def test_vector_infos_are_copies_of_the_trackers_state():
    envs = SwirlVectorWrapper(SyncVectorEnv([PointEnv, PointEnv]), line_task())
    _, infos = envs.reset(seed=0)
    before = envs.tracker.index.copy()
    infos["segment"][:] = 5
    _, rewards, *_, infos = envs.step(np.zeros(2, dtype=int))
    rewards *= 0
    assert envs.tracker.index.tolist() == infos["segment"].tolist()
    assert np.all(envs.tracker.index >= before) and np.all(envs.tracker.index <= 1)
    assert np.any(infos["segment_reward"] != 0)


def test_vector_partial_reset_with_mask():
    envs = SwirlVectorWrapper(
        SyncVectorEnv([PointEnv, PointEnv], autoreset_mode=AutoresetMode.DISABLED), line_task()
    )
    envs.reset(seed=0)
    envs.step(np.array([UP, UP]))
    envs.step(np.array([UP, UP]))
    assert envs.tracker.index.tolist() == [1, 1] and envs.tracker.t.tolist() == [2, 2]
    _, info = envs.reset(options={"reset_mask": np.array([True, False])})
    assert info["segment"].tolist() == [0, 1] and envs.tracker.t.tolist() == [0, 2]
    assert info["_segment"].tolist() == [True, False]  # only the reset row has a reset info


def test_all_wrappers_expose_the_task():
    task = line_task()
    assert SwirlWrapper(PointEnv(), task).task is task
    assert SwirlVecEnv(DummyVecEnv([PointEnv]), task).task is task
    assert SwirlVectorWrapper(SyncVectorEnv([PointEnv]), task).task is task
    assert SegmentTracker(task, num_envs=2).task is task
    config = RewardConfig(region_bonus=1.0)
    # SB3 algorithms read them with get_attr, whichever way the env is wrapped
    for venv in (
        SwirlVecEnv(DummyVecEnv([PointEnv] * 2), task, config),
        DummyVecEnv([lambda: SwirlWrapper(PointEnv(), task, config)] * 2),
    ):
        assert venv.get_attr("task") == [task, task]
        assert venv.get_attr("reward_config") == [config, config]
        assert venv.has_attr("task") and venv.get_attr("terminate_on_completion") == [False] * 2
        assert venv.get_attr("state_key") == [None, None]
        venv.reset()
        for _ in range(2):  # sub-env 0 moves on into the next segment, sub-env 1 stays
            obs, *_ = venv.step(np.array([1, 0]))
        assert venv.get_attr("segment") == [int(np.argmax(o[-task.n_indices :])) for o in obs]
        assert venv.get_attr("segment") == [1, 0]
        assert venv.get_attr("segment", indices=[1]) == [0]


# ----------------------------------------------------------------------- fuzzing
@st.composite
def tasks_on_points(draw):
    obs_dim = draw(st.integers(1, 4))
    p = draw(st.integers(1, obs_dim))
    dims = draw(st.permutations(range(obs_dim)))[:p]
    k = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    regions, rewards = [], []
    for _ in range(k):
        a = rng.normal(size=(p, p)) * draw(st.floats(0.05, 2.0))
        bounds = None
        if draw(st.booleans()):
            lo = draw(st.integers(0, 10))
            bounds = (lo, lo + draw(st.integers(0, 20)))
        regions.append(
            Region(
                rng.uniform(-1.5, 1.5, p), a @ a.T + 1e-3 * np.eye(p), rng.uniform(0.5, 9), bounds
            )
        )
        b = rng.normal(size=(p, draw(st.integers(1, p))))
        rewards.append(QuadraticReward(rng.uniform(-1.5, 1.5, p), b @ b.T))
    task = TaskModel(regions, rewards, dims=dims)
    config = RewardConfig(scale=draw(st.floats(0, 5)), region_bonus=draw(st.floats(0, 10)))
    return obs_dim, task, config, draw(st.booleans()), seed


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tasks_on_points())
def test_fuzz_wrapper_invariants(case):
    obs_dim, task, config, complete_ends, seed = case
    env = SwirlWrapper(
        PointEnv(dim=obs_dim, step_size=0.3, jitter=1.0, limit=3.0, max_steps=25),
        task,
        config,
        terminate_on_completion=complete_ends,
    )
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    for _ in range(60):
        assert obs in env.observation_space
        before = info["segment"]
        assert 0 <= before <= task.n_segments
        obs, reward, terminated, truncated, info = env.step(int(rng.integers(2 * obs_dim + 1)))
        after = info["segment"]
        assert before <= after <= min(before + 1, task.n_segments)
        assert np.isfinite(reward)
        want = config.scale * float(task.reward(obs[:obs_dim], before))
        want += config.region_bonus * (after > before)
        assert reward == pytest.approx(want, rel=1e-9, abs=1e-9)
        assert np.argmax(obs[obs_dim:]) == after
        if complete_ends and after == task.n_segments and after > before:
            assert terminated
        if terminated or truncated:
            obs, info = env.reset()


# ----------------------------------------------------------------------- reward modes
def _phi(task, x, index):
    return index + 1.0 / (1.0 - float(task.reward(np.array([x]), index)))


def test_task_reward_weight_adds_the_env_reward_in_quadratic_mode():
    task = line_task()
    plain = SwirlWrapper(PointEnv(), task, {"scale": 3.0})
    mixed = SwirlWrapper(PointEnv(), task, {"scale": 3.0, "task_reward_weight": 0.25})
    plain.reset(seed=0)
    mixed.reset(seed=0)
    for action in (UP, UP, DOWN, UP, UP):
        _, r_plain, *_ = plain.step(action)
        _, r_mixed, _, _, info = mixed.step(action)
        assert r_mixed == pytest.approx(r_plain + 0.25 * info["task_reward"], abs=1e-12)
    assert mixed.reward_config.task_reward_weight == 0.25
    assert plain.reward_config.task_reward_weight == 0.0


def test_potential_mode_exact_values_and_terminal_potential():
    task = line_task()
    # the env terminates when |x| > 2.2: x = 2.5 after the last region
    potential = RewardConfig(mode="potential", gamma=0.9)
    env = SwirlWrapper(PointEnv(step_size=0.5, limit=2.2), task, potential)
    assert env.reward_config.task_reward_weight == 1.0  # the default in potential mode
    env.reset(seed=0)
    phi = _phi(task, 0.0, 0)
    assert env.potential == pytest.approx(phi)
    # (position after the action, index after, terminated)
    for x, after, done in [(0.5, 0, False), (1.0, 1, False), (1.5, 1, False), (2.0, 2, False)]:
        _, reward, terminated, _, info = env.step(UP)
        new_phi = _phi(task, x, after)
        assert reward == pytest.approx(x + 0.9 * new_phi - phi, abs=1e-12)
        assert info["segment"] == after and terminated is done
        assert after <= new_phi <= after + 1  # segments done plus closeness in (0, 1]
        phi = new_phi
    _, reward, terminated, _, _ = env.step(UP)  # x = 2.5: terminates, the potential drops to 0
    assert terminated and env.potential == 0.0
    assert reward == pytest.approx(2.5 - phi, abs=1e-12)


def test_potential_shaping_telescopes_to_the_task_return():
    """Shaped discounted return = weight * task return - scale * Phi(s_0), whatever the policy."""
    task = plane_task()
    gamma, weight, scale = 0.95, 2.0, 1.5
    rng = np.random.default_rng(3)
    for episode in range(6):
        env = SwirlWrapper(
            PointEnv(dim=2, step_size=0.25, jitter=0.2, limit=1.0, max_steps=500),
            task,
            RewardConfig(mode="potential", scale=scale, task_reward_weight=weight, gamma=gamma),
        )
        env.reset(seed=episode)
        phi0, shaped, true, discount, terminated = env.potential, 0.0, 0.0, 1.0, False
        while not terminated:
            _, reward, terminated, truncated, info = env.step(int(rng.integers(5)))
            assert not truncated
            shaped += discount * reward
            true += discount * info["task_reward"]
            discount *= gamma
        assert shaped == pytest.approx(weight * true - scale * phi0, abs=1e-9)


def test_potential_mode_bootstraps_through_truncation():
    env = SwirlWrapper(PointEnv(max_steps=1), line_task(), {"mode": "potential", "gamma": 1.0})
    env.reset(seed=0)
    phi = env.potential
    _, reward, terminated, truncated, _ = env.step(UP)
    assert truncated and not terminated
    assert env.potential == pytest.approx(_phi(line_task(), 0.5, 0))  # not zeroed
    assert reward == pytest.approx(0.5 + env.potential - phi)


def test_tracker_refuses_batches_of_the_wrong_shape():
    task = plane_task()
    tracker = SegmentTracker(task, num_envs=3)
    good = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"states must have shape \(3, state_dim\)"):
        tracker.reset(np.zeros((1, 2)))
    tracker.reset(good)
    for states in (np.zeros((1, 2)), np.zeros(3)):
        with pytest.raises(ValueError, match=r"states must have shape \(3, state_dim\)"):
            tracker.step(states, 0.0, False)
    with pytest.raises(ValueError, match=r"restart must have shape \(3,\)"):
        tracker.step(good, 0.0, False, restart=np.array([True, False]))
    with pytest.raises(ValueError, match=r"task_rewards must have shape \(3,\)"):
        tracker.step(good, np.zeros(2), False)
    restart = np.array([True, False, True])
    for final in (np.zeros((1, 2)), np.zeros((3, 2)), np.zeros((2, 3)), np.zeros(2)):
        with pytest.raises(ValueError, match="one state per restart row"):
            tracker.step(good, 0.0, False, restart=restart, final_states=final)
    # A refused step changes nothing.
    assert tracker.t.tolist() == [0, 0, 0] and tracker.index.tolist() == [0, 0, 0]
    with pytest.raises(ValueError, match="num_envs"):
        SegmentTracker(task, num_envs=2.7)
    single = SegmentTracker(task)
    with pytest.raises(ValueError, match=r"one state, a numpy array of shape \(d,\)"):
        single.reset(good)
    single.reset(good[0])
    with pytest.raises(ValueError, match="restart and mask"):
        single.step(good[0], 0.0, False, restart=np.array([True]))


def test_one_episode_returns_python_numbers():
    env = SwirlWrapper(PointEnv(), line_task())
    _, info = env.reset(seed=0)
    assert type(info["segment"]) is int
    _, reward, terminated, _, info = env.step(UP)
    assert type(reward) is float and type(terminated) is bool
    assert type(info["segment"]) is int and type(info["segment_reward"]) is float
    assert type(env.segment) is int and type(env.potential) is float


def test_a_task_on_states_of_another_width_than_its_fit_is_warned_about():
    """Demos recorded with ``observation_dims=[6, 7, 8]`` (9 values), the env made without
    them (31): dims 0-2 then read the gripper's position, not the object's offset."""
    fitted = TaskModel(
        [Region([0.0, 0.0], np.eye(2), 4.0)],
        [QuadraticReward([0.0, 0.0], np.eye(2))],
        dims=(0, 1),
        metadata={"state_dim": 6},
    )
    with pytest.warns(UserWarning, match="fitted on states of 6 values and is given states of 4"):
        SwirlWrapper(gym.make("CartPole-v1"), fitted)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for metadata in ({"state_dim": 4}, {}):  # the same width, or not recorded
            SwirlWrapper(gym.make("CartPole-v1"), dataclasses.replace(fitted, metadata=metadata))


def test_demos_far_outside_the_observation_bounds_are_warned_about():
    """MountainCar demos in cm (x100) never enter the regions of a task fitted on them; the
    states the fit recorded tell it against the env's bounds (position -1.2 .. 0.6)."""
    from sb3_swirl import fit_task
    from sb3_swirl.demos import make_piecewise_linear_demos

    demos = make_piecewise_linear_demos(n_demos=4, n_phases=2, dim=2, random_state=0)[0]
    low, high = gym.make("MountainCar-v0").observation_space.low, [0.6, 0.07]
    inside = [low + (d.observations - d.observations.min()) / np.ptp(d.observations) * (
        np.asarray(high) - low) for d in demos]  # fmt: skip
    task = fit_task(inside, indicator="velocity", random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SwirlWrapper(gym.make("MountainCar-v0"), task)
    in_cm = fit_task([100 * x for x in inside], indicator="velocity", random_state=0)
    with pytest.warns(UserWarning, match=r"far outside this env's observation bounds \(dim 0: "):
        SwirlWrapper(gym.make("MountainCar-v0"), TaskModel.from_json(in_cm.to_json()))


def test_make_swirl_env_takes_make_vec_envs_arguments(tmp_path):
    """As SB3's make_vec_env: env_kwargs, render_mode="rgb_array", one Monitor (it was two)
    writing to monitor_dir with monitor_kwargs, start_index."""
    from stable_baselines3.common.monitor import Monitor

    from sb3_swirl import make_swirl_env

    task = TaskModel(
        [Region([0.0, 0.0], np.eye(2), 4.0)], [QuadraticReward([0.0, 0.0], np.eye(2))], dims=(0, 1)
    )
    venv = make_swirl_env(
        "sb3_swirl/ParallelParking-v0",
        task,
        n_envs=2,
        start_index=3,
        monitor_dir=str(tmp_path),
        env_kwargs={"max_speed": 0.5},
        monitor_kwargs={"info_keywords": ("is_success",)},
    )
    env = venv.envs[0]
    assert isinstance(env, Monitor) and isinstance(env.env, SwirlWrapper)
    assert env.unwrapped.max_speed == 0.5 and env.render_mode == "rgb_array"
    venv.reset()
    assert venv.render().ndim == 3  # make_vec_env's default: frames
    for _ in range(200):  # past the time limit: each monitor logs an episode
        venv.step(np.zeros(2, dtype=int))
    venv.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["3.monitor.csv", "4.monitor.csv"]
    assert "is_success" in (tmp_path / "3.monitor.csv").read_text().splitlines()[1]
    factory = make_swirl_env(lambda radius: PointEnv(), line_task(), env_kwargs={"radius": 2.0})
    assert isinstance(factory.envs[0].unwrapped, PointEnv)  # the factory took the setting
    with pytest.raises(TypeError, match=r"env_kwargs \['radius'\] .*got an env instance"):
        make_swirl_env(PointEnv(), line_task(), env_kwargs={"radius": 2.0})
    # a registered env that renders no frames is not asked for them (gymnasium warned at
    # every make that rgb_array is not among its render_modes)
    gym.register("test_wrappers/Point-v0", entry_point=PointEnv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            own = make_swirl_env("test_wrappers/Point-v0", line_task(), n_envs=2)
        assert own.envs[0].render_mode is None
    finally:
        gym.registry.pop("test_wrappers/Point-v0")


# ----------------------------------------------------------------------- subprocess workers
def test_make_swirl_env_runs_in_fresh_worker_processes():
    """Workers started fresh (``spawn``) know nothing of sb3_swirl: the factory imports it
    there, so the sb3_swirl/ ids resolve (gymnasium no longer loads plugin entry points). SB3's
    default start method, ``forkserver``, is the next test's."""
    from sb3_swirl import make_swirl_env

    task = TaskModel(
        [Region([0.0, 0.0], np.eye(2), 4.0)], [QuadraticReward([0.0, 0.0], np.eye(2))], dims=(0, 1)
    )
    venv = make_swirl_env(
        "sb3_swirl/ParallelParking-v0",
        task,
        n_envs=2,
        seed=0,
        vec_env_cls=SubprocVecEnv,
        vec_env_kwargs={"start_method": "spawn"},
    )
    try:
        assert venv.reset().shape == (2, 4 + task.n_indices)
        _, _, _, infos = venv.step(np.zeros(2, dtype=int))
        assert all("segment" in info and "task_reward" in info for info in infos)
        assert venv.get_attr("task")[0].to_json() == task.to_json()
    finally:
        venv.close()


def test_make_swirl_env_with_subprocesses_from_python_c(tmp_path):
    """The user's case: a script run with ``python -c`` (no importable __main__), workers
    started by SB3's default method (``forkserver``)."""
    TaskModel([Region([0.0], [[1.0]], 4.0)], [QuadraticReward([0.0], [[1.0]])], dims=(0,)).to_json(
        tmp_path / "task.json"
    )
    code = (
        "import numpy as np\n"
        "from stable_baselines3.common.vec_env import SubprocVecEnv\n"
        "from sb3_swirl import TaskModel, make_swirl_env\n"
        f"task = TaskModel.from_json({str(tmp_path / 'task.json')!r})\n"
        "venv = make_swirl_env('sb3_swirl/NoisyAcrobot-v0', task, n_envs=2, "
        "vec_env_cls=SubprocVecEnv)\n"
        "venv.reset(); venv.step(np.zeros(2, dtype=int)); venv.close(); print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "ok"


def test_a_state_that_is_not_a_number_is_warned_about_once():
    """NaN from the env would be a NaN reward the agent learns from, without a word."""
    env = SwirlWrapper(PointEnv(), line_task())
    env.reset(seed=0)
    env.unwrapped.pos[0] = np.nan
    with pytest.warns(
        UserWarning, match=r"proxy reward is nan \(said once\): the state \[nan\].*VecCheckNan"
    ) as caught:
        env.step(STAY)
    assert caught[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(env.step(STAY)[1])  # once per tracker: no warning at every step
    venv = SwirlVecEnv(DummyVecEnv([PointEnv, PointEnv]), line_task())
    venv.reset()
    venv.envs[1].unwrapped.pos[0] = np.inf
    with pytest.warns(UserWarning, match=r"proxy reward is -?(inf|nan) in env 1 .*\[inf\]"):
        venv.step(np.array([STAY, STAY]))


def test_an_env_that_breaks_its_own_spaces_is_named():
    """An observation wider than the env's space declares, or a reward of None, failed deep in
    numpy (shapes not aligned) or in the tracker (float * NoneType)."""

    class Wide(PointEnv):
        def step(self, action):
            obs, reward, terminated, truncated, info = super().step(action)
            return np.r_[obs, 0.0], reward, terminated, truncated, info

    class NoReward(PointEnv):
        def step(self, action):
            obs, _, terminated, truncated, info = super().step(action)
            return obs, None, terminated, truncated, info

    wide = SwirlWrapper(Wide(), line_task())
    wide.reset(seed=0)
    with pytest.raises(ValueError, match=r"observation of shape \(2,\) where its .* 1 value$"):
        wide.step(STAY)
    silent = SwirlWrapper(NoReward(), line_task())
    silent.reset(seed=0)
    with pytest.raises(ValueError, match="returned the reward None, not a number"):
        silent.step(STAY)

    class NumpyReward(PointEnv):  # rewards that worked before the check, and still do
        kinds = (np.bool_(True), np.array([0.5]), np.float32(1.0), np.array(2), True, 3)

        def step(self, action):
            obs, _, terminated, truncated, info = super().step(action)
            return obs, self.kinds[self.steps % 6], terminated, truncated, info

    numpy_rewards = SwirlWrapper(NumpyReward(), line_task(), {"task_reward_weight": 1.0})
    numpy_rewards.reset(seed=0)
    for _ in range(6):
        assert np.isfinite(numpy_rewards.step(STAY)[1])
    with pytest.raises(ValueError, match=r"observation of shape \(2, 3\) where"):
        SwirlVecEnv(DummyVecEnv([PointEnv, PointEnv]), line_task()).lifter.state(np.zeros((2, 3)))
