"""Segmentation on demonstrations with known switch points: ours against ruptures.

Generators (:func:`sb3_swirl.datasets.make_switching_demos`): four kinds of phase dynamics
(constant velocity, goal reaching, linear dynamics, phases that differ in one dimension only),
each in seven variants that change one thing from a base of 10 demos, 4-D, 3 phases of about
40 samples, observation noise 0.1 (of a sample's motion), demonstrator speeds varying 1.5x:

* ``base``; ``dims``: 12-20 dimensions; ``phases``: 5-6 phases; ``noisy``: noise 0.5;
  ``nuisance``: 3 extra dimensions moving on their own; ``warped``: speeds varying 2x and time
  warped inside each demo; ``rates``: every other demo sampled at half the rate.

Plus **parking**: 5 supervisor demos, the supervisor's own phases (forward, reverse in,
reverse out, final) as the truth.

Metric: a switch found in a demo (the step at which the fitted segmentation enters a new
segment; the goal region is not a switch) is a hit if a true switch of that demo lies within
the tolerance, ``max(3, 3 % of the demo's length)`` steps, each true switch matched once.
Precision, recall and F1 pool the hits over a set's demos. Also: segments found against true,
and fit time (the segmentation alone).

Generator seeds are split: seeds 0-4 (tuning) chose the defaults, seeds 100-104 (held out) are
the result; ``--split tuning`` shows the former.

Methods: ``default`` (our defaults: ``indicator="auto"``, the best of gmm, velocity, linear
and phases by :func:`~sb3_swirl.segmentation.dynamics_cv_error`; time normalised; fragments
merged; nuisance dimensions left out where they cut transitions; region entries aligned);
ablations of it: ``unaligned`` (``align_entries=False``), ``same-dynamics``
(``merge_same_dynamics=True``), ``all-dims`` (``ignore_nuisance_dims=False``), ``unmerged``
(``merge_fragments=False``); one indicator instead of ``auto``, other settings default:
``gmm``, ``velocity``, ``linear``, ``phases``; ``gmm-unaligned`` (the paper's GMM with the
regions of Algorithm 1: the default before ``auto`` and ``align_entries``, and the fit of
every shipped task); ``before-benchmark`` (the defaults before this benchmark: the GMM, region
floor ``reg_covar=1e-3``, no time normalisation, no merging, every dimension clustered);
``rpt-*``: ruptures (Pelt and Binseg with the l2 cost on velocities, KernelCPD with the RBF
kernel on velocities) run per demo, then the same cross-demo consensus (clustering, pruning)
and settings as ours.

Run: ``python benchmarks/bench_segmentation.py [--quick] [--split tuning|held-out]
[--methods default velocity ...] [--no-parking] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import statistics
import time
import warnings
from collections import defaultdict
from typing import Any

import numpy as np

from sb3_swirl.datasets import KINDS, make_switching_demos
from sb3_swirl.segmentation import (
    SegmentationWarning,
    TransitionStateClustering,
    ruptures_indicator,
    switch_scores,
)

SEEDS = {"tuning": [0, 1, 2, 3, 4], "held-out": [100, 101, 102, 103, 104]}
VARIANTS = ("base", "dims", "phases", "noisy", "nuisance", "warped", "rates")
GMM = {"indicator": "gmm", "align_entries": False}
METHODS: dict[str, dict[str, Any]] = {
    "default": {},
    "unaligned": {"align_entries": False},
    "same-dynamics": {"merge_same_dynamics": True},
    "all-dims": {"ignore_nuisance_dims": False},
    "unmerged": {"merge_fragments": False},
    "gmm": {"indicator": "gmm"},
    "velocity": {"indicator": "velocity"},
    "linear": {"indicator": "linear"},
    "phases": {"indicator": "phases"},
    "gmm-unaligned": GMM,
    "before-benchmark": {
        **GMM,
        "reg_covar": 1e-3,
        "normalize_time": False,
        "merge_fragments": False,
        "ignore_nuisance_dims": False,
    },
    "rpt-pelt": {"indicator": functools.partial(ruptures_indicator, method="pelt")},
    "rpt-binseg": {"indicator": functools.partial(ruptures_indicator, method="binseg")},
    "rpt-kernel": {"indicator": functools.partial(ruptures_indicator, method="kernel")},
}


def variant_kwargs(variant: str, rng: np.random.Generator) -> dict[str, Any]:
    """Generator arguments of one variant (drawn with ``rng`` where it has a range)."""
    base: dict[str, Any] = {"n_demos": 10, "dim": 4, "n_phases": 3, "noise": 0.1}
    extra = {
        "base": {},
        "dims": {"dim": int(rng.integers(12, 21))},
        "phases": {"n_phases": int(rng.integers(5, 7))},
        "noisy": {"noise": 0.5},
        "nuisance": {"nuisance_dims": 3},
        "warped": {"speed_ratio": 2.0, "time_warp": 0.4},
        "rates": {"rates": (1, 2)},
    }[variant]
    return {**base, **extra}


def score(
    demos: list, switches: list[np.ndarray], params: dict[str, Any], seed: int
) -> dict[str, Any]:
    """Fit the segmentation and score it against the true switches."""
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SegmentationWarning)
        try:
            tsc = TransitionStateClustering(random_state=seed, **params).fit(demos)
            found, n_segments = tsc.switches_, len(tsc.regions_)
            error = None
        except ValueError as exc:  # no region shared: nothing found
            found, n_segments, error = [np.zeros(0, np.int64)] * len(demos), 0, str(exc)
    seconds = time.perf_counter() - start
    scores = switch_scores(found, switches, [len(d) for d in demos])
    warned = any(issubclass(w.category, SegmentationWarning) for w in caught) or bool(error)
    return {
        "f1": scores["f1"],
        "precision": scores["precision"],
        "recall": scores["recall"],
        "segments": n_segments,
        "true_segments": len(switches[0]) + 1,
        "seconds": seconds,
        "warned": warned,
        "error": error,
    }


def parking_sets(seeds: list[int]) -> list[tuple[str, int, list, list[np.ndarray]]]:
    """Five supervisor demos per seed, with the supervisor's phase switches as the truth."""
    from sb3_swirl.supervisors import collect_demos

    out = []
    for seed in seeds:
        demos, phases = collect_demos(
            "sb3_swirl/ParallelParking-v0", 5, seed=seed, return_phases=True
        )
        # a switch is the first step of a later phase than any before (a re-plan that starts
        # the manoeuvre over in the last steps is not one)
        switches = [np.flatnonzero(np.diff(np.maximum.accumulate(p))) + 1 for p in phases]
        out.append(("parking", seed, demos, switches))
    return out


def generator_sets(seeds: list[int], quick: bool) -> list[tuple[str, int, list, list]]:
    out = []
    for kind in KINDS:
        for variant in ("base", "rates") if quick else VARIANTS:
            for seed in seeds:
                rng = np.random.default_rng([seed, KINDS.index(kind), VARIANTS.index(variant)])
                kwargs = variant_kwargs(variant, rng)
                demos, switches = make_switching_demos(kind, random_state=rng, **kwargs)
                out.append((f"{kind}/{variant}", seed, demos, switches))
    return out


def summarise(rows: list[dict[str, Any]], methods: list[str]) -> None:
    by_gen: dict[str, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for row in rows:
        by_gen[row["generator"]][row["method"]].append(row)

    def f1(gen: str, method: str) -> list[float]:
        return [r["f1"] for r in by_gen[gen][method]]

    width = max(len(g) for g in by_gen)
    print(f"\nF1 median/mean per generator; {len(rows) // len(methods)} sets")
    cols = [max(11, len(m)) for m in methods]  # a column as wide as its method's name
    header = " ".join(f"{m:>{c}}" for m, c in zip(methods, cols, strict=True))
    print(f"{'generator':<{width}} {header}")
    for gen in by_gen:
        cells = [
            f"{statistics.median(f1(gen, m)):.2f}/{statistics.mean(f1(gen, m)):.2f}"
            for m in methods
        ]
        print(f"{gen:<{width}} " + " ".join(f"{x:>{c}}" for x, c in zip(cells, cols, strict=True)))
    # the README's table: per family (the generators of one kind of dynamics), then all sets
    families: dict[str, list[str]] = defaultdict(list)
    for gen in by_gen:
        families[gen.split("/")[0]].append(gen)
    print(f"\nF1 median/mean per family (the README's table); {len(rows) // len(methods)} sets")
    print(f"{'family':<{width}} {header}")
    for family, gens in [*families.items(), ("all", list(by_gen))]:
        cells = []
        for m in methods:
            scores = [x for g in gens for x in f1(g, m)]
            cells.append(f"{statistics.median(scores):.2f}/{statistics.mean(scores):.2f}")
        print(
            f"{family:<{width}} " + " ".join(f"{x:>{c}}" for x, c in zip(cells, cols, strict=True))
        )
    synthetic = [g for g in by_gen if g != "parking"]
    print(f"\noverall, per method (worst and below 0.7: the {len(synthetic)} synthetic generators)")
    name_width = max(len(m) for m in methods)
    for m in methods:
        mine = [r for r in rows if r["method"] == m]
        scores = [r["f1"] for r in mine]
        medians = [statistics.median(f1(g, m)) for g in synthetic]
        silent = sum(
            1 for r in mine if r["segments"] <= 1 and r["true_segments"] >= 2 and not r["warned"]
        )
        seconds = [r["seconds"] for r in mine]
        print(
            f"  {m:<{name_width}} median F1 {statistics.median(scores):.3f}, "
            f"mean {statistics.mean(scores):.3f}, "
            f"worst generator (median) {min(medians, default=math.nan):.2f}, "
            f"below 0.7 {sum(x < 0.7 for x in medians)}, "
            f"sets with segments = truth {sum(r['segments'] == r['true_segments'] for r in mine)}"
            f"/{len(mine)}, silent collapses {silent}, "
            f"fit time median {statistics.median(seconds):.3f} s max {max(seconds):.2f} s"
        )
    ruptures = [m for m in methods if m.startswith("rpt-")]
    for m in (m for m in methods if not m.startswith("rpt-")) if ruptures else ():
        for stat in (statistics.median, statistics.mean):
            beaten = []
            for g in by_gen:
                score = {r: stat(f1(g, r)) for r in ruptures}
                best = max(score, key=score.__getitem__)
                if stat(f1(g, m)) < score[best]:
                    beaten.append(f"{g} ({stat(f1(g, m)):.2f} < {best} {score[best]:.2f})")
            print(
                f"  {m}: a ruptures method has the higher {stat.__name__} on {len(beaten)} of "
                f"{len(by_gen)} generators" + (f": {', '.join(beaten)}" if beaten else "")
            )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="two variants, one seed, a smoke run")
    parser.add_argument("--split", choices=list(SEEDS), default="held-out")
    parser.add_argument("--methods", nargs="+", choices=list(METHODS), default=list(METHODS))
    parser.add_argument("--no-parking", action="store_true")
    parser.add_argument("--json", help="write every row to this file")
    args = parser.parse_args(argv)
    args.methods = list(dict.fromkeys(args.methods))  # a method named twice runs once
    if args.json:  # a path that cannot be written fails now, not after the fits
        folder = os.path.dirname(os.path.abspath(args.json))
        if os.path.isdir(args.json) or not os.access(folder, os.W_OK):
            parser.error(f"--json: cannot write {args.json} (a folder, or not a writable one)")
    seeds = SEEDS[args.split][:1] if args.quick else SEEDS[args.split]
    sets = generator_sets(seeds, args.quick)
    if not args.no_parking:
        sets += parking_sets(seeds)
    rows = []
    for generator, seed, demos, switches in sets:
        for method in args.methods:
            result = score(demos, switches, METHODS[method], seed)
            rows.append({"generator": generator, "seed": seed, "method": method, **result})
    summarise(rows, args.methods)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
