"""How hard are the acrobots? A random policy and one-line feedback rules, no learning.

For ``NoisyAcrobot-v0`` (a torque on either joint) and ``UnderactuatedAcrobot-v0`` (joint 2
only, as gymnasium's ``Acrobot-v1``): success rate over 100 episodes (seeds 100-199, 1000
steps) and the median length of the successful ones. A task that a one-line rule solves
cannot show what learning from demonstrations adds.

Run: ``.venv/bin/python benchmarks/acrobot_rules.py [--episodes 100]``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from _cli import integer_arg

import sb3_swirl  # noqa: F401  (registers the envs)

RULES: dict[str, dict[str, Callable[[np.ndarray], int] | None]] = {
    "sb3_swirl/NoisyAcrobot-v0": {
        "random": None,
        "pump joint 1 (+ if w1 >= 0)": lambda o: 0 if o[2] >= 0 else 1,
        "pump joint 2 (+ if w2 >= 0)": lambda o: 2 if o[3] >= 0 else 3,
    },
    "sb3_swirl/UnderactuatedAcrobot-v0": {
        "random": None,
        "oppose w1 (+ if w1 < 0)": lambda o: 2 if o[2] < 0 else 0,
        "pump joint 2 (+ if w2 >= 0)": lambda o: 2 if o[3] >= 0 else 0,
        "follow w1 (+ if w1 >= 0)": lambda o: 2 if o[2] >= 0 else 0,
    },
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=integer_arg(1), default=100)
    args = parser.parse_args(argv)
    for env_id, rules in RULES.items():
        env = gym.make(env_id)
        print(env_id)
        for name, rule in rules.items():
            rng = np.random.default_rng(0)
            successes, lengths = [], []
            for seed in range(100, 100 + args.episodes):
                obs, _ = env.reset(seed=seed)
                steps, done, info = 0, False, {}
                while not done:
                    n = int(env.action_space.n)
                    action = int(rng.integers(n)) if rule is None else rule(obs)
                    obs, _, terminated, truncated, info = env.step(action)
                    steps += 1
                    done = terminated or truncated
                successes.append(bool(info["is_success"]))
                if info["is_success"]:
                    lengths.append(steps)
            median = f"{np.median(lengths):.0f}" if lengths else "-"
            print(f"  {name:<30} success {np.mean(successes):.2f}, median steps {median}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
