"""Step throughput of the shipped envs beside gymnasium's classic ones, and demo generation time.

Targets (random actions, raw envs: no ``TimeLimit`` or checker wrappers on either side):

- ``ParallelParkingEnv`` steps/s >= 0.5x gymnasium's ``CartPoleEnv``;
- ``NoisyAcrobotEnv`` steps/s >= 0.8x gymnasium's ``AcrobotEnv``;
- ``collect_demos``: 5 parking demos and 15 acrobot demos in <= 30 s each, on one core.

Both envs of a pair alternate, repeat after repeat, and the medians are compared, so slow
phases of a shared machine hit both sides alike.

Run: ``.venv/bin/python benchmarks/bench_envs.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np
from _timing import side_by_side, stepper
from gymnasium.envs.classic_control.acrobot import AcrobotEnv
from gymnasium.envs.classic_control.cartpole import CartPoleEnv

from sb3_swirl.envs.acrobot import NoisyAcrobotEnv
from sb3_swirl.envs.parking import ParallelParkingEnv
from sb3_swirl.supervisors import collect_demos

THROUGHPUT_TARGETS = {"parking/CartPole": 0.5, "acrobot/Acrobot": 0.8}
DEMO_SECONDS_TARGET = 30.0


def steps_per_second(
    ours: gym.Env, theirs: gym.Env, steps: int, repeats: int
) -> tuple[float, float]:
    """Median steps/s of both envs, run alternately."""
    ours_t, theirs_t = side_by_side(stepper(ours, steps, 0), stepper(theirs, steps, 0), repeats)
    return steps / ours_t, steps / theirs_t


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer steps and repeats, 1+3 demos")
    args = parser.parse_args(argv)
    steps, repeats = (2_000, 3) if args.quick else (20_000, 7)
    n_parking, n_acrobot = (1, 3) if args.quick else (5, 15)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{os.cpu_count()} CPUs, load average {load} (steps/s are medians of {repeats} pairs)")

    results: dict[str, float] = {}
    pairs = {
        "parking/CartPole": (ParallelParkingEnv(), CartPoleEnv()),
        "acrobot/Acrobot": (NoisyAcrobotEnv(), AcrobotEnv()),
    }
    for name, (ours, theirs) in pairs.items():
        ours_sps, theirs_sps = steps_per_second(ours, theirs, steps, repeats)
        ratio = ours_sps / theirs_sps
        target = THROUGHPUT_TARGETS[name]
        results[name] = ratio
        print(
            f"{type(ours).__name__:>20}: {ours_sps:9.0f} steps/s   "
            f"{type(theirs).__name__:>12}: {theirs_sps:9.0f} steps/s   "
            f"ratio {ratio:5.2f} (target >= {target})  {'ok' if ratio >= target else 'MISSED'}"
        )

    for env_id, n in [
        ("sb3_swirl/ParallelParking-v0", n_parking),
        ("sb3_swirl/NoisyAcrobot-v0", n_acrobot),
    ]:
        start = time.perf_counter()
        demos = collect_demos(env_id, n, seed=0)
        seconds = time.perf_counter() - start
        results[f"demos {env_id}"] = seconds
        mean_len = np.mean([len(d) for d in demos])
        print(
            f"collect_demos({env_id!r}, {n}): {seconds:5.1f} s, mean length {mean_len:.0f} steps "
            f"(target <= {DEMO_SECONDS_TARGET:.0f} s for the full count)  "
            + (
                "no verdict (--quick: fewer demos)"
                if args.quick
                else ("ok" if seconds <= DEMO_SECONDS_TARGET else "MISSED")
            )
        )
    return results


if __name__ == "__main__":
    main()
