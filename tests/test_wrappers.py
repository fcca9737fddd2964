"""SwirlWrapper, SwirlVectorWrapper and SwirlVecEnv: exact values, checkers, equivalence."""

from __future__ import annotations

import pickle
import sys
import warnings
from collections import OrderedDict
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from sb3_swirl.vec_env import SwirlVecEnv
from swirl_wrappers import (
    QuadraticReward,
    RBFFeatures,
    Region,
    SegmentTracker,
    SwirlVectorWrapper,
    SwirlWrapper,
    TaskModel,
    _compiled,
)


@pytest.fixture(params=["compiled", "numpy"])
def backend(request, monkeypatch):
    """Run a test on the tracker's compiled step (numba) and on its numpy path."""
    if request.param == "numpy":
        monkeypatch.setattr(_compiled, "step", None)
    else:
        # Not a skip: sb3-swirl installs numba, so the compiled path is the one users run.
        assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    return request.param


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
    env = SwirlWrapper(PointEnv(), line_task(), reward_scale=3.0, region_bonus=10.0)
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


def test_regions_must_be_reached_in_order():
    env = SwirlWrapper(PointEnv(), line_task())
    env.reset(options={"start": [2.0]})  # starts in region 1, which is not next
    assert env.segment == 0
    indices = [env.step(a)[4]["segment"] for a in (STAY, DOWN, DOWN, UP, UP)]
    # x: 2.0, 1.5, 1.0 (region 0 -> 1), 1.5, 2.0 (region 1 -> 2)
    assert indices == [0, 0, 1, 1, 2]


def test_initial_state_inside_region_zero_advances_on_reset():
    env = SwirlWrapper(PointEnv(), line_task(), region_bonus=5.0)
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
    env = SwirlWrapper(PointEnv(as_dict=True), line_task(), region_bonus=1.0)
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


# ----------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: SwirlWrapper(gym.make("FrozenLake-v1"), line_task()), "Box or Dict"),
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
        (lambda: SwirlWrapper(PointEnv(), line_task(), reward_scale=np.nan), "reward_scale"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), region_bonus="a"), "region_bonus"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), region_bonus="1"), "must be a number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), reward_scale=True), "must be a number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), reward_scale=np.ones(1)), "a number"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), reward_scale=-1.0), r"reward_scale .* >= 0"),
        (lambda: SwirlWrapper(PointEnv(), line_task(), region_bonus=-2), r"region_bonus .* >= 0"),
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
    with pytest.raises(ValueError, match="1-D Box"):
        SwirlWrapper(_ImageEnv(), task)
    no_obs_key = _ImageEnv(dict_keys=("state",))
    with pytest.raises(ValueError, match="no 'observation' key"):
        SwirlWrapper(no_obs_key, task)
    with pytest.raises(ValueError, match="already has a 'segment'"):
        SwirlWrapper(_ImageEnv(dict_keys=("observation", "segment")), task)


class _ImageEnv(gym.Env):
    def __init__(self, dict_keys=()):
        box = spaces.Box(0, 255, (4, 4), dtype=np.uint8)
        self.observation_space = (
            spaces.Dict({k: spaces.Box(-1.0, 1.0, (1,)) for k in dict_keys}) if dict_keys else box
        )
        self.action_space = spaces.Discrete(2)


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
        lambda: SwirlWrapper(gym.make("Acrobot-v1"), _acrobot_task(), region_bonus=1.0),
        lambda: SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), reward_scale=0.1),
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
    env = SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), region_bonus=2.0)
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
    env = SwirlWrapper(gym.make("CartPole-v1"), _cartpole_task(), reward_scale=0.5)
    spec = env.spec
    assert spec.additional_wrappers[-1].kwargs["reward_scale"] == 0.5
    again = gym.make(spec)
    assert isinstance(again, SwirlWrapper) and again.reward_scale == 0.5
    assert again.task.to_dict() == env.task.to_dict()


def test_sb3_dummy_and_subproc_vec_envs():
    task = _cartpole_task()
    kwargs = {"task": task, "region_bonus": 1.0}
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


SWIRL_KWARGS = {"reward_scale": 2.0, "region_bonus": 3.0}


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
def test_swirl_vec_env_matches_independent_wrappers(as_dict, kwargs, timed, backend):
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
    "reward_mode": "potential",
    "reward_scale": 2.0,
    "task_reward_weight": 0.5,
    "gamma": 0.9,
}


@pytest.mark.parametrize("kwargs", [SWIRL_KWARGS, POTENTIAL_KWARGS], ids=["quadratic", "potential"])
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("as_dict", [False, True], ids=["box", "dict"])
@pytest.mark.parametrize("timed", [False, True], ids=["untimed", "timed"])
def test_swirl_vector_wrapper_matches_independent_wrappers(mode, as_dict, kwargs, timed, backend):
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


def test_vector_wrappers_refuse_terminate_on_completion():
    with pytest.raises(ValueError, match="SwirlWrapper"):
        SwirlVecEnv(DummyVecEnv([PointEnv]), line_task(), terminate_on_completion=True)
    with pytest.raises(ValueError, match="SwirlWrapper"):
        SwirlVectorWrapper(SyncVectorEnv([PointEnv]), line_task(), terminate_on_completion=True)
    with pytest.raises(ValueError, match="wraps an SB3 VecEnv"):
        SwirlVecEnv(PointEnv(), line_task())


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
    assert SegmentTracker(task, 2, PointEnv().observation_space).task is task


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
    kwargs = {
        "reward_scale": draw(st.floats(0, 5)),
        "region_bonus": draw(st.floats(0, 10)),
        "terminate_on_completion": draw(st.booleans()),
    }
    return obs_dim, task, kwargs, seed


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tasks_on_points())
def test_fuzz_wrapper_invariants(case):
    obs_dim, task, kwargs, seed = case
    env = SwirlWrapper(
        PointEnv(dim=obs_dim, step_size=0.3, jitter=1.0, limit=3.0, max_steps=25), task, **kwargs
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
        want = kwargs["reward_scale"] * float(task.reward(obs[:obs_dim], before))
        want += kwargs["region_bonus"] * (after > before)
        assert reward == pytest.approx(want, rel=1e-9, abs=1e-9)
        assert np.argmax(obs[obs_dim:]) == after
        if kwargs["terminate_on_completion"] and after == task.n_segments and after > before:
            assert terminated
        if terminated or truncated:
            obs, info = env.reset()


# ----------------------------------------------------------------------- reward modes
def _phi(task, x, index):
    return index + 1.0 / (1.0 - float(task.reward(np.array([x]), index)))


def test_task_reward_weight_adds_the_env_reward_in_quadratic_mode():
    task = line_task()
    plain = SwirlWrapper(PointEnv(), task, reward_scale=3.0)
    mixed = SwirlWrapper(PointEnv(), task, reward_scale=3.0, task_reward_weight=0.25)
    plain.reset(seed=0)
    mixed.reset(seed=0)
    for action in (UP, UP, DOWN, UP, UP):
        _, r_plain, *_ = plain.step(action)
        _, r_mixed, _, _, info = mixed.step(action)
        assert r_mixed == pytest.approx(r_plain + 0.25 * info["task_reward"], abs=1e-12)
    assert mixed.task_reward_weight == 0.25 and plain.task_reward_weight == 0.0


def test_potential_mode_exact_values_and_terminal_potential():
    task = line_task()
    # the env terminates when |x| > 2.2: x = 2.5 after the last region
    env = SwirlWrapper(PointEnv(step_size=0.5, limit=2.2), task, reward_mode="potential", gamma=0.9)
    assert env.task_reward_weight == 1.0  # the default in potential mode
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
            reward_mode="potential",
            reward_scale=scale,
            task_reward_weight=weight,
            gamma=gamma,
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
    env = SwirlWrapper(PointEnv(max_steps=1), line_task(), reward_mode="potential", gamma=1.0)
    env.reset(seed=0)
    phi = env.potential
    _, reward, terminated, truncated, _ = env.step(UP)
    assert truncated and not terminated
    assert env.potential == pytest.approx(_phi(line_task(), 0.5, 0))  # not zeroed
    assert reward == pytest.approx(0.5 + env.potential - phi)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reward_mode": "exp"}, "reward_mode"),
        ({"reward_mode": "potential", "task_reward_weight": 0.0}, "task_reward_weight > 0"),
        ({"gamma": 1.5}, "gamma"),
        ({"task_reward_weight": "a lot"}, "task_reward_weight must be a number"),
    ],
)
def test_invalid_reward_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SwirlWrapper(PointEnv(), line_task(), **kwargs)
    with pytest.raises(ValueError, match=message):
        SegmentTracker(line_task(), 1, PointEnv().observation_space, **kwargs)


def test_tracker_needs_the_env_signals_its_reward_mode_uses(backend):
    space = PointEnv().observation_space
    tracker = SegmentTracker(line_task(), 2, space, reward_mode="potential")
    tracker.reset(np.zeros((2, 1)))
    with pytest.raises(ValueError, match="terminated"):
        tracker.step(np.ones((2, 1)), task_rewards=np.zeros(2))
    with pytest.raises(ValueError, match="task_rewards"):
        tracker.step(np.ones((2, 1)), terminated=np.zeros(2, dtype=bool))
    quadratic = SegmentTracker(line_task(), 2, space)
    quadratic.reset(np.zeros((2, 1)))
    assert quadratic.step(np.ones((2, 1))).shape == (2,)  # the default mode needs neither


def test_tracker_refuses_batches_of_the_wrong_shape(backend):
    task = plane_task()
    tracker = SegmentTracker(task, 3, PointEnv(dim=2).observation_space)
    good = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"states must have shape \(3, 2\)"):
        tracker.reset(np.zeros((1, 2)))
    tracker.reset(good)
    for states in (np.zeros((1, 2)), np.zeros((3, 1)), np.zeros(3)):
        with pytest.raises(ValueError, match=r"states must have shape \(3, 2\)"):
            tracker.step(states)
    with pytest.raises(ValueError, match="restart must have shape"):
        tracker.step(good, restart=np.array([True, False]))
    restart = np.array([True, False, True])
    for final in (np.zeros((1, 2)), np.zeros((3, 2)), np.zeros((2, 3)), np.zeros(2)):
        with pytest.raises(ValueError, match="one state per restart row"):
            tracker.step(good, restart=restart, final_states=final)
    # A refused step changes nothing.
    assert tracker.t.tolist() == [0, 0, 0] and tracker.index.tolist() == [0, 0, 0]
    for rewards32 in (np.zeros(3), np.zeros(2, dtype=np.float32), [0.0, 0.0, 0.0]):
        with pytest.raises(ValueError, match=r"float32_rewards must be a float32 array of shape"):
            tracker.step_lift(good, float32_rewards=rewards32)
    weighted = SegmentTracker(task, 3, PointEnv(dim=2).observation_space, task_reward_weight=1.0)
    weighted.reset(good)
    with pytest.raises(ValueError, match=r"task_rewards must have shape \(3,\)"):
        weighted.step(good, task_rewards=np.zeros(2))
    with pytest.raises(ValueError, match="num_envs"):
        SegmentTracker(task, 2.7, PointEnv(dim=2).observation_space)


def test_compiled_tracker_refuses_a_corrupted_index_or_potential():
    """The kernel reads without bounds checks: what a caller can set is checked before it runs."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    space = PointEnv(dim=2).observation_space
    states = np.zeros((3, 2), dtype=np.float32)
    for kwargs, attribute, value, message in (
        ({}, "index", np.array([0, 7, 0]), "segment index out of range"),
        ({}, "index", np.array([0, -1, 0]), "segment index out of range"),
        ({}, "index", np.array([0, 0]), "one entry per environment"),
        (POTENTIAL_KWARGS, "potential", np.zeros(2), "one entry per environment"),
    ):
        tracker = SegmentTracker(plane_task(), 3, space, **kwargs)
        tracker.reset(states)
        setattr(tracker, attribute, value)
        with pytest.raises(ValueError, match=message):
            tracker.step_lift(states, task_rewards=np.zeros(3), terminated=np.zeros(3, dtype=bool))
        assert tracker.t.tolist() == [0, 0, 0]  # nothing changed


def _tracker_tasks() -> dict[str, tuple[TaskModel, int]]:
    """Tasks with linear and non-linear (angle features, an RBF map) inputs: (task, obs dim)."""
    rng = np.random.default_rng(0)

    def random_regions(p: int) -> tuple[list[Region], list[QuadraticReward]]:
        regions, rewards = [], []
        for _ in range(3):
            a = rng.normal(size=(p, p))
            regions.append(Region(rng.normal(size=p) * 0.3, a @ a.T + 0.5 * np.eye(p), 4.0))
            rewards.append(QuadraticReward(rng.normal(size=p), a.T @ a))
        return regions, rewards

    rbf = RBFFeatures(rng.normal(size=(6, 3)), 0.7, rng.normal(size=(6, 2)), rng.normal(size=2))
    return {
        "plane": (plane_task(), 2),
        "timed": (plane_task(timed=True), 2),
        "dims": (TaskModel(*random_regions(2), dims=(3, 1)), 5),
        "angles": (TaskModel(*random_regions(6), dims=(4, 0), angles=((1,), (1, 3))), 5),
        "rbf": (TaskModel(*random_regions(2), dims=(4, 0, 2), features=rbf), 5),
    }


@pytest.mark.parametrize("task_name", ["plane", "timed", "dims", "angles", "rbf"])
@pytest.mark.parametrize(
    "kwargs",
    [{}, SWIRL_KWARGS, {"task_reward_weight": 0.3}, POTENTIAL_KWARGS],
    ids=["plain", "scale-bonus", "task-weight", "potential"],
)
def test_compiled_tracker_matches_its_numpy_path(task_name, kwargs):
    """Every step of the compiled tracker agrees with numpy: no restarts, NEXT_STEP, SAME_STEP."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    task, dim = _tracker_tasks()[task_name]
    n = 8
    space = spaces.Box(-5.0, 5.0, (dim,), dtype=np.float32)
    compiled, reference = (SegmentTracker(task, n, space, **kwargs) for _ in range(2))
    reference.compiled = False
    assert compiled.compiled
    rng = np.random.default_rng(1)
    states = rng.normal(size=(n, dim)).astype(np.float32)
    compiled.reset(states)
    reference.reset(states)
    moved = restarted = 0
    for step in range(90):
        states = (states + rng.normal(size=(n, dim)) * 0.4).astype(np.float32)
        kind = step % 3  # 0: no restart, 1: NEXT_STEP restarts, 2: SAME_STEP restarts
        restart = rng.random(n) < 0.3 if kind else None
        final = None
        if kind == 2:
            final = rng.normal(size=(int(restart.sum()), dim)).astype(np.float32)
        signals = {"task_rewards": rng.normal(size=n), "terminated": rng.random(n) < 0.2}
        before = compiled.index
        rewards32 = np.full(n, np.nan, dtype=np.float32)
        lifted, rewards, lifted_final = compiled.step_lift(
            states, restart, final, **signals, float32_rewards=rewards32
        )
        expected32 = np.full(n, np.nan, dtype=np.float32)
        expected = reference.step_lift(
            states, restart, final, **signals, float32_rewards=expected32
        )
        np.testing.assert_allclose(rewards, expected[1], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(rewards32, rewards.astype(np.float32))
        np.testing.assert_array_equal(expected32, expected[1].astype(np.float32))
        np.testing.assert_array_equal(lifted, expected[0])
        if final is None:
            assert lifted_final is None and expected[2] is None
        else:
            np.testing.assert_array_equal(lifted_final, expected[2])
        for name in ("index", "ended_index", "t"):
            np.testing.assert_array_equal(getattr(compiled, name), getattr(reference, name))
        if kwargs.get("reward_mode") == "potential":
            np.testing.assert_allclose(compiled.potential, reference.potential, rtol=1e-12)
        assert compiled.index is not before  # published index arrays are never written again
        moved += int(np.count_nonzero(compiled.ended_index != before))
        restarted += 0 if restart is None else int(restart.sum())
    assert moved >= 5 and restarted >= 20  # the walks reached regions and restarted


# ------------------------------------------------ SB3 info dicts: compiled reads and stores
def _counting_step_infos(monkeypatch) -> list[int]:
    """The results of every ``_compiled.step_infos`` call from now on."""
    results: list[int] = []
    kernel = _compiled.step_infos

    def counted(*args):
        results.append(kernel(*args))
        return results[-1]

    monkeypatch.setattr(_compiled, "step_infos", counted)
    return results


def _sb3_infos(restart: np.ndarray, final: np.ndarray) -> list[dict]:
    """Infos as an SB3 vector env hands them over, with a stale ``"segment"`` to overwrite."""
    infos = []
    for i, done in enumerate(restart):
        info = {"from_env": i, "segment": None}
        if done:
            info["terminal_observation"] = final[i].copy()
        infos.append(info)
    return infos


def _assert_same_step(got, want, got_infos, want_infos):
    """Same lifted observations and rewards, and infos with the same keys, order and types."""
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, b)
        assert a.dtype == b.dtype
    for g, w in zip(got_infos, want_infos, strict=True):
        assert list(g) == list(w)
        for key, value in w.items():
            if key == "terminal_observation":
                np.testing.assert_array_equal(g[key], value)
                assert g[key].dtype == value.dtype
            else:
                assert g[key] == value and type(g[key]) is type(value)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("task_name", ["plane", "timed", "dims"])
@pytest.mark.parametrize(
    "kwargs",
    [{}, SWIRL_KWARGS, {"task_reward_weight": 0.3}, POTENTIAL_KWARGS],
    ids=["plain", "scale-bonus", "task-weight", "potential"],
)
def test_step_lift_infos_kernel_matches_its_python_path(kwargs, task_name, dtype, monkeypatch):
    """The compiled reads and stores of SB3's infos give exactly what the Python path gives."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    task, dim = _tracker_tasks()[task_name]
    n = 8
    space = spaces.Box(-5.0, 5.0, (dim,), dtype=dtype)
    kernel, python = (SegmentTracker(task, n, space, **kwargs) for _ in range(2))
    python._infos_kernel = False  # the Python path around the same compiled step
    results = _counting_step_infos(monkeypatch)
    rng = np.random.default_rng(3)
    states = rng.normal(size=(n, dim)).astype(dtype)
    kernel.reset(states)
    python.reset(states)
    restarted = 0
    for _ in range(60):
        states = (states + rng.normal(size=(n, dim)) * 0.4).astype(dtype)
        restart = rng.random(n) < 0.3
        final = rng.normal(size=(n, dim)).astype(dtype)
        signals = {
            "task_rewards": rng.normal(size=n).astype(np.float32),
            "terminated": restart & (rng.random(n) < 0.5),
        }
        got_infos, want_infos = _sb3_infos(restart, final), _sb3_infos(restart, final)
        got = kernel.step_lift_infos(states, restart, infos=got_infos, **signals)
        want = python.step_lift_infos(states, restart, infos=want_infos, **signals)
        _assert_same_step(got, want, got_infos, want_infos)
        assert got[1].dtype == np.float32
        for name in ("index", "ended_index", "t", "potential"):
            np.testing.assert_array_equal(getattr(kernel, name), getattr(python, name))
        restarted += int(restart.sum())
    assert results == [_compiled.DONE] * 60 and restarted >= 60


def _sb3_step(tracker: SegmentTracker, infos) -> tuple:
    states = np.array([[0.1, 0.2], [0.5, 0.0], [-1.0, 0.0], [1.0, 0.5]], dtype=np.float32)
    restart = np.array([True, False, True, False])
    return tracker.step_lift_infos(states, restart, np.ones(4), infos)


@pytest.mark.parametrize(
    "change",
    [
        "tuple of infos",
        "dict subclass",
        "float64 final observation",
        "list as final observation",
        "strided final observation",
        "byte-swapped final observation",
    ],
)
def test_step_lift_infos_leaves_what_its_kernel_does_not_read_to_python(change, monkeypatch):
    """Infos the kernel does not read stop it before anything changed; Python does the step."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    space = PointEnv(dim=2).observation_space
    kernel, python = (SegmentTracker(plane_task(), 4, space) for _ in range(2))
    python._infos_kernel = False
    results = _counting_step_infos(monkeypatch)
    final = np.array([[0.5, 0.0], [0.0, 0.0], [0.5, 0.05], [0.0, 0.0]], dtype=np.float32)

    def infos():
        infos = _sb3_infos(np.array([True, False, True, False]), final)
        if change == "dict subclass":
            infos[3] = OrderedDict(infos[3])
        elif change == "tuple of infos":
            infos = tuple(infos)
        else:
            infos[2]["terminal_observation"] = {
                "float64 final observation": final[2].astype(np.float64),
                "list as final observation": final[2].tolist(),
                "strided final observation": np.stack((final[2], final[2]), axis=1)[:, 0],
                "byte-swapped final observation": final[2].astype(">f4"),
            }[change]
        return infos

    for tracker in (kernel, python):
        tracker.reset(np.zeros((4, 2), dtype=np.float32))
    got_infos, want_infos = infos(), infos()
    got, want = _sb3_step(kernel, got_infos), _sb3_step(python, want_infos)
    _assert_same_step(got, want, got_infos, want_infos)
    # The transition ended in region 0 at the final observation; the next episode starts away.
    assert got_infos[2]["segment"] == 1 and kernel.index[2] == 0
    assert results == ([] if change == "tuple of infos" else [_compiled.NOT_HANDLED])


def test_step_lift_infos_kernel_takes_observations_of_any_order_and_float_dtype(monkeypatch):
    """Observations of another dtype than the space's, in Fortran order, then in C order."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    space = PointEnv(dim=2).observation_space  # float32
    kernel, python = (SegmentTracker(plane_task(), 4, space) for _ in range(2))
    python._infos_kernel = False
    results = _counting_step_infos(monkeypatch)
    for tracker in (kernel, python):
        tracker.reset(np.zeros((4, 2), dtype=np.float32))
    rng = np.random.default_rng(0)
    restart = np.array([True, False, True, False])
    for order in ("F", "C", "F"):
        states = np.asarray(rng.normal(size=(4, 2)) * 0.5, order=order)
        final = rng.normal(size=(4, 2)) * 0.5
        got_infos, want_infos = _sb3_infos(restart, final), _sb3_infos(restart, final)
        got = kernel.step_lift_infos(states, restart, np.zeros(4), got_infos)
        want = python.step_lift_infos(states, restart, np.zeros(4), want_infos)
        _assert_same_step(got, want, got_infos, want_infos)
        assert got[0].dtype == np.float64
    assert results == [_compiled.DONE] * 3


@pytest.mark.parametrize("backend_name", ["kernel", "python"])
def test_step_lift_infos_refuses_bad_infos_before_changing_anything(backend_name):
    space = PointEnv(dim=2).observation_space
    tracker = SegmentTracker(plane_task(), 4, space)
    tracker._infos_kernel = backend_name == "kernel"
    tracker.reset(np.zeros((4, 2), dtype=np.float32))
    final = np.zeros((4, 2), dtype=np.float32)
    restart = np.array([True, False, True, False])
    missing = _sb3_infos(restart, final)
    del missing[2]["terminal_observation"]
    with pytest.raises(KeyError, match="terminal_observation"):
        _sb3_step(tracker, missing)
    too_wide = _sb3_infos(restart, np.zeros((4, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="final_states must hold one state per restart row"):
        _sb3_step(tracker, too_wide)
    with pytest.raises(ValueError, match=r"infos must hold one dict per environment \(4\), got 3"):
        _sb3_step(tracker, _sb3_infos(restart, final)[:3])
    assert tracker.t.tolist() == [0, 0, 0, 0]
    assert [info["segment"] for info in missing] == [None] * 4  # nothing was stored


def test_step_lift_infos_kernel_keeps_reference_counts():
    """The kernel's C API calls take and drop references in pairs: nothing leaks or is lost."""
    assert _compiled.step is not None, "numba is missing: pip install swirl-wrappers[numba]"
    tracker = SegmentTracker(plane_task(), 4, PointEnv(dim=2).observation_space)
    tracker.reset(np.zeros((4, 2), dtype=np.float32))
    final = np.ones((4, 2), dtype=np.float32)
    infos = _sb3_infos(np.array([True, False, True, False]), final)
    watched = [*infos, "terminal_observation", "segment", "task_reward", "segment_reward", dict]

    def step():
        for i in (0, 2):
            infos[i]["terminal_observation"] = final[i].copy()
        _sb3_step(tracker, infos)

    step()  # the first step adds the keys to the dicts
    counts = [sys.getrefcount(obj) for obj in watched]
    for _ in range(200):
        step()
    assert [sys.getrefcount(obj) for obj in watched] == counts
    # The stored values are referenced by their dict alone (and getrefcount's argument).
    stored = [sys.getrefcount(infos[0][key]) for key in ("terminal_observation", "task_reward")]
    assert stored == [2, 2]
