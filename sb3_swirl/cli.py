"""The ``sb3-swirl`` command line: make demos, fit a proxy task, inspect it, run the main job."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from sb3_swirl.experiments import PRESETS, REPRODUCTIONS, _writable_folder

console = Console(stderr=True)
# another indicator's dynamics error within 1% of the kept one's is a near tie; `fit` says so
# when its segment count differs (on the segmentation benchmark: 11 of 145 tuning sets and 5
# of 145 held-out ones, 4 and 2 of them fits with a switch F1 under 0.9)
_NEAR_TIE = 0.01


def _dims(text: str) -> list[int]:
    """``--dims 0,1,3``: comma-separated observation dims."""
    try:
        return [int(d) for d in text.split(",") if d.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers (e.g. 0,1,3), got {text!r}"
        ) from None


def _env_kwarg(text: str) -> tuple[str, Any]:
    """``--env-kwarg observation_dims=[6,7,8]``: a setting of ``gym.make``, its value JSON or a
    Python literal (``true``, ``False``, ``None``, ``.5``, ``(6, 7)``), else a plain string."""
    import ast
    import json

    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(
            f"expected NAME=VALUE (e.g. goal_offset=true), got {text!r}"
        )
    for parse in (json.loads, ast.literal_eval):
        try:
            return key, parse(value)
        except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
            continue
    return key, value


def _angles(text: str) -> list[list[int]]:
    """``--angles 0;0,1``: ';'-separated groups of dims, each summed into one angle."""
    groups = [_dims(group) for group in text.split(";")]
    if not all(groups):
        raise argparse.ArgumentTypeError(f"every ';'-separated group needs a dim, got {text!r}")
    return groups


def integer_arg(
    low: int, high: int | None = None, shown: str | None = None
) -> Callable[[str], int]:
    """An argparse type: an integer in ``[low, high)`` (``high`` None: no bound), or argparse's
    usage error saying ``expected an integer >= low`` (or ``in [low, shown)``). The benchmark
    scripts use it too."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low or (high is not None and value >= high):
            bound = f">= {low}" if high is None else f"in [{low}, {shown or high})"
            raise argparse.ArgumentTypeError(f"expected an integer {bound}, got {text!r}")
        return value

    return parse


#: ``--seed``: an integer numpy accepts as a seed
_seed = integer_arg(0, 2**32, "2**32")
#: ``--jobs``, ``-n``: an integer >= 1
_positive = integer_arg(1)


def _n_demos(text: str) -> int:
    """``demos -n``: SWIRL needs at least 2 demonstrations (checked before collecting)."""
    value = _positive(text)
    if value < 2:
        raise argparse.ArgumentTypeError(f"SWIRL needs at least 2 demonstrations, got {text!r}")
    return value


def _check_output(output: str, *inputs: str | None) -> None:
    """Raise before any long work unless the file ``output`` can be written and is none of
    ``inputs``."""
    if not output.strip():
        raise ValueError("the output (-o) is empty; give a file name")
    path = Path(output)
    for source in inputs:
        if source is not None and (
            path.resolve() == Path(source).resolve()
            or (path.exists() and Path(source).exists() and path.samefile(source))
        ):
            raise ValueError(
                f"the output {output} is the input {source}: writing it would replace what is "
                "being read; choose another -o"
            )
    if path.is_dir():
        raise ValueError(f"the output {output} is a directory; give a file name")
    _writable_folder(path.resolve().parent)
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(f"the output {output} is not writable")


class _DemoHelp(argparse.Action):
    """``demo --help``, ending with every task's defaults (read from the zoo entries only
    when asked, not at every start)."""

    def __call__(self, parser: argparse.ArgumentParser, *args: Any) -> None:
        defaults = "; ".join(
            f"{name}: {preset.n_demos} demos, {preset.total_timesteps} steps"
            for name, preset in sorted(PRESETS.items())
        )
        parser.epilog = f"the tasks' defaults: {defaults}"
        parser.print_help()
        parser.exit()


def _cmd_demos(args: argparse.Namespace) -> int:
    from sb3_swirl.demos import save_demos
    from sb3_swirl.supervisors import collect_demos

    _check_output(args.output)
    console.print(f"collecting {args.n} demos of {args.env_id}")
    state_key = None if args.state_key is None else args.state_key.split(",")
    if state_key is not None and not all(key.strip() for key in state_key):
        raise ValueError(f"--state-key: an empty key in {args.state_key!r}")
    env_kwargs = dict(args.env_kwarg)
    if len(env_kwargs) < len(args.env_kwarg):
        raise ValueError("--env-kwarg: a setting given twice")
    demos = collect_demos(
        args.env_id,
        args.n,
        seed=args.seed,
        progress=not args.quiet,
        state_key=state_key,
        **env_kwargs,
    )
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    save_demos(demos, args.output)
    lengths = [len(d) for d in demos]
    cut = sum(d.truncated for d in demos)
    console.print(
        f"wrote {len(demos)} demos of {args.env_id} to {args.output} "
        f"(lengths {min(lengths)}–{max(lengths)} steps"
        + (f"; {cut} ended at the env's time limit, recorded as truncated)" if cut else ")")
    )
    return 0


def _cmd_fit(args: argparse.Namespace) -> int:
    from sb3_swirl.demos import load_demos
    from sb3_swirl.fitting import fit_task

    _check_output(args.output, args.demos)
    demos = load_demos(args.demos)
    if len(demos) < 2:
        raise ValueError(f"{args.demos} holds 1 demonstration: SWIRL needs at least 2")
    segmentation = {"indicator": args.indicator}
    if args.window is not None:
        segmentation["window"] = args.window
    if args.min_demo_fraction is not None:
        segmentation["min_demo_fraction"] = args.min_demo_fraction
    if args.reg_covar is not None:
        segmentation["reg_covar"] = args.reg_covar
    if args.no_merge_fragments:
        segmentation["merge_fragments"] = False
    if args.cluster_all_dims:
        segmentation["ignore_nuisance_dims"] = False
    if args.merge_same_dynamics:
        segmentation["merge_same_dynamics"] = True
    if args.no_align_entries:
        segmentation["align_entries"] = False
    if args.no_normalize_time:
        segmentation["normalize_time"] = False
    if args.reward == "maxent" and args.metric != "mahalanobis":
        raise ValueError("--metric is the quadratic reward's; --reward maxent learns its own")
    reward = "maxent" if args.reward == "maxent" else {"metric": args.metric}
    with console.status(f"fitting SWIRL on {len(demos)} demos...") as status:
        task = fit_task(
            demos,
            dims=args.dims,
            angles=args.angles,
            segmentation=segmentation,
            reward=reward,
            random_state=args.seed,
            progress=lambda msg: status.update(msg),
        )
    Path(args.output).parent.mkdir(parents=True, exist_ok=True)
    task.to_json(args.output)
    console.print(
        f"wrote a task with {task.n_segments} segment{'s' * (task.n_segments != 1)} to "
        f"{args.output}"
    )
    scores = task.metadata["indicator_scores"]
    if len(scores) > 1:
        segments = task.metadata["indicator_segments"]
        tried = ", ".join(
            f"{name} failed" if error is None else f"{name} {error:.4g} ({segments[name]})"
            for name, error in scores.items()
        )
        console.print(
            f"indicator: {task.metadata['indicator']} (dynamics error, lower is better, and "
            f"segments: {tried})"
        )
        _print_near_ties(task.metadata["indicator"], scores, segments)
        for name, why in task.metadata.get("indicator_failures", {}).items():
            console.print(f"  {name} failed: {why}", markup=False)
    switches = task.metadata["switches"]
    shown = "; ".join(f"demo {d}: {s}" for d, s in enumerate(switches[:5]))
    console.print(
        f"steps at which each demo enters a new segment: {shown}"
        + (f"; ... ({len(switches) - 5} more in the task's metadata)" if len(switches) > 5 else "")
    )
    _print_task(task)
    return 0


def _print_near_ties(kept: str, scores: dict, segments: dict) -> None:
    """Say which other indicators explain the demos nearly as well with another count."""
    close: dict[int, list[str]] = {}
    for name, error in scores.items():
        if (
            error is not None
            and segments[name] not in (0, segments[kept])
            and error <= scores[kept] * (1 + _NEAR_TIE)
        ):
            close.setdefault(segments[name], []).append(name)
    for count, names in close.items():
        names.sort(key=scores.__getitem__)  # the closest first: the one to try
        worst = scores[names[-1]] - scores[kept]
        gap = worst / scores[kept] if scores[kept] > 0 else 0.0
        console.print(
            f"  {' and '.join(names)} explain{'s' * (len(names) == 1)} the demos nearly as well "
            f"(within {100 * gap:.2g}%) with {count} segment{'s' * (count != 1)} against "
            f"{segments[kept]}: the "
            f"demos barely decide between them; to compare, fit with --indicator {names[0]} "
            "and look at both with `sb3-swirl show TASK --plot DIR --demos DEMOS`"
        )


def _print_task(task) -> None:
    # the metadata is the fit's record, not part of the task: a hand-edited one is shown as
    # far as it reads
    kept = task.metadata.get("cluster_dims")  # absent from tasks fitted before it existed
    if isinstance(kept, list) and all(isinstance(k, int) for k in kept):
        ignored = sorted(set(range(task.regions[0].mean.size)) - set(kept))
        console.print(
            f"transition states clustered without task-space dims {ignored}: they move on "
            "their own in each demo and cut transitions into fragments (--cluster-all-dims "
            "to use them)"
        )
    dropped = task.metadata.get("dropped_regions")
    merged = [
        d
        for d in (dropped if isinstance(dropped, list) else [])
        if isinstance(d, dict)
        and "merge_same_dynamics=True" in str(d.get("reason"))
        and isinstance(d.get("time"), int | float)
    ]
    if merged:
        steps = ", ".join(f"{d['time']:.0f}" for d in merged)
        console.print(
            f"dropped {len(merged)} region(s) (near steps {steps}): the segments on either "
            "side follow the same locally linear dynamics (--merge-same-dynamics)"
        )
    table = Table(
        title=f"SWIRL proxy task: {task.n_segments} segment{'s' * (task.n_segments != 1)}",
        caption="segment i leads to region i; its reward is -(x - centre)ᵀ Ψ (x - centre)",
    )
    for name in ("segment", "region centre", "χ² threshold", "time window", "diag(Ψ)"):
        table.add_column(name)
    for i, (region, reward) in enumerate(zip(task.regions, task.rewards, strict=True)):
        bounds = region.time_bounds
        table.add_row(
            str(i),
            " ".join(f"{v:.3g}" for v in region.mean),
            f"{region.threshold:.3g}",
            "any" if bounds is None else f"{bounds[0]:.0f}–{bounds[1]:.0f}",
            " ".join(f"{v:.3g}" for v in reward.weight.diagonal()),
        )
    Console().print(table)


def _cmd_show(args: argparse.Namespace) -> int:
    from swirl_wrappers import TaskModel

    if args.demos is not None and args.plot is None:
        raise ValueError(
            "--demos are drawn in DIR/segments.png and transitions.png: give --plot DIR too"
        )
    if args.plot is not None:
        _writable_folder(Path(args.plot))
        names = ["rewards.png"] + (["segments.png", "transitions.png"] if args.demos else [])
        for name in names:
            if (Path(args.plot) / name).is_dir():
                raise ValueError(f"cannot write {Path(args.plot) / name}: it is a folder")
    task = TaskModel.from_json(args.task)
    demos = None
    if args.demos is not None:  # read and checked before anything is printed or written
        from sb3_swirl.demos import load_demos
        from sb3_swirl.plotting import _task_demos

        demos = load_demos(args.demos)  # its errors name the file
        try:
            demos = _task_demos(demos, task)
        except ValueError as exc:
            raise ValueError(f"{args.demos}: {exc}") from None
    _print_task(task)
    if args.plot is not None:
        from sb3_swirl.plotting import plot_rewards, plot_segments, plot_transitions

        out = Path(args.plot)
        out.mkdir(parents=True, exist_ok=True)
        plot_rewards(task, path=out / "rewards.png")
        written = [out / "rewards.png"]
        if demos is not None:
            plot_segments(demos, task, path=out / "segments.png")
            plot_transitions(demos, task, path=out / "transitions.png")
            written += [out / "segments.png", out / "transitions.png"]
        console.print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from sb3_swirl.experiments import run_demo

    _writable_folder(Path(args.out))
    run_demo(
        args.task,
        seed=args.seed,
        n_demos=args.n_demos,
        total_timesteps=args.timesteps,
        out_dir=args.out,
        progress=not args.quiet,
    )
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from sb3_swirl.experiments import EXPERIMENTS, reproduce_all

    _writable_folder(Path(args.out))
    if args.address and args.backend != "ray":
        raise ValueError("--address is a Ray cluster's: add --backend ray")
    if args.name != "fig9" and args.repeats is not None:
        raise ValueError("--repeats is Fig. 9's (random demo sets)")
    for flag in ("panels", "methods"):
        if getattr(args, flag) and args.name not in EXPERIMENTS:
            raise ValueError(f"--{flag} applies to the figures, not to {args.name}")
    for flag in ("seeds", "panels", "methods"):  # one was run once, and the table said so
        given = getattr(args, flag) or []
        twice = sorted({value for value in given if given.count(value) > 1})
        if twice:
            raise ValueError(f"--{flag} names {', '.join(map(str, twice))} more than once")
    common = {
        "quick": args.quick,
        "out_dir": args.out,
        "progress": not args.quiet,
        "backend": args.backend,
        "jobs": args.jobs,
        "address": args.address,
        "resume": args.resume,
    }
    if args.name == "all":
        if args.seeds:
            raise ValueError("--seeds applies to one table or figure, not to all")
        reproduce_all(**common)
    elif args.name in EXPERIMENTS:
        REPRODUCTIONS[args.name](
            **common,
            seeds=args.seeds,
            panels=args.panels,
            methods=args.methods,
            repeats=args.repeats,
        )
    else:
        REPRODUCTIONS[args.name](**common, seeds=args.seeds)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sb3-swirl",
        description="SWIRL for Stable-Baselines3: demos -> segments -> rewards -> RL.",
    )
    from sb3_swirl import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demos", help="generate supervisor demonstrations of a shipped env")
    p.add_argument("env_id", help="e.g. sb3_swirl/ParallelParking-v0")
    p.add_argument("-n", type=_n_demos, default=5, help="number of demos, 2 or more (default 5)")
    p.add_argument(
        "--seed", type=_seed, default=0, help="seeds the episodes and the supervisor (default 0)"
    )
    p.add_argument("-o", "--output", required=True, help="output .npz file")
    p.add_argument(
        "--state-key",
        help="Dict observations (Fetch): the comma-separated keys a demo records, joined in "
        "this order, the wrapper's state_key (default: observation)",
    )
    p.add_argument(
        "--env-kwarg",
        type=_env_kwarg,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a setting of the env, its value JSON or a Python literal (repeatable; e.g. "
        "goal_offset=true observation_dims=[6,7,8])",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_demos)

    p = sub.add_parser("fit", help="fit a SWIRL proxy task to demonstrations")
    p.add_argument("demos", help=".npz file of demonstrations (see `sb3-swirl demos`)")
    p.add_argument("-o", "--output", required=True, help="output task JSON")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the fit (default 0)")
    p.add_argument(
        "--indicator",
        default="auto",
        help="auto (default: the best of gmm, velocity, linear and phases by how well locally "
        "linear dynamics explain the demos), gmm (the paper's), velocity, linear, phases "
        "(phases with their own linear dynamics, shared by every demo), ruptures (needs the "
        "ruptures package), or several joined by '+'",
    )
    p.add_argument(
        "--window",
        type=int,
        default=None,
        help="window length of the indicator (default 3 for gmm and velocity; linear: "
        "max(2 (dims + 1), 8); phases and ruptures: the fewest steps of a phase)",
    )
    p.add_argument(
        "--min-demo-fraction",
        type=float,
        default=None,
        help="keep a transition region shared by at least this fraction of the demos "
        "(default 1.0: all, as in the paper's Algorithm 1)",
    )
    p.add_argument(
        "--reg-covar",
        type=float,
        default=None,
        help="floor of each region's covariance, relative to each axis's variance (default "
        "1e-4; few demos: raise it; parking with 5 demos: 0.1)",
    )
    p.add_argument(
        "--no-merge-fragments",
        action="store_true",
        help="prune state clusters that hold only some demos as the paper's Algorithm 1 does, "
        "without first merging those that share no demo and overlap in time",
    )
    p.add_argument(
        "--cluster-all-dims",
        action="store_true",
        help="cluster transition states on every dimension, also those that move on their "
        "own in each demo (by default left out where they cut transitions into fragments)",
    )
    p.add_argument(
        "--merge-same-dynamics",
        action="store_true",
        help="drop each transition region without which the demos are explained as locally "
        "linear dynamics as well (cuts where the motion only slows down within a phase)",
    )
    p.add_argument(
        "--no-align-entries",
        action="store_true",
        help="build each region from the demos' transition states, as the paper's Algorithm 1 "
        "does (by default from their states up to a window later, where entering the region "
        "best matches the demos' own transitions)",
    )
    p.add_argument(
        "--no-normalize-time",
        action="store_true",
        help="run the indicator on the demos as given, not resampled to a common rate "
        "(parking's, the acrobot's and Fetch's zoo entries fit so)",
    )
    p.add_argument(
        "--reward",
        default="quadratic",
        choices=["quadratic", "maxent"],
        help="quadratic (default: model-free, from the segment's demo states) or maxent "
        "(maximum-entropy IRL on the demos' actions, with a linear model of each segment)",
    )
    p.add_argument(
        "--metric",
        default="mahalanobis",
        choices=["mahalanobis", "euclidean"],
        help="distance of each segment's quadratic reward (default mahalanobis: weighted by "
        "the inverse covariance of the segment's demo states)",
    )
    p.add_argument(
        "--dims", type=_dims, help="comma-separated observation dims to use (e.g. 0,1,3)"
    )
    p.add_argument(
        "--angles",
        type=_angles,
        help="angles as sums of observation dims, ';'-separated, used as (cos, sin) "
        "(acrobot: '0;0,1' for theta1 and theta1+theta2; then --dims selects the rest)",
    )
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser("show", help="print a fitted task; optionally plot it")
    p.add_argument("task", help="task JSON written by `sb3-swirl fit`")
    p.add_argument(
        "--plot",
        metavar="DIR",
        default=None,
        help="write rewards.png (with --demos also segments.png, transitions.png)",
    )
    p.add_argument(
        "--demos", default=None, help="demos .npz to draw in segments.png and transitions.png"
    )
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("demo", help="the main job: SWIRL vs DQN on a shipped task", add_help=False)
    p.add_argument(
        "-h", "--help", action=_DemoHelp, nargs=0, help="show this help message and exit"
    )
    p.add_argument("task", choices=sorted(PRESETS), metavar="TASK", help=", ".join(sorted(PRESETS)))
    p.add_argument("--seed", type=_seed, default=0, help="seed of the demos and agents (default 0)")
    p.add_argument("--n-demos", type=int, default=None, help="default: the task's (listed below)")
    p.add_argument(
        "--timesteps",
        type=int,
        default=None,
        help="training steps per method (default: the task's, listed below; fewer for a "
        "quick look)",
    )
    p.add_argument("--out", default="results", help="output folder (default results/)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("reproduce", help="reproduce a table or figure of the paper")
    p.add_argument(
        "name",
        choices=[*REPRODUCTIONS, "all"],
        metavar="NAME",
        help=", ".join([*REPRODUCTIONS, "all"]),
    )
    p.add_argument(
        "--quick", action="store_true", help="one seed (fig9: three), small budgets (minutes)"
    )
    p.add_argument("--seeds", type=_seed, nargs="+", default=None, help="override the seeds")
    p.add_argument("--out", default="results", help="output folder (default results/)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.add_argument("--jobs", type=_positive, default=2, help="runs at once (default 2)")
    p.add_argument(
        "--backend",
        default="joblib",
        choices=["joblib", "ray"],
        help="where the runs go: local processes (default) or a Ray cluster "
        "(pip install sb3-swirl[ray])",
    )
    p.add_argument(
        "--address",
        default=None,
        help="with --backend ray: the cluster's address (HEAD:6379, auto for the one started "
        "on this machine with `ray start --head`, or ray://HEAD:10001); default: a local Ray "
        "with --jobs workers",
    )
    p.add_argument("--resume", action="store_true", help="continue an interrupted sweep")
    p.add_argument(
        "--panels", nargs="+", default=None, help="a subset of a figure's panels (e.g. parking)"
    )
    p.add_argument(
        "--methods",
        nargs="+",
        default=None,
        help="a subset of a figure's methods by name, as its records and results.json spell "
        "them (e.g. swirl dqn; a wrong one lists the figure's)",
    )
    p.add_argument("--repeats", type=int, default=None, help="fig9: random demo sets (default 20)")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser(
        "zoo",
        help="RL Baselines3 Zoo with swirl_dqn: train, enjoy, plot_train, all_plots, "
        "plot_from_file, with rl_zoo3's own arguments",
        add_help=False,
    )
    p.add_argument("args", nargs=argparse.REMAINDER)
    return parser


# The fit's messages advise in TransitionStateClustering's arguments; `sb3-swirl fit` says
# them as its flags (the ones it has). Keyed on the wording of segmentation.py's messages
# (_warn_lost, _check_complete, fit): tests/test_cli.py checks the translated lines.
_AS_FLAGS = [
    (re.compile(r"indicator='(\w+)'"), r"--indicator \1"),
    (re.compile(r"min_demo_fraction=(\S+?)(?=[ ,;)]|$)"), r"--min-demo-fraction \1"),
    (re.compile(r"(lower|raise) min_demo_fraction"), r"\1 --min-demo-fraction"),
    (re.compile(r"the indicator or window"), "--indicator or --window"),
    (re.compile(r"a longer window"), "a longer --window"),
    (re.compile(r"merge_fragments=True"), "without --no-merge-fragments"),
    (re.compile(r"merge_same_dynamics=False"), "without --merge-same-dynamics"),
    (re.compile(r"merge_same_dynamics=True"), "--merge-same-dynamics"),
]


def _as_flags(text: str) -> str:
    """``text`` with the fit's arguments named as ``sb3-swirl fit``'s flags."""
    for pattern, flag in _AS_FLAGS:
        text = pattern.sub(flag, text)
    return text


def _warning_printer(say: Callable[[str], str]) -> Callable[..., None]:
    """``warnings.showwarning`` printing each warning on one line, worded by ``say``."""

    def show(message: Warning | str, *args: Any, **kwargs: Any) -> None:
        console.print(f"[yellow]warning:[/] {escape(say(str(message)))}", soft_wrap=True)

    return show


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, a job scheduler) taken as Ctrl-C is."""


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """While a command runs, SIGTERM stops it as Ctrl-C does: a sweep stops its workers (killed
    outright, its joblib workers would go on running their jobs) and no file is half-written."""
    if threading.current_thread() is not threading.main_thread():  # only there can it be set
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``sb3-swirl`` command."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["zoo"]:  # rl_zoo3 parses its own arguments, and prints its own errors
        from sb3_swirl.zoo import main as zoo_main

        try:  # Ctrl-C while training: rl_zoo3 saves the model so far and exits 0
            with _terminate_as_interrupt():
                return zoo_main(argv[1:])
        except KeyboardInterrupt as exc:
            return _interrupted(exc)
    args = build_parser().parse_args(argv)
    return run_command(lambda: args.func(args), _as_flags if args.func is _cmd_fit else str)


def run_command(command: Callable[[], int | None], say: Callable[[str], str] = str) -> int:
    """Run ``command`` as ``sb3-swirl`` runs each of its commands (the benchmark scripts too).

    Each warning is one line; a bad setting or path (``ValueError``, ``OSError``,
    ``ImportError``) is one ``error:`` line and exit status 2; Ctrl-C or SIGTERM stops it with
    one line and 130 or 143. ``say`` words the messages (``sb3-swirl fit``: as its flags).
    """
    try:
        with warnings.catch_warnings(), _terminate_as_interrupt():
            warnings.showwarning = _warning_printer(say)
            return command() or 0
    # OSError: a path that is a folder, unwritable...; ImportError: an optional extra missing
    except (ValueError, OSError, ImportError) as exc:
        # soft_wrap: never break a path a user may copy; escape: paths may contain [brackets]
        console.print(f"[bold red]error:[/] {escape(say(str(exc)))}", soft_wrap=True)
        return 2
    except KeyboardInterrupt as exc:  # files are written atomically: none is left half-done
        return _interrupted(exc)


def _interrupted(exc: KeyboardInterrupt) -> int:
    """Say how a command was stopped (Ctrl-C, or SIGTERM); its exit status."""
    console.print("terminated" if isinstance(exc, _Terminated) else "interrupted")
    return 128 + (signal.SIGTERM if isinstance(exc, _Terminated) else signal.SIGINT)


if __name__ == "__main__":
    sys.exit(main())
