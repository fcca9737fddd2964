"""Per-step cost of the SWIRL wrappers, measured side by side with the raw environments.

Targets: ``SwirlWrapper(Acrobot-v1)`` steps at most 1.15x the time of raw ``Acrobot-v1``; the
vector wrappers (SB3 ``SwirlVecEnv`` over ``DummyVecEnv``, gymnasium ``SwirlVectorWrapper``
over ``SyncVectorEnv``, 64 sub-envs) add at most 3 microseconds per env-step; and the first
wrapped step after import costs no more than the next ones (no compilation); SB3 ``DQN.learn``
on parking runs at least 0.95x as many env steps per second with the SWIRL wrapper (the tuned
settings, a fitted task) as on the raw env, both taking the same random actions.

The vector sub-envs are a cheap 4-D env (a few microseconds a step), so the wrappers' cost is
measured directly rather than lost in the noise of a costly env. Each sub-env ends an episode
every 25 steps (``--episode-length``), out of phase with the others (as real sub-envs are), so
about 2.6 sub-envs reset on each vector step and the wrappers' autoreset path runs on almost
every step.

Raw and wrapped runs alternate, repeat after repeat, and the medians are compared, so slow
phases of a shared machine hit both sides alike. A control line times an SB3 ``VecEnvWrapper``
that does nothing the same way: what it reads is the noise of the comparison.

Run: ``.venv/bin/python benchmarks/bench_wrappers.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import time
import timeit
from functools import partial

import gymnasium as gym
import numpy as np
from _timing import side_by_side, stepper, vector_stepper
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper

from sb3_swirl.vec_env import SwirlVecEnv
from swirl_wrappers import QuadraticReward, Region, SwirlVectorWrapper, SwirlWrapper, TaskModel

ACROBOT_RATIO_TARGET = 1.15
DQN_THROUGHPUT_TARGET = 0.95
VECTOR_ADDED_US_TARGET = 3.0
N_ENVS = 64
EPISODE_LENGTH = 25
CONTROL = "control: PassThrough(DummyVecEnv)"


def three_region_task(dims: tuple[int, ...], seed: int = 0) -> TaskModel:
    """A 3-region task in a 4-D task space (full covariances and weights, like a fitted one)."""
    rng = np.random.default_rng(seed)
    regions, rewards = [], []
    for _ in range(3):
        a = rng.normal(size=(4, 4)) * 0.3
        regions.append(Region(rng.normal(size=4) * 0.5, a @ a.T + 0.05 * np.eye(4), 9.0))
        b = rng.normal(size=(4, 4))
        rewards.append(QuadraticReward(rng.normal(size=4) * 0.5, b @ b.T))
    return TaskModel(regions, rewards, dims=dims)


class CheapEnv(gym.Env):
    """A 4-D env whose step costs little more than gymnasium's own call overhead."""

    observation_space = gym.spaces.Box(-5.0, 5.0, (4,), dtype=np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, episode_length: int = EPISODE_LENGTH) -> None:
        self.episode_length = episode_length
        self._states = np.random.default_rng(0).uniform(-1, 1, (97, 4)).astype(np.float32)
        self._t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._t = int(self.np_random.integers(97))
        # A seeded (first) reset starts part-way into an episode: the sub-envs of a vector env
        # then end their episodes on different steps.
        self._steps = 0 if seed is None else int(self.np_random.integers(self.episode_length))
        return self._states[self._t].copy(), {}

    def step(self, action):
        self._t = (self._t + 1 + int(action)) % 97
        self._steps += 1
        return self._states[self._t].copy(), 0.0, self._steps >= self.episode_length, False, {}


class PassThrough(VecEnvWrapper):
    """An SB3 ``VecEnvWrapper`` that adds nothing: the control of the vector comparisons."""

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        return self.venv.step_wait()


FIRST_STEP = """
import sys, time
start = time.perf_counter()
import sb3_swirl
imported = time.perf_counter()
sys.path.insert(0, {here!r})
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv
from bench_wrappers import CheapEnv, three_region_task
from sb3_swirl import SwirlVecEnv
venv = SwirlVecEnv(DummyVecEnv([CheapEnv] * 64), three_region_task(dims=(0, 1, 2, 3)))
venv.reset()
actions = np.zeros(64, dtype=int)
times = []
for _ in range(20):
    t = time.perf_counter()
    venv.step(actions)
    times.append(time.perf_counter() - t)
print(imported - start, times[0], sorted(times[1:])[len(times) // 2])
"""


def first_step_costs() -> tuple[float, float, float]:
    """Seconds to import sb3_swirl, then of the first and the median later ``SwirlVecEnv``
    step (64 sub-envs), in a fresh Python process."""
    import subprocess
    import sys
    from pathlib import Path

    code = FIRST_STEP.format(here=str(Path(__file__).parent))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    imported, first, later = (float(v) for v in out.stdout.split())
    return imported, first, later


def dqn_throughput(steps: int, repeats: int) -> tuple[float, float]:
    """Env steps/s of SB3 DQN training on parking without and with the SWIRL wrapper (medians
    of runs that alternate, after a warm-up)."""
    import torch
    from stable_baselines3 import DQN

    from sb3_swirl import collect_demos, fit_task
    from sb3_swirl.experiments import (
        PRESETS,
        _algo_kwargs,
        _swirl_wrapper_kwargs,
        load_hyperparams,
    )

    torch.set_num_threads(1)
    preset = PRESETS["parking"]
    demos = collect_demos(preset.env_id, preset.n_demos, seed=0)
    task = fit_task(demos, random_state=0, **preset.fit_kwargs)
    wrapper_kwargs = _swirl_wrapper_kwargs(load_hyperparams("swirl_dqn", preset.env_id))
    kwargs = _algo_kwargs(load_hyperparams("dqn", preset.env_id))
    kwargs.pop("policy", None)
    # Uniformly random actions (the same seeded draws on both sides): both runs then drive the
    # car through the same episodes, so the rates differ by the wrapper's cost, not by how
    # often two differently trained policies crash and reset. Gradient steps run as usual.
    kwargs.update(exploration_initial_eps=1.0, exploration_final_eps=1.0)

    def rate(wrapped: bool) -> float:
        env = gym.make(preset.env_id)
        if wrapped:
            env = SwirlWrapper(env, task, **wrapper_kwargs)
        model = DQN("MlpPolicy", env, seed=0, **kwargs)
        start = time.perf_counter()
        model.learn(total_timesteps=steps)
        return steps / (time.perf_counter() - start)

    rate(False)  # warm-up: torch's first calls are slow
    rates: dict[bool, list[float]] = {False: [], True: []}
    for k in range(repeats):  # alternate, so slow phases of a shared machine hit both alike
        for wrapped in (False, True) if k % 2 == 0 else (True, False):
            rates[wrapped].append(rate(wrapped))
    return float(np.median(rates[False])), float(np.median(rates[True]))


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short smoke run")
    parser.add_argument(
        "--num-envs",
        type=int,
        default=N_ENVS,
        help=f"sub-envs of the vector wrappers (the target is for {N_ENVS})",
    )
    parser.add_argument(
        "--episode-length",
        type=int,
        default=EPISODE_LENGTH,
        help=f"steps per episode of the vector sub-envs (the target is for {EPISODE_LENGTH})",
    )
    args = parser.parse_args(argv)
    n_envs, episode_length = args.num_envs, args.episode_length
    if n_envs < 1 or episode_length < 1:
        parser.error("--num-envs and --episode-length must be at least 1")

    def judged(met: bool) -> str:
        """OK or MISSED; a --quick sample is too short to judge a target."""
        return "no verdict (--quick)" if args.quick else ("OK" if met else "MISSED")

    steps, vec_steps, repeats = (200, 20, 5) if args.quick else (500, 100, 31)
    results: dict[str, float] = {}
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"{os.cpu_count()} CPUs, load average {load} (timings are medians of {repeats} pairs)")
    # The vector wrappers cost a fixed number of small numpy calls per step: report what one
    # costs here, so the added microseconds can be compared across machines.
    row = np.zeros(n_envs)
    ufunc_us = min(timeit.repeat(lambda: row + 1.0, number=2000, repeat=5)) / 2000 * 1e6
    print(f"one numpy ufunc call on {n_envs} floats: {ufunc_us:.2f} us")
    results["ufunc_us"] = ufunc_us

    # Acrobot observations are (cos t1, sin t1, cos t2, sin t2, w1, w2); the task reads 4 of them.
    task = three_region_task(dims=(0, 1, 2, 3))
    raw, wrapped = side_by_side(
        stepper(gym.make("Acrobot-v1"), steps, seed=0),
        stepper(SwirlWrapper(gym.make("Acrobot-v1"), task), steps, seed=0),
        repeats,
    )
    ratio = wrapped / raw
    results["acrobot_ratio"] = ratio
    print(
        f"SwirlWrapper(Acrobot-v1): raw {raw / steps * 1e6:.1f} us/step, wrapped "
        f"{wrapped / steps * 1e6:.1f} us/step, ratio {ratio:.3f}x "
        f"(target <= {ACROBOT_RATIO_TARGET}x) {judged(ratio <= ACROBOT_RATIO_TARGET)}"
    )

    imported, first, later = first_step_costs()
    results.update(import_s=imported, first_step_s=first, later_step_s=later)
    print(
        f"fresh process: import sb3_swirl {imported:.2f} s; SwirlVecEnv(64 sub-envs) first "
        f"step {first * 1e3:.2f} ms, later steps {later * 1e3:.2f} ms (median): first / later "
        f"{first / later:.1f}x (no compilation: target a few x at most, the cold caches)"
    )

    dqn_steps, dqn_repeats = (1_000, 2) if args.quick else (5_000, 8)
    raw_rate, swirl_rate = dqn_throughput(dqn_steps, dqn_repeats)
    ratio = swirl_rate / raw_rate
    results["dqn_throughput_ratio"] = ratio
    verdict = judged(ratio >= DQN_THROUGHPUT_TARGET)
    print(
        f"SB3 DQN training on parking ({dqn_steps} steps x {dqn_repeats}, medians): raw "
        f"{raw_rate:.0f} steps/s, with SwirlWrapper {swirl_rate:.0f} steps/s, ratio "
        f"{ratio:.3f} (target >= {DQN_THROUGHPUT_TARGET}) {verdict}"
    )

    vec_task = three_region_task(dims=(0, 1, 2, 3), seed=1)

    def make_envs():
        return [partial(CheapEnv, episode_length) for _ in range(n_envs)]

    def verdict(name: str, added: float) -> str:
        if name == CONTROL:
            return "(a wrapper that does nothing: the noise of this comparison)"
        if n_envs != N_ENVS or episode_length != EPISODE_LENGTH:
            return f"(the target is for {N_ENVS} sub-envs, {EPISODE_LENGTH}-step episodes)"
        return f"(target <= {VECTOR_ADDED_US_TARGET} us) {judged(added <= VECTOR_ADDED_US_TARGET)}"

    for name, raw_run, wrapped_run in (
        (
            "SwirlVecEnv(DummyVecEnv)",
            vector_stepper(DummyVecEnv(make_envs()), vec_steps, seed=0),
            vector_stepper(SwirlVecEnv(DummyVecEnv(make_envs()), vec_task), vec_steps, seed=0),
        ),
        (
            CONTROL,
            vector_stepper(DummyVecEnv(make_envs()), vec_steps, seed=0),
            vector_stepper(PassThrough(DummyVecEnv(make_envs())), vec_steps, seed=0),
        ),
        (
            "SwirlVectorWrapper(SyncVectorEnv)",
            vector_stepper(gym.vector.SyncVectorEnv(make_envs()), vec_steps, seed=0),
            vector_stepper(
                SwirlVectorWrapper(gym.vector.SyncVectorEnv(make_envs()), vec_task),
                vec_steps,
                seed=0,
            ),
        ),
    ):
        raw, wrapped = side_by_side(raw_run, wrapped_run, repeats)
        env_steps = vec_steps * n_envs
        added = (wrapped - raw) / env_steps * 1e6
        results[name] = added
        print(
            f"{name}, {n_envs} sub-envs, {episode_length}-step episodes: "
            f"raw {raw / env_steps * 1e6:.2f} us/env-step, "
            f"added {added:.3f} us/env-step ({wrapped / raw:.3f}x) {verdict(name, added)}"
        )
    return results


if __name__ == "__main__":
    main()
