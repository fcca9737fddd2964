"""The dVRK line-cutting task on robosuite: env contract, geometry, supervisor, pipeline."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_swirl.envs  # noqa: F401
from sb3_swirl.envs.dvrk import DVRKLineCuttingEnv
from sb3_swirl.envs.dvrk.line_cutting import PLUS_X, distance_to_polyline, line_points
from sb3_swirl.supervisors import collect_demos
from sb3_swirl.supervisors.line_cutting import FOLLOW, LineCuttingSupervisor

ENV_ID = "sb3_swirl/DVRKLineCutting-v0"


@pytest.fixture(scope="module")
def env() -> DVRKLineCuttingEnv:
    env = DVRKLineCuttingEnv(radius=2.0)
    yield env
    env.close()


def test_env_checkers(env):
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)


def test_same_seed_same_trajectory():
    """Also the first episode of a new env: nothing from construction leaks into it."""
    env = DVRKLineCuttingEnv(radius=2.0)

    def run(seed):
        obs = [env.reset(seed=seed)[0]]
        for action in [0, 0, 2, 1, 3, 0]:
            obs.append(env.step(action)[0])
        return np.array(obs)

    first = run(3)
    assert not np.array_equal(first, run(4))
    np.testing.assert_array_equal(first, run(3))
    env.close()


def test_a_step_moves_the_tool_two_millimetres(env):
    env.reset(seed=0)
    for _ in range(5):
        env.step(PLUS_X)
    for _ in range(5):
        env._command(env.commanded_position)  # let the arm settle on its command
    before = env.tool_position
    for _ in range(10):
        env.step(PLUS_X)
    for _ in range(10):
        env._command(env.commanded_position)
    moved = env.tool_position - before
    assert moved[0] == pytest.approx(0.02, abs=0.0015)
    assert abs(moved[1]) < 0.001


def test_observation_is_position_and_line_distance_in_cm(env):
    obs, _ = env.reset(seed=1)
    xy = env.tool_position[:2]
    d, _ = env.line_distance(xy)
    np.testing.assert_allclose(obs, np.array([*xy, d]) * 100, rtol=1e-5, atol=1e-5)


def test_point_along_walks_the_line(env):
    env.reset(seed=0)
    line = env.line
    np.testing.assert_allclose(env.point_along(0.0), line[0])
    np.testing.assert_allclose(env.point_along(1.0), line[-1])  # clipped to the end
    d, s = env.line_distance(env.point_along(0.02))
    assert d < 1e-6 and s == pytest.approx(0.02, abs=1e-6)


def test_line_geometry_on_known_points():
    straight = line_points(None, 0.05)
    assert distance_to_polyline(np.array([0.02, 0.01]), straight) == pytest.approx((0.01, 0.02))
    assert distance_to_polyline(np.array([-0.01, 0.0]), straight) == pytest.approx((0.01, 0.0))
    assert distance_to_polyline(np.array([0.06, 0.0]), straight) == pytest.approx((0.01, 0.05))
    r = 0.02
    arc = line_points(r, 0.05)
    # the arc's centre is (0, r): every point of the arc is r from it
    np.testing.assert_allclose(np.linalg.norm(arc - [0.0, r], axis=1), r)
    np.testing.assert_allclose(np.linalg.norm(np.diff(arc, axis=0), axis=1).sum(), 0.05, rtol=1e-4)
    # a point 5 mm outside the arc, a quarter turn along it (arc length pi r / 2)
    outside = np.array([r + 0.005, r])
    d, s = distance_to_polyline(outside, arc)
    assert d == pytest.approx(0.005, abs=1e-6)
    assert s == pytest.approx(np.pi * r / 2, abs=1e-4)


@pytest.mark.parametrize("radius", [None, 1.5])
def test_supervisor_succeeds_with_small_errors(radius):
    env = gym.make(ENV_ID, radius=radius, line_jitter=1.0)
    for seed in range(3):
        sup = LineCuttingSupervisor(env.unwrapped, seed=seed)
        obs, _ = env.reset(seed=seed)
        sup.reset(obs)
        while True:
            obs, reward, terminated, truncated, info = env.step(sup.act(obs))
            if terminated or truncated:
                break
        assert info["is_success"] and reward == 1.0
        assert sup.phase == FOLLOW
        assert info["position_error_cm"] < 0.5
        assert info["tracking_error_cm"] < 0.3
    env.close()


def test_supervisor_lines_up_across_the_line_before_moving_in(env):
    """While positioning, every sideways step comes before the first step along the line, and
    the supervisor's seed changes nothing: one action per place, which clones can learn."""
    runs = []
    for sup_seed in (0, 1):
        sup = LineCuttingSupervisor(env, seed=sup_seed)
        obs, _ = env.reset(seed=4)
        sup.reset(obs)
        actions = []
        while sup.phase != FOLLOW:
            actions.append(sup.act(obs))
            obs = env.step(actions[-1])[0]
        runs.append(actions)
    assert runs[0] == runs[1]
    sideways = [a in (2, 3) for a in runs[0]]
    assert any(sideways) and not any(sideways[sideways.index(False) :])


def test_leaving_the_line_fails_the_cut_which_goes_on_to_the_end(env):
    sup = LineCuttingSupervisor(env, seed=0)
    obs, _ = env.reset(seed=0)
    sup.reset(obs)
    while sup.phase != FOLLOW or not env.step(sup.act(obs))[4]["cutting"]:
        obs = env.step(sup.act(obs))[0]
    for _ in range(8):  # -y, more than 1 cm off the line
        obs, reward, terminated, _, info = env.step(3)
    assert obs[2] > 1.0 and info["cut_failed"] and not terminated  # failed, not ended
    for _ in range(100):  # back to the line and along it, as the supervisor would
        obs, reward, terminated, truncated, info = env.step(sup.act(obs))
        if terminated or truncated:
            break
    assert terminated and not info["is_success"] and reward == 0.0
    assert info["cut_failed"] and info["line_distance_cm"] < 1.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"radius": -2.0}, "radius"),
        ({"radius": float("nan")}, "radius"),
        ({"robot": "Baxter9000"}, "unsupported robot 'Baxter9000'"),
        ({"robot": "Sawyer"}, r"unsupported robot 'Sawyer'; supported: \['Panda'\]"),
        ({"line_start": (1.0, 2.0, 3.0)}, "line_start"),
        ({"line_jitter": -1.0}, "line_jitter"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_constructor_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DVRKLineCuttingEnv(**kwargs)


def _success_rate(model, env, seeds) -> float:
    from sb3_swirl.experiments import greedy_infos

    return float(np.mean([greedy_infos(model, env, seed)[-1]["is_success"] for seed in seeds]))


def test_entry_fit_makes_the_last_segment_the_cut():
    """The zoo entry's fit puts a region at the line's start, so the last segment is the cut
    and its reward weighs the distance to the line most (paper §10.2). On these demos (seed 7)
    the GMM alone put it 0.7 cm before the start, where the reward weighed y more than d."""
    from sb3_swirl.experiments import PRESETS
    from sb3_swirl.fitting import fit_task

    preset = PRESETS["linecutting"]
    demos = collect_demos(ENV_ID, preset.n_demos, seed=7, **preset.demo_env_kwargs)
    task = fit_task(demos, random_state=7, **preset.fit_kwargs)
    start = task.regions[-2].mean  # the region before the goal
    assert abs(start[0] - -2.0) < 0.3 and start[2] < 0.3, start
    weight = np.diag(task.rewards[-1].weight)
    assert np.argmax(weight) == 2 and weight[2] > 10 * weight[1], weight


def test_swirl_pipeline_learns_to_position_and_cut():
    """Straight-line demos -> two segments (position, cut) -> SwirlDQN (BC start, then 2000
    steps of Q-learning) cuts lines that its untrained network does not."""
    from sb3_swirl.dqn import SwirlDQN
    from sb3_swirl.experiments import PRESETS
    from sb3_swirl.fitting import fit_task
    from swirl_wrappers import SwirlWrapper

    demos = collect_demos(ENV_ID, 5, seed=0, line_jitter=1.0)
    task = fit_task(demos, random_state=0)
    assert task.n_segments == 2
    # the first region is the line's start: on the line (d ~ 0) near x = -2 cm
    first = task.regions[0].mean
    assert abs(first[0] - -2.0) < 0.5 and first[2] < 0.3

    reward_config = PRESETS["linecutting"].swirl["reward_config"]
    env = SwirlWrapper(gym.make(ENV_ID), task, reward_config=reward_config)
    model = SwirlDQN(
        "MlpPolicy",
        env,
        demonstrations=demos,
        seed=0,
        learning_rate=3e-4,
        learning_starts=200,
        exploration_initial_eps=0.1,
        exploration_final_eps=0.02,
        target_update_interval=500,
        prefill_replay=True,
    )
    eval_seeds = range(100, 105)
    untrained = _success_rate(model, env, eval_seeds)
    model.learn(total_timesteps=2000)
    trained = _success_rate(model, env, eval_seeds)
    assert trained >= 0.4 and trained > untrained, (untrained, trained)


@pytest.mark.slow
def test_reproduce_table2_quick(tmp_path):
    import json

    from sb3_swirl.experiments import reproduce_table2

    reproduce_table2(quick=True, out_dir=tmp_path, progress=False)
    results = json.loads((tmp_path / "table2" / "results.json").read_text())
    assert [entry["radius_cm"] for entry in results["summary"]] == [None, 3.0, 1.5]
    for run in results["runs"]:
        for method in ("svm", "swirl"):
            assert 0.0 <= run[method]["success_rate"] <= run[method]["cut_rate"] <= 1.0
    assert results["swirl_successes"][1] == 15
