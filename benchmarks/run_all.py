"""Run the benchmarks in this folder, one after the other (``make bench``).

Each benchmark prints ratios measured side by side in one run. ``--quick`` runs each in its
smoke mode; the long studies (sample efficiency, the baselines, SwirlDQN's stability over 20
seeds) run only with ``--with-slow`` (the sweeps each in its own ``results/bench/<time>/``
folder). ``acrobot_rules.py`` is not a benchmark but a check of how hard the acrobots are (the
README's Environments): run it on its own. At the end it lists the targets missed (the lines
that say MISSED; exit status 0, since a miss is a measurement) and the benchmarks that failed
(exit status 1).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).parent
FAST = [
    "bench_wrappers.py",
    "bench_envs.py",
    "bench_fit.py",
    "bench_demo_checks.py",
    "bench_segmentation.py",
    "bench_dvrk.py",
]
SLOW = ["sample_efficiency.py", "baselines.py", "swirl_dqn_stability.py"]
# sweeps that keep their runs (and refuse to overwrite them): each run of this script gets its
# own folder
SWEEPS = {"sample_efficiency.py", "baselines.py"}


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="smoke mode of each benchmark")
    parser.add_argument(
        "--with-slow",
        action="store_true",
        help="also the sample-efficiency, baseline and SwirlDQN-stability studies",
    )
    args = parser.parse_args()
    failed, missed = [], {}
    stamp = time.strftime("%Y%m%d-%H%M%S")
    for name in FAST + (SLOW if args.with_slow else []):
        print(f"\n===== {name} =====", flush=True)
        cmd = [sys.executable, str(HERE / name)] + (["--quick"] if args.quick else [])
        if name in SWEEPS:
            cmd += ["--out", f"results/bench/{stamp}/{Path(name).stem}"]
        with subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, bufsize=1) as proc:
            for line in proc.stdout:  # shown as it comes, and its missed targets counted
                print(line, end="", flush=True)
                if "MISSED" in line:
                    missed.setdefault(name, []).append(line.strip())
        if proc.returncode != 0:
            failed.append(name)
    if missed:  # a target missed is a measurement, not a failure: listed, exit status 0
        print("\ntargets missed:")
        for name, lines in missed.items():
            print("\n".join(f"  {name}: {line}" for line in lines))
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
