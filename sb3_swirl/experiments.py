"""The main job: demos -> SWIRL -> training -> comparison with DQN -> plot and table.

``run_demo("parking")`` is what ``make demo`` / ``sb3-swirl demo parking`` runs. Hyperparameters
come from ``zoo_configs/{swirl_dqn,dqn}.yml`` (rl-zoo format), so the CLI, the benchmark and
rl-zoo share one tuned set.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import statistics
import sys
import textwrap
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from importlib.resources import files
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_int, check_option

#: progress and summaries; 160 columns when piped to a log, so no title is cut at 80
console = Console(stderr=True, width=None if sys.stderr.isatty() else 160)


def _table_console() -> Console:
    """Where tables are printed: the terminal's width, or 160 columns when piped to a file."""
    return Console(width=None if sys.stdout.isatty() else 160)


#: what the tables print after a ``--quick`` run
_QUICK_TABLE = ". A --quick run (few episodes) checks the pipeline; it is not the result"


def _output_name(stem: str, suffix: str, quick: bool) -> str:
    """``results.json`` for a full run, ``results_quick.json`` for ``--quick``: a quick run
    never overwrites the full run's outputs."""
    return f"{stem}{'_quick' if quick else ''}{suffix}"


@contextmanager
def _kept_warnings() -> Iterator[list[str]]:
    """Warnings raised inside, kept (once each, deprecations left out) in the list it yields
    instead of printed: a sweep's worker processes would interleave them with its progress
    bar. The record of the run carries them."""
    kept: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield kept
    kept.extend(
        dict.fromkeys(
            f"{w.category.__name__}: {w.message}"
            for w in caught
            if not issubclass(w.category, DeprecationWarning)
        )
    )


def _writable_folder(path: Path) -> None:
    """Raise unless files can be made in folder ``path`` (created if missing, as by mkdir -p)."""
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"cannot write into {path}: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"cannot write into {path}: {existing} is not writable")


def _check_outputs(folder: Path, names: Sequence[str]) -> None:
    """Raise before any work where the files ``names`` cannot be written into ``folder``: it
    cannot be made or written into, or one of the names is a folder (the write failed after
    the training, or with a raw ``[Errno 17]``)."""
    _writable_folder(folder)
    for name in names:
        if (folder / name).is_dir():
            raise ValueError(f"cannot write {folder / name}: it is a folder")


def _sweep_outputs(out_dir: str | Path, name: str, quick: bool) -> tuple[Path, Path]:
    """Sweep ``name``'s runs file and results file. Results without the runs beside them (an
    earlier version's table, or runs moved away) are an error, with ``resume`` too: a sweep
    cannot go on from them, and they are not overwritten."""
    out = Path(out_dir) / name
    runs_file = out / _output_name("runs", ".jsonl", quick)
    results = out / _output_name("results", ".json", quick)
    _check_outputs(out, [runs_file.name, results.name, _output_name("figure", ".png", quick)])
    if results.exists() and not runs_file.exists():
        raise ValueError(
            f"{results} exists without its runs ({runs_file.name}), so --resume cannot go on "
            "from it: it is not overwritten; move it away or choose another output"
        )
    return runs_file, results


def _say_others(runs_file: Path, work: list[dict[str, Any]], which: str) -> None:
    """Say so when a resumed sweep's ``runs_file`` holds runs that ``work`` does not ask for
    (``which``: "other seeds, ..."): the results cover only this call's runs."""
    from sb3_swirl.runner import _key, _read_done

    others = len(_read_done(runs_file).keys() - {_key(job) for job in work})
    if others > 0:
        console.print(
            f"{runs_file.name} also holds {others} run{'s' * (others != 1)} this command did not "
            f"ask for ({which}); the results cover only this command's runs: ask for them all, "
            "with --resume, to see them together",
            soft_wrap=True,
        )


def _sweep(
    name: str,
    function: Any,
    work: list[dict[str, Any]],
    quick: bool,
    out_dir: str | Path,
    backend: str,
    jobs: int,
    address: str | None,
    resume: bool,
    progress: bool,
) -> tuple[list[dict[str, Any]], Path, Path, dict[str, str]]:
    """Table or figure ``name``'s jobs through :func:`sb3_swirl.runner.run_sweep` into
    ``out_dir/name/runs.jsonl``, stamped with :func:`_settings_stamp`: their records, the
    runs file, where the results go and the stamp."""
    from sb3_swirl.runner import run_sweep

    runs_file, results = _sweep_outputs(out_dir, name, quick)
    stamp = _settings_stamp()
    records = run_sweep(
        function,
        work,
        runs_file,
        backend=backend,
        n_jobs=jobs,
        address=address,
        resume=resume,
        progress=progress,
        stamp=stamp,
    )
    return records, runs_file, results, stamp


def _table_warnings(work: list[dict[str, Any]], records: list[dict[str, Any]]) -> None:
    """Print each warning of a table's runs once, with the seeds whose runs raised it (a
    seed's fit warns in each of its runs)."""
    warned: dict[str, list[int]] = {}
    for job, record in zip(work, records, strict=True):
        for text in record["warnings"]:
            warned.setdefault(text, []).append(job["seed"])
    for text, seeds in warned.items():
        which = ", ".join(map(str, dict.fromkeys(seeds)))
        console.print(f"warning (seed {which}; {len(seeds)} of {len(records)} runs): {text}")


@dataclass(frozen=True)
class Preset:
    """What the main job runs on one shipped task.

    The demos, the fit and the budget are those of the task's entry in
    ``zoo_configs/swirl_dqn.yml`` (its ``SwirlTaskWrapper`` settings and ``n_timesteps``), so
    ``sb3-swirl demo`` and ``sb3-swirl zoo train`` run the same setup.
    """

    env_id: str
    eval_freq: int
    n_eval_episodes: int
    target_success: float
    #: the two observation axes ``segments.png`` draws, and the observation's entries' names
    plot_dims: tuple[int, int] = (0, 1)
    names: tuple[str, ...] | None = None
    #: the demo's table also gives the final true return (the task's score beside success)
    return_column: bool = False

    @property
    def swirl(self) -> dict[str, Any]:
        """The ``SwirlTaskWrapper`` settings of the task's ``swirl_dqn`` entry."""
        return _swirl_spec(load_hyperparams("swirl_dqn", self.env_id))

    @property
    def n_demos(self) -> int:
        """Supervisor demos (``demos: {n_demos: ...}``)."""
        return int(self.swirl["demos"]["n_demos"])

    @property
    def fit_kwargs(self) -> dict[str, Any]:
        """:func:`sb3_swirl.fit_task` settings (``fit:``)."""
        return dict(self.swirl.get("fit") or {})

    @property
    def demo_env_kwargs(self) -> dict[str, Any]:
        """``gym.make`` arguments of the env the supervisor demonstrates on."""
        return dict(self.swirl["demos"].get("env_kwargs") or {})

    @property
    def state_key(self) -> str | list[str] | None:
        """What a demo records of a ``Dict`` observation (the wrapper's ``state_key``)."""
        return self.swirl.get("state_key")

    @property
    def total_timesteps(self) -> int:
        """The training budget (``n_timesteps``)."""
        return int(load_hyperparams("swirl_dqn", self.env_id)["n_timesteps"])


PRESETS: dict[str, Preset] = {
    "parking": Preset(
        "sb3_swirl/ParallelParking-v0",
        1_000,
        20,
        0.95,
        names=("x (m)", "y (m)", "heading (rad)", "speed (m/s)"),
    ),
    # evaluation episodes are up to 1000 steps: evaluate less often
    "acrobot": Preset("sb3_swirl/NoisyAcrobot-v0", 10_000, 10, 0.95),
    # the paper's §10.2: demos on straight lines at random positions; the agent learns on one
    "linecutting": Preset(
        "sb3_swirl/DVRKLineCutting-v0",
        500,
        10,
        0.95,
        names=("x (cm)", "y (cm)", "offset from the line (cm)"),
    ),
    # the paper's §10.1; the segments seen from the side (x, height): reach down, lift, pull
    "tensioning": Preset(
        "sb3_swirl/DVRKTensioning-v0",
        2_000,
        5,
        0.95,
        plot_dims=(0, 2),
        names=(
            "x (cm)",
            "y (cm)",
            "height (cm)",
            "gripper closed",
            "wrist load (N)",
            "disparity (cm²)",
        ),
        return_column=True,  # Table 1's value
    ),
    # gymnasium-robotics' Fetch tasks, to 90% success; the segments drawn over the goal's
    # offset from the gripper (reach: x, y), the object's (push: x, y; pick-and-place: x, z)
    "fetchreach": Preset("sb3_swirl/FetchReachDiscrete-v0", 1_000, 20, 0.9),
    "fetchpush": Preset("sb3_swirl/FetchPushDiscrete-v0", 5_000, 10, 0.9),
    "fetchpickandplace": Preset(
        "sb3_swirl/FetchPickAndPlaceDiscrete-v0", 5_000, 10, 0.9, plot_dims=(0, 2)
    ),
}

_ZOO_ONLY_KEYS = {
    "n_timesteps",
    "policy",
    "env_wrapper",
    "env_kwargs",
    "normalize",
    "frame_stack",
    "callback",
    "monitor_kwargs",  # the zoo's monitor file only
}


def _checked_seeds(seeds: list[int]) -> list[int]:
    """Each seed once, in the order given (a repeated one would count its runs twice), and
    each an integer >= 0."""
    seeds = list(dict.fromkeys(seeds))
    for seed in seeds:
        check_int("seed", seed, low=0)
    return seeds


def _settings_stamp() -> dict[str, str]:
    """What a run depends on beyond its arguments: this package's version and a digest of the
    shipped zoo configs (the tuned hyperparameters; their parsed entries, so that a comment or
    a layout change leaves the stamp as it was). Stored with sweeps' runs and results."""
    from sb3_swirl import __version__

    digest = hashlib.sha256()
    for algo in ("dqn", "swirl_dqn"):
        digest.update(json.dumps(_shipped_entries(algo), sort_keys=True).encode())
    return {"sb3_swirl": __version__, "zoo_configs": digest.hexdigest()[:16]}


def _shipped_entries(algo: str) -> dict[str, Any]:
    """The parsed entries of the shipped ``zoo_configs/{algo}.yml``."""
    path = files("sb3_swirl.zoo_configs") / f"{algo}.yml"
    if not path.is_file():
        raise ValueError(f"no zoo config for algorithm {algo!r} ({path})")
    return yaml.safe_load(path.read_text())


def load_hyperparams(algo: str, env_id: str) -> dict[str, Any]:
    """The tuned hyperparameters of ``algo`` on ``env_id`` from the shipped zoo configs.

    Returns the rl-zoo entry as a dict: ``policy``, ``n_timesteps``, the algorithm's constructor
    arguments and, for ``swirl_dqn``, ``env_wrapper`` (the SWIRL wrapper's arguments).
    """
    entries = _shipped_entries(algo)
    if env_id not in entries and "default" not in entries:
        raise ValueError(f"{algo}.yml has no entry for {env_id} and no default")
    return dict(entries.get(env_id, entries.get("default")))


def _algo_kwargs(hyperparams: dict[str, Any]) -> dict[str, Any]:
    kwargs = {k: v for k, v in hyperparams.items() if k not in _ZOO_ONLY_KEYS}
    if "policy_kwargs" in kwargs:
        kwargs["policy_kwargs"] = _policy_kwargs(kwargs["policy_kwargs"])
    if isinstance(kwargs.get("learning_rate"), str):
        kwargs["learning_rate"] = _linear_schedule(kwargs["learning_rate"])
    return kwargs


def _linear_schedule(value: str) -> Any:
    """rl-zoo's ``lin_<initial value>``: a learning rate that falls linearly to 0 over the run."""
    from stable_baselines3.common.utils import LinearSchedule

    kind, _, initial = value.partition("_")
    if kind == "lin":
        try:
            return LinearSchedule(float(initial), 0.0, 1.0)
        except ValueError:
            pass
    raise ValueError(f"learning_rate {value!r}: give a number or rl-zoo's 'lin_<initial value>'")


def _policy_kwargs(policy_kwargs: Any) -> dict[str, Any] | None:
    """An rl-zoo ``policy_kwargs`` value as a dict. rl-zoo evaluates strings in its own
    module's scope, which has nn, th and np but not sb3_swirl (hence
    ``__import__('sb3_swirl').KeysExtractor`` in our entries); we give nn, th and np."""
    import torch as th
    from torch import nn

    if isinstance(policy_kwargs, str):
        return eval(policy_kwargs, {"nn": nn, "th": th, "np": np})
    return policy_kwargs


def _normalize_kwargs(normalize: Any) -> dict[str, Any] | None:
    """``VecNormalize`` arguments of an rl-zoo ``normalize`` value (``true``, a mapping or its
    string); None for ``false``."""
    if isinstance(normalize, str):
        normalize = eval(normalize, {})  # rl-zoo evaluates it the same way
    if normalize is False or normalize is None:
        return None
    return {} if normalize is True else dict(normalize)


def _swirl_spec(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """The ``sb3_swirl.zoo.SwirlTaskWrapper`` settings of an rl-zoo entry's ``env_wrapper``."""
    wrappers = hyperparams.get("env_wrapper") or []
    for entry in wrappers if isinstance(wrappers, list) else [wrappers]:
        if isinstance(entry, dict) and "sb3_swirl.zoo.SwirlTaskWrapper" in entry:
            return dict(entry["sb3_swirl.zoo.SwirlTaskWrapper"] or {})
    return {}


def _swirl_wrapper_kwargs(hyperparams: dict[str, Any]) -> dict[str, Any]:
    """The ``SwirlWrapper`` arguments (no task) of an rl-zoo entry's ``SwirlTaskWrapper``."""
    spec = _swirl_spec(hyperparams)
    keys = ("reward_config", "terminate_on_completion", "state_key")
    return {key: spec[key] for key in keys if key in spec}


def rollouts_to_success(
    curve: list[dict[str, float]], target: float, key: str = "episodes"
) -> int | None:
    """Training episodes (or another ``key`` of the curve: ``"timesteps"``) completed at the
    first evaluation whose success rate reaches ``target``."""
    for point in curve:
        if point["success_rate"] >= target:
            return int(point[key])
    return None


def rollout_ratio(
    ours: dict[str, Any], theirs: dict[str, Any], target: float, key: str = "episodes"
) -> dict[str, Any]:
    """Rollouts to ``target`` success of two runs on one seed (records with a ``curve``) and
    their ratio ours / theirs, which a run that never reaches the target *censors*: it needed
    more than the ``N`` rollouts it ran.

    ``kind`` says what the ratio is: ``"="`` measured; ``"<"`` an upper bound (only ours
    reached: ours / N_theirs); ``">"`` a lower bound (only theirs reached); ``"?"`` unknown
    (neither reached, or theirs reached before finishing a rollout). ``key`` counts env steps
    (``"timesteps"``) instead of rollouts.
    """
    out: dict[str, Any] = {"target": target}
    for name, run in (("ours", ours), ("theirs", theirs)):
        out[name] = rollouts_to_success(run["curve"], target, key)
        out[f"{name}_rollouts_run"] = int(run["curve"][-1][key]) if run["curve"] else 0
    s, t = out["ours"], out["theirs"]
    if t == 0 or (s is None and t is None):
        out.update(ratio=None, kind="?")
    elif s is not None and t is not None:
        out.update(ratio=s / t, kind="=")
    elif s is not None:
        out.update(ratio=s / max(out["theirs_rollouts_run"], 1), kind="<")
    else:
        out.update(ratio=out["ours_rollouts_run"] / t, kind=">")
    return out


def summarise_ratios(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The median of per-seed ratios (:func:`rollout_ratio`), exact when every one is measured.
    Otherwise each seed counts at an upper bound of its ratio (its censoring bound, or +inf
    where only a lower bound or nothing is known): the median being monotone in every value,
    the median of these bounds bounds the true median from above (``bound`` ``"<="``). It is
    ``"unresolved"`` when that bound is +inf."""
    kinds = [r["kind"] for r in rows]
    uppers = [r["ratio"] if r["kind"] in ("=", "<") else math.inf for r in rows]
    summary: dict[str, Any] = {
        "n_seeds": len(rows),
        "ours_reached": sum(r.get("ours") is not None for r in rows),
        "theirs_reached": sum(r.get("theirs") is not None for r in rows),
        "kinds": kinds,
        "n_infinite": sum(math.isinf(u) for u in uppers),
    }
    median = statistics.median(uppers) if uppers else math.inf
    if math.isinf(median):
        summary.update(median=None, bound="unresolved")
        return summary
    # "higher": quartiles of upper bounds stay upper bounds (no interpolation towards +inf)
    q25, q75 = np.percentile(uppers, [25, 75], method="higher")
    return summary | {
        "median": median,
        "bound": "=" if all(k == "=" for k in kinds) else "<=",
        "min": min(uppers),
        "max": max(uppers),
        "q25": float(q25),
        "q75": float(q75),
    }


def train_and_evaluate(
    algo: str,
    preset: Preset,
    *,
    task=None,
    demos=None,
    total_timesteps: int,
    seed: int,
    progress: bool = True,
    hyperparams: dict[str, Any] | None = None,
    keep_model: bool = False,
    env_kwargs: dict[str, Any] | None = None,
    max_episodes: int | None = None,
) -> dict[str, Any]:
    """Train ``algo`` ("swirl_dqn" or "dqn") and evaluate true success along the way.

    ``hyperparams`` (rl-zoo format) default to ``zoo_configs/{algo}.yml``'s for the env.
    ``env_kwargs`` go to ``gym.make`` for the training and evaluation envs, over the entry's
    own ``env_kwargs``; ``max_episodes``
    stops training after that many training episodes (or ``total_timesteps``, if sooner).
    Returns the learning curve (timesteps, training episodes, success rate, true return at each
    evaluation), the final success rate and the wall time; with ``keep_model``, also the trained
    model and its evaluation env under ``"model"`` and ``"eval_env"`` (not JSON).
    """
    from stable_baselines3 import DQN

    from sb3_swirl.callbacks import TaskEvalCallback
    from sb3_swirl.dqn import SwirlDQN
    from swirl_wrappers import SwirlWrapper

    check_int("total_timesteps", total_timesteps, low=1)
    if hyperparams is None:
        hyperparams = load_hyperparams(algo, preset.env_id)
    kwargs = _algo_kwargs(hyperparams)
    policy = hyperparams.get("policy", "MlpPolicy")
    env_kwargs = {**(hyperparams.get("env_kwargs") or {}), **(env_kwargs or {})}

    def make(env_seed: int) -> gym.Env:
        env = gym.make(preset.env_id, **env_kwargs)
        if algo == "swirl_dqn":
            env = SwirlWrapper(env, task, **_swirl_wrapper_kwargs(hyperparams))
        env.reset(seed=env_seed)
        return env

    env, eval_env = make(seed), make(seed + 10_000)
    normalize = _normalize_kwargs(hyperparams.get("normalize", False))
    if normalize is not None:  # rl-zoo's `normalize`: VecNormalize, statistics synced to eval
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

        def vectorised(one: gym.Env) -> DummyVecEnv:
            return DummyVecEnv([lambda: one])

        env = VecNormalize(vectorised(env), **normalize)
        eval_env = VecNormalize(
            vectorised(eval_env), training=False, **{**normalize, "norm_reward": False}
        )
    if algo == "swirl_dqn":
        model = SwirlDQN(policy, env, demonstrations=demos, seed=seed, **kwargs)
    else:
        model = DQN(policy, env, seed=seed, **kwargs)
    callback = TaskEvalCallback(
        eval_env,
        n_eval_episodes=preset.n_eval_episodes,
        eval_freq=min(preset.eval_freq, total_timesteps),
        deterministic=True,
        verbose=0,
    )
    callbacks: list[Any] = [callback]
    if max_episodes is not None:
        from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

        callbacks.append(StopTrainingOnMaxEpisodes(check_int("max_episodes", max_episodes, low=1)))
    start = time.perf_counter()
    model.learn(total_timesteps=total_timesteps, callback=callbacks, progress_bar=progress)
    wall = time.perf_counter() - start
    if callback.evaluations_timesteps[-1:] != [model.num_timesteps]:
        callback.evaluate()  # the final policy, when the budget is not a multiple of eval_freq
    curve = [
        {
            "timesteps": int(t),
            "episodes": int(e),
            "success_rate": float(s),
            "task_return": float(r),
        }
        for t, e, s, r in zip(
            callback.evaluations_timesteps,
            callback.evaluations_episodes,
            callback.success_rates,
            callback.task_returns,
            strict=True,
        )
    ]
    best = max(curve, key=lambda p: p["success_rate"], default=None)
    # the settings this run used: its own budget, not the entry's n_timesteps
    used = {**hyperparams, "n_timesteps": total_timesteps}
    spec = _swirl_spec(used)
    if demos is not None and "demos" in spec:  # the run's demos, not the entry's
        spec["demos"] = f"{len(demos)} demos given to the run"  # _swirl_spec returns a copy
        wrappers = used["env_wrapper"]
        used["env_wrapper"] = [
            {"sb3_swirl.zoo.SwirlTaskWrapper": spec}
            if isinstance(w, dict) and "sb3_swirl.zoo.SwirlTaskWrapper" in w
            else w
            for w in (wrappers if isinstance(wrappers, list) else [wrappers])
        ]
    return {
        "algo": algo,
        "hyperparams": used,
        "curve": curve,
        "final_success": curve[-1]["success_rate"] if curve else float("nan"),
        "best_success": best["success_rate"] if best else float("nan"),
        "best_success_episodes": best["episodes"] if best else None,
        "rollouts_to_target": rollouts_to_success(curve, preset.target_success),
        "wall_time_s": wall,
    } | ({"model": model, "eval_env": eval_env} if keep_model else {})


def write_results(results: dict[str, Any], path: str | Path) -> None:
    """Write ``results`` as indented JSON, atomically: a failure leaves the old file."""
    with atomic_write(path) as fh:
        fh.write(json.dumps(results, indent=1))


def plot_learning_curves(
    runs: list[dict[str, Any]], preset: Preset, path: Path, n_demos: int | None = None
) -> None:
    """Success rate and true return against training episodes, one line per method (the
    paper's Fig. 2; the return is what Table 1 reports for tensioning). ``n_demos``: the demos
    trained from, in the title (default the preset's)."""
    from matplotlib.ticker import MaxNLocator

    from sb3_swirl.plotting import _finish, _new_figure

    fig = _new_figure((11, 4))
    success_ax, return_ax = fig.subplots(1, 2)
    labels = {"swirl_dqn": "SWIRL (SwirlDQN)", "dqn": "DQN"}
    for run in runs:
        episodes = [p["episodes"] for p in run["curve"]]
        size = 3 if len(episodes) > 2 else 7  # a short run's few evaluations stay visible
        for ax, key in ((success_ax, "success_rate"), (return_ax, "task_return")):
            values = [p[key] for p in run["curve"]]
            ax.plot(episodes, values, marker="o", markersize=size, label=labels[run["algo"]])
    success_ax.axhline(
        preset.target_success,
        color="grey",
        linestyle="--",
        linewidth=1,
        label=f"target ({preset.target_success:.0%})",
    )
    success_ax.set_ylabel(f"true success rate ({preset.n_eval_episodes} eval episodes)")
    success_ax.set_ylim(-0.02, 1.02)
    return_ax.set_ylabel("true return (mean over eval episodes)")
    for ax in (success_ax, return_ax):
        ax.set_xlabel("training episodes (rollouts)")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    fig.suptitle(f"{preset.env_id}: {preset.n_demos if n_demos is None else n_demos} demos")
    _finish(fig, path)


def _swirl_env(env_id: str, task: Any, hyperparams: dict[str, Any], **env_kwargs: Any) -> gym.Env:
    """``env_id`` made with the entry's ``env_kwargs`` (``env_kwargs`` over them) and lifted by
    ``SwirlWrapper`` with the entry's settings."""
    from swirl_wrappers import SwirlWrapper

    env = gym.make(env_id, **{**(hyperparams.get("env_kwargs") or {}), **env_kwargs})
    return SwirlWrapper(env, task, **_swirl_wrapper_kwargs(hyperparams))


def _save_final_frame(
    model: Any, preset: Preset, task: Any, hyperparams: dict[str, Any], seed: int, path: Path
) -> bool:
    """Save the last frame (``rgb_array``) of one greedy episode of a SWIRL ``model``; False,
    with a note, where offscreen rendering is not available (it needs EGL)."""
    from matplotlib.image import imsave

    try:
        env = _swirl_env(preset.env_id, task, hyperparams, render_mode="rgb_array")
        greedy_infos(model, env, seed)
        picture = env.render()
        env.close()
    except Exception as exc:  # no OpenGL here: the picture is optional, the plots are not
        console.print(f"no rendered picture ({type(exc).__name__}: {exc}); the plots are there")
        return False
    with atomic_write(path, "wb") as fh:
        imsave(fh, picture, format="png")
    return True


def run_demo(
    name: str,
    *,
    seed: int = 0,
    n_demos: int | None = None,
    total_timesteps: int | None = None,
    out_dir: str | Path = "results",
    progress: bool = True,
) -> dict[str, Any]:
    """Run the main job on a shipped task and write ``<out_dir>/<name>/``.

    Parameters
    ----------
    name : {"parking", "acrobot", "linecutting", "tensioning"}
    seed : int
        Seeds the demos, the SWIRL fit, both learners and the evaluation envs.
    n_demos, total_timesteps : int, optional
        Override the preset's number of demos and training steps per method.
    out_dir : path
        ``results.json``, ``learning_curve.png`` and ``segments.png`` go in ``out_dir/name``;
        line cutting adds ``cut_paths.png`` and ``cut_paths_arc.png`` (SWIRL's greedy paths on
        a straight line and, with no exploration there, on an arc of 3 cm), tensioning
        ``sheet.png``, and the dVRK and Fetch tasks ``final_frame.png`` where EGL works.
    progress : bool
        Show progress bars.

    Returns
    -------
    dict
        What ``results.json`` holds.
    """
    from sb3_swirl.fitting import fit_task
    from sb3_swirl.plotting import _segments, plot_segments
    from sb3_swirl.supervisors import collect_demos

    if name not in PRESETS:
        raise ValueError(f"unknown task {name!r}; choose from {sorted(PRESETS)}")
    preset = PRESETS[name]
    n_demos = preset.n_demos if n_demos is None else n_demos
    steps = preset.total_timesteps if total_timesteps is None else total_timesteps
    check_int("n_demos", n_demos, low=2)
    check_int("total_timesteps", steps, low=1)
    out = Path(out_dir) / name
    _check_outputs(
        out,
        [
            *("results.json", "learning_curve.png", "segments.png", "task.json"),
            *("cut_paths.png", "cut_paths_arc.png", "sheet.png", "final_frame.png"),
        ],
    )
    out.mkdir(parents=True, exist_ok=True)

    console.rule(f"[bold]SWIRL vs DQN on {preset.env_id}")
    demos = collect_demos(
        preset.env_id,
        n_demos,
        seed=seed,
        progress=progress,
        state_key=preset.state_key,
        **preset.demo_env_kwargs,
    )
    console.print(f"{n_demos} supervisor demos, {sum(len(d) for d in demos)} steps")
    fit_start = time.perf_counter()
    task = fit_task(demos, random_state=seed, **preset.fit_kwargs)
    fit_time = time.perf_counter() - fit_start
    console.print(f"SWIRL found {_segments(task)} in {fit_time:.1f} s")
    task.to_json(out / "task.json")
    plot_segments(demos, task, preset.plot_dims, names=preset.names, path=out / "segments.png")

    runs = []
    for algo in ("swirl_dqn", "dqn"):
        console.print(f"training {algo} for {steps} steps")
        runs.append(
            train_and_evaluate(
                algo,
                preset,
                task=task,
                demos=demos,
                total_timesteps=steps,
                seed=seed,
                progress=progress,
                keep_model=True,
            )
        )
    models = [(run.pop("model"), run.pop("eval_env")) for run in runs]
    pictures = ["segments.png"]
    if preset.env_id == "sb3_swirl/DVRKLineCutting-v0":
        from sb3_swirl.plotting import plot_cut_paths

        plot_cut_paths(*models[0], path=out / "cut_paths.png", seed=seed)
        # the same policy on an arc that no demo showed (Table 2 explores 25 episodes on it)
        arc = _swirl_env(preset.env_id, task, runs[0]["hyperparams"], radius=3.0)
        plot_cut_paths(models[0][0], arc, path=out / "cut_paths_arc.png", seed=seed)
        arc.close()
        pictures += ["cut_paths.png", "cut_paths_arc.png"]
    elif preset.env_id == "sb3_swirl/DVRKTensioning-v0":
        from sb3_swirl.plotting import plot_sheet

        plot_sheet(*models[0], path=out / "sheet.png", seed=seed)
        pictures.append("sheet.png")
    if preset.env_id.startswith(("sb3_swirl/DVRK", "sb3_swirl/Fetch")):
        frame = out / "final_frame.png"
        if _save_final_frame(models[0][0], preset, task, runs[0]["hyperparams"], seed, frame):
            pictures.append(frame.name)
    swirl, dqn = runs
    ratio = None
    if swirl["rollouts_to_target"] is not None and dqn["rollouts_to_target"]:
        ratio = swirl["rollouts_to_target"] / dqn["rollouts_to_target"]
    results = {
        "task": name,
        "preset": asdict(preset)
        | {"n_demos": n_demos, "total_timesteps": steps, "fit_kwargs": preset.fit_kwargs},
        "seed": seed,
        "n_segments": task.n_segments,
        "fit_time_s": fit_time,
        "runs": runs,
        "rollout_ratio_swirl_over_dqn": ratio,
    }
    write_results(results, out / "results.json")
    plot_learning_curves(runs, preset, out / "learning_curve.png", n_demos)

    table = Table(title=f"{name}: SWIRL vs DQN ({steps} steps each, seed {seed})")
    table.add_column("method")
    table.add_column(f"rollouts to {preset.target_success:.0%} success", justify="right")
    table.add_column("best success (at rollout)", justify="right")
    table.add_column("final success", justify="right")
    if preset.return_column:
        table.add_column("final true return", justify="right")
    table.add_column("wall time", justify="right")
    for run in runs:
        reached = run["rollouts_to_target"]
        final_return = [f"{run['curve'][-1]['task_return']:.1f}"] if preset.return_column else []
        table.add_row(
            run["algo"],
            "not reached" if reached is None else str(reached),
            f"{run['best_success']:.0%}"
            + (f" ({run['best_success_episodes']})" if run["best_success"] > 0 else ""),
            f"{run['final_success']:.0%}",
            *final_return,
            f"{run['wall_time_s']:.0f} s",
        )
    _table_console().print(table)
    if ratio is not None:
        console.print(f"SWIRL needed {ratio:.2f}× DQN's rollouts")
    console.print(f"wrote {out}/results.json, learning_curve.png, {', '.join(pictures)}, task.json")
    return results


#: Table 1 of the paper (gauze tensioning, 15 demos, 100 rollouts): the disparity value.
PAPER_TABLE1 = {
    "rl": -8210.0,
    "bc": -7591.0,
    "segmented_bc": -3516.0,
    "swirl": -3110.0,
    "swirl_no_bc": None,  # "success only in the first two segments", no value given
    "supervisor": None,  # not reported
}
_TABLE1_LABELS = {
    "rl": "pure exploration (DQN)",
    "bc": "pure demonstration (BC)",
    "segmented_bc": "segmented demonstrations (BC on the lifted state)",
    "swirl": "SWIRL (BC start + rollouts)",
    "swirl_no_bc": "SWIRL without the BC start",
    "supervisor": "the demonstrator (our supervisor)",
}


class _OneEpisode:
    """A supervisor as a policy with SB3's ``predict``, for one episode: it is reset on the
    episode's first observation."""

    def __init__(self, supervisor: Any) -> None:
        self.supervisor = supervisor
        self._started = False

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[int, None]:
        if not self._started:
            self.supervisor.reset(obs)
            self._started = True
        return self.supervisor.act(obs), None


def greedy_infos(policy: Any, env: gym.Env, seed: int) -> list[dict[str, Any]]:
    """The ``info`` of every step of one greedy episode of ``policy`` (anything with SB3's
    ``predict``) in ``env``, reset with ``seed``; a model trained under ``VecNormalize`` sees
    the observations normalised as in training."""
    normalizer = getattr(policy, "get_vec_normalize_env", lambda: None)()
    obs, _ = env.reset(seed=seed)
    infos = []
    while True:
        seen = obs if normalizer is None else normalizer.normalize_obs(obs)
        action, _ = policy.predict(seen, deterministic=True)
        obs, _, terminated, truncated, info = env.step(int(action))
        infos.append(info)
        if terminated or truncated:
            return infos


def _score_policy(policy: Any, env: gym.Env, seeds: list[int]) -> dict[str, float]:
    """:func:`_score_episodes` of greedy episodes of ``policy``, one per seed."""
    return _score_episodes([greedy_infos(policy, env, seed) for seed in seeds])


def _score_episodes(episodes: list[list[dict[str, Any]]]) -> dict[str, float]:
    """Tensioning episodes (each a list of step infos): mean disparity value (minus the
    disparity summed over the episode), success (flat at the end) and grasp rates."""
    return {
        "value": float(np.mean([-sum(i["disparity_cm2"] for i in e) for e in episodes])),
        "success_rate": float(np.mean([e[-1]["is_success"] for e in episodes])),
        "grasp_rate": float(np.mean([any(i["grasped"] for i in e) for e in episodes])),
    }


#: Table 1's learners: (algorithm, whether it learns from the demos, hyperparameter overrides)
_TABLE1_LEARNERS: dict[str, tuple[str, bool, dict[str, Any]]] = {
    "rl": ("dqn", False, {}),
    "swirl": ("swirl_dqn", True, {}),
    "swirl_no_bc": (
        "swirl_dqn",
        False,
        {
            "prefill_replay": False,
            "pretrain_td_steps": 0,
            "demo_loss_coef": 0.0,
            "exploration_initial_eps": 1.0,
        },
    ),
}
#: Table 1's jobs per seed: each learner (long), and the methods scored without training
_TABLE1_GROUPS = (*_TABLE1_LEARNERS, "clones")


def table1_run(seed: int, group: str, steps: int, n_eval: int) -> dict[str, Any]:
    """One job of :func:`reproduce_table1`: seed ``seed``'s 15 supervisor demos and SWIRL's
    fit, then the methods of ``group`` scored on ``n_eval`` greedy episodes: ``"clones"``
    (BC on the raw and on the lifted observation, and the supervisor; no training) or one
    learner (``"rl"``, ``"swirl"``, ``"swirl_no_bc"``) trained for ``steps`` env steps.
    Module-level with JSON arguments and result: sweeps
    (:func:`sb3_swirl.runner.run_sweep`) run it in other processes.

    Returns
    -------
    dict
        ``"methods"`` (method -> its scores: value, success and grasp rates, and the
        learner's ``wall_time_s``), ``"n_segments"`` (the fit's; None for ``"rl"``, which
        learns without demos) and ``"warnings"`` (of the fit and the training).
    """
    import torch

    from sb3_swirl.baselines import BCPolicy, lifted_demos
    from sb3_swirl.fitting import fit_task
    from sb3_swirl.supervisors import TensioningSupervisor, collect_demos
    from swirl_wrappers import SwirlWrapper

    check_option("group", group, _TABLE1_GROUPS)
    torch.set_num_threads(1)  # tiny networks: extra threads only contend for the cores
    base = PRESETS["tensioning"]
    # train_and_evaluate's own evaluation runs once, at the end, on one episode: every method
    # is scored below on the same episodes
    preset = replace(base, eval_freq=steps, n_eval_episodes=1)
    eval_seeds = [20_000 + 100 * seed + i for i in range(n_eval)]
    methods: dict[str, dict[str, Any]] = {}
    task = None
    with _kept_warnings() as kept:
        if group != "rl":  # pure exploration learns from no demos and no fit
            demos = collect_demos(base.env_id, base.n_demos, seed=seed, progress=False)
            task = fit_task(demos, random_state=seed, **base.fit_kwargs)
        if group == "clones":
            env = gym.make(base.env_id)
            lifted_env = SwirlWrapper(gym.make(base.env_id), task)
            observations = np.concatenate([d.observations[:-1] for d in demos])
            actions = np.concatenate([d.actions for d in demos])
            lifted = lifted_demos(demos, task, env.observation_space)
            clones = {
                "bc": (BCPolicy(random_state=seed).fit(observations, actions), env),
                "segmented_bc": (BCPolicy(random_state=seed).fit(*lifted), lifted_env),
            }
            for name, (policy, score_env) in clones.items():
                methods[name] = _score_policy(policy, score_env, eval_seeds)
            episodes = [
                greedy_infos(_OneEpisode(TensioningSupervisor(env.unwrapped, seed=s)), env, s)
                for s in eval_seeds
            ]
            methods["supervisor"] = _score_episodes(episodes)
            env.close()
            lifted_env.close()
        else:
            algo, with_demos, overrides = _TABLE1_LEARNERS[group]
            run = train_and_evaluate(
                algo,
                preset,
                task=task,
                demos=demos if with_demos else None,
                total_timesteps=steps,
                seed=seed,
                progress=False,
                hyperparams=load_hyperparams(algo, base.env_id) | overrides,
                keep_model=True,
            )
            scored = _score_policy(run["model"], run["eval_env"], eval_seeds)
            methods[group] = {"wall_time_s": run["wall_time_s"]} | scored
            run["eval_env"].close()
    return {
        "methods": methods,
        "n_segments": None if task is None else task.n_segments,
        "warnings": kept,
    }


def reproduce_table1(
    *,
    quick: bool = False,
    seeds: list[int] | None = None,
    out_dir: str | Path = "results",
    progress: bool = True,
    backend: str = "joblib",
    jobs: int = 2,
    address: str | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """The paper's Table 1 on ``DVRKTensioning-v0``: five methods, 15 demos, 100 rollouts.

    Per seed: 15 supervisor demos; SWIRL's fit; a BC clone of the demos on the raw observation
    (``bc``) and on the lifted one (``segmented_bc``, run in the SWIRL wrapper); DQN from
    scratch (``rl``), SwirlDQN (``swirl``) and SwirlDQN without demos (``swirl_no_bc``) for the
    same number of steps; and the supervisor that made the demos (``supervisor``, seeded with
    each episode's seed), the demonstrator's own score. Every method is scored on the same
    greedy evaluation episodes by the disparity value (minus the disparity in cm² summed over
    the 100 steps; the paper's units are not given, so only ratios compare).

    A sweep of four jobs per seed (:func:`table1_run`: the three learners, and the rest) through
    :func:`sb3_swirl.runner.run_sweep`, as the figures are: each record lands in
    ``out_dir/table1/runs.jsonl`` as it finishes (``resume`` goes on from it). Then writes
    ``out_dir/table1/results.json``; with ``quick``, ``runs_quick.jsonl`` and
    ``results_quick.json``.

    Parameters
    ----------
    quick : bool
        One seed, 20 rollouts, 3 evaluation episodes (minutes), instead of seeds 0-2, 100
        rollouts and 10 evaluation episodes.
    seeds : list of int, optional
        Override the seeds.
    backend, jobs, address, resume : see :func:`sb3_swirl.runner.run_sweep`
    """
    base = PRESETS["tensioning"]
    steps = 2_000 if quick else base.total_timesteps
    n_eval = 3 if quick else 10
    seeds = _checked_seeds(([0] if quick else [0, 1, 2]) if seeds is None else seeds)
    console.rule(f"[bold]Table 1: gauze tensioning, {len(seeds)} seed(s), {steps} steps")
    work = [
        {"seed": seed, "group": group, "steps": steps, "n_eval": n_eval}
        for seed in seeds
        for group in _TABLE1_GROUPS
    ]
    records, runs_file, path, stamp = _sweep(
        "table1", table1_run, work, quick, out_dir, backend, jobs, address, resume, progress
    )
    _say_others(runs_file, work, "other seeds")
    _table_warnings(work, records)
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in _TABLE1_LABELS}
    segments = []
    for job, record in zip(work, records, strict=True):
        if job["group"] == "clones":
            segments.append(record["n_segments"])
        for name, scores in record["methods"].items():
            runs[name].append({"seed": job["seed"]} | scores)

    summary = {}
    for name, per_seed in runs.items():
        values = [r["value"] for r in per_seed]
        summary[name] = {
            "value_mean": float(np.mean(values)),
            "value_std": float(np.std(values)),
            "success_rate": float(np.mean([r["success_rate"] for r in per_seed])),
            "grasp_rate": float(np.mean([r["grasp_rate"] for r in per_seed])),
            "paper_value": PAPER_TABLE1[name],
        }
    gain = 1.0 - summary["swirl"]["value_mean"] / summary["segmented_bc"]["value_mean"]
    results = {
        "experiment": "table1",
        "env_id": base.env_id,
        "settings": {
            "n_demos": base.n_demos,
            "total_timesteps": steps,
            "n_eval_episodes": n_eval,
            "seeds": seeds,
            "quick": quick,
        },
        "n_segments": segments,
        "runs": runs,
        "summary": summary,
        "swirl_gain_over_segmented_bc": gain,
        "paper_swirl_gain_over_segmented_bc": 1.0
        - PAPER_TABLE1["swirl"] / PAPER_TABLE1["segmented_bc"],
        "stamp": stamp,
    }
    write_results(results, path)

    table = Table(
        title=f"Table 1, gauze tensioning ({len(seeds)} seed(s) × {n_eval} episodes)",
        caption="value: minus the disparity (cm²) summed over the episode; the paper's is in units "
        "it does not state, so compare ratios, not values",
    )
    spread = len(seeds) > 1
    value = "value (mean ± std over seeds)" if spread else "value"
    for column in ("method", value, "flat at the end", "grasped"):
        table.add_column(column, justify="left" if column == "method" else "right")
    table.add_column("paper", justify="right")
    for name, row in summary.items():
        paper = row["paper_value"]
        table.add_row(
            _TABLE1_LABELS[name],
            f"{row['value_mean']:.1f}" + (f" ± {row['value_std']:.1f}" if spread else ""),
            f"{row['success_rate']:.0%}",
            f"{row['grasp_rate']:.0%}",
            "—" if paper is None else f"{paper:.0f}",
        )
    _table_console().print(table)
    console.print(
        f"SWIRL's value is {abs(gain):.1%} {'better' if gain >= 0 else 'worse'} than segmented "
        "BC's "
        f"(paper: {results['paper_swirl_gain_over_segmented_bc']:.1%}); "
        f"SWIRL found {', '.join(map(str, segments))} segments"
        + (" (per seed)" if spread else "")
        + (_QUICK_TABLE if quick else "")
        + f". Wrote {path}"
    )
    return results


#: Table 2 of the paper (line cutting): radius (cm, None = straight) -> (SVM position error,
#: SVM tracking error, SWIRL position error, SWIRL tracking error) in cm; None where the SVM
#: failed.
PAPER_TABLE2 = {
    None: (0.46, 0.23, 0.42, 0.21),
    4.0: (0.43, 0.59, 0.45, 0.33),
    3.5: (0.51, 1.21, 0.56, 0.38),
    3.0: (0.86, 3.03, 0.66, 0.57),
    2.5: (1.43, None, 0.74, 0.87),
    2.0: (None, None, 0.87, 1.45),
    1.5: (None, None, 1.12, 2.44),
}


def _score_cuts(policy: Any, env: gym.Env, seeds: list[int]) -> dict[str, Any]:
    """Greedy line-cutting episodes: how many began a cut and succeeded, and the mean position
    and tracking errors (cm) of those that began one (None if none did)."""
    position, tracking, successes = [], [], []
    for seed in seeds:
        info = greedy_infos(policy, env, seed)[-1]
        successes.append(bool(info["is_success"]))
        if info["cutting"]:
            position.append(info["position_error_cm"])
            tracking.append(info["tracking_error_cm"])
    return {
        "success_rate": float(np.mean(successes)),
        "began_cut_rate": len(position) / len(seeds),
        "position_error_cm": float(np.mean(position)) if position else None,
        "tracking_error_cm": float(np.mean(tracking)) if tracking else None,
    }


def table2_run(seed: int, radius: float | None, episodes: int, n_eval: int) -> dict[str, Any]:
    """One job of :func:`reproduce_table2`: seed ``seed``'s 5 straight-line demos, SWIRL's fit
    and the SVM clone, then SwirlDQN with ``episodes`` episodes of exploration on the line of
    ``radius`` (cm; None: straight), and both policies scored by :func:`_score_cuts` on
    ``n_eval`` greedy episodes. Module-level with JSON arguments and result, for
    :func:`sb3_swirl.runner.run_sweep`.

    Returns
    -------
    dict
        ``"svm"`` and ``"swirl"`` (their :func:`_score_cuts`), ``"n_segments"`` (the fit's)
        and ``"warnings"`` (of the fit and the training).
    """
    import torch

    from sb3_swirl.baselines import BCPolicy
    from sb3_swirl.fitting import fit_task
    from sb3_swirl.supervisors import collect_demos

    torch.set_num_threads(1)  # tiny networks: extra threads only contend for the cores
    preset = PRESETS["linecutting"]
    eval_seeds = [30_000 + 100 * seed + i for i in range(n_eval)]
    with _kept_warnings() as kept:
        demos = collect_demos(
            preset.env_id, preset.n_demos, seed=seed, progress=False, **preset.demo_env_kwargs
        )
        task = fit_task(demos, random_state=seed, **preset.fit_kwargs)
        observations = np.concatenate([d.observations[:-1] for d in demos])
        actions = np.concatenate([d.actions for d in demos])
        svm = BCPolicy("svm", random_state=seed).fit(observations, actions)
        env = gym.make(preset.env_id, radius=radius)
        swirl = train_and_evaluate(
            "swirl_dqn",
            replace(preset, eval_freq=10**9, n_eval_episodes=1),
            task=task,
            demos=demos,
            total_timesteps=150 * episodes,
            seed=seed,
            progress=False,
            keep_model=True,
            env_kwargs={"radius": radius},
            max_episodes=episodes,
        )
        scores = {
            "svm": _score_cuts(svm, env, eval_seeds),
            "swirl": _score_cuts(swirl["model"], swirl["eval_env"], eval_seeds),
        }
        env.close()
        swirl["eval_env"].close()
    return {"n_segments": task.n_segments} | scores | {"warnings": kept}


def reproduce_table2(
    *,
    quick: bool = False,
    seeds: list[int] | None = None,
    out_dir: str | Path = "results",
    progress: bool = True,
    backend: str = "joblib",
    jobs: int = 2,
    address: str | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """The paper's Table 2 on ``DVRKLineCutting-v0``: SWIRL vs an SVM clone on curved lines.

    Per seed: 5 supervisor demos on straight lines at random positions (``line_jitter=3``);
    SWIRL's fit on them; an RBF-kernel SVM clone of them (the paper's SVM baseline); then for
    every test line (straight, and arcs of radius 4.0 to 1.5 cm) SwirlDQN from the demos with
    25 episodes of exploration on that line, and both policies scored on the same greedy
    episodes: cut success (start within 1 cm of the line's start, never more than 1 cm off it),
    position and tracking errors (cm, over the episodes that began a cut).

    A sweep of one job per seed and line (:func:`table2_run`) through
    :func:`sb3_swirl.runner.run_sweep`, as the figures are: each record lands in
    ``out_dir/table2/runs.jsonl`` as it finishes (``resume`` goes on from it). Then writes
    ``out_dir/table2/results.json``; with ``quick``, ``runs_quick.jsonl`` and
    ``results_quick.json``.

    Parameters
    ----------
    quick : bool
        One seed, three lines (straight, r = 3.0 and 1.5 cm), 10 episodes of exploration and 5
        evaluation episodes, instead of seeds 0-2, the seven lines, 25 and 15.
    seeds : list of int, optional
        Override the seeds.
    backend, jobs, address, resume : see :func:`sb3_swirl.runner.run_sweep`
    """
    preset = PRESETS["linecutting"]
    radii = [None, 3.0, 1.5] if quick else list(PAPER_TABLE2)
    episodes, n_eval = (10, 5) if quick else (25, 15)
    seeds = _checked_seeds(([0] if quick else [0, 1, 2]) if seeds is None else seeds)
    console.rule(
        f"[bold]Table 2: line cutting, {len(seeds)} seed(s), {episodes} episodes of exploration"
    )
    work = [
        {"seed": seed, "radius": radius, "episodes": episodes, "n_eval": n_eval}
        for seed in seeds
        for radius in radii
    ]
    records, runs_file, path, stamp = _sweep(
        "table2", table2_run, work, quick, out_dir, backend, jobs, address, resume, progress
    )
    _say_others(runs_file, work, "other seeds")
    _table_warnings(work, records)
    runs = [
        {"seed": job["seed"], "radius_cm": job["radius"], "n_segments": record["n_segments"]}
        | {method: record[method] for method in ("svm", "swirl")}
        for job, record in zip(work, records, strict=True)
    ]

    def mean(values: list[float | None]) -> float | None:
        known = [v for v in values if v is not None]
        return float(np.mean(known)) if known else None

    summary = []
    for radius in radii:
        rows = [r for r in runs if r["radius_cm"] == radius]
        entry: dict[str, Any] = {"radius_cm": radius, "paper": PAPER_TABLE2[radius]}
        for method in ("svm", "swirl"):
            entry[method] = {
                key: mean([r[method][key] for r in rows])
                for key in (
                    "success_rate",
                    "began_cut_rate",
                    "position_error_cm",
                    "tracking_error_cm",
                )
            }
        summary.append(entry)
    combined = sum(round(r["swirl"]["success_rate"] * n_eval) for r in runs)
    results = {
        "experiment": "table2",
        "env_id": preset.env_id,
        "settings": {
            "n_demos": preset.n_demos,
            "episodes_of_exploration": episodes,
            "n_eval_episodes": n_eval,
            "seeds": seeds,
            "quick": quick,
        },
        "runs": runs,
        "summary": summary,
        "swirl_successes": [combined, n_eval * len(runs)],
        "stamp": stamp,
    }
    write_results(results, path)

    def cm(value: float | None) -> str:
        return "—" if value is None else f"{value:.2f}"

    table = Table(
        title=f"Table 2, line cutting ({len(seeds)} seed(s) × {n_eval} greedy episodes per line, "
        f"after {episodes} of exploration); errors in cm",
        caption="cut: the share of episodes that start within 1 cm of the line and never leave "
        "it by more than 1 cm; pos / track: the errors of the episodes that began a cut",
    )
    columns = ("line", "SVM cut", "SVM pos / track", "SWIRL cut", "SWIRL pos / track")
    for column in (*columns, "paper SVM", "paper SWIRL"):
        table.add_column(column, justify="left" if column == "line" else "right")
    for entry in summary:
        svm_row, swirl_row, paper = entry["svm"], entry["swirl"], entry["paper"]
        table.add_row(
            "straight" if entry["radius_cm"] is None else f"r = {entry['radius_cm']} cm",
            f"{svm_row['success_rate']:.0%}",
            f"{cm(svm_row['position_error_cm'])} / {cm(svm_row['tracking_error_cm'])}",
            f"{swirl_row['success_rate']:.0%}",
            f"{cm(swirl_row['position_error_cm'])} / {cm(swirl_row['tracking_error_cm'])}",
            f"{cm(paper[0])} / {cm(paper[1])}",
            f"{cm(paper[2])} / {cm(paper[3])}",
        )
    _table_console().print(table)
    console.print(
        f"SWIRL cut the line in {combined} of {n_eval * len(runs)} episodes ({len(runs)} lines × "
        f"{n_eval}, one line at a time; the paper's 11 of 15 were trials on sequences of lines "
        "and curves, on gauze)" + (_QUICK_TABLE if quick else "") + f". Wrote {path}"
    )
    return results


# ---------------------------------------------------------------------- the paper's figures
def method_run(
    preset: str,
    method: str,
    seed: int,
    steps: int,
    env_id: str | None = None,
    eval_freq: int | None = None,
    n_eval_episodes: int | None = None,
    n_demos: int | None = None,
    demo_env_id: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
    fit: dict[str, Any] | None = None,
    max_episodes: int | None = None,
) -> dict[str, Any]:
    """One run of a comparison method (:func:`sb3_swirl.baselines.run_method`) on the shipped
    task ``preset``: ``n_demos`` (default: the task's) of its supervisor's demos (``seed``;
    none for pure exploration), ``steps`` env steps.

    ``env_id`` runs it on a variant of the task (its own zoo entry gives the demos and the
    fit), ``demo_env_id`` takes the demos from another variant (transfer), ``env_kwargs`` go
    to ``gym.make`` of the env learned on, ``fit`` over the fit settings, ``max_episodes``
    stops training after that many rollouts, ``eval_freq`` and ``n_eval_episodes`` change
    the evaluation schedule. Module-level and with JSON arguments and result: sweeps
    (:func:`sb3_swirl.runner.run_sweep`) run it in other processes."""
    import torch

    from sb3_swirl.baselines import run_method
    from sb3_swirl.supervisors import collect_demos

    torch.set_num_threads(1)  # tiny networks: extra threads only contend for the cores
    chosen = PRESETS[preset]
    changes = {"env_id": env_id, "eval_freq": eval_freq, "n_eval_episodes": n_eval_episodes}
    chosen = replace(chosen, **{k: v for k, v in changes.items() if v is not None})
    # pure exploration learns from no demos: do not run the supervisor for it
    pure = method in ("dqn", "dqn_rbf", "dqn_her")
    n = chosen.n_demos if n_demos is None else n_demos
    demo_env = chosen.env_id if demo_env_id is None else demo_env_id
    # a sweep runs hundreds of fits in worker processes: the record keeps their warnings
    with _kept_warnings() as kept:
        demos = (
            []
            if pure
            else collect_demos(
                demo_env, n, seed=seed, state_key=chosen.state_key, **chosen.demo_env_kwargs
            )
        )
        record = run_method(
            method,
            chosen,
            demos,
            seed=seed,
            total_timesteps=steps,
            env_kwargs=env_kwargs,
            fit_kwargs=fit,
            max_episodes=max_episodes,
        )
    record.pop("hyperparams", None)  # classes in policy_kwargs are not JSON
    record["warnings"] = kept
    return record


@dataclass(frozen=True)
class Panel:
    """One panel of a paper figure: a task, its budget and what is swept on it.

    ``run`` holds :func:`method_run` arguments for every run of the panel (``quick_run`` over
    them in ``--quick``), ``by_method`` per method label. ``values`` are the swept points
    ``(x, method_run arguments)`` of a figure whose x axis is not rollouts (empty: learning
    curves); ``quick_values`` the subset ``--quick`` runs. ``skip`` lists method labels that
    do not apply to the panel.
    """

    title: str
    preset: str
    env_id: str
    steps: int
    run: dict[str, Any] = field(default_factory=dict)
    quick_run: dict[str, Any] = field(default_factory=dict)
    by_method: dict[str, dict[str, Any]] = field(default_factory=dict)
    values: tuple[tuple[Any, dict[str, Any]], ...] = ()
    quick_values: tuple[Any, ...] = ()
    skip: tuple[str, ...] = ()


@dataclass(frozen=True)
class Experiment:
    """A figure of the paper's §9: panels × methods × seeds (× swept values).

    ``methods`` maps a label to :func:`method_run` arguments (at least ``method``).
    ``spread`` shades the seeds' ``"range"`` (min to max) or ``"2std"`` (mean ± 2 std, Fig. 9).
    """

    name: str
    title: str
    claim: str
    panels: dict[str, Panel]
    methods: dict[str, dict[str, Any]]
    x_label: str = "rollouts (training episodes)"
    #: held-out seeds: the shipped zoo entries were tuned on seeds 0-9
    seeds: tuple[int, ...] = (10, 11, 12, 13, 14)
    spread: str = "range"
    #: how many of ``seeds`` ``--quick`` runs
    quick_seeds: int = 1
    #: method pairs (ours, theirs) whose rollouts to the target are compared per seed
    ratios: tuple[tuple[str, str], ...] = ()
    #: what learning is counted in: ``"episodes"`` (rollouts, the paper's) or ``"timesteps"``
    x_key: str = "episodes"

    @property
    def counted(self) -> str:
        return "env steps" if self.x_key == "timesteps" else "rollouts"


#: ``--quick``'s budget and evaluation schedule
_QUICK = {"steps": 3_000, "eval_freq": 1_000, "n_eval_episodes": 3}
_PARKING, _ACROBOT = "sb3_swirl/ParallelParking-v0", "sb3_swirl/NoisyAcrobot-v0"
_UNDERACTUATED = "sb3_swirl/UnderactuatedAcrobot-v0"
#: the labels of the plots and tables
METHOD_LABELS = {
    "swirl": "SWIRL",
    "swirl_maxent": "SWIRL, MaxEnt rewards (est. dynamics)",
    "swirl_maxent_model": "SWIRL, MaxEnt rewards (true dynamics)",
    "dqn": "Q-learning (DQN)",
    "dqn_rbf": "RBF Q-learning",
    "dqn_her": "DQN + HER",
    "swirl_her": "SWIRL + HER",
    "bc_linear_svm": "linear SVM",
    "bc_rbf_svm": "RBF SVM",
    "qinit": "Q-init",
    "global_irl": "IRL (est. dynamics)",
    "global_irl_model": "IRL (true dynamics)",
    "swirl_gmm": "SWIRL, GMM",
    "swirl_velocity": "SWIRL, velocity",
    "swirl_linear": "SWIRL, linear dynamics",
}


def _curve_panels(
    parking: int, acrobot: int, acrobot_run: dict[str, Any] | None = None
) -> dict[str, Panel]:
    """Parking (5 demos) and both acrobots (15 demos) with these step budgets (and these
    :func:`method_run` arguments on the acrobots)."""
    run = acrobot_run or {}
    return {
        "parking": Panel("parking, 5 demos", "parking", _PARKING, parking),
        "acrobot": Panel("acrobot, 15 demos", "acrobot", _ACROBOT, acrobot, run=run),
        "underactuated_acrobot": Panel(
            "under-actuated acrobot, 15 demos (not in the paper)",
            "acrobot",
            _UNDERACTUATED,
            acrobot,
            run=run,
        ),
    }


def _methods(*names: str, **variants: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {name: {"method": name} for name in names} | variants


_LONG_RL = {"steps": 1_000_000, "eval_freq": 5_000}  # Fig. 2's pure RL on parking
_FETCH, _V0 = "sb3_swirl/Fetch", "Discrete-v0"
_LINKS = tuple(
    (length, {"env_kwargs": {"link_length_2": length}}) for length in (1.0, 1.25, 1.5, 1.75, 2.0)
)
EXPERIMENTS: dict[str, Experiment] = {
    "fig2": Experiment(
        "fig2",
        "Fig. 2: SWIRL vs Q-learning",
        "SWIRL needs far fewer rollouts than Q-learning (parking: about 0.15 of them)",
        {
            # the preset evaluates every 10k steps: after 30-100 rollouts of SWIRL, whose
            # episodes end in success, and 10 of Q-learning, whose episodes time out; every
            # 2000 steps, rollouts to 95% are counted on a grid five times as fine
            **_curve_panels(100_000, 60_000, {"eval_freq": 2_000}),
            "parking": Panel(
                "parking, 5 demos",
                "parking",
                _PARKING,
                100_000,
                by_method={"dqn": _LONG_RL, "dqn_rbf": _LONG_RL},
            ),
        },
        _methods("swirl", "dqn", "dqn_rbf"),
        ratios=(("swirl", "dqn"), ("swirl", "dqn_rbf")),
    ),
    "fig3": Experiment(
        "fig3",
        "Fig. 3: SWIRL vs behavioural cloning (SVM) against the number of demos",
        "BC-SVM needs more than 10 times as many demos as SWIRL to be competitive",
        {
            "parking": Panel(
                "parking, 500 rollouts",
                "parking",
                _PARKING,
                100_000,
                run={"max_episodes": 500},
                values=tuple((n, {"n_demos": n}) for n in (2, 5, 10, 20, 50)),
                quick_values=(2, 5),
            ),
            **{
                name: Panel(
                    f"{title}, 3000 rollouts (at most 60k steps)",
                    "acrobot",
                    env_id,
                    60_000,
                    run={"max_episodes": 3_000},
                    values=tuple((n, {"n_demos": n}) for n in (2, 5, 15, 50)),
                    quick_values=(2, 5),
                )
                for name, title, env_id in (
                    ("acrobot", "acrobot", _ACROBOT),
                    (
                        "underactuated_acrobot",
                        "under-actuated acrobot (not in the paper)",
                        _UNDERACTUATED,
                    ),
                )
            },
        },
        _methods("swirl", "bc_linear_svm", "bc_rbf_svm"),
        x_label="demonstrations",
    ),
    "fig4": Experiment(
        "fig4",
        "Fig. 4: SWIRL vs other hybrids",
        "SWIRL is the most sample-efficient; Q-init is no better than Q-learning; "
        "IRL beats Q-learning on parking",
        _curve_panels(60_000, 60_000),
        _methods("swirl", "qinit", "global_irl", "dqn"),
    ),
    "fig5": Experiment(
        "fig5",
        "Fig. 5: true vs estimated dynamics",
        "IRL and SWIRL both learn significantly faster with the true dynamics",
        _curve_panels(60_000, 60_000),
        _methods("swirl_maxent", "swirl_maxent_model", "global_irl", "global_irl_model"),
    ),
    "fig6": Experiment(
        "fig6",
        "Fig. 6: transition indicators",
        "the GMM indicator is the most reliable across the domains",
        _curve_panels(60_000, 60_000),
        {
            f"swirl_{name}": {"method": "swirl", "fit": {"indicator": name}}
            for name in ("gmm", "velocity", "linear")
        },
    ),
    "fig7": Experiment(
        "fig7",
        "Fig. 7: parking transfer to perturbed dynamics (100 demos, 500 rollouts)",
        "the SVM parks 95% on the standard car and never on the perturbed one; IRL transfers; "
        "model-free SWIRL drops 16%",
        {
            "parking": Panel(
                "parking, demos on the standard car",
                "parking",
                _PARKING,
                100_000,
                run={"n_demos": 100, "max_episodes": 500, "demo_env_id": _PARKING},
                quick_run={"n_demos": 20},
                values=(
                    ("standard", {}),
                    ("perturbed", {"env_id": "sb3_swirl/ParallelParkingPerturbed-v0"}),
                ),
                quick_values=("standard", "perturbed"),
            )
        },
        _methods("dqn", "bc_linear_svm", "bc_rbf_svm", "global_irl", "swirl"),
        x_label="dynamics the agent learns and is evaluated on",
    ),
    "fig8": Experiment(
        "fig8",
        "Fig. 8: acrobot transfer against link-2 length (250 demos, 3000 rollouts)",
        "the SVM fails as soon as the link changes; SWIRL holds until the change is large",
        {
            name: Panel(
                f"{title}, demos with a 1 m link",
                "acrobot",
                env_id,
                60_000,
                run={"n_demos": 250, "max_episodes": 3_000},
                quick_run={"n_demos": 30},
                values=_LINKS,
                quick_values=(1.0, 1.5),
            )
            for name, title, env_id in (
                ("acrobot", "acrobot", _ACROBOT),
                (
                    "underactuated_acrobot",
                    "under-actuated acrobot (not in the paper)",
                    _UNDERACTUATED,
                ),
            )
        },
        _methods("dqn", "bc_rbf_svm", "global_irl", "swirl"),
        x_label="length of link 2 [m]",
        seeds=(10, 11, 12),
    ),
    "fig9": Experiment(
        "fig9",
        "Fig. 9: sensitivity to the demo set (mean ± 2 std)",
        "SWIRL is not very sensitive to the demo set: the 2-std band is narrower than its "
        "gain over Q-learning",
        _curve_panels(30_000, 60_000),
        _methods("swirl"),
        seeds=tuple(range(100, 120)),
        spread="2std",
        quick_seeds=3,
    ),
    "fig10": Experiment(
        "fig10",
        "Fig. 10: partial-observation parking (velocity hidden), 5 demos",
        "after 250k steps model-based SWIRL parks 95%, Q-learning < 10%, MaxEnt-IRL 0%, SVM 0%",
        {
            "parking_partial": Panel(
                "parking, velocity hidden",
                "parking",
                "sb3_swirl/ParallelParkingPartial-v0",
                250_000,
                run={"eval_freq": 5_000},
            ),
            # not in the paper: a one-step memory, the regions and rewards unchanged
            "parking_partial_displacement": Panel(
                "parking, last step's displacement seen (not in the paper)",
                "parking",
                "sb3_swirl/ParallelParkingPartialDisplacement-v0",
                250_000,
                run={"eval_freq": 5_000},
            ),
        },
        _methods("swirl", "swirl_maxent", "dqn", "global_irl", "bc_linear_svm"),
    ),
    "fetch": Experiment(
        "fetch",
        "SWIRL on gymnasium-robotics' Fetch tasks (2 cm steps, 10 demos) against HER",
        "(not in the paper) our goal: SwirlDQN reaches 90% on push in at most 1/5 of the env "
        "steps DQN + HER needs",
        {
            # reach's task is the goal's offset, which HER's relabelling would leave stale
            "reach": Panel(
                "reach, 10 demos",
                "fetchreach",
                f"{_FETCH}Reach{_V0}",
                20_000,
                skip=("swirl_her",),
            ),
            "push": Panel("push, 10 demos", "fetchpush", f"{_FETCH}Push{_V0}", 100_000),
            "pickandplace": Panel(
                "pick and place, 10 demos",
                "fetchpickandplace",
                f"{_FETCH}PickAndPlace{_V0}",
                50_000,
            ),
        },
        _methods("swirl", "swirl_her", "dqn", "dqn_her", "bc_rbf_svm"),
        x_label="env steps",
        ratios=(("swirl", "dqn_her"), ("swirl_her", "dqn_her"), ("swirl", "dqn")),
        x_key="timesteps",
    ),
}


def _jobs(
    experiment: Experiment, panels: list[str], methods: list[str], seeds: list[int], quick: bool
) -> tuple[list[tuple[str, str, Any, int]], list[dict[str, Any]]]:
    """The labels ``(panel, method label, x, seed)`` and :func:`method_run` arguments of
    every run (only the arguments that differ from the defaults, so a job is the same
    mapping in every version that runs it the same way: ``--resume`` finds it)."""
    labels, work = [], []
    for name in panels:
        panel = experiment.panels[name]
        points = panel.values or ((None, {}),)
        if quick and panel.values:
            points = tuple(p for p in points if p[0] in panel.quick_values)
        for label in methods:
            if label in panel.skip:
                continue
            args = experiment.methods[label]
            for x, swept in points:
                for seed in seeds:
                    job = {
                        "preset": panel.preset,
                        "env_id": panel.env_id,
                        "method": args["method"],
                        "seed": seed,
                        "steps": panel.steps,
                        **{k: v for k, v in args.items() if k != "method"},
                        **panel.run,
                        **panel.by_method.get(label, {}),
                        **swept,
                    }
                    if quick:
                        job |= panel.quick_run | _QUICK
                    labels.append((name, label, x, seed))
                    work.append(job)
    return labels, work


def _summary(experiment: Experiment, runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per panel, method and swept value: the seeds' final success (mean, std), best success,
    median rollouts (env steps, for ``x_key="timesteps"``) to the target (never: None) and how
    many seeds reached it."""
    rows = []
    groups: dict[tuple[str, str, Any], list[dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault((run["panel"], run["label"], run["x"]), []).append(run)
    for (panel, label, x), group in groups.items():
        finals = [r["final_success"] for r in group]
        target = PRESETS[experiment.panels[panel].preset].target_success
        counts = [rollouts_to_success(r["curve"], target, experiment.x_key) for r in group]
        reached = [count for count in counts if count is not None]
        median = float(np.median(reached + [np.inf] * (len(group) - len(reached))))
        rows.append(
            {
                "panel": panel,
                "method": label,
                "x": x,
                "seeds": len(group),
                "final_success_mean": float(np.mean(finals)),
                "final_success_std": float(np.std(finals)),
                "best_success_mean": float(np.mean([r["best_success"] for r in group])),
                "median_rollouts_to_target": None if np.isinf(median) else median,
                "reached_target": len(reached),
            }
        )
    return rows


def reproduce(
    name: str,
    *,
    quick: bool = False,
    seeds: list[int] | None = None,
    out_dir: str | Path = "results",
    progress: bool = True,
    backend: str = "joblib",
    jobs: int = 2,
    address: str | None = None,
    resume: bool = False,
    panels: list[str] | None = None,
    methods: list[str] | None = None,
    repeats: int | None = None,
) -> dict[str, Any]:
    """Reproduce a figure of the paper's §9 (:data:`EXPERIMENTS`): every panel × method ×
    seed (× swept value) is a :func:`method_run`, fanned out by
    :func:`sb3_swirl.runner.run_sweep`.

    Each record lands in ``out_dir/NAME/runs.jsonl`` as it finishes, so an interrupted sweep
    resumes (``resume``). Then writes ``results.json`` (the settings and the stamp of this
    call, the paper's claim, every run with its curve, and the summary of :func:`_summary`)
    and ``figure.png`` (one panel per task: mean true success against rollouts, or against the
    swept value, shaded over the seeds), and prints the summary table. With ``quick`` the
    three files are ``runs_quick.jsonl``, ``results_quick.json`` and ``figure_quick.png``.

    Parameters
    ----------
    name : str
        A key of :data:`EXPERIMENTS` ("fig2" ... "fig10").
    quick : bool
        One seed (Fig. 9: three), 3000 steps, 3 evaluation episodes every 1000 steps, fewer
        demos and swept values (minutes); otherwise the full setting of :data:`EXPERIMENTS`.
    seeds : list of int, optional
        Instead of the experiment's (held-out seeds: the presets were tuned on 0-9).
    panels : list of str, optional
        A subset of the experiment's panels.
    methods : list of str, optional
        A subset of the experiment's method labels (the rest can follow later with
        ``resume``: the runs already made are kept).
    repeats : int, optional
        Demo sets of Fig. 9 (seeds 100, 101, ...; the paper used 100, the full setting 20).
    backend, jobs, address : see :func:`sb3_swirl.runner.run_sweep`
    """
    experiment = EXPERIMENTS[check_option("experiment", name, tuple(EXPERIMENTS))]
    # each once, in the order given: a repeated one would count its runs twice
    panels = list(dict.fromkeys(experiment.panels if panels is None else panels))
    for panel in panels:
        check_option("panel", panel, tuple(experiment.panels))
    methods = list(dict.fromkeys(experiment.methods if methods is None else methods))
    for label in methods:
        check_option("method", label, tuple(experiment.methods))
    if repeats is not None:
        if seeds is not None:
            raise ValueError("repeats sets Fig. 9's demo-set seeds (100, 101, ...): drop seeds")
        seeds = list(range(100, 100 + check_int("repeats", repeats, low=2)))
    if seeds is None:
        seeds = list(experiment.seeds[: experiment.quick_seeds] if quick else experiment.seeds)
    seeds = _checked_seeds(seeds)
    labels, work = _jobs(experiment, panels, methods, seeds, quick)
    console.rule(f"[bold]{experiment.title}: {len(work)} run{'s' * (len(work) != 1)}, {backend}")
    if quick:
        console.print(_quick_note(experiment))
    # the folder is made by run_sweep, which removes it if no run starts
    records, runs_file, saved, stamp = _sweep(
        name, method_run, work, quick, out_dir, backend, jobs, address, resume, progress
    )
    runs = [
        {"panel": panel, "label": label, "x": x, "seed": seed, "job": job} | record
        for (panel, label, x, seed), job, record in zip(labels, work, records, strict=True)
    ]
    summary = _summary(experiment, runs)
    _print_summary(experiment, summary)
    ratios = _ratios(experiment, runs)
    for row in ratios:
        console.print(_ratio_line(row, experiment.counted), soft_wrap=True)
    warned = sum(bool(run.get("warnings")) for run in runs)
    if warned:
        console.print(f"{warned} of {len(runs)} runs warned (their fits: runs[].warnings)")
    _say_others(runs_file, work, "other seeds, panels or methods")
    results = {
        "figure": name,
        "title": experiment.title,
        "paper_claim": experiment.claim,
        "quick": quick,
        "seeds": seeds,
        "panels": panels,
        "methods": methods,
        "backend": backend,
        "stamp": stamp,
        "summary": summary,
        "ratios": ratios,
        "runs": runs,
    }
    figure = saved.with_name(_output_name("figure", ".png", quick))
    write_results(results, saved)
    _plot_experiment(experiment, panels, methods, runs, figure, quick)
    claim = experiment.claim
    console.print(
        claim if claim.startswith("(not in the paper)") else f"paper: {claim}", soft_wrap=True
    )
    console.print(f"wrote {saved}, {figure.name}", soft_wrap=True)
    return results


def _ratios(experiment: Experiment, runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per panel (and swept value) and pair of :attr:`Experiment.ratios`: every seed's
    :func:`rollout_ratio` to the task's target and their :func:`summarise_ratios`."""
    groups: dict[tuple[str, Any], dict[tuple[str, int], dict[str, Any]]] = {}
    for run in runs:
        groups.setdefault((run["panel"], run["x"]), {})[run["label"], run["seed"]] = run
    out = []
    for (panel, x), mine in groups.items():
        target = PRESETS[experiment.panels[panel].preset].target_success
        for ours, theirs in experiment.ratios:
            seeds = sorted(s for label, s in mine if label == ours and (theirs, s) in mine)
            if not seeds:
                continue
            rows = [
                {"seed": s}
                | rollout_ratio(mine[ours, s], mine[theirs, s], target, experiment.x_key)
                for s in seeds
            ]
            pair = {"panel": panel, "x": x, "ours": ours, "theirs": theirs, "seeds": rows}
            out.append(pair | summarise_ratios(rows))
    return out


def _ratio_line(row: dict[str, Any], counted: str = "rollouts") -> str:
    names = " / ".join(METHOD_LABELS.get(row[k], row[k]) for k in ("ours", "theirs"))
    where = row["panel"] + ("" if row["x"] is None else f" at {row['x']}")
    n = row["n_seeds"]
    head = f"{where}: {counted} to {row['seeds'][0]['target']:.0%}, {names}:"
    if row["median"] is None:
        return f"{head} unresolved (half the {n} seeds or more have no upper bound)"
    iqr = f"IQR {row['q25']:.3f}-{row['q75']:.3f}; " if n > 1 else ""
    return (
        f"{head} median {row['bound']} {row['median']:.3f} over {n} seed{'s' * (n != 1)} "
        f"({iqr}reached: {row['ours_reached']} / {row['theirs_reached']} seeds)"
    )


def _print_summary(experiment: Experiment, summary: list[dict[str, Any]]) -> None:
    swept = any(row["x"] is not None for row in summary)
    table = Table(title=f"{experiment.title}: true success over the seeds")
    columns = ["panel", "method"] + ([experiment.x_label] if swept else [])
    counted = experiment.counted
    columns += ["seeds", "final success", f"{counted} to target (median)", "seeds reaching it"]
    for column in columns:
        table.add_column(column)
    for row in summary:
        rollouts = row["median_rollouts_to_target"]
        table.add_row(
            row["panel"],
            METHOD_LABELS.get(row["method"], row["method"]),
            *([str(row["x"])] if swept else []),
            str(row["seeds"]),
            f"{row['final_success_mean']:.2f} ± {row['final_success_std']:.2f}",
            "never" if rollouts is None else f"{rollouts:g}",
            f"{row['reached_target']}/{row['seeds']}",
        )
    _table_console().print(table)


def _quick_note(experiment: Experiment) -> str:
    """What a ``--quick`` run of ``experiment`` runs instead of the title's setting."""
    demos = sorted(
        {p.quick_run["n_demos"] for p in experiment.panels.values() if "n_demos" in p.quick_run}
    )
    fewer = f"{', '.join(map(str, demos))} demos, " if demos else ""
    return f"--quick run ({fewer}small budgets): not the paper's setting"


def _band(values: np.ndarray, spread: str) -> tuple[np.ndarray, np.ndarray]:
    if spread == "2std":
        mean, std = values.mean(axis=0), values.std(axis=0)
        return np.clip(mean - 2 * std, 0, 1), np.clip(mean + 2 * std, 0, 1)
    return values.min(axis=0), values.max(axis=0)


def _plot_experiment(
    experiment: Experiment,
    panels: list[str],
    methods: list[str],
    runs: list[dict[str, Any]],
    path: Path,
    quick: bool = False,
) -> None:
    """One subplot per panel, like the paper's figures: true success against rollouts (a
    line per method, shaded over the seeds; behavioural cloning, which takes none, as a
    dashed level), or against the swept value (lines; bars for named settings). A ``quick``
    run says so in the title: its budgets are not those the panel titles give."""
    from matplotlib.ticker import ScalarFormatter

    from sb3_swirl.plotting import _finish, _new_figure

    fig = _new_figure((max(5.5 * len(panels), 8.0), 4.4))
    axes = np.atleast_1d(fig.subplots(1, len(panels)))
    for ax, name in zip(axes, panels, strict=True):
        mine = [r for r in runs if r["panel"] == name]
        xs = list(dict.fromkeys(r["x"] for r in mine))
        named = any(isinstance(x, str) for x in xs)
        ends: list[float] = []  # the rollouts each learning curve ran
        banded = False  # a shaded band over more than one seed was drawn
        width = 0.8 / len(methods)
        drawn: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # each line's points, by label
        for i, label in enumerate(methods):
            these = [r for r in mine if r["label"] == label]
            if not these:  # a method the panel skips
                continue
            text = METHOD_LABELS.get(label, label)
            k = list(experiment.methods).index(label)  # a method's colour, also in a subset
            color = f"C{k}"
            # drawn earlier, drawn wider: a method whose line a later one covers still shows
            behind = len(methods) - 1 - i
            style = {"color": color, "marker": "osD^v"[k % 5]}
            style |= {"markersize": 4 + 1.2 * behind, "linewidth": 1.5 + 0.6 * behind}
            if xs != [None]:  # success after the budget against the swept value
                finals = [[r["final_success"] for r in these if r["x"] == x] for x in xs]
                mean = np.array([np.mean(f) for f in finals])
                low, high = (np.array([b(f) for f in finals]) for b in (np.min, np.max))
                if named:
                    where = np.arange(len(xs)) + (i - (len(methods) - 1) / 2) * width
                    bars = {"yerr": [mean - low, high - mean], "color": color, "label": text}
                    # the value on each bar: a method at 0 is otherwise not there to see
                    ax.bar_label(ax.bar(where, mean, width, **bars), fmt="%.2f", fontsize=7)
                else:
                    ax.plot(xs, mean, label=_same_as_drawn(drawn, text, xs, mean), **style)
                    ax.fill_between(xs, low, high, color=color, alpha=0.15)
                    banded |= any(len(f) > 1 for f in finals)
                continue
            curves = [r["curve"] for r in these]
            n = min(len(c) for c in curves)
            success = np.array([[p["success_rate"] for p in c[:n]] for c in curves])
            key = experiment.x_key
            episodes = np.array([[p[key] for p in c[:n]] for c in curves]).mean(axis=0)
            if n == 1:  # behavioural cloning: no rollouts
                level = _same_as_drawn(drawn, text, [], [success.mean()])
                ax.axhline(success.mean(), linestyle="--", color=color, label=level)
                continue
            mean = success.mean(axis=0)
            ax.plot(episodes, mean, label=_same_as_drawn(drawn, text, episodes, mean), **style)
            band = _band(success, experiment.spread)
            ax.fill_between(episodes, *band, color=color, alpha=0.15)
            banded |= len(success) > 1
            ends.append(episodes[-1])
        # budgets far apart (Fig. 2: 1M steps) and reaching 1000 rollouts or more: a log axis
        if ends and max(ends) >= 1000 and max(ends) > 5 * max(min(ends), 1):
            ax.set_xscale("symlog", linthresh=10)
            ax.xaxis.set_major_formatter(ScalarFormatter())  # 1000, not 10³
        if named:
            ax.set_xticks(np.arange(len(xs)), xs)
        elif xs != [None]:
            ax.set_xticks(xs)
        ax.set_title(textwrap.fill(experiment.panels[name].title, 48))  # a panel's width
        ax.set_xlabel(experiment.x_label)
        ax.set_ylabel("true success rate")
        ax.set_ylim(-0.02, 1.05)
        ax.grid(alpha=0.3)
        if banded:
            spread = "mean ± 2 std" if experiment.spread == "2std" else "min to max"
            ax.fill_between([], [], [], color="0.5", alpha=0.15, label=f"{spread} over seeds")
        ax.legend(loc="best", fontsize="small")
    title = experiment.title
    if quick:
        title = f"{title}\n{_quick_note(experiment)}"
    fig.suptitle(title, fontsize="medium")
    _finish(fig, path)


def _same_as_drawn(
    drawn: dict[str, tuple[np.ndarray, np.ndarray]], text: str, x: Any, y: Any
) -> str:
    """A line's legend ``text``, naming the methods in ``drawn`` (label -> points, this line
    added) whose lines are the very same, hidden under it: a --quick run's few runs often all
    end at 0 or 1."""
    points = (np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    same = [t for t, p in drawn.items() if all(map(np.array_equal, p, points))]
    drawn[text] = points
    return f"{text} (= {', '.join(same)})" if same else text


def reproduce_all(*, quick: bool = False, out_dir: str | Path = "results", **sweep: Any) -> dict:
    """Every table and figure, one after the other (each in its own ``out_dir/NAME/``);
    ``sweep`` (``jobs``, ``backend``, ``address``, ``resume``, ``progress``) goes to each.
    Every output is checked first: without ``resume`` any runs or results file that exists is
    an error; with it, each sweep goes on from its runs. Returns ``{name: results}``."""
    outputs = [_sweep_outputs(out_dir, name, quick) for name in REPRODUCTIONS]
    existing = [path for pair in outputs for path in pair if path.exists()]
    if existing and not sweep.get("resume", False):  # checked before hours of work, not after
        raise ValueError(
            f"{', '.join(map(str, existing))} exist{'s' * (len(existing) == 1)}: resume "
            "(--resume keeps the runs done) or choose another output"
        )
    return {name: run(quick=quick, out_dir=out_dir, **sweep) for name, run in REPRODUCTIONS.items()}


#: ``sb3-swirl reproduce NAME``: the experiment functions by name.
REPRODUCTIONS = {"table1": reproduce_table1, "table2": reproduce_table2} | {
    name: partial(reproduce, name) for name in EXPERIMENTS
}
