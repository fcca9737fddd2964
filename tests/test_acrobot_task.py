"""SWIRL on the acrobot: the proxy task learned from 15 supervisor demos is a sensible one.

The swing-up pumps energy with swings of growing amplitude, then rises above the line. The
learned task must follow that: several regions, each reached by every demonstration in order at
its own time (growing swings, not all at the start or the end), a goal that means "tip high"
and is reached only at the end, and local rewards that lead to the next region. The angles wrap
at ±pi, so the task is fitted on the absolute link angles' (cos, sin) (``angles``).
"""

from __future__ import annotations

import numpy as np
import pytest

from sb3_swirl.fitting import fit_task
from sb3_swirl.supervisors import collect_demos
from swirl_wrappers import TaskModel

#: the fit_task arguments for NoisyAcrobot: absolute link angles theta1 and theta1 + theta2 as
#: (cos, sin), in which the tip height is linear, and the two angular velocities
ACROBOT_TASK = {"angles": [[0], [0, 1]], "dims": [2, 3]}


def _tip_height(obs: np.ndarray) -> np.ndarray:
    return -np.cos(obs[:, 0]) - np.cos(obs[:, 0] + obs[:, 1])


@pytest.fixture(scope="module")
def acrobot():
    demos = collect_demos("sb3_swirl/NoisyAcrobot-v0", 15, seed=0)
    task = fit_task(demos, random_state=0, **ACROBOT_TASK)
    # reach[j, i]: the step at which demo j reaches region i (-1: never)
    reach = []
    for demo in demos:
        index = task.segment_indices(demo.observations)
        reach.append(
            [int(np.argmax(index > i)) if index[-1] > i else -1 for i in range(task.n_segments)]
        )
    reach = np.array(reach)
    return demos, task, reach


def test_every_demo_reaches_every_region_in_order_at_distinct_times(acrobot):
    demos, task, reach = acrobot
    assert task.n_segments >= 3  # at least two swing regions and the goal
    assert (reach >= 0).all(), "every demonstration reaches every region"
    assert (np.diff(reach, axis=1) > 0).all()
    lengths = np.array([len(d) for d in demos])
    # Not at the start: the first region needs some energy pumping first.
    assert (reach[:, 0] > 0.1 * lengths).all()


def test_regions_are_spread_over_the_swing_up_at_growing_amplitude(acrobot):
    demos, _, reach = acrobot
    lengths = np.array([len(d) for d in demos])[:, None]
    median_time = np.median(reach / lengths, axis=0)
    assert (np.diff(median_time) > 0).all()
    # Spread: no stretch of more than 60% of a demo without progress, from the start on.
    assert np.diff(np.r_[0.0, median_time]).max() < 0.6
    # The largest swing so far when each region is reached: every region is a larger swing.
    amplitude = np.array(
        [
            [np.abs(d.observations[: r + 1, 0]).max() for r in row]
            for d, row in zip(demos, reach, strict=True)
        ]
    )
    assert (np.diff(np.median(amplitude, axis=0)) > 0).all()


def test_goal_means_tip_high_and_is_reached_only_at_the_end(acrobot):
    demos, task, reach = acrobot
    lengths = np.array([len(d) for d in demos])
    assert (reach[:, -1] >= 0.75 * lengths).all()
    goal = task.regions[-1]
    for demo in demos:
        obs = demo.observations
        inside = goal.contains(task.featurize(obs))
        assert inside.any()
        # Compact: only states with the tip near or above the success line are in the goal.
        assert _tip_height(obs[inside]).min() > 0.5
    # The hanging start is far outside it.
    assert not goal.contains(task.featurize(np.zeros(4)))


def test_rewards_lead_to_the_next_region(acrobot):
    demos, task, reach = acrobot
    for i in range(task.n_segments):
        ahead_of_start = ahead_of_median = 0
        for demo, row in zip(demos, reach, strict=True):
            start = 0 if i == 0 else row[i - 1] + 1
            reward = task.reward(demo.observations[start : row[i] + 1], i)
            ahead_of_start += reward[-1] > reward[0]
            ahead_of_median += reward[-1] > np.median(reward)
        assert ahead_of_start >= 0.8 * len(demos), f"segment {i}"
        assert ahead_of_median >= 0.8 * len(demos), f"segment {i}"


def test_task_ignores_how_angles_wrap_and_survives_json(acrobot):
    demos, task, _ = acrobot
    loaded = TaskModel.from_json(task.to_json())
    for demo in demos[:5]:
        obs = demo.observations
        index = task.segment_indices(obs)
        other_branch = obs + np.array([2 * np.pi, -4 * np.pi, 0.0, 0.0])
        np.testing.assert_array_equal(task.segment_indices(other_branch), index)
        np.testing.assert_array_equal(loaded.segment_indices(obs), index)
        np.testing.assert_allclose(
            task.reward(other_branch, index), task.reward(obs, index), rtol=1e-9, atol=1e-9
        )
