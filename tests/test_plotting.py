"""Plots of a fitted task (Agg backend, set in conftest)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from sb3_swirl.demos import make_piecewise_linear_demos
from sb3_swirl.fitting import fit_task
from sb3_swirl.plotting import plot_rewards, plot_segments, plot_transitions


@pytest.fixture(scope="module")
def fitted():
    demos, _ = make_piecewise_linear_demos(n_demos=6, dim=3, noise=0.1, random_state=2)
    return demos, fit_task(demos, random_state=0)


def test_plot_segments_draws_demos_and_region_ellipses(fitted, tmp_path):
    demos, task = fitted
    fig = plot_segments(demos, task, dims=(0, 2), path=tmp_path / "segments.png")
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    ax = fig.axes[0]
    ellipses = [p for p in ax.patches if isinstance(p, Ellipse)]
    assert len(ellipses) == 2 * task.n_segments  # a filled and an outlined ellipse per region
    lines = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(lines) == len(demos)
    # Steps are coloured by segment: every segment's colour appears.
    colors = {tuple(np.round(c, 3)) for lc in lines for c in lc.get_colors()}
    assert len(colors) == task.n_segments
    outlined = [e for e in ellipses if e.get_facecolor()[3] == 0]
    np.testing.assert_allclose(outlined[0].center, task.regions[0].mean[[0, 2]])
    assert (tmp_path / "segments.png").stat().st_size > 1000
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("obs[0]", "obs[2]")
    named = plot_segments(demos, task, dims=(0, 2), names=["x (m)", "y (m)", "z (m)"]).axes[0]
    assert (named.get_xlabel(), named.get_ylabel()) == ("x (m)", "z (m)")


def test_plot_rewards_has_one_heat_map_per_segment(fitted, tmp_path):
    _, task = fitted
    fig = plot_rewards(task, path=tmp_path / "rewards.png")
    heat = [ax for ax in fig.axes if ax.images]
    assert len(heat) == task.n_segments
    assert len(fig.axes) == 2 * task.n_segments  # each with its colour bar
    np.testing.assert_array_equal(heat[1].images[0].get_array(), task.rewards[1].weight)
    assert (tmp_path / "rewards.png").stat().st_size > 1000


def test_plot_segments_rejects_bad_dims(fitted):
    demos, task = fitted
    with pytest.raises(ValueError, match="two different task-space axes"):
        plot_segments(demos, task, dims=(0, 0))
    with pytest.raises(ValueError, match="two different task-space axes"):
        plot_segments(demos, task, dims=(0, 5))
    plot_segments(demos, task, dims=np.array([0, 2]))  # an array of axes is fine
    for dims in [(0,), (0, 1, 2), (0.5, 1), "01", 5]:
        with pytest.raises(ValueError, match="two different task-space axes"):
            plot_segments(demos, task, dims=dims)
    with pytest.raises(ValueError, match="max_demos must be an integer >= 1, got 0"):
        plot_transitions(demos, task, max_demos=0)


def test_plots_refuse_a_path_in_place_of_a_task(fitted):
    demos, _ = fitted
    with pytest.raises(ValueError, match=r"TaskModel.from_json reads a file.*got str"):
        plot_rewards("task.json")
    with pytest.raises(ValueError, match="got str"):
        plot_segments(demos, "task.json")


def test_plot_transitions_marks_candidates_and_region_entries(fitted, tmp_path):
    demos, task = fitted
    fig = plot_transitions(demos, task, max_demos=3, path=tmp_path / "transitions.png")
    panels = [ax for ax in fig.axes if ax.get_ylabel().startswith("demo")]
    assert len(panels) == 3
    first = panels[0]
    dots = [ln for ln in first.get_lines() if ln.get_marker() == "o"]
    assert len(dots[0].get_xdata()) == len(task.metadata["transitions"][0])
    assert dots[0].get_label() == f"candidate ({task.metadata['indicator']})"  # the indicator used
    entries = [ln for ln in first.get_lines() if ln.get_label().startswith("enters region")]
    steps = task.segment_indices(demos[0].observations)
    assert [ln.get_xdata()[0] for ln in entries] == [
        int(np.argmax(steps >= i)) for i in range(1, task.n_indices)
    ]
    assert (tmp_path / "transitions.png").stat().st_size > 1000
    low, high = first.get_xlim()  # every entry inside the panel, not on its border
    assert all(low < ln.get_xdata()[0] < high for ln in entries)
    # demos the task was not fitted on: no candidates, said in the title
    other, _ = make_piecewise_linear_demos(n_demos=4, dim=3, noise=0.1, random_state=5)
    fig = plot_transitions(other, task)
    assert "fitted on other demonstrations" in fig.get_suptitle()
    assert fig.get_suptitle().startswith("Transitions over time: 4 demonstrations")


@pytest.mark.parametrize("suffix", ["png", "svg", "pdf"])
def test_the_same_plot_saves_the_same_bytes(fitted, tmp_path, suffix):
    # No creation date, and SVG's element ids from a fixed salt: a plot can be diffed.
    _, task = fitted
    first, second = tmp_path / f"a.{suffix}", tmp_path / f"b.{suffix}"
    plot_rewards(task, path=first)
    plot_rewards(task, path=second)
    assert first.read_bytes() == second.read_bytes()


def test_a_figure_legend_names_methods_hidden_under_the_same_line():
    from sb3_swirl.experiments import _same_as_drawn

    drawn: dict = {}
    assert _same_as_drawn(drawn, "SWIRL", [2, 5], [1.0, 1.0]) == "SWIRL"
    assert _same_as_drawn(drawn, "DQN", [2, 5], [1.0, 0.5]) == "DQN"  # apart at one point
    assert _same_as_drawn(drawn, "BC", [2, 5], [1.0, 1.0]) == "BC (= SWIRL)"
    assert _same_as_drawn(drawn, "RBF", [2, 5, 9], [1.0, 1.0, 1.0]) == "RBF"  # other points
    assert _same_as_drawn(drawn, "SVM", [2, 5], [1.0, 1.0]) == "SVM (= SWIRL, BC)"
