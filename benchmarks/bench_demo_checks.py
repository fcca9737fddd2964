"""How ``check_demos_agree`` tells a demo at another rate from ordinary variety.

For each demo set: the largest ratio of a demo's typical step (and of its number of steps) to
the other demos' median, ``max(r, 1/r)``, which ``check_demos_agree`` warns about above 3, and
the warnings it gives. Tuning sets chose the threshold; held-out sets (other seeds and
generator variants) check it; then one demo of held-out sets is resampled 7x coarser and 10x
finer, which must be named.

Run: ``.venv/bin/python benchmarks/bench_demo_checks.py [--quick]``.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from sb3_swirl import collect_demos
from sb3_swirl.demos import (
    _rate_ratios,
    _robust_scale,
    as_demonstrations,
    check_demos_agree,
    make_piecewise_linear_demos,
)

PARKING, ACROBOT = "sb3_swirl/ParallelParking-v0", "sb3_swirl/NoisyAcrobot-v0"


def _states(demos) -> list[np.ndarray]:
    return [np.asarray(d.observations, dtype=np.float64) for d in demos]


def _sets(seeds_parking, seeds_acrobot, seeds_synthetic, variants):
    for seed in seeds_parking:
        yield f"parking, 5 demos, seed {seed}", _states(collect_demos(PARKING, 5, seed=seed))
    for seed in seeds_acrobot:
        yield f"acrobot, 15 demos, seed {seed}", _states(collect_demos(ACROBOT, 15, seed=seed))
    for seed in seeds_synthetic:
        for name, kwargs in variants:
            demos, _ = make_piecewise_linear_demos(random_state=seed, **kwargs)
            yield f"generator {name}, seed {seed}", _states(demos)


def _finer(x: np.ndarray, k: int) -> np.ndarray:
    t, fine = np.arange(len(x)), np.linspace(0, len(x) - 1, (len(x) - 1) * k + 1)
    return np.stack([np.interp(fine, t, x[:, j]) for j in range(x.shape[1])], axis=1)


def _report(name: str, states: list[np.ndarray]) -> tuple[float, float, int]:
    ratios = _rate_ratios(states, _robust_scale(states)[1])
    step, length = (float(np.nanmax(np.maximum(r, 1 / r))) for r in ratios.T)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        n_warned = len(check_demos_agree(as_demonstrations(states)))
    print(f"  {name:42s} step {step:5.2f}  length {length:5.2f}  warnings {n_warned}")
    return step, length, n_warned


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few sets only")
    args = parser.parse_args(argv)
    tuning_variants = [("25-40-step phases", {}), ("20-60-step phases", {"phase_length": (20, 60)})]
    held_variants = [
        *tuning_variants,
        ("10-D, noise 0.2", {"n_demos": 6, "dim": 10, "noise": 0.2, "n_phases": 5}),
        ("two demos", {"n_demos": 2}),
    ]
    tuning = (range(2), range(1), range(2)) if args.quick else (range(5), range(3), range(5))
    held = (
        (range(10, 11), range(10, 11), range(10, 11))
        if args.quick
        else (
            range(10, 15),
            range(10, 13),
            range(10, 15),
        )
    )
    for label, seeds, variants in (
        ("tuning", tuning, tuning_variants),
        ("held out", held, held_variants),
    ):
        print(f"{label}:")
        rows = [_report(name, states) for name, states in _sets(*seeds, variants)]
        print(
            f"  largest ratios {max(r[0] for r in rows):.2f} (step), {max(r[1] for r in rows):.2f} "
            f"(length); sets warned about: {sum(r[2] > 0 for r in rows)} of {len(rows)}"
        )
    print("held out, one demo resampled (must be named):")
    named = total = 0
    for env, n, seeds in ((PARKING, 5, held[0]), (ACROBOT, 15, held[1])):
        for seed in seeds:
            states = _states(collect_demos(env, n, seed=seed))
            for how, odd in (
                ("7x coarser", states[-1][::7]),
                ("10x finer", _finer(states[-1], 10)),
            ):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    said = check_demos_agree(as_demonstrations([*states[:-1], odd]))
                hit = any(m.startswith(f"demo {n - 1}:") for m in said)
                named, total = named + hit, total + 1
                print(
                    f"  {env.split('/')[1]} seed {seed}, {how}: {said[0] if said else 'NOT NAMED'}"
                )
    print(f"named in {named} of {total}")


if __name__ == "__main__":
    main()
