"""``make bench``: the benchmarks' missed targets are listed at the end, failures fail."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path


def test_run_all_lists_missed_targets_and_fails_on_a_failed_benchmark(
    tmp_path, monkeypatch, capsys
):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "run_all.py"
    spec = importlib.util.spec_from_file_location("run_all", path)
    run_all = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_all)
    (tmp_path / "met.py").write_text("print('ratio 1.2 (target >= 1)  ok')\n")
    (tmp_path / "missed.py").write_text("print('first')\nprint('ratio 0.9  MISSED')\n")
    (tmp_path / "broken.py").write_text("raise SystemExit(3)\n")
    monkeypatch.setattr(run_all, "HERE", tmp_path)
    monkeypatch.setattr(sys, "argv", ["run_all.py"])
    monkeypatch.setattr(run_all, "FAST", ["met.py", "missed.py"])
    assert run_all.main() == 0  # a miss is a measurement
    out = capsys.readouterr().out
    assert "ratio 1.2 (target >= 1)  ok" in out and "first" in out  # shown as it comes
    assert out.endswith("targets missed:\n  missed.py: ratio 0.9  MISSED\n")
    monkeypatch.setattr(run_all, "FAST", ["met.py", "broken.py"])
    assert run_all.main() == 1
    out = capsys.readouterr().out
    assert "targets missed" not in out and out.endswith("failed: broken.py\n")
