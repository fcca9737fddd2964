"""SWIRL (model-free and MaxEnt-IRL rewards) beside the paper's comparison methods.

Every method of :data:`sb3_swirl.baselines.METHODS` but the HER ones (goal envs only) runs through
:func:`sb3_swirl.baselines.run_method` on the same demos, seeds, step budget and evaluation
schedule (true success over ``preset.n_eval_episodes`` greedy episodes every
``preset.eval_freq`` steps); the tuning effort is the same for all: the shipped
``zoo_configs/`` (tuned for SwirlDQN and DQN on parking) and each library's defaults.

* ``parking``: 5 supervisor demos, the standard car.
* ``partial``: the same with the velocity hidden (``ParallelParkingPartial-v0``, §9.8), where
  the paper says model-based SWIRL helps most. No known model there (the hidden velocity).
* ``displacement``: the velocity hidden, the last step's displacement seen
  (``ParallelParkingPartialDisplacement-v0``, not in the paper): a one-step memory.

Prints, per task, each method's rollouts to 95 % true success (median over seeds, with how
many seeds reached it), final and best success, and wall time; writes
``results/baselines/results.json`` with every seed's curve (``--quick``: ``results_quick.json``
and ``runs_quick.jsonl``, beside a full run's).

Runs go through :func:`sb3_swirl.runner.run_sweep`: each run's record lands in
``OUT/runs.jsonl`` as it finishes (``--resume`` continues an interrupted sweep), on local
processes or a Ray cluster (``--backend ray [--address ...]``).

Run: ``.venv/bin/python benchmarks/baselines.py [--tasks parking partial displacement]
[--seeds 10 11 12] [--methods swirl dqn ...] [--total-timesteps 30000] [--jobs 2]
[--backend joblib|ray] [--resume] [--quick] [--out results/baselines]`` (``--tasks``: parking
and partial by default).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path
from typing import Any

from _cli import integer_arg, run_main, seed_arg

TASKS = {
    "parking": "sb3_swirl/ParallelParking-v0",
    "partial": "sb3_swirl/ParallelParkingPartial-v0",
    "displacement": "sb3_swirl/ParallelParkingPartialDisplacement-v0",
}
#: the tasks run by default (``--tasks``)
DEFAULT_TASKS = ["parking", "partial"]


def summarise(records: list[dict[str, Any]]) -> dict[str, Any]:
    """One method's runs on one task: seeds, how many reached 95 %, the median rollouts to it
    (``None`` where half the seeds or more never reached it), mean final and best success and
    wall time."""
    reached = [r["rollouts_to_target"] for r in records if r["rollouts_to_target"] is not None]
    # seeds that never reach the target count as +inf: a median over all seeds
    median = statistics.median(reached + [math.inf] * (len(records) - len(reached)))
    return {
        "n_seeds": len(records),
        "reached": len(reached),
        "median_rollouts": None if math.isinf(median) else median,
        "final_success_mean": statistics.mean(r["final_success"] for r in records),
        "best_success_mean": statistics.mean(r["best_success"] for r in records),
        "wall_time_s_mean": statistics.mean(r["wall_time_s"] for r in records),
    }


def main(argv: list[str] | None = None) -> int:
    from sb3_swirl.baselines import GOAL_ENV_METHODS, METHODS
    from sb3_swirl.experiments import method_run
    from sb3_swirl.runner import BACKENDS, run_sweep

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=DEFAULT_TASKS, choices=list(TASKS))
    parser.add_argument("--seeds", type=seed_arg, nargs="+", default=[10, 11, 12, 13, 14])
    # the parking cars are not goal envs (HER runs in `sb3-swirl reproduce fetch`)
    methods = [m for m in METHODS if m not in GOAL_ENV_METHODS]
    parser.add_argument("--methods", nargs="+", default=methods, choices=methods)
    parser.add_argument("--total-timesteps", type=integer_arg(1), default=30_000)
    parser.add_argument("--jobs", type=integer_arg(1), default=2, help="runs at once (local CPUs)")
    parser.add_argument("--backend", default="joblib", choices=BACKENDS)
    parser.add_argument("--address", default=None, help="Ray cluster address (--backend ray)")
    parser.add_argument(
        "--resume", action="store_true", help="keep the runs in OUT/runs.jsonl, run the rest"
    )
    parser.add_argument("--quick", action="store_true", help="1 seed, 1500 steps: a smoke run")
    parser.add_argument("--out", default="results/baselines")
    args = parser.parse_args(argv)
    seeds = args.seeds[:1] if args.quick else args.seeds
    steps = 1_500 if args.quick else args.total_timesteps
    jobs = [
        (task, method, seed)
        for task in args.tasks
        for method in args.methods
        # no known model of the partially observed car (its velocity is hidden)
        if not (task != "parking" and method.endswith("_model"))
        for seed in seeds
    ]
    if not jobs:
        parser.error("no run: the *_model methods run on parking only (its car's model is known)")
    path = Path(args.out)
    suffix = "_quick" if args.quick else ""  # a smoke run never touches a full run's files
    schedule = {"eval_freq": 500, "n_eval_episodes": 3} if args.quick else {}
    records = run_sweep(
        method_run,
        [
            {"preset": "parking", "env_id": TASKS[task], "method": m, "seed": seed, "steps": steps}
            | schedule
            for task, m, seed in jobs
        ],
        path / f"runs{suffix}.jsonl",
        backend=args.backend,
        n_jobs=args.jobs,
        address=args.address,
        resume=args.resume,
    )
    for (task, _, seed), record in zip(jobs, records, strict=True):
        record.update(task=task, seed=seed, total_timesteps=steps)
    settings = vars(args) | {"seeds": seeds, "total_timesteps": steps}  # what ran
    out: dict[str, Any] = {"settings": settings, "records": records, "summary": {}}
    for task in args.tasks:
        print(f"\n{task} ({TASKS[task]}), {len(seeds)} seeds, {steps} steps per method")
        print(
            f"{'method':<20} {'rollouts to 95%':>16} {'reached':>8} {'final':>6} {'best':>6} "
            f"{'wall s':>7}"
        )
        for method in args.methods:
            rows = [r for r in records if r["task"] == task and r["method"] == method]
            if not rows:
                continue
            s = summarise(rows)
            out["summary"][f"{task}/{method}"] = s
            median = s["median_rollouts"]
            shown = "not reached" if median is None else f"{median:g}"
            print(
                f"{method:<20} {shown:>16} {s['reached']:>4}/{s['n_seeds']:<3} "
                f"{s['final_success_mean']:>6.2f} {s['best_success_mean']:>6.2f} "
                f"{s['wall_time_s_mean']:>7.1f}"
            )
    (path / f"results{suffix}.json").write_text(json.dumps(out, indent=1, default=str))
    print(f"\nwrote {path / f'results{suffix}.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
