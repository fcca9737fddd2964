"""Step throughput of the dVRK tasks beside robosuite's own Lift, and 2-worker scaling.

Targets (random actions, single process, resets included; issue 19):

- ``DVRKLineCutting-v0`` steps/s >= 0.5x robosuite ``Lift`` (Panda, its default controller,
  20 Hz, no cameras);
- ``DVRKTensioning-v0`` steps/s >= 0.25x ``Lift``, driven by its supervisor (reach, grasp,
  lift, pull: the cloth is under load most of the time, the slow case) rather than by random
  actions (which rarely grasp);
- ``SubprocVecEnv`` with 2 workers >= 1.6x the steps/s of one env in ``DummyVecEnv``.

Lift and our env alternate, repeat after repeat, and the medians are compared. Our env runs at
10 Hz (the dVRK's rate; one step is twice Lift's simulated time) with a 4 ms physics step.

Run: ``.venv/bin/python benchmarks/bench_dvrk.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np
from _timing import side_by_side, stepper, vector_stepper

import sb3_swirl.envs  # noqa: F401

TARGETS = {"line cutting / Lift": 0.5, "tensioning / Lift": 0.25, "2 workers / 1": 1.6}


def supervised_stepper(env_id: str, steps: int, seed: int):
    """A function that takes ``steps`` steps of the env's supervisor; returns seconds."""
    from sb3_swirl.supervisors import supervisor_for

    env = gym.make(env_id)
    supervisor = supervisor_for(env_id)(env.unwrapped, seed=seed)

    def run() -> float:
        start = time.perf_counter()
        obs, _ = env.reset(seed=seed)
        supervisor.reset(obs)
        for _ in range(steps):
            obs, _, terminated, truncated, _ = env.step(supervisor.act(obs))
            if terminated or truncated:
                obs, _ = env.reset()
                supervisor.reset(obs)
        return time.perf_counter() - start

    return run


def lift_stepper(steps: int, seed: int):
    import logging

    logging.getLogger("robosuite_logs").setLevel(logging.ERROR)
    import robosuite

    env = robosuite.make(
        "Lift",
        robots="Panda",
        has_renderer=False,
        has_offscreen_renderer=False,
        use_camera_obs=False,
        control_freq=20,
        horizon=150,
        hard_reset=False,
    )
    env.reset()
    low, high = env.action_spec
    actions = np.random.default_rng(seed).uniform(low, high, size=(steps, len(low)))

    def run() -> float:
        start = time.perf_counter()
        for a in actions:
            _, _, done, _ = env.step(a)
            if done:
                env.reset()
        return time.perf_counter() - start

    return run


def main(argv: list[str] | None = None) -> dict[str, float]:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer steps and repeats")
    args = parser.parse_args(argv)
    steps, repeats = (300, 2) if args.quick else (1_500, 5)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{os.cpu_count()} CPUs, load average {load} (medians of {repeats} pairs)")

    results = {}
    ours = gym.make("sb3_swirl/DVRKLineCutting-v0")
    ours_t, lift_t = side_by_side(stepper(ours, steps, 0), lift_stepper(steps, 0), repeats)
    print(f"line cutting {steps / ours_t:7.0f} steps/s   Lift {steps / lift_t:7.0f} steps/s")
    results["line cutting / Lift"] = lift_t / ours_t
    ours_t, lift_t = side_by_side(
        supervised_stepper("sb3_swirl/DVRKTensioning-v0", steps, 0),
        lift_stepper(steps, 0),
        repeats,
    )
    print(f"tensioning   {steps / ours_t:7.0f} steps/s   Lift {steps / lift_t:7.0f} steps/s")
    results["tensioning / Lift"] = lift_t / ours_t

    one = make_vec_env("sb3_swirl/DVRKLineCutting-v0", n_envs=1, vec_env_cls=DummyVecEnv)
    two = make_vec_env("sb3_swirl/DVRKLineCutting-v0", n_envs=2, vec_env_cls=SubprocVecEnv)
    one_t, two_t = side_by_side(
        vector_stepper(one, steps, 0), vector_stepper(two, steps // 2, 0), repeats
    )
    print(f"1 env {steps / one_t:7.0f} steps/s   2 workers {steps / two_t:7.0f} steps/s")
    results["2 workers / 1"] = one_t / two_t
    two.close()

    for name, ratio in results.items():
        target = TARGETS[name]
        verdict = "meets" if ratio >= target else "MISSES"
        print(f"{name:22s} {ratio:5.2f}x  ({verdict} the {target}x target)")
    return results


if __name__ == "__main__":
    main()
