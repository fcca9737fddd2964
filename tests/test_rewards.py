"""Model-free local rewards (eq. 1) and the reward-learner protocol."""

from __future__ import annotations

import numpy as np
import pytest

from sb3_swirl.demos import make_piecewise_linear_demos
from sb3_swirl.fitting import fit_task
from sb3_swirl.rewards import QuadraticRewardLearner, RewardLearner, segment_states
from sb3_swirl.segmentation import TransitionStateClustering
from swirl_wrappers import Region


@pytest.fixture(scope="module")
def fitted():
    demos, _ = make_piecewise_linear_demos(n_demos=8, noise=0.1, random_state=11)
    return demos, TransitionStateClustering(random_state=0).fit(demos)


def _segments_by_index(demos, tsc):
    """Segment states independently: state t is in segment i while the index before it is i."""
    out = [[] for _ in tsc.regions_]
    for demo, bounds in zip(demos, tsc.segments_, strict=True):
        index = np.searchsorted(
            bounds, np.arange(len(demo.observations))
        )  # regions reached before t
        for i in range(len(out)):
            out[i].append(demo.observations[index == i])
    return [np.concatenate(s) for s in out]


def test_segment_states_partition_each_demo(fitted):
    demos, tsc = fitted
    segments, regions = segment_states(demos, tsc)
    assert len(segments) == len(regions) == len(tsc.regions_)
    for k, demo in enumerate(demos):
        parts = [seg[k] for seg in segments]
        np.testing.assert_array_equal(np.concatenate(parts), demo.observations)
        for i, part in enumerate(parts):
            assert regions[i].contains(part[-1])  # each segment ends on arrival in its region
    expected = _segments_by_index(demos, tsc)
    for seg, exp in zip(segments, expected, strict=True):
        np.testing.assert_array_equal(np.concatenate(seg), exp)


def test_mahalanobis_rewards_follow_eq1_and_are_normalised(fitted):
    demos, tsc = fitted
    learner = QuadraticRewardLearner(regularization=1e-3).fit(demos, tsc)
    raw = QuadraticRewardLearner(regularization=1e-3, normalize=False).fit(demos, tsc)
    pooled = np.concatenate([d.observations for d in demos])
    floor = 1e-3 * np.diag(pooled.var(axis=0)) + 1e-12 * np.eye(2)
    for i, states in enumerate(_segments_by_index(demos, tsc)):
        np.testing.assert_array_equal(learner.rewards_[i].target, tsc.regions_[i].mean)
        np.testing.assert_allclose(
            raw.rewards_[i].weight, np.linalg.inv(np.cov(states, rowvar=False) + floor), rtol=1e-8
        )
        assert np.mean(learner.rewards_[i](states)) == pytest.approx(-1.0)
        # Normalising only rescales Psi.
        ratio = learner.rewards_[i].weight / raw.rewards_[i].weight
        np.testing.assert_allclose(ratio, ratio[0, 0])
        assert np.all(np.linalg.eigvalsh(learner.rewards_[i].weight) > 0)


def test_euclidean_rewards_are_scaled_identities(fitted):
    demos, tsc = fitted
    learner = QuadraticRewardLearner(metric="euclidean").fit(demos, tsc)
    unscaled = QuadraticRewardLearner(metric="euclidean", normalize=False).fit(demos, tsc)
    for r, u in zip(learner.rewards_, unscaled.rewards_, strict=True):
        np.testing.assert_array_equal(u.weight, np.eye(2))
        np.testing.assert_allclose(r.weight, r.weight[0, 0] * np.eye(2))


def test_regions_task_model_and_segmenter_give_the_same_rewards(fitted):
    demos, tsc = fitted
    task = fit_task(demos, segmentation=tsc)
    by_tsc = QuadraticRewardLearner().fit(demos, tsc).rewards_
    by_task = QuadraticRewardLearner().fit(demos, task).rewards_
    by_regions = QuadraticRewardLearner().fit(demos, tsc.regions_).rewards_
    for a, b, c in zip(by_tsc, by_task, by_regions, strict=True):
        np.testing.assert_allclose(a.weight, b.weight)
        np.testing.assert_allclose(a.weight, c.weight)


def test_bad_inputs_raise_value_error(fitted):
    demos, _ = fitted
    with pytest.raises(ValueError, match="'metric' parameter of QuadraticRewardLearner"):
        QuadraticRewardLearner(metric="cosine").fit(demos, TransitionStateClustering())
    with pytest.raises(ValueError, match="not fitted"):
        QuadraticRewardLearner().fit(demos, TransitionStateClustering())
    with pytest.raises(ValueError, match="sequence of Region"):
        QuadraticRewardLearner().fit(demos, [1, 2])
    with pytest.raises(ValueError, match="sequence of Region, got NoneType"):
        QuadraticRewardLearner().fit(demos, None)  # sklearn's fit(X, y=None) habit
    with pytest.raises(ValueError, match=r"'regularization' parameter .* range \(0\.0, inf\)"):
        QuadraticRewardLearner(regularization=0).fit(demos, [])


def test_reward_learner_is_an_abstract_protocol():
    with pytest.raises(TypeError):
        RewardLearner()
    assert issubclass(QuadraticRewardLearner, RewardLearner)


def test_a_dimension_no_demo_moves_in_is_ignored_with_a_warning(fitted):
    demos, _ = fitted
    plain = [d.observations for d in demos]
    padded = [np.c_[x, np.full(len(x), 7.0)] for x in plain]
    regions = TransitionStateClustering(random_state=0).fit(plain).regions_
    # the same regions with the constant dimension (at its value): the same segments
    lifted = [
        Region(np.r_[r.mean, 7.0], np.pad(r.covariance, (0, 1)) + np.diag([0, 0, 1.0]), r.threshold)
        for r in regions
    ]
    with pytest.warns(UserWarning, match=r"dimensions \[2\] are constant"):
        learner = QuadraticRewardLearner().fit(padded, lifted)
    reference = QuadraticRewardLearner().fit(plain, regions)
    for mine, theirs in zip(learner.rewards_, reference.rewards_, strict=True):
        # its inverse variance was the floor's, 1e12: off by 1e-4 online cost 1e4 times more
        np.testing.assert_array_equal(mine.weight[2], 0.0)
        np.testing.assert_allclose(mine.weight[:2, :2], theirs.weight, rtol=1e-9)
