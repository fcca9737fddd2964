"""Sample efficiency of SWIRL against plain DQN (the paper's Fig. 2).

For each task and seed, SwirlDQN on the SWIRL proxy task (demos -> ``fit_task`` -> wrapper) and
plain SB3 DQN on the true sparse task train with the same network and step budget, with the
tuned hyperparameters of ``zoo_configs/{swirl_dqn,dqn}.yml``, through
:func:`sb3_swirl.experiments.train_and_evaluate`; both are evaluated on the *true* success
(``preset.n_eval_episodes`` deterministic episodes every ``preset.eval_freq`` steps).

Measured per seed: the training episodes (rollouts) completed at the first evaluation that
reaches the target, and the ratio SWIRL / DQN.

* **parking** (5 demos): the target is 95 % true success.
* **acrobot** (15 demos): the target is 95 % of the best success rate that *either* method
  reaches on that seed (the paper's "max success"); undefined when neither ever succeeds.

A method that never reaches the target *censors* the ratio, which becomes a bound, and the
median over seeds an upper bound (:func:`sb3_swirl.experiments.rollout_ratio` and
:func:`~sb3_swirl.experiments.summarise_ratios` give the rules; ``sb3-swirl reproduce fig2``
uses the same ones). Targets on the median: parking <= 0.15 (paper) and
<= 0.10 (this project), acrobot <= 0.3.

Writes ``results/sample_efficiency/results.json`` (``--quick``: ``results_quick.json``); every
run's record lands in ``runs.jsonl`` (``runs_quick.jsonl``) as it finishes
(:func:`sb3_swirl.runner.run_sweep`: ``--resume`` continues an interrupted sweep, or only
summarises a finished one; ``--backend ray`` runs it on a Ray cluster). Not a test (hours of
CPU at full size).

Run: ``.venv/bin/python benchmarks/sample_efficiency.py [--quick] [--seeds 10 11 12 13 14]
[--tasks parking acrobot] [--jobs 2] [--backend joblib|ray] [--total-timesteps N
--eval-freq M] [--out DIR] [--resume]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path
from typing import Any

from _cli import integer_arg, run_main, seed_arg

from sb3_swirl.experiments import rollout_ratio, summarise_ratios, write_results
from sb3_swirl.runner import BACKENDS, run_sweep

RATIO_TARGETS = {"parking": (0.15, 0.10), "acrobot": (0.3,)}
ALGOS = ("swirl_dqn", "dqn")


def _preset(
    task: str, quick: bool, total_timesteps: int | None, eval_freq: int | None = None
) -> tuple[Any, int]:
    from sb3_swirl.experiments import PRESETS

    preset = PRESETS[task]
    steps = preset.total_timesteps if total_timesteps is None else total_timesteps
    if eval_freq is not None:
        preset = dataclasses.replace(preset, eval_freq=eval_freq)
    if quick:
        preset = dataclasses.replace(preset, eval_freq=500, n_eval_episodes=3)
        steps = min(steps, 1_500)
    return preset, steps


def run_one(
    task: str,
    algo: str,
    seed: int,
    quick: bool,
    total_timesteps: int | None,
    eval_freq: int | None = None,
) -> dict:
    """Train one method on one seed of one task (:func:`sb3_swirl.experiments.method_run`);
    returns ``train_and_evaluate``'s record."""
    from sb3_swirl.experiments import method_run

    preset, steps = _preset(task, quick, total_timesteps, eval_freq)
    method = {"swirl_dqn": "swirl", "dqn": "dqn"}[algo]
    record = method_run(
        task,
        method,
        seed,
        steps,
        eval_freq=preset.eval_freq,
        n_eval_episodes=preset.n_eval_episodes,
    )
    record.update(task=task, seed=seed, total_timesteps=steps)
    return record


def compare_seed(task: str, swirl: dict, dqn: dict, target_success: float) -> dict[str, Any]:
    """Rollouts to target of both methods on one seed and their (possibly censored) ratio
    (:func:`sb3_swirl.experiments.rollout_ratio`; ``ours`` is SWIRL, ``theirs`` DQN)."""
    best = max(p["success_rate"] for run in (swirl, dqn) for p in run["curve"])
    if task == "parking":
        target = target_success
    else:  # the paper's "max success"; none when neither method ever succeeds
        target = 0.95 * best if best > 0 else math.inf
    return {"seed": swirl["seed"], "best_success": best} | rollout_ratio(swirl, dqn, target)


def _fmt_episodes(row: dict[str, Any], name: str) -> str:
    if row.get(name) is not None:
        return str(row[name])
    if f"{name}_rollouts_run" in row:
        return f">{row[f'{name}_rollouts_run']} (not reached)"
    return "n/a"


def _fmt_ratio(row: dict[str, Any]) -> str:
    kind, ratio = row["kind"], row["ratio"]
    if kind == "?":
        return "undefined (neither reached, or DQN at 0 episodes)"
    return {"=": f"{ratio:.3f}", "<": f"< {ratio:.3f} (DQN censored)", ">": f"> {ratio:.3f}"}[kind]


def print_task(
    task: str, rows: list[dict[str, Any]], summary: dict[str, Any], quick: bool = False
) -> None:
    """Print one task's seeds, the median ratio and the verdict on each target (none for a
    ``--quick`` smoke run); records the verdicts in ``summary["targets"]``."""
    print(f"\n{task}: training episodes to target (SWIRL vs DQN)")
    print(f"{'seed':>5}  {'target':>6}  {'SWIRL':>24}  {'DQN':>24}  ratio SWIRL/DQN")
    for r in rows:
        print(
            f"{r['seed']:>5}  {r['target']:>6.3f}  {_fmt_episodes(r, 'ours'):>24}  "
            f"{_fmt_episodes(r, 'theirs'):>24}  {_fmt_ratio(r)}"
        )
    n = summary["n_seeds"]
    print(
        f"SWIRL reached the target on {summary['ours_reached']}/{n} seeds, DQN on "
        f"{summary['theirs_reached']}/{n}"
    )
    if summary["median"] is None:
        print(
            "median ratio: unresolved (half the seeds or more have no upper bound: only a lower "
            "bound, or undefined)"
        )
        verdicts = ["not shown" for _ in RATIO_TARGETS[task]]
    else:
        sign = "=" if summary["bound"] == "=" else "<="
        print(
            f"median ratio {sign} {summary['median']:.3f}  (min {summary['min']:.3f}, "
            f"IQR {summary['q25']:.3f}-{summary['q75']:.3f}, max {summary['max']:.3f})"
        )
        if summary["bound"] == "<=":
            print(
                "  an upper bound: censored seeds count at their bound, and "
                f"{summary['n_infinite']} seed(s) without an upper bound count as +inf"
            )
        verdicts = ["PASS" if summary["median"] <= t else "FAIL" for t in RATIO_TARGETS[task]]
    if quick:  # one seed and 1500 steps measure no target
        verdicts = ["no verdict (--quick)" for _ in RATIO_TARGETS[task]]
    for t, verdict in zip(RATIO_TARGETS[task], verdicts, strict=True):
        print(f"  target median ratio <= {t:.2f}: {verdict}")
    summary["targets"] = dict(zip([str(t) for t in RATIO_TARGETS[task]], verdicts, strict=True))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="1 seed, 1500 steps: a smoke run")
    parser.add_argument("--seeds", type=seed_arg, nargs="+", default=[10, 11, 12, 13, 14])
    parser.add_argument(
        "--tasks", nargs="+", default=["parking", "acrobot"], choices=["parking", "acrobot"]
    )
    parser.add_argument("--jobs", type=integer_arg(1), default=2, help="training runs at once")
    parser.add_argument("--backend", default="joblib", choices=BACKENDS)
    parser.add_argument("--address", default=None, help="Ray cluster address (--backend ray)")
    parser.add_argument(
        "--total-timesteps",
        type=integer_arg(1),
        default=None,
        help="override the presets' step budget (the same for both methods)",
    )
    parser.add_argument(
        "--eval-freq",
        type=integer_arg(1),
        default=None,
        help="override the presets' steps between evaluations (long budgets: evaluate less)",
    )
    parser.add_argument("--out", default="results/sample_efficiency")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="keep the runs already in OUT/runs.jsonl and train only the others (all there: "
        "only summarise them)",
    )
    args = parser.parse_args(argv)
    if args.quick and args.eval_freq is not None:
        parser.error("--quick evaluates every 500 steps; leave out --eval-freq")

    out = Path(args.out)
    name = "results_quick.json" if args.quick else "results.json"
    start = time.perf_counter()
    seeds = args.seeds[:1] if args.quick else args.seeds
    jobs = [
        {
            "task": task,
            "algo": algo,
            "seed": seed,
            "quick": args.quick,
            "total_timesteps": args.total_timesteps,
            "eval_freq": args.eval_freq,
        }
        for task in args.tasks
        for seed in seeds
        for algo in ALGOS
    ]
    print(f"{len(jobs)} training runs ({', '.join(args.tasks)}; seeds {seeds})", flush=True)
    records = run_sweep(
        run_one,
        jobs,
        out / ("runs_quick.jsonl" if args.quick else "runs.jsonl"),
        backend=args.backend,
        n_jobs=args.jobs,
        address=args.address,
        resume=args.resume,
    )
    results: dict[str, Any] = {"seeds": seeds, "quick": args.quick, "tasks": {}}
    for task in args.tasks:
        preset, steps = _preset(task, args.quick, args.total_timesteps, args.eval_freq)
        by_seed = {(r["algo"], r["seed"]): r for r in records if r["task"] == task}
        rows = [
            compare_seed(task, by_seed["swirl_dqn", s], by_seed["dqn", s], preset.target_success)
            for s in seeds
        ]
        summary = summarise_ratios(rows)
        print_task(task, rows, summary, args.quick)
        results["tasks"][task] = {
            "preset": dataclasses.asdict(preset),
            "total_timesteps": steps,
            "per_seed": rows,
            "summary": summary,
            "runs": [r for r in records if r["task"] == task],
        }
    results["wall_s_this_invocation"] = time.perf_counter() - start
    write_results(results, out / name)
    print(f"wrote {out / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
