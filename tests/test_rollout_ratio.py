"""The censoring rules of a rollout ratio (Fig. 2's and the sample-efficiency headline's)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

from sb3_swirl.experiments import rollout_ratio, summarise_ratios


def run(seed: int, curve: list[tuple[int, float]]) -> dict:
    return {"seed": seed, "curve": [{"episodes": e, "success_rate": s} for e, s in curve]}


def test_exact_censored_and_unknown_ratios():
    reached = run(0, [(10, 0.5), (20, 1.0)])
    never = run(0, [(100, 0.0), (300, 0.0)])
    exact = rollout_ratio(reached, run(0, [(50, 0.2), (200, 0.95)]), 0.95)
    assert exact["kind"] == "=" and exact["ratio"] == pytest.approx(0.1)
    censored = rollout_ratio(reached, never, 0.95)
    assert censored["kind"] == "<" and censored["ratio"] == pytest.approx(20 / 300)
    lower = rollout_ratio(never, run(0, [(40, 1.0)]), 0.95)
    assert lower["kind"] == ">" and lower["ratio"] == pytest.approx(300 / 40)
    assert rollout_ratio(never, never, 0.95)["kind"] == "?"


def test_the_benchmark_targets_the_best_success_on_the_acrobot(monkeypatch):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "sample_efficiency.py"
    monkeypatch.syspath_prepend(str(path.parent))  # its helpers, as when run as a script
    spec = importlib.util.spec_from_file_location("sample_efficiency", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    swirl, dqn = run(0, [(10, 0.3), (20, 0.6)]), run(0, [(100, 0.0), (300, 0.6)])
    row = bench.compare_seed("acrobot", swirl, dqn, 0.95)  # target 0.95 of the best, 0.6
    assert row["target"] == pytest.approx(0.57) and row["ratio"] == pytest.approx(20 / 300)
    assert bench.compare_seed("parking", swirl, dqn, 0.95)["kind"] == "?"
    assert (
        bench.compare_seed("acrobot", run(0, [(9, 0.0)]), dqn | {"curve": []}, 0.95)["kind"] == "?"
    )


def test_median_is_an_upper_bound_with_unknown_seeds_as_infinity():
    rows = [{"kind": "<", "ratio": r} for r in (0.03, 0.04, 0.05, 0.3)] + [
        {"kind": "?", "ratio": None}
    ]
    summary = summarise_ratios(rows)
    assert summary["bound"] == "<=" and summary["median"] == pytest.approx(0.05)
    assert math.isinf(summary["max"]) and summary["n_infinite"] == 1
    # the bound must not drop below the true median whatever the unknown seed's ratio is
    for unknown in (0.0, 0.04, 10.0):
        known = [0.03, 0.04, 0.05, 0.3, unknown]
        assert sorted(known)[2] <= summary["median"]


def test_median_is_unresolved_when_half_the_seeds_have_no_upper_bound():
    rows = [{"kind": "=", "ratio": 0.1}, {"kind": ">", "ratio": 2.0}, {"kind": "?", "ratio": None}]
    assert summarise_ratios(rows)["bound"] == "unresolved"
    exact = summarise_ratios([{"kind": "=", "ratio": r} for r in (0.1, 0.2, 0.3)])
    assert exact["bound"] == "=" and exact["median"] == pytest.approx(0.2)
