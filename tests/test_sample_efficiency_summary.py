"""The censoring rules of benchmarks/sample_efficiency.py (the headline's arithmetic)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "sample_efficiency.py"
_spec = importlib.util.spec_from_file_location("sample_efficiency", _PATH)
se = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(se)


def run(seed: int, curve: list[tuple[int, float]]) -> dict:
    return {"seed": seed, "curve": [{"episodes": e, "success_rate": s} for e, s in curve]}


def test_exact_censored_and_unknown_ratios():
    reached = run(0, [(10, 0.5), (20, 1.0)])
    never = run(0, [(100, 0.0), (300, 0.0)])
    assert se.compare_seed("parking", reached, run(0, [(50, 0.2), (200, 0.95)]), 0.95)[
        "ratio"
    ] == pytest.approx(0.1)
    censored = se.compare_seed("parking", reached, never, 0.95)
    assert censored["kind"] == "<" and censored["ratio"] == pytest.approx(20 / 300)
    lower = se.compare_seed("parking", never, run(0, [(40, 1.0)]), 0.95)
    assert lower["kind"] == ">" and lower["ratio"] == pytest.approx(300 / 40)
    assert se.compare_seed("parking", never, never, 0.95)["kind"] == "?"


def test_median_is_an_upper_bound_with_unknown_seeds_as_infinity():
    rows = [{"kind": "<", "ratio": r} for r in (0.03, 0.04, 0.05, 0.3)] + [
        {"kind": "?", "ratio": None}
    ]
    summary = se.summarise(rows)
    assert summary["bound"] == "<=" and summary["median"] == pytest.approx(0.05)
    assert math.isinf(summary["max"]) and summary["n_infinite"] == 1
    # the bound must not drop below the true median whatever the unknown seed's ratio is
    for unknown in (0.0, 0.04, 10.0):
        known = [0.03, 0.04, 0.05, 0.3, unknown]
        assert sorted(known)[2] <= summary["median"]


def test_median_is_unresolved_when_half_the_seeds_have_no_upper_bound():
    rows = [{"kind": "=", "ratio": 0.1}, {"kind": ">", "ratio": 2.0}, {"kind": "?", "ratio": None}]
    assert se.summarise(rows)["bound"] == "unresolved"
    exact = se.summarise([{"kind": "=", "ratio": r} for r in (0.1, 0.2, 0.3)])
    assert exact["bound"] == "=" and exact["median"] == pytest.approx(0.2)
