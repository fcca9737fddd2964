"""fit_task: the one-line path from demonstrations to a TaskModel."""

from __future__ import annotations

import json
import traceback

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sb3_swirl.demos import Demonstration, make_piecewise_linear_demos, save_demos, to_imitation
from sb3_swirl.fitting import fit_task
from sb3_swirl.segmentation import TransitionStateClustering
from swirl_wrappers import TaskModel


@pytest.fixture(scope="module")
def demos():
    return make_piecewise_linear_demos(n_demos=8, noise=0.1, random_state=4)[0]


def _same_task(a: TaskModel, b: TaskModel, rtol: float = 0.0) -> None:
    assert a.n_segments == b.n_segments
    for ra, rb in zip(a.regions, b.regions, strict=True):
        np.testing.assert_allclose(ra.mean, rb.mean, rtol=rtol, atol=0)
        np.testing.assert_allclose(ra.covariance, rb.covariance, rtol=rtol, atol=0)
        assert ra.threshold == pytest.approx(rb.threshold, rel=rtol, abs=0)
    for wa, wb in zip(a.rewards, b.rewards, strict=True):
        np.testing.assert_allclose(wa.target, wb.target, rtol=rtol, atol=0)
        np.testing.assert_allclose(wa.weight, wb.weight, rtol=rtol, atol=0)


def test_fit_task_returns_a_task_whose_segmentation_matches_the_segmenter(demos):
    task = fit_task(demos, random_state=0)
    tsc = TransitionStateClustering(random_state=0).fit(demos)
    assert isinstance(task, TaskModel) and task.n_segments == 3
    for demo, segs in zip(demos, tsc.segments_, strict=True):
        index = task.segment_indices(demo.observations)
        np.testing.assert_array_equal(np.flatnonzero(np.diff(np.r_[0, index])), segs)
        assert index[-1] == task.n_segments
        rewards = task.reward(demo.observations[1:], index[:-1])
        assert np.all(np.isfinite(rewards)) and np.all(rewards <= 0)


def test_json_round_trip_keeps_segmentation_and_rewards(demos, tmp_path):
    task = fit_task(demos, random_state=0)
    again = TaskModel.from_json(task.to_json(tmp_path / "task.json"))
    _same_task(task, again)
    assert again.metadata == json.loads(task.to_json())["metadata"]
    for demo in demos:
        obs = demo.observations
        index = task.segment_indices(obs)
        np.testing.assert_array_equal(again.segment_indices(obs), index)
        np.testing.assert_array_equal(again.reward(obs, index), task.reward(obs, index))


def test_same_seed_same_task_and_metadata_records_parameters(demos):
    a = fit_task(demos, random_state=3, window=4, metric="euclidean")
    b = fit_task(demos, random_state=3, window=4, metric="euclidean")
    _same_task(a, b)
    meta = a.metadata
    assert meta["n_demos"] == 8 and meta["random_state"] == 3
    assert meta["segmentation"]["class"] == "TransitionStateClustering"
    assert meta["segmentation"]["params"]["window"] == 4
    assert meta["segmentation"]["params"]["random_state"] == 3
    assert meta["reward"]["params"]["metric"] == "euclidean"
    json.dumps(meta)  # JSON-safe


def test_dims_select_state_columns(demos):
    rng = np.random.default_rng(0)
    # Add a pure-noise column in front; the task uses columns (1, 2) only.
    wide = [np.column_stack([rng.normal(size=len(d.observations)), d.observations]) for d in demos]
    task = fit_task(wide, dims=[1, 2], random_state=0)
    plain = fit_task(demos, random_state=0)
    assert task.dims == (1, 2)
    _same_task(task, plain, rtol=1e-9)  # column slices differ from a fresh array in rounding
    with pytest.raises(ValueError, match="dims must be indices"):
        fit_task(wide, dims=[3])
    with pytest.raises(ValueError, match="dims must be integer indices"):
        fit_task(wide, dims=[[1, 2]])
    with pytest.raises(ValueError, match=r"dims lists an index more than once: \[1, 1\]"):
        fit_task(wide, dims=[1, 1])  # said before the fit, not by the task model after it


def test_estimators_and_kwargs_are_routed(demos):
    tsc = TransitionStateClustering(indicator="velocity", random_state=9)
    task = fit_task(demos, segmentation=tsc, reward={"metric": "euclidean"})
    assert not hasattr(tsc, "regions_")  # the given instance is cloned, not fitted in place
    assert task.metadata["segmentation"]["params"]["indicator"] == "velocity"
    assert task.metadata["reward"]["params"]["metric"] == "euclidean"
    with pytest.raises(TypeError, match=r"arguments \['windw'\] \(did you mean 'window' for"):
        fit_task(demos, windw=3)
    with pytest.raises(TypeError, match="cannot be combined"):
        fit_task(demos, segmentation=tsc, window=3)
    with pytest.raises(TypeError, match="segmentation must be a TransitionStateClustering"):
        fit_task(demos, segmentation="tsc")
    with pytest.raises(TypeError, match=r"reward must be a RewardLearner, .* got int"):
        fit_task(demos, reward=3)
    with pytest.raises(ValueError, match=r"reward must be one of \['maxent', 'quadratic'\]"):
        fit_task(demos, reward="quadraticc")
    with pytest.raises(
        ValueError, match=r"random_state must be an integer in \[0, 4294967295\], got -1"
    ):
        fit_task(demos, random_state=-1)
    with pytest.raises(ValueError, match=r"or a numpy RandomState .* got a Generator"):
        fit_task(demos, random_state=np.random.default_rng(0))
    by_name = fit_task(demos, reward="quadratic", metric="euclidean", random_state=0)
    assert by_name.metadata["reward"]["class"] == "QuadraticRewardLearner"


def test_accepts_npz_paths_and_imitation_trajectories(demos, tmp_path):
    with_actions = [Demonstration(d.observations, np.zeros(len(d), dtype=np.int64)) for d in demos]
    path = tmp_path / "demos.npz"
    save_demos(with_actions, path)
    base = fit_task(demos, random_state=0)
    _same_task(fit_task(path, random_state=0), base)
    _same_task(fit_task(to_imitation(with_actions), random_state=0), base)


def test_progress_callback_reports_stages(demos, capsys):
    seen = []
    task = fit_task(demos, random_state=0, progress=seen.append)
    assert seen[0] == "validating demonstrations"
    assert any("transition regions from 8 demonstrations" in m for m in seen)
    assert seen[-1] == f"done: {task.n_segments} segments"
    fit_task(demos, random_state=0, progress=True)
    assert "learning local rewards" in capsys.readouterr().out
    with pytest.raises(ValueError, match="progress must be True, False or a callable, got 'yes'"):
        fit_task(demos, random_state=0, progress="yes")  # was ignored


def test_kernel_task_works_end_to_end(demos):
    task = fit_task(demos, kernel="rbf", kernel_sigma=10.0, n_landmarks=50, random_state=0)
    assert task.features is not None and task.task_dim == task.features.output_dim
    again = TaskModel.from_json(task.to_json())
    for demo in demos:
        index = task.segment_indices(demo.observations)
        assert index[-1] == task.n_segments
        np.testing.assert_array_equal(again.segment_indices(demo.observations), index)
        assert np.all(np.isfinite(task.reward(demo.observations, index)))


@st.composite
def demo_sets(draw):
    d = draw(st.integers(1, 4))
    n = draw(st.integers(2, 6))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["walk", "piecewise", "constant", "tiny"]))
    noise = draw(st.sampled_from([0.0, 1e-3, 0.1, 1.0]))
    out = []
    for _ in range(n):
        T = int(rng.integers(3, 60))
        if kind == "walk":
            x = np.cumsum(rng.normal(size=(T, d)), axis=0)
        elif kind == "piecewise":
            turns = rng.integers(1, T, size=2)
            v = np.where(np.arange(T)[:, None] < turns.min(), 1.0, -1.0) * np.ones((T, d))
            x = np.cumsum(v, axis=0)
        elif kind == "constant":
            x = np.zeros((T, d))
        else:
            x = rng.normal(size=(T, d)) * 1e-9
        out.append(x + noise * rng.normal(size=x.shape))
    window = draw(st.integers(1, 5))
    indicator = draw(st.sampled_from(["gmm", "velocity", "linear"]))
    return out, window, indicator


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(demo_sets())
def test_fuzz_fit_task_returns_a_valid_task_or_a_clear_value_error(case):
    data, window, indicator = case
    try:
        task = fit_task(data, window=window, indicator=indicator, random_state=0)
    except ValueError as exc:
        # a message, raised by our own checks (not numpy's or sklearn's, deep inside)
        raiser = traceback.extract_tb(exc.__traceback__)[-1].filename
        assert str(exc) and ("sb3_swirl" in raiser or "swirl_wrappers" in raiser), raiser
        return
    assert isinstance(task, TaskModel)
    medians = task.metadata["segmentation"]  # parameters recorded
    assert medians["params"]["window"] == window
    for reward in task.rewards:
        assert np.all(np.isfinite(reward.weight)) and np.all(np.isfinite(reward.target))
    for x in data:
        index = task.segment_indices(x)
        assert np.all(np.diff(index) >= 0)
        assert np.all(np.isfinite(task.reward(x, index)))


def _wrap(angle):
    return (angle + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def angular_demos(demos):
    # Column 0 becomes an angle whose path crosses pi; column 1 passes through. Returns the
    # demos with the angle unwrapped and wrapped to [-pi, pi).
    unwrapped = [
        np.column_stack([np.pi - 0.5 + 0.15 * d.observations[:, 0], d.observations[:, 1]])
        for d in demos
    ]
    return unwrapped, [np.column_stack([_wrap(x[:, 0]), x[:, 1]]) for x in unwrapped]


def test_angles_make_the_task_continuous_across_the_wrap(angular_demos):
    unwrapped, wrapped = angular_demos
    assert any(np.abs(np.diff(x[:, 0])).max() > np.pi for x in wrapped)  # demos do wrap
    task = fit_task(wrapped, angles=[[0]], dims=[1], random_state=0)
    assert task.angles == ((0,),) and task.dims == (1,) and task.task_dim == 3
    assert task.metadata["angles"] == [[0]]
    assert task.n_segments >= 2
    for x in wrapped:
        index = task.segment_indices(x)
        assert index[-1] == task.n_segments and index[0] == 0
    # The wrap is invisible: the same task as from the unwrapped angles.
    _same_task(fit_task(unwrapped, angles=[[0]], dims=[1], random_state=0), task, rtol=1e-9)
    loaded = TaskModel.from_json(task.to_json())
    for x, y in zip(wrapped, unwrapped, strict=True):
        np.testing.assert_array_equal(loaded.segment_indices(x), task.segment_indices(y))


def test_bad_angles_are_clear_value_errors(angular_demos):
    angular_demos = angular_demos[1]
    with pytest.raises(ValueError, match="dims must be given with angles"):
        fit_task(angular_demos, angles=[[0]])
    with pytest.raises(ValueError, match="angles use index 2"):
        fit_task(angular_demos, angles=[[2]], dims=[1])
    with pytest.raises(ValueError, match="angles must be a sequence"):
        fit_task(angular_demos, angles=[["x"]], dims=[1])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(dims=[0.7, 1.9]), "integer indices"),
        (dict(dims="01"), "integer indices"),
        (dict(angles=[[0.9]], dims=[]), "sequences of ints"),
        (dict(angles="01", dims=[]), "sequences of ints"),
    ],
)
def test_non_integer_indices_are_refused_not_truncated(demos, kwargs, match):
    with pytest.raises(ValueError, match=match):
        fit_task(demos, random_state=0, **kwargs)


def test_metadata_is_the_same_for_the_same_fit(demos):
    import functools

    from sb3_swirl.segmentation import gmm_indicator

    def fit():
        indicator = functools.partial(gmm_indicator, window=4)
        return fit_task(
            demos, random_state=np.random.RandomState(0), segmentation={"indicator": indicator}
        )

    first, second = fit(), fit()
    assert first.to_json() == second.to_json()
    recorded = first.metadata["segmentation"]["params"]["indicator"]
    assert recorded["kwargs"] == {"window": 4}


def test_demos_that_start_at_the_goal_fit_one_segment_with_a_warning():
    """Balancing: the demos end where one of them begins (CartPole under a feedback rule); the
    fit keeps the goal and names that demo instead of failing."""
    import gymnasium as gym

    from sb3_swirl.segmentation import SegmentationWarning

    env = gym.make("CartPole-v1")
    demos = []
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        states, actions, done = [obs], [], False
        while not done:
            actions.append(int(obs[2] + 0.5 * obs[3] > 0))
            obs, _, terminated, truncated, _ = env.step(actions[-1])
            states.append(obs)
            done = terminated or truncated
        demos.append(Demonstration(np.array(states), np.array(actions)))
    # the GMM keeps only the goal here (the default, "auto", keeps velocity's 2 segments)
    with pytest.warns(SegmentationWarning, match=r"Demos \[9\] start inside the goal region"):
        task = fit_task(demos, indicator="gmm", random_state=0)
    assert task.n_segments == 1 and len(demos[9].observations) == 501
