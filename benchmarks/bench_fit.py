"""Fit time of ``fit_task`` against the number of demonstrations (about 1000 steps, 4-D each).

Targets: 15 demos <= 5 s, 1000 demos <= 60 s, and growth at most linear (the per-demo time
should not rise with the number of demos); without the kernel also 15 demos <= 1 s and within
2x of the paper's path measured beside it (the segmentation benchmark's issue). ``--kernel``
fits with the approximate RBF kernel PCA (Nyström, 200 landmarks; sigma 10, on the scale of
these demos) and reports the peak memory, which must stay bounded at 1000 demos x 1000 steps.
Beside each fit, the same demos fitted the paper's way (``indicator="gmm",
align_entries=False``, the default before the segmentation benchmark), timed in the same run:
``x gmm`` is the ratio.
Run: ``python benchmarks/bench_fit.py [--quick] [--kernel] [--indicator auto|gmm|...]``.
"""

from __future__ import annotations

import argparse
import resource
import time

from sb3_swirl.demos import make_piecewise_linear_demos
from sb3_swirl.fitting import fit_task


def _demos(n_demos: int, steps: int, seed: int):
    phases = 5
    per_phase = steps // phases
    return make_piecewise_linear_demos(
        n_demos=n_demos,
        n_phases=phases,
        dim=4,
        phase_length=(int(0.8 * per_phase), int(1.2 * per_phase)),
        noise=0.05,
        random_state=seed,
    )[0]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="small sizes, a smoke run")
    parser.add_argument(
        "--indicator", default="auto", choices=["auto", "gmm", "velocity", "linear", "phases"]
    )
    parser.add_argument("--kernel", action="store_true", help="approximate RBF kernel PCA")
    args = parser.parse_args(argv)
    kernel = {"kernel": "rbf", "kernel_sigma": 10.0} if args.kernel else {}
    sizes, steps = ([5, 20], 200) if args.quick else ([15, 60, 240, 1000], 1000)

    features = "RBF kernel PCA" if kernel else "no kernel"
    print(f"fit_task, indicator={args.indicator}, {features}, 4-D demos of ~{steps} steps")
    print(
        f"{'demos':>6} {'steps':>9} {'fit s':>8} {'ms/demo':>8} {'ratio':>6} {'regions':>7}"
        f" {'gmm s':>7} {'x gmm':>6}"
    )
    warm_up = _demos(sizes[0], steps, seed=0)  # first calls, pages: both paths timed below
    fit_task(warm_up, indicator=args.indicator, random_state=0, **kernel)
    fit_task(warm_up, indicator="gmm", align_entries=False, random_state=0, **kernel)
    base = None
    rows = []
    for n in sizes:
        demos = _demos(n, steps, seed=n)
        start = time.perf_counter()
        task = fit_task(demos, indicator=args.indicator, random_state=0, **kernel)
        elapsed = time.perf_counter() - start
        start = time.perf_counter()
        fit_task(demos, indicator="gmm", align_entries=False, random_state=0, **kernel)
        paper = time.perf_counter() - start
        per_demo = elapsed / n
        base = per_demo if base is None else base
        rows.append((n, elapsed, paper))
        print(
            f"{n:>6} {sum(len(d) for d in demos):>9} {elapsed:>8.2f} {1e3 * per_demo:>8.1f} "
            f"{per_demo / base:>6.2f} {task.n_segments:>7} {paper:>7.2f} {elapsed / paper:>6.1f}"
        )
    if not args.quick:
        (_, small, small_paper), (_, large, _) = rows[0], rows[-1]
        print(f"target 15 demos <= 5 s: {small:.2f} s ({'ok' if small <= 5 else 'MISSED'})")
        print(f"target 1000 demos <= 60 s: {large:.2f} s ({'ok' if large <= 60 else 'MISSED'})")
        if not kernel:
            print(f"target 15 demos <= 1 s: {small:.2f} s ({'ok' if small <= 1 else 'MISSED'})")
            ratio = small / small_paper
            print(
                f"target 15 demos within 2x of the paper's path: {ratio:.1f}x "
                f"({'ok' if ratio <= 2 else 'MISSED'})"
            )
    print("ratio = per-demo time relative to the smallest set (<= ~1 means at most linear)")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    print(f"peak resident memory of this process: {peak_mb:.0f} MB")


if __name__ == "__main__":
    main()
