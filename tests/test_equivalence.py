"""The same answer everywhere: every wrapper, and the offline segmentation of a demo.

``SwirlWrapper`` (one episode), ``SwirlVectorWrapper`` (gymnasium, both autoreset modes) and
``SwirlVecEnv`` (SB3) all step through one ``SegmentTracker`` whose maths makes the same
BLAS calls for a state whatever the batch; ``TaskModel.segment_indices`` segments a demo
offline with the same maths. Hypothesis draws random tasks and reward settings, and scripted
trajectories that pass through region boundaries and end mid-segment (terminated or
truncated); every path must give identical segments, rewards and lifted observations.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_swirl.vec_env import SwirlVecEnv
from swirl_wrappers import (
    QuadraticReward,
    Region,
    RewardConfig,
    SwirlVectorWrapper,
    SwirlWrapper,
    TaskModel,
)

N_ENVS = 3


class ScriptEnv(gym.Env):
    """Replays scripted episodes, one after the other: observations, rewards and endings."""

    def __init__(self, episodes: list[dict]) -> None:
        self.episodes = episodes
        dim = episodes[0]["obs"].shape[1]
        self.observation_space = spaces.Box(-np.inf, np.inf, (dim,), dtype=np.float64)
        self.action_space = spaces.Discrete(1)
        self._episode, self._t = -1, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._episode = (self._episode + 1) % len(self.episodes)
        self._t = 0
        return self.episodes[self._episode]["obs"][0].copy(), {}

    def step(self, action):
        episode = self.episodes[self._episode]
        self._t += 1
        end = self._t == len(episode["obs"]) - 1
        terminated = end and episode["terminated"]
        reward = float(episode["rewards"][self._t - 1])
        return episode["obs"][self._t].copy(), reward, terminated, end and not terminated, {}


@st.composite
def cases(draw):
    """A random task, reward settings and ``N_ENVS`` scripts of episodes."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    obs_dim = draw(st.integers(1, 4))
    p = draw(st.integers(1, obs_dim))
    dims = rng.permutation(obs_dim)[:p].tolist() if draw(st.booleans()) else None
    if dims is None:
        p = obs_dim
    k = draw(st.integers(1, 4))
    timed = draw(st.booleans())
    regions, rewards = [], []
    for i in range(k):
        a = rng.normal(size=(p, p)) * rng.uniform(0.05, 1.0)
        bounds = (float(rng.integers(0, 4)), float(rng.integers(4, 12))) if timed else None
        regions.append(Region(rng.normal(size=p), a @ a.T + 0.01 * np.eye(p), 1 + 8 * i, bounds))
        b = rng.normal(size=(p, rng.integers(1, p + 1)))
        rewards.append(QuadraticReward(rng.normal(size=p), b @ b.T))
    task = TaskModel(regions, rewards, dims=dims)
    if draw(st.booleans()):
        config = RewardConfig(
            mode="potential",
            scale=draw(st.floats(0.0, 3.0)),
            region_bonus=draw(st.sampled_from([0.0, 1.5])),
            task_reward_weight=draw(st.floats(0.1, 5.0)),
            gamma=draw(st.floats(0.5, 1.0)),
        )
    else:
        config = RewardConfig(
            scale=draw(st.floats(0.0, 3.0)),
            region_bonus=draw(st.sampled_from([0.0, 1.5])),
            task_reward_weight=draw(st.sampled_from([0.0, 0.5])),
        )

    def state(kind: str) -> np.ndarray:
        obs = rng.normal(size=obs_dim) * 2.0
        region = regions[rng.integers(k)]
        if kind == "random":
            return obs
        x = region.mean.copy()
        if kind == "boundary":  # on the ellipsoid's surface, up to rounding
            u = rng.normal(size=p)
            x += (
                np.sqrt(region.threshold)
                * np.linalg.cholesky(region.covariance)
                @ (u / np.linalg.norm(u))
            )
        else:  # near the centre
            x += 0.01 * rng.normal(size=p)
        obs[dims if dims is not None else slice(None)] = x
        return obs

    scripts = []
    for _ in range(N_ENVS):
        episodes = []
        for _ in range(rng.integers(2, 5)):
            length = int(rng.integers(1, 12))
            kinds = rng.choice(["random", "boundary", "centre"], size=length + 1)
            episodes.append(
                {
                    "obs": np.array([state(kind) for kind in kinds]),
                    # multiples of 1/8: exact in the float32 rewards of SB3's vector envs
                    "rewards": rng.integers(-8, 9, size=length) / 8.0,
                    "terminated": bool(rng.integers(2)),
                }
            )
        scripts.append(episodes)
    return task, config, scripts


def _steps(scripts: list[list[dict]]) -> int:
    """Vector steps that run every script's episodes at least twice (with the autoresets)."""
    return 2 * max(sum(len(e["obs"]) for e in episodes) for episodes in scripts)


def _wrapped(scripts, task, config):
    return [lambda s=s: SwirlWrapper(ScriptEnv(s), task, config) for s in scripts]


def _raw(scripts):
    return [lambda s=s: ScriptEnv(s) for s in scripts]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_sb3_vec_env_gives_what_independent_wrappers_give(case):
    task, config, scripts = case
    reference = DummyVecEnv(_wrapped(scripts, task, config))
    vectorised = SwirlVecEnv(DummyVecEnv(_raw(scripts)), task, config)
    np.testing.assert_array_equal(vectorised.reset(), reference.reset())
    actions = np.zeros(N_ENVS, dtype=int)
    for _ in range(_steps(scripts)):
        got, want = vectorised.step(actions), reference.step(actions)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        np.testing.assert_array_equal(got[2], want[2])
        for g, w in zip(got[3], want[3], strict=True):
            for key in ("segment", "task_reward", "segment_reward"):
                assert g[key] == w[key], key
            if "terminal_observation" in w:
                np.testing.assert_array_equal(g["terminal_observation"], w["terminal_observation"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases(), st.sampled_from([AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]))
def test_gymnasium_vector_wrapper_gives_what_independent_wrappers_give(case, mode):
    task, config, scripts = case
    reference = SyncVectorEnv(_wrapped(scripts, task, config), autoreset_mode=mode)
    vectorised = SwirlVectorWrapper(SyncVectorEnv(_raw(scripts), autoreset_mode=mode), task, config)
    got_obs, got_info = vectorised.reset()
    want_obs, want_info = reference.reset()
    np.testing.assert_array_equal(got_obs, want_obs)
    np.testing.assert_array_equal(got_info["segment"], want_info["segment"])
    actions = np.zeros(N_ENVS, dtype=int)
    for _ in range(_steps(scripts)):
        got, want = vectorised.step(actions), reference.step(actions)
        for g, w in zip(got[:4], want[:4], strict=True):
            np.testing.assert_array_equal(g, w)
        for g_info, w_info in (
            (got[4], want[4]),
            (got[4].get("final_info"), want[4].get("final_info")),
        ):
            if w_info is None:
                continue
            for key in ("segment", "task_reward", "segment_reward"):
                mask = w_info.get("_" + key, np.zeros(N_ENVS, dtype=bool))
                np.testing.assert_array_equal(g_info["_" + key], mask)
                if mask.any():  # a key no sub-env reported is absent from the reference
                    np.testing.assert_array_equal(g_info[key][mask], w_info[key][mask])
        for i in np.flatnonzero(want[4].get("_final_obs", [])):
            np.testing.assert_array_equal(got[4]["final_obs"][i], want[4]["final_obs"][i])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_offline_segmentation_of_a_demo_is_what_the_wrapper_does_online(case):
    """``segment_indices`` of a recorded episode equals the segments a replay shows."""
    task, config, scripts = case
    for episodes in scripts:
        env = SwirlWrapper(ScriptEnv(episodes), task, config)
        for episode in episodes:
            _, info = env.reset()
            online = [info["segment"]]
            for _ in range(len(episode["obs"]) - 1):
                online.append(env.step(0)[4]["segment"])
            np.testing.assert_array_equal(task.segment_indices(episode["obs"]), online)
