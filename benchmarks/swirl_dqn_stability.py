"""Does SwirlDQN keep what it learned? Final true success on parking over many seeds.

For each seed: 5 supervisor demos, the parking preset's ``fit_task``, then SwirlDQN with the
tuned settings of ``zoo_configs/swirl_dqn.yml`` (overridable) for 30k steps, evaluated on the
true success every 1000 steps (20 episodes). Prints per seed the final success, the mean of
the last 5 evaluations, the rollouts to 95 % and the final policy's success over
``--final-episodes`` more episodes (default 100: one evaluation of 20 reads a true 0.9 as
0.85 or less about a third of the time), then how many seeds end at >= 0.9.

``--diagnose SEED`` trains one seed and every 3000 steps evaluates 40 episodes greedily,
printing how they end (success, crash, time limit), the segment each ends in, and the mean
largest Q-value and gap to the second per segment: where a policy loses what it learned and
whether the Q-values there run away.

Run: ``python benchmarks/swirl_dqn_stability.py [--quick] [--seeds 30 31 ...]
[--set double_q=true] [--fit reg_covar=0.2] [--jobs 2]`` or ``--diagnose 49``. Seeds 30-49
are tuning seeds; the held-out ones (10-14, 20-24) belong to ``sample_efficiency.py``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import warnings
from typing import Any

import numpy as np
from _cli import integer_arg, run_main, seed_arg


def _parse(pairs: list[str]) -> dict[str, Any]:
    """``key=value`` pairs, values read as JSON where they parse (numbers, true/false)."""
    out = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _setup(seed: int, overrides: dict[str, Any], fit: dict[str, Any]):
    import torch

    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    import sb3_swirl.experiments as ex
    from sb3_swirl import collect_demos, fit_task

    preset = ex.PRESETS["parking"]
    demos = collect_demos(preset.env_id, preset.n_demos, seed=seed)
    task = fit_task(demos, random_state=seed, **{**preset.fit_kwargs, **fit})
    hyperparams = {**ex.load_hyperparams("swirl_dqn", preset.env_id), **overrides}
    return ex, preset, demos, task, hyperparams


def run(
    seed: int, overrides: dict[str, Any], fit: dict[str, Any], final_episodes: int = 0
) -> dict[str, Any]:
    """One seed through ``train_and_evaluate`` with the overrides; with ``final_episodes``,
    the final policy is also scored on that many more greedy episodes (fresh starts)."""
    from sb3_swirl.baselines import evaluate_true_success

    ex, preset, demos, task, hyperparams = _setup(seed, overrides, fit)
    record = ex.train_and_evaluate(
        "swirl_dqn",
        preset,
        task=task,
        demos=demos,
        total_timesteps=30_000,
        seed=seed,
        progress=False,
        hyperparams=hyperparams,
        keep_model=final_episodes > 0,
    )
    curve = [p["success_rate"] for p in record["curve"]]
    row = {
        "seed": seed,
        "final": curve[-1],
        "last5": statistics.mean(curve[-5:]),
        "rollouts_to_95": record["rollouts_to_target"],
    }
    if final_episodes:
        # starts the training-time evaluations (seed + 10_000 onwards) never drew
        row["final_more"], _ = evaluate_true_success(
            record["model"], record["eval_env"], final_episodes, seed + 20_000
        )
    return row


def diagnose(seed: int, overrides: dict[str, Any], fit: dict[str, Any]) -> None:
    import gymnasium as gym
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_swirl import SwirlDQN
    from swirl_wrappers import SwirlWrapper

    ex, preset, demos, task, hyperparams = _setup(seed, overrides, fit)

    def make(env_seed: int) -> gym.Env:
        env = SwirlWrapper(gym.make(preset.env_id), task, **ex._swirl_wrapper_kwargs(hyperparams))
        env.reset(seed=env_seed)
        return env

    model = SwirlDQN(
        "MlpPolicy", make(seed), demonstrations=demos, seed=seed, **ex._algo_kwargs(hyperparams)
    )
    evaluation_env = make(seed + 10_000)

    def evaluate() -> str:
        ends = {"success": 0, "crash": 0, "time limit": 0}
        final_segments, q_rows = [], []
        for _ in range(40):
            obs, _ = evaluation_env.reset()
            while True:
                with torch.no_grad():
                    q = model.q_net(torch.as_tensor(obs[None], dtype=torch.float32))[0].numpy()
                top = np.sort(q)
                q_rows.append((int(np.argmax(obs[-task.n_indices :])), top[-1], top[-1] - top[-2]))
                obs, _, terminated, truncated, info = evaluation_env.step(int(q.argmax()))
                if terminated or truncated:
                    break
            final_segments.append(info["segment"])
            end = "success" if info.get("is_success") else "crash" if terminated else "time limit"
            ends[end] += 1
        rows = np.array(q_rows)
        per_segment = {
            int(s): f"{rows[rows[:, 0] == s, 1].mean():.2f}/{rows[rows[:, 0] == s, 2].mean():.2f}"
            for s in np.unique(rows[:, 0])
        }
        counts = np.bincount(final_segments, minlength=task.n_indices).tolist()
        return f"{ends}, ends in segment {counts}, Q max/gap per segment {per_segment}"

    class Every3000(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % 3000 == 0:
                print(f"{self.num_timesteps:6d} steps: {evaluate()}", flush=True)
            return True

    print(f"seed {seed}: {task.n_segments} segments")
    model.learn(30_000, callback=Every3000())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=seed_arg, nargs="+", default=list(range(30, 50)))
    parser.add_argument("--set", nargs="*", default=[], help="SwirlDQN settings, key=value")
    parser.add_argument("--fit", nargs="*", default=[], help="fit_task settings, key=value")
    parser.add_argument("--jobs", type=integer_arg(1), default=2)
    parser.add_argument(
        "--final-episodes",
        type=integer_arg(0),
        default=100,
        help="score the final policy on this many more episodes too (0: only the 20 of the "
        "last evaluation)",
    )
    parser.add_argument("--diagnose", type=seed_arg, default=None, metavar="SEED")
    parser.add_argument("--quick", action="store_true", help="two seeds, a smoke run")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds = args.seeds[:2]
    overrides, fit = _parse(args.set), _parse(args.fit)
    import inspect

    from sb3_swirl import SwirlDQN

    unknown = sorted(set(overrides) - set(inspect.signature(SwirlDQN).parameters))
    if unknown:  # named now, not in a worker after the demos and the fit
        parser.error(f"--set: SwirlDQN has no setting {unknown}")
    if args.diagnose is not None:
        diagnose(args.diagnose, overrides, fit)
        return
    from joblib import Parallel, delayed

    more = args.final_episodes
    rows = Parallel(n_jobs=args.jobs)(delayed(run)(s, overrides, fit, more) for s in args.seeds)
    print(f"SwirlDQN on parking, settings {overrides or 'as tuned'}, fit {fit or 'preset'}")
    for r in rows:
        print(
            f"  seed {r['seed']}: final {r['final']:.2f}, last 5 {r['last5']:.2f}, "
            f"rollouts to 95% {r['rollouts_to_95']}"
            + (f", final policy over {more} more episodes {r['final_more']:.2f}" if more else "")
        )
    reached = [r["rollouts_to_95"] for r in rows if r["rollouts_to_95"] is not None]
    print(
        f"final >= 0.9 on {sum(r['final'] >= 0.9 for r in rows)}/{len(rows)} seeds, mean final "
        f"{statistics.mean(r['final'] for r in rows):.3f}; 95% reached on {len(reached)}, "
        f"median rollouts {statistics.median(reached) if reached else 'n/a'}"
    )
    if more:
        print(
            f"over {more} more episodes: >= 0.9 on {sum(r['final_more'] >= 0.9 for r in rows)}"
            f"/{len(rows)} seeds, mean {statistics.mean(r['final_more'] for r in rows):.3f}"
        )


if __name__ == "__main__":
    raise SystemExit(run_main(main))
