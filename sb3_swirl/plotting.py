"""Plots of a learned proxy task: segmented demonstrations (the paper's Fig. 13), reward
matrices (Fig. 14) and the transitions found along each demonstration. Matplotlib only, safe
under the Agg backend; every function returns the Figure and saves it when given ``path``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from sb3_swirl.demos import _as_demonstrations
from sb3_swirl.segmentation import turn_angles
from swirl_wrappers import TaskModel
from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_int


def _colors(n: int) -> list[Any]:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "viridis"]
    return [cmap(i if n <= 10 else i / max(n - 1, 1)) for i in range(n)]


def _new_figure(figsize: tuple[float, float]) -> Figure:
    # A bare Figure (no pyplot): no global state, no GUI backend, nothing to close.
    return Figure(figsize=figsize, layout="constrained")


def _finish(fig: Figure, path: str | os.PathLike | None) -> Figure:
    """Save ``fig`` atomically (in the format of the path's suffix) when ``path`` is given.

    PNG, SVG and PDF files are the same bytes for the same figure: no creation date, and SVG's
    element ids drawn from a fixed salt."""
    if path is not None:
        from matplotlib import rc_context

        suffix = os.path.splitext(path)[1].lstrip(".").lower() or "png"
        undated = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}.get(suffix)
        with atomic_write(path, "wb") as fh, rc_context({"svg.hashsalt": "sb3-swirl"}):
            fig.savefig(fh, format=suffix, dpi=120, metadata=undated)
    return fig


def _axis_names(task: TaskModel, names: Sequence[str] | None = None) -> list[str]:
    """The task-space axes' names, from the observation's (``names``, else ``obs[i]``)."""

    def name(i: int) -> str:
        return names[i] if names is not None and i < len(names) else f"obs[{i}]"

    if task.features is not None:
        return [f"feature {j}" for j in range(task.task_dim)]
    if task.dims is not None:
        sums = ["+".join(name(i) for i in angle) for angle in task.angles or ()]
        trig = [f"{f}({phi})" for phi in sums for f in ("cos", "sin")]
        return trig + [name(d) for d in task.dims]
    return [name(j) for j in range(task.task_dim)]


def _check_task(task: Any) -> None:
    if not isinstance(task, TaskModel):
        raise ValueError(
            f"task must be a swirl_wrappers.TaskModel (TaskModel.from_json reads a file), "
            f"got {type(task).__name__}"
        )


def _task_demos(demos: Any, task: TaskModel) -> list:
    """``demos`` as demonstrations, each checked to hold the task's states (naming the demo);
    one is enough to draw."""
    demos = _as_demonstrations(demos, None, None, minimum=1)
    for k, demo in enumerate(demos):
        try:
            task.check_state_dim(demo.observations.shape[1])
        except ValueError as exc:
            raise ValueError(f"demo {k}: {exc} (demos of another task?)") from None
    return demos


def _segments(task: TaskModel) -> str:
    """The number of segments in words: "1 segment", "3 segments"."""
    return f"{task.n_segments} segment" + ("" if task.n_segments == 1 else "s")


def plot_segments(
    demos: Any,
    task: TaskModel,
    dims: tuple[int, int] = (0, 1),
    *,
    names: Sequence[str] | None = None,
    ax: Axes | None = None,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Demonstrations coloured by segment, with the transition regions as ellipses.

    Each demonstration is segmented with :meth:`TaskModel.segment_indices` (exactly as an agent
    would be) and drawn in task space, projected onto two task-space axes; segment ``i`` and
    the region ``rho_{i+1}`` it leads to share a colour; steps after the last region are grey.
    A region's ellipse is the projection of its ellipsoid (sub-covariance of the two axes, same
    threshold).

    Parameters
    ----------
    demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts (full observations)
    task : TaskModel
    dims : (int, int)
        Task-space axes to draw (after the task's ``dims`` selection and feature map).
    names : sequence of str, optional
        Names of the observation's entries for the axis labels (default ``obs[i]``).
    ax : matplotlib Axes, optional
        Draw into this axes instead of a new figure.
    path : str or path-like, optional
        Save the figure there.

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_task(task)
    demos = _task_demos(demos, task)
    try:  # a pair of whole axes: a tuple, a list, an array
        pair = () if isinstance(dims, str) else tuple(dims)
    except TypeError:
        pair = ()
    whole = len(pair) == 2 and all(isinstance(d, int | np.integer) for d in pair)
    a, b = (int(d) for d in pair) if whole else (-1, -1)
    if task.task_dim < 2 or not (0 <= a < task.task_dim and 0 <= b < task.task_dim and a != b):
        raise ValueError(
            f"dims must be two different task-space axes in 0..{task.task_dim - 1}, got {dims}"
        )
    if ax is None:
        fig = _new_figure((6.4, 5.2))
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    # Steps after the last region (index k) are grey: the demo went on past its final target.
    colors = [*_colors(task.n_segments), (0.5, 0.5, 0.5, 1.0)]
    for k, demo in enumerate(demos):
        x = task.featurize(demo.observations)[:, [a, b]]
        index = task.segment_indices(demo.observations)
        # The step s_t -> s_{t+1} belongs to the segment index[t] (the one rewarding s_{t+1}).
        seg_of_step = index[:-1]
        lines = LineCollection(
            np.stack([x[:-1], x[1:]], axis=1),
            colors=[colors[i] for i in seg_of_step],
            linewidths=1.5,
            alpha=0.8,
        )
        ax.add_collection(lines)
        ax.plot(*x[0], "o", color="black", ms=4, label="start" if k == 0 else None)
        ax.plot(*x[-1], "x", color="black", ms=6, label="end" if k == 0 else None)
    for i, region in enumerate(task.regions):
        cov = region.covariance[np.ix_([a, b], [a, b])]
        vals, vecs = np.linalg.eigh(cov)
        radius = np.sqrt(region.threshold * np.maximum(vals, 0.0))
        angle = np.degrees(np.arctan2(vecs[1, 1], vecs[0, 1]))
        for fill in (True, False):
            ax.add_patch(
                Ellipse(
                    region.mean[[a, b]],
                    2 * radius[1],
                    2 * radius[0],
                    angle=angle,
                    facecolor=colors[i] if fill else "none",
                    edgecolor=colors[i],
                    alpha=0.25 if fill else 1.0,
                    lw=0 if fill else 2.0,
                    label=None if fill else f"region {i}",
                )
            )
    for i in range(task.n_segments):
        ax.plot([], [], color=colors[i], lw=2, label=f"segment {i}")
    if any((task.segment_indices(d.observations)[:-1] == task.n_segments).any() for d in demos):
        ax.plot([], [], color=colors[-1], lw=2, label="after the last region")
    axis_names = _axis_names(task, names)
    ax.set_xlabel(axis_names[a])
    ax.set_ylabel(axis_names[b])
    ax.set_title(f"{len(demos)} demonstration{'s' * (len(demos) != 1)}, {_segments(task)}")
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize="small", ncols=2)
    return _finish(fig, path)


def plot_transitions(
    demos: Any,
    task: TaskModel,
    *,
    max_demos: int = 8,
    path: str | os.PathLike | None = None,
) -> Figure:
    """Each demonstration's motion over time, with the candidate and the final transitions.

    One panel per demonstration (the first ``max_demos``): the speed in task space (each axis
    divided by its spread over all demonstrations) and the change of direction of motion
    (the angle between the mean velocities over the 3 steps before and after each step, the
    velocity indicator's signal), with the candidate transitions the fit's indicator proposed
    (``task.metadata["transitions"]``, when the task was fitted on these demonstrations; the
    legend names the indicator, ``task.metadata["indicator"]``) as dots and the steps at
    which the task's segmentation enters each region as vertical lines. Candidates far from
    every line were dropped by the clustering or the pruning
    (``task.metadata["dropped_regions"]`` says why).

    Parameters
    ----------
    demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts (full observations)
    task : TaskModel
    max_demos : int
    path : str or path-like, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    _check_task(task)
    demos = _task_demos(demos, task)
    shown = demos[: check_int("max_demos", max_demos, low=1)]
    states = [task.featurize(d.observations) for d in demos]
    spread = np.concatenate(states).std(axis=0)
    spread[spread == 0] = 1.0
    candidates = task.metadata.get("transitions")
    indicator = task.metadata.get("indicator")  # the one indicator="auto" chose
    candidate_label = "candidate" if not isinstance(indicator, str) else f"candidate ({indicator})"
    lengths = task.metadata.get("demo_lengths", {})
    if candidates is not None and (
        len(candidates) != len(demos)
        or lengths.get("min") != min(len(d) for d in demos)
        or lengths.get("max") != max(len(d) for d in demos)
    ):
        candidates = None  # fitted on other demonstrations
    colors = _colors(task.n_segments)
    fig = _new_figure((8.0, 1.6 * len(shown) + 0.8))
    axes = fig.subplots(len(shown), 1, sharex=False, squeeze=False)[:, 0]
    w = 3
    for k, (ax, x) in enumerate(zip(axes, states, strict=False)):
        z = x / spread
        speed = np.linalg.norm(np.diff(z, axis=0), axis=1)
        ax.plot(np.arange(1, len(z)), speed, color="tab:gray", lw=1.0, label="speed")
        twin = ax.twinx()
        if len(z) > 2 * w:
            angle = np.degrees(turn_angles(z, w))
            # black and dotted: the regions' lines take tab10's colours
            twin.plot(np.arange(w, len(z) - w), angle, "k:", lw=1.0, label="turn (right axis)")
        twin.set_ylim(0, 180)
        twin.set_ylabel("turn (°)", fontsize="small")
        if candidates is not None and candidates[k]:
            steps = np.asarray(candidates[k], dtype=int)
            ax.plot(
                steps,
                speed[np.clip(steps - 1, 0, len(speed) - 1)],
                "o",
                color="black",
                ms=4,
                label=candidate_label,
            )
        index = task.segment_indices(demos[k].observations)
        for i in range(1, task.n_indices):
            entered = np.flatnonzero(index >= i)
            if entered.size and entered[0] > 0:
                ax.axvline(
                    entered[0], color=colors[i - 1], lw=2, alpha=0.8, label=f"enters region {i - 1}"
                )
        ax.set_ylabel(f"demo {k}\nspeed", fontsize="small")
        pad = max(0.5, 0.01 * len(z))  # a region entered at the last step stays in view
        ax.set_xlim(-pad, len(z) - 1 + pad)
    axes[-1].set_xlabel("step")
    fig.supylabel(
        "speed per step in task space,\neach axis divided by its spread", fontsize="small"
    )
    some = f"{len(shown)} of {len(demos)}" if len(shown) < len(demos) else f"{len(demos)}"
    title = f"Transitions over time: {some} demonstration{'s' * (len(demos) != 1)}, "
    title += _segments(task)
    if candidates is None:
        title += "\n(candidates not shown: the task was fitted on other demonstrations)"
    fig.suptitle(title, fontsize="medium")
    handles, labels = [], []
    for ax in fig.axes:  # the panels and their twins
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="outside lower center", ncols=4, fontsize="small")
    return _finish(fig, path)


def plot_rewards(task: TaskModel, *, path: str | os.PathLike | None = None) -> Figure:
    """The reward matrices ``Psi_i`` as heat maps, one panel per segment (the paper's Fig. 14).

    A larger value means deviation along that axis (pair) is penalised more in that segment.

    Parameters
    ----------
    task : TaskModel
    path : str or path-like, optional
        Save the figure there.

    Returns
    -------
    matplotlib.figure.Figure
        One heat-map axes per segment, each with its colour bar.
    """
    _check_task(task)
    k = task.n_segments
    names = _axis_names(task)
    fig = _new_figure((3.2 * k + 0.6, 3.4))
    axes = fig.subplots(1, k, squeeze=False)[0]
    for i, (ax, reward) in enumerate(zip(axes, task.rewards, strict=True)):
        weight = reward.weight
        limit = float(np.abs(weight).max()) or 1.0
        image = ax.imshow(weight, cmap="RdBu_r", vmin=-limit, vmax=limit)
        ax.set_title(f"segment {i} → region {i}")
        ticks = np.arange(weight.shape[0])
        ax.set_xticks(ticks, names, rotation=45, ha="right", fontsize="small")
        ax.set_yticks(ticks, names, fontsize="small")
        if weight.shape[0] <= 6:
            for r in ticks:
                for c in ticks:
                    value = weight[r, c]
                    ax.text(
                        c,
                        r,
                        f"{value:.2g}",
                        ha="center",
                        va="center",
                        fontsize="small",
                        color="white" if abs(value) > 0.6 * limit else "black",
                    )
        fig.colorbar(image, ax=ax, shrink=0.8)
    fig.suptitle("Reward matrices Ψ_i (larger: deviation penalised more)")
    return _finish(fig, path)


def plot_cut_paths(
    model: Any,
    env: Any,
    *,
    n_episodes: int = 3,
    seed: int = 0,
    path: str | os.PathLike | None = None,
) -> Figure:
    """The tool paths of a policy's greedy episodes over the marked line (line cutting).

    ``env`` is a (possibly wrapped) :class:`~sb3_swirl.envs.dvrk.DVRKLineCuttingEnv`; each
    episode is reset with ``seed + i``. Successful cuts are drawn solid, failed ones dashed.

    Parameters
    ----------
    model : SB3 algorithm or anything with ``predict(obs, deterministic=True)``
    env : gymnasium.Env
        The env the model acts in (SWIRL-wrapped for a SWIRL agent).
    n_episodes : int
        Greedy episodes drawn.
    seed : int
        Seed of the first episode's reset.
    path : str or path-like, optional
        Save the figure there.

    Returns
    -------
    matplotlib.figure.Figure
    """
    base = env.unwrapped
    fig = _new_figure((7, 3.5))
    ax = fig.add_subplot()
    colors = _colors(n_episodes)
    line = None
    for i in range(n_episodes):
        obs, _ = env.reset(seed=seed + i)
        line = base.line * 100.0
        tool = [base.tool_position[:2] * 100.0]
        while True:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(int(action))
            tool.append(base.tool_position[:2] * 100.0)
            if terminated or truncated:
                break
        tool = np.array(tool)
        ok = bool(info.get("is_success"))
        if info.get("cutting"):
            errors = f"errors {info['position_error_cm']:.2f} / {info['tracking_error_cm']:.2f} cm"
            label = f"episode {i}: " + ("cut, " if ok else "failed, ") + errors
        else:
            label = f"episode {i}: failed (never on the line)"
        ax.plot(*tool.T, color=colors[i], linestyle="-" if ok else "--", label=label)
        ax.plot(*tool[0], "o", color=colors[i], markersize=4)
    ax.plot(*line.T, color="black", linewidth=3, alpha=0.6, label="marked line")
    ax.plot(*line[0], "k>", markersize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    shape = "a straight line" if base.radius is None else f"an arc of radius {base.radius:g} cm"
    ax.set_title(f"tool paths over {shape} (greedy policy); errors: position / tracking")
    # below the plot: the paths fill the wide, flat axes, so a legend inside hides them
    fig.legend(loc="outside lower center", fontsize=8, ncol=2)
    ax.grid(alpha=0.3)
    return _finish(fig, path)


def plot_sheet(
    model: Any,
    env: Any,
    *,
    seed: int = 0,
    path: str | os.PathLike | None = None,
) -> Figure:
    """One greedy episode of a policy on the gauze (tensioning): the sheet and its signals.

    Left, the sheet seen from the side (x, z) at the start and at the end of the episode, with
    the tool's path and the 3 x 3 markers whose heights give the disparity; right, the
    disparity, the wrist load and the tool height over the episode (the signals of the paper's
    Fig. 11), with the SWIRL segment switches where ``env`` is a
    :class:`~swirl_wrappers.SwirlWrapper`. ``env`` is a (possibly wrapped)
    :class:`~sb3_swirl.envs.dvrk.DVRKTensioningEnv`, reset with ``seed``.

    Parameters
    ----------
    model : SB3 algorithm or anything with ``predict(obs, deterministic=True)``
    env : gymnasium.Env
        The env the model acts in (SWIRL-wrapped for a SWIRL agent).
    seed : int
        Seed of the episode's reset.
    path : str or path-like, optional
        Save the figure there.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.ticker import SymmetricalLogLocator

    from sb3_swirl.envs.dvrk._robosuite import TABLE_TOP
    from sb3_swirl.envs.dvrk.tensioning import GRID, MARKERS

    base = env.unwrapped
    obs, info = env.reset(seed=seed)
    start = base.vertices
    signals = [np.asarray(obs[:6], dtype=float)]
    segments = [info.get("segment")]  # the SWIRL segment, where the env is wrapped
    while True:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, terminated, truncated, info = env.step(int(action))
        signals.append(np.asarray(obs[:6], dtype=float))
        segments.append(info.get("segment"))
        if terminated or truncated:
            break
    signals = np.array(signals)
    fig = _new_figure((11, 4.6))
    side, over_time = fig.subplots(1, 2)
    for vertices, color, label in ((start, "0.6", "start"), (base.vertices, "C0", "end")):
        grid = ((vertices - [0.0, 0.0, TABLE_TOP]) * 100.0).reshape(GRID, GRID, 3)
        for j in range(GRID):  # each column of the grid, from the free edge to the pins
            side.plot(grid[:, j, 0], grid[:, j, 2], color=color, linewidth=1, alpha=0.8)
        side.plot([], [], color=color, label=f"sheet at the {label}")
    markers = (base.vertices[list(MARKERS)] - [0.0, 0.0, TABLE_TOP]) * 100.0
    side.plot(markers[:, 0], markers[:, 2], "C3.", label="markers (their heights' variance)")
    side.plot(signals[:, 0], signals[:, 2], "k:", linewidth=1, label="tool path")
    side.axhline(0.0, color="saddlebrown", linewidth=2, label="table")
    side.set_aspect("equal")
    side.set_xlabel("x (cm)")
    side.set_ylabel("height above the table (cm)")
    outcome = "flat" if info.get("is_success") else "not flat"
    side.set_title(f"gauze from the side: {outcome}, disparity {info['disparity_cm2']:.3f} cm²")
    side.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncols=3, fontsize=8)
    steps = np.arange(len(signals))
    over_time.plot(steps, signals[:, 5], label="disparity (cm²)")
    over_time.plot(steps, signals[:, 4], label="wrist load (N)")
    over_time.plot(steps, signals[:, 2], label="tool height (cm)")
    over_time.plot(steps, signals[:, 3], label="gripper closed")
    switches = [t for t in range(1, len(segments)) if segments[t] != segments[t - 1]]
    for k, t in enumerate(switches):
        over_time.axvline(
            t,
            color="0.4",
            linestyle="--",
            linewidth=1,
            label="SWIRL segment switch" if k == 0 else None,
        )
    over_time.set_yscale("symlog", linthresh=0.1)
    over_time.set_ylim(bottom=0.0)  # every signal is >= 0
    over_time.yaxis.set_minor_locator(
        SymmetricalLogLocator(base=10, linthresh=0.1, subs=np.arange(2, 10))
    )
    over_time.set_xlabel("step")
    over_time.set_ylabel("each signal in its unit (symlog scale)")
    over_time.set_title("signals over the episode (greedy policy)")
    over_time.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncols=3, fontsize=8)
    for ax in (side, over_time):
        ax.grid(alpha=0.3)
        ax.grid(alpha=0.15, which="minor")
    return _finish(fig, path)
