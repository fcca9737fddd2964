"""The dVRK line-cutting task on robosuite: env contract, geometry, supervisor, pipeline."""

from __future__ import annotations

import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_swirl.envs  # noqa: F401
from sb3_swirl.envs.dvrk import DVRKLineCuttingEnv
from sb3_swirl.envs.dvrk.line_cutting import (
    PLUS_X,
    distance_to_polyline,
    line_points,
    signed_offset,
)
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


def test_observation_is_position_and_signed_line_offset_in_cm(env):
    obs, _ = env.reset(seed=1)
    xy = env.tool_position[:2]
    offset = signed_offset(xy, env.line)
    np.testing.assert_allclose(obs, np.array([*xy, offset]) * 100, rtol=1e-5, atol=1e-5)
    unsigned = DVRKLineCuttingEnv(radius=2.0, signed_distance=False)
    obs, _ = unsigned.reset(seed=1)
    d, _ = unsigned.line_distance(unsigned.tool_position[:2])
    assert obs[2] == pytest.approx(100 * d, rel=1e-5) and unsigned.observation_space.low[2] == 0
    unsigned.close()


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


def test_signed_offset_on_known_points():
    """Beside the line: the distance, positive on the left (+y of a line along +x); before its
    start and past its end: the offset across its extension there."""
    straight = line_points(None, 0.05)
    assert signed_offset(np.array([0.02, 0.01]), straight) == pytest.approx(0.01)
    assert signed_offset(np.array([0.02, -0.01]), straight) == pytest.approx(-0.01)
    assert signed_offset(np.array([-0.03, 0.0]), straight) == pytest.approx(0.0)
    assert signed_offset(np.array([-0.03, -0.004]), straight) == pytest.approx(-0.004)
    assert signed_offset(np.array([0.08, 0.002]), straight) == pytest.approx(0.002)
    r = 0.02
    arc = line_points(r, 0.05)  # bends to the left, towards +y: its centre (0, r) is inside
    assert signed_offset(np.array([r + 0.005, r]), arc) == pytest.approx(-0.005, abs=1e-6)
    assert signed_offset(np.array([r - 0.005, r]), arc) == pytest.approx(0.005, abs=1e-6)


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
    with pytest.warns(UserWarning, match="step\\(\\) called after the episode terminated"):
        assert env.step(FOLLOW)[1:3] == (0.0, True)  # it paid 1.0 again, and every step after
    assert env.step(FOLLOW)[1] == 0.0
    with pytest.raises(ValueError, match=r"reset takes no options, got \{'radius': 3.0\}"):
        env.reset(options={"radius": 3.0})
    env.close()


def test_render_says_what_offscreen_opengl_needs(monkeypatch):
    """Without a working backend, mujoco failed deep inside (gladLoadGL, no GLContext...)."""
    import mujoco

    def no_gl(*args, **kwargs):
        raise AttributeError("module 'mujoco.gl_context' has no attribute 'GLContext'")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    env = DVRKLineCuttingEnv(render_mode="rgb_array")
    env.reset(seed=0)
    with pytest.raises(RuntimeError, match=r"needs offscreen OpenGL, and MuJoCo's backend .*EGL"):
        env.render()
    env.close()


def test_importing_sets_no_gl_backend_on_a_machine_without_egl():
    """MUJOCO_GL=egl without libEGL broke every MuJoCo env, rendering or not."""
    code = (
        "import ctypes, os\n"
        "real = ctypes.CDLL\n"
        "def cdll(name, *a, **k):\n"
        "    if 'EGL' in str(name):\n"
        "        raise OSError(name)\n"
        "    return real(name, *a, **k)\n"
        "ctypes.CDLL = cdll\n"
        "import sb3_swirl\n"
        "print(os.environ.get('MUJOCO_GL'))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == "None"


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


def test_supervisor_slips_across_the_line_and_steps_back():
    """While following, the hand slips across the line (seeded) and steps back to it: the demos
    hold corrections from both sides, always within the tolerance; slip=0 follows exactly."""
    env = gym.make(ENV_ID, line_jitter=3.0)

    def cut(sup_seed, **kwargs):
        sup = LineCuttingSupervisor(env.unwrapped, seed=sup_seed, **kwargs)
        obs, _ = env.reset(seed=2)
        sup.reset(obs)
        offsets, actions = [], []
        while True:
            action = sup.act(obs)
            obs, _, terminated, truncated, info = env.step(action)
            if sup.phase == FOLLOW:
                offsets.append(obs[2])
                actions.append(action)
            if terminated or truncated:
                return np.array(offsets), actions, info

    offsets, actions, info = cut(0)
    assert info["is_success"]
    assert offsets.max() > 0.3 and offsets.min() < -0.3  # off the line on either side
    assert {2, 3} <= set(actions)
    np.testing.assert_array_equal(offsets, cut(0)[0])  # seeded
    assert not np.array_equal(offsets, cut(1)[0])
    offsets, actions, info = cut(0, slip=0.0)
    assert info["is_success"] and np.abs(offsets).max() < 0.3 and set(actions) == {PLUS_X}
    with pytest.raises(ValueError, match="slip"):
        LineCuttingSupervisor(env.unwrapped, slip=1.5)
    # metres: 4.0 (cm, as the env's radius) or a negative lookahead failed every cut silently
    for kwargs in [{"lookahead": 4.0}, {"lookahead": -0.004}, {"approach": "x"}]:
        with pytest.raises(ValueError, match=rf"{next(iter(kwargs))} \(m\) must be a finite"):
            LineCuttingSupervisor(env.unwrapped, **kwargs)
    env.close()


def test_leaving_the_line_fails_the_cut_which_goes_on_to_the_end(env):
    sup = LineCuttingSupervisor(env, seed=0)
    obs, _ = env.reset(seed=0)
    sup.reset(obs)
    while sup.phase != FOLLOW or not env.step(sup.act(obs))[4]["cutting"]:
        obs = env.step(sup.act(obs))[0]
    for _ in range(8):  # -y, more than 1 cm off the line
        obs, reward, terminated, _, info = env.step(3)
    assert obs[2] < -1.0 and info["cut_failed"] and not terminated  # right of it: negative
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
        ({"signed_distance": "no"}, "signed_distance must be True or False, got 'no'"),
    ],
)
def test_bad_constructor_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DVRKLineCuttingEnv(**kwargs)


def _success_rate(model, env, seeds) -> float:
    from sb3_swirl.experiments import greedy_infos

    return float(np.mean([greedy_infos(model, env, seed)[-1]["is_success"] for seed in seeds]))


@pytest.fixture(scope="module")
def entry_demos():
    """The zoo entry's demos (5 straight lines spread 3 cm) on demo seed 5."""
    from sb3_swirl.experiments import PRESETS

    preset = PRESETS["linecutting"]
    return collect_demos(ENV_ID, preset.n_demos, seed=5, **preset.demo_env_kwargs)


def test_a_clone_of_straight_lines_follows_an_arc_with_the_signed_offset(entry_demos):
    """The slips' corrections, seen with the signed offset, teach a clone which way to step
    back to the line, so an SVM clone of straight-line demos follows a 3 cm arc it never saw.
    The same demos seen with the unsigned distance (the paper's *pix* read literally) do not."""
    from sb3_swirl.baselines import BCPolicy
    from sb3_swirl.experiments import greedy_infos

    def arc_success(demos, signed):
        observations = np.concatenate([d.observations[:-1] for d in demos])
        actions = np.concatenate([d.actions for d in demos])
        clone = BCPolicy("svm", random_state=0).fit(observations, actions)
        arc = gym.make(ENV_ID, radius=3.0, signed_distance=signed)
        rate = np.mean([greedy_infos(clone, arc, s)[-1]["is_success"] for s in range(100, 110)])
        arc.close()
        return rate

    unsigned_demos = collect_demos(ENV_ID, 5, seed=5, line_jitter=3.0, signed_distance=False)
    assert [len(d.actions) for d in unsigned_demos] == [len(d.actions) for d in entry_demos]
    assert arc_success(entry_demos, True) >= 0.6
    assert arc_success(unsigned_demos, False) <= 0.2


def test_entry_fit_makes_the_last_segment_the_cut(entry_demos):
    """The zoo entry fits on x and the offset from the line (the lines' y is random): the first
    segment ends where the demos have lined up with the line, before its start, and the last
    is the cut, whose reward weighs the offset most (paper §10.2)."""
    from sb3_swirl.experiments import PRESETS
    from sb3_swirl.fitting import fit_task

    task = fit_task(entry_demos, random_state=5, **PRESETS["linecutting"].fit_kwargs)
    assert task.n_segments == 2
    lined_up = task.regions[0].mean  # (x, offset) in cm
    assert lined_up[0] < -2.0 and abs(lined_up[1]) < 0.3, lined_up
    weight = np.diag(task.rewards[-1].weight)
    assert weight[1] > 10 * weight[0], weight


def test_swirl_pipeline_learns_to_position_and_cut(entry_demos):
    """Straight-line demos at random positions -> the entry's fit (two segments: line up, cut)
    -> SwirlDQN: its BC start cuts lines that its untrained network does not, and 2000 steps of
    Q-learning keep it (test_dqn.py shows the Q-learning itself learn)."""
    from sb3_swirl.dqn import SwirlDQN
    from sb3_swirl.experiments import PRESETS
    from sb3_swirl.fitting import fit_task
    from swirl_wrappers import SwirlWrapper

    preset = PRESETS["linecutting"]
    demos = entry_demos
    task = fit_task(demos, random_state=5, **preset.fit_kwargs)
    assert task.n_segments == 2

    reward_config = preset.swirl["reward_config"]
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
    model.pretrain()
    cloned = _success_rate(model, env, eval_seeds)
    model.learn(total_timesteps=2000)
    trained = _success_rate(model, env, eval_seeds)
    assert untrained == 0.0 and cloned >= 0.4 and trained >= cloned, (untrained, cloned, trained)


def test_table2_jobs_run_in_worker_processes_as_in_this_one(tmp_path):
    """Table 2 is a sweep: its jobs (one per seed and line) give JSON records, the same in a
    worker process as in this one, so --jobs and Ray do not change the table."""
    import json

    from sb3_swirl.experiments import table2_run
    from sb3_swirl.runner import run_sweep

    job = {"seed": 0, "radius": 3.0, "episodes": 1, "n_eval": 2}
    (record,) = run_sweep(table2_run, [job], tmp_path / "runs.jsonl", n_jobs=2, progress=False)
    assert record == json.loads(json.dumps(table2_run(**job)))
    for method in ("svm", "swirl"):
        assert 0.0 <= record[method]["success_rate"] <= record[method]["began_cut_rate"] <= 1.0
    assert record["swirl"]["began_cut_rate"] == 1.0  # the demos' start is found on an arc too


@pytest.mark.slow
def test_reproduce_table2_quick(tmp_path, capsys):
    import json

    from sb3_swirl.experiments import reproduce_table2

    first = reproduce_table2(quick=True, out_dir=tmp_path, progress=False)  # 2 jobs at once
    results = json.loads((tmp_path / "table2" / "results_quick.json").read_text())
    assert results == json.loads(json.dumps(first))
    # a sweep of one job per line: resumed, it trains nothing and reads the same
    assert reproduce_table2(quick=True, out_dir=tmp_path, progress=False, resume=True) == first
    assert "kept 3 runs done before (--resume)" in capsys.readouterr().err
    assert [entry["radius_cm"] for entry in results["summary"]] == [None, 3.0, 1.5]
    for run in results["runs"]:
        for method in ("svm", "swirl"):
            assert 0.0 <= run[method]["success_rate"] <= run[method]["began_cut_rate"] <= 1.0
    assert results["swirl_successes"][1] == 15
