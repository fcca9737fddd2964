"""The zoo's ``default`` entry on envs that have no entry of their own (the README's own env).

For each env: 10 demos of a feedback rule, recorded with the env's rewards (reset seeds 0-9):
MountainCar-v0 pushes the way the car moves, CartPole-v1 pushes the way the pole leans
(``obs[2] + 0.5 obs[3] > 0``), Acrobot-v1 torques the way the second link swings
(``obs[5] > 0``). Each (env, seed) then runs in a fresh folder holding them as ``demos.npz``:
``sb3-swirl zoo train --algo swirl_dqn --env ENV -n STEPS -f logs --eval-freq 2000
--eval-episodes 10 --seed SEED``, the shipped ``default`` entry as it is. Success is read from
the evaluation episodes' lengths (these envs report no ``is_success``): MountainCar under 200
steps, Acrobot under 500, CartPole 500. Prints per env and seed the success averaged over the
evaluations and at the last, and the segments fitted.

Run: ``python benchmarks/own_env.py [--envs MountainCar-v0 CartPole-v1 Acrobot-v1]
[--seeds 20 21 22 23 24] [--steps 20000] [--jobs 2]``. The entry was chosen on MountainCar
with seeds 0-4; 20-24 are held out (README, "Training with the zoo").
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _cli import integer_arg, run_main, seed_arg

#: each env's feedback rule (observation -> action) and the episode lengths that succeed
RULES = {
    "MountainCar-v0": (lambda obs: 2 if obs[1] >= 0 else 0, lambda n: n < 200),
    "CartPole-v1": (lambda obs: int(obs[2] + 0.5 * obs[3] > 0), lambda n: n >= 500),
    "Acrobot-v1": (lambda obs: 1 + int(np.sign(obs[5])), lambda n: n < 500),
}


def record_demos(env_id: str, path: Path, n: int = 10) -> None:
    """``n`` demos of ``env_id``'s feedback rule, with the env's rewards, saved to ``path``."""
    import gymnasium as gym

    from sb3_swirl import Demonstration, save_demos

    env, rule = gym.make(env_id), RULES[env_id][0]
    demos = []
    for seed in range(n):
        obs, _ = env.reset(seed=seed)
        states, actions, rewards, done = [obs], [], [], False
        while not done:
            action = rule(obs)
            obs, reward, terminated, truncated, _ = env.step(action)
            states.append(obs)
            actions.append(action)
            rewards.append(reward)
            done = terminated or truncated
        # CartPole's demos balance until the time limit: not a terminal state
        arrays = np.array(states), np.array(actions), np.array(rewards)
        demos.append(Demonstration(*arrays, truncated=not terminated))
    save_demos(demos, path)


def run(env_id: str, seed: int, steps: int) -> dict:
    """One zoo run of the ``default`` entry on ``env_id``; its success over the evaluations."""
    from sb3_swirl import TaskModel

    with tempfile.TemporaryDirectory() as tmp:
        record_demos(env_id, Path(tmp) / "demos.npz")
        command = [sys.executable, "-m", "sb3_swirl.cli", "zoo", "train", "--algo", "swirl_dqn"]
        command += ["--env", env_id, "-n", str(steps), "-f", "logs", "--eval-freq", "2000"]
        command += ["--eval-episodes", "10", "--seed", str(seed)]
        out = subprocess.run(command, cwd=tmp, capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(f"{env_id} seed {seed}: the zoo failed:\n{out.stderr[-3000:]}")
        run_dir = next((Path(tmp) / "logs" / "swirl_dqn").iterdir())
        with np.load(run_dir / "evaluations.npz") as npz:
            lengths = npz["ep_lengths"]
        segments = TaskModel.from_json(next(run_dir.rglob("task.json"))).n_segments
    succeeded = np.vectorize(RULES[env_id][1])(lengths).mean(axis=1)
    return {
        "env": env_id,
        "seed": seed,
        "over_run": float(succeeded.mean()),
        "final": float(succeeded[-1]),
        "segments": segments,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", nargs="+", choices=sorted(RULES), default=list(RULES))
    parser.add_argument("--seeds", type=seed_arg, nargs="+", default=[20, 21, 22, 23, 24])
    parser.add_argument("--steps", type=integer_arg(2000), default=20000)
    parser.add_argument("--jobs", type=integer_arg(1), default=2)
    args = parser.parse_args(argv)
    from joblib import Parallel, delayed

    jobs = [(env_id, seed) for env_id in args.envs for seed in args.seeds]
    rows = Parallel(n_jobs=args.jobs)(delayed(run)(e, s, args.steps) for e, s in jobs)
    print(f"the zoo's default entry, {args.steps} steps, 10 demos with the env's rewards")
    for env_id in args.envs:
        mine = [r for r in rows if r["env"] == env_id]
        for r in mine:
            print(
                f"  {env_id} seed {r['seed']}: {r['over_run']:.2f} ({r['final']:.2f}), "
                f"{r['segments']} segment" + "s" * (r["segments"] != 1)
            )
        over, final = np.mean([r["over_run"] for r in mine]), np.mean([r["final"] for r in mine])
        print(f"{env_id}: success over the run {over:.2f} (at the end {final:.2f})")


if __name__ == "__main__":
    raise SystemExit(run_main(main))
