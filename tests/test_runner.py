"""Sweeps: joblib and Ray give the same records; an interrupted sweep resumes."""

from __future__ import annotations

import json
import signal
import socket
import warnings
from pathlib import Path

import numpy as np
import pytest

from sb3_swirl.runner import _read_done, run_sweep

JOBS = [{"seed": seed, "scale": scale} for seed in range(3) for scale in (1.0, 10.0)]


def noisy(seed: int, scale: float) -> dict[str, float]:
    """A seeded run: the same job gives the same record in any process."""
    return {"value": float(scale * np.random.default_rng(seed).normal())}


@pytest.fixture
def importable(monkeypatch):
    """Worker processes import this module by name, as the parent does."""
    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).parent))


def test_joblib_sweep_returns_records_in_job_order_and_writes_each(tmp_path, importable):
    path = tmp_path / "runs.jsonl"
    results = run_sweep(noisy, JOBS, path, n_jobs=2, progress=False)
    assert results == [noisy(**job) for job in JOBS]
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert sorted(json.dumps(r["job"], sort_keys=True) for r in lines) == sorted(
        json.dumps(j, sort_keys=True) for j in JOBS
    )
    with pytest.raises(ValueError, match="exists: resume the sweep"):
        run_sweep(noisy, JOBS, path, progress=False)


def test_an_interrupted_sweep_resumes_to_the_same_results(tmp_path, importable, capsys):
    full = run_sweep(noisy, JOBS, tmp_path / "full.jsonl", progress=False)
    path = tmp_path / "cut.jsonl"
    run_sweep(noisy, JOBS[:3], path, progress=False)  # "killed" after three runs ...
    with path.open("a") as fh:
        fh.write('{"job": {"seed": 2, "sca')  # ... in the middle of writing a fourth
    resumed = run_sweep(noisy, JOBS, path, resume=True, progress=False)
    assert resumed == full
    said = " ".join(capsys.readouterr().err.split())
    assert "cut.jsonl: kept 3 runs done before (--resume); dropped 1 line cut short" in said
    lines = path.read_text().splitlines()
    assert len(lines) == len(JOBS)  # one whole record a line: the cut one is gone ...
    jobs = [json.loads(line)["job"] for line in lines]
    assert sorted(jobs, key=str) == sorted(JOBS, key=str)  # ... and none was run twice
    assert len(_read_done(path)) == len(JOBS)


def test_ray_backend_gives_the_same_records_as_joblib(tmp_path, importable):
    pytest.importorskip("ray")
    by_ray = run_sweep(noisy, JOBS, tmp_path / "ray.jsonl", backend="ray", progress=False)
    assert by_ray == [noisy(**job) for job in JOBS]


def interrupts_ignored(seed: int) -> bool:
    return signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def test_workers_leave_ctrl_c_to_the_main_process(tmp_path, importable):
    """Ctrl-C reaches the whole process group: workers ignore it, the main process stops."""
    # as in a terminal: a shell's background job (nohup, `cmd &`) starts with SIGINT ignored
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _check_workers_leave_ctrl_c(tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


def _check_workers_leave_ctrl_c(tmp_path):
    assert run_sweep(interrupts_ignored, [{"seed": 0}, {"seed": 1}], tmp_path / "r.jsonl") == [
        True,
        True,
    ]
    assert not interrupts_ignored(0)


def test_a_ray_address_where_nothing_listens_fails_at_once(tmp_path, importable):
    pytest.importorskip("ray")
    with socket.socket() as probe:  # a free local port, closed again: nothing listens there
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(ValueError, match=f"no Ray cluster answers at 127.0.0.1:{port}"):
        run_sweep(noisy, JOBS, tmp_path / "r.jsonl", backend="ray", address=f"127.0.0.1:{port}")


def test_bad_backend_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="backend"):
        run_sweep(noisy, JOBS, tmp_path / "x.jsonl", backend="dask", progress=False)


def test_a_backend_that_fails_to_start_leaves_no_runs_file(tmp_path, monkeypatch):
    """Else the same command, run again, would refuse: the (empty) runs file exists. The
    folders it made go too (an empty results/fig2 left behind); folders it found stay."""
    monkeypatch.setitem(__import__("sys").modules, "ray", None)  # Ray not installed
    (tmp_path / "results").mkdir()
    for path in (tmp_path / "results/fig2/runs.jsonl", tmp_path / "results/runs.jsonl"):
        with pytest.raises(ImportError, match=r"needs Ray: pip install 'sb3-swirl\[ray\]'"):
            run_sweep(noisy, JOBS, path, backend="ray", progress=False)
        assert not path.exists()
        assert sorted(p.name for p in tmp_path.rglob("*")) == ["results"]


def test_resuming_runs_made_under_other_settings_warns(tmp_path, importable):
    """Runs are stamped (code version, configs digest); a resume that keeps runs stamped
    otherwise says so, and which part differs."""
    path = tmp_path / "runs.jsonl"
    old = {"sb3_swirl": "0.1.0", "zoo_configs": "aaaa"}
    run_sweep(noisy, JOBS[:2], path, progress=False, stamp=old)
    assert all(json.loads(line)["stamp"] == old for line in path.read_text().splitlines())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run_sweep(noisy, JOBS[:3], path, resume=True, progress=False, stamp=old)  # no warning
    new = {"sb3_swirl": "0.1.0", "zoo_configs": "bbbb"}
    with pytest.warns(UserWarning, match=r"3 of the 3 runs kept .* \(not the same: zoo_configs\)"):
        results = run_sweep(noisy, JOBS[:4], path, resume=True, progress=False, stamp=new)
    assert results == [noisy(**job) for job in JOBS[:4]]


def test_the_configs_stamp_reads_settings_not_comments(tmp_path, monkeypatch):
    """A comment or a layout change in the shipped zoo configs keeps the stamp (so --resume
    does not warn); a changed setting changes it."""
    from importlib.resources import files

    from sb3_swirl.experiments import _settings_stamp

    shipped = {
        a: (files("sb3_swirl.zoo_configs") / f"{a}.yml").read_text() for a in ("dqn", "swirl_dqn")
    }
    monkeypatch.setattr("sb3_swirl.experiments.files", lambda package: tmp_path)
    for algo, text in shipped.items():
        (tmp_path / f"{algo}.yml").write_text(text)
    before = _settings_stamp()
    (tmp_path / "dqn.yml").write_text("# a new comment\n" + shipped["dqn"].replace(": ", ":  "))
    assert _settings_stamp() == before
    (tmp_path / "dqn.yml").write_text(shipped["dqn"].replace("batch_size: 64", "batch_size: 65", 1))
    assert "batch_size: 64" in shipped["dqn"] and _settings_stamp() != before


def test_a_runs_file_that_cannot_be_appended_to_fails_before_any_run(tmp_path, monkeypatch):
    """Not after the first run, whose record would be lost (the permission is faked: root, as
    on CI, may write any file)."""
    monkeypatch.setattr("sb3_swirl.runner.os.access", lambda path, mode: False)
    path = tmp_path / "runs.jsonl"
    with pytest.raises(ValueError, match=r"cannot write .*runs\.jsonl: no permission"):
        run_sweep(noisy, JOBS, path, progress=False)
    assert not path.exists()


def numpy_record(seed: int) -> dict:
    return {"n": np.int64(seed), "arr": np.arange(3), "f32": np.float32(0.5)}


def opaque_record(seed: int) -> dict:
    return {"path": Path("x")}


def test_numpy_results_are_kept_as_numbers_and_others_refused(tmp_path, importable):
    results = run_sweep(numpy_record, [{"seed": 0}], tmp_path / "a.jsonl", n_jobs=1, progress=False)
    assert results == [{"n": 0, "arr": [0, 1, 2], "f32": 0.5}]  # not the strings '0', '[0 1 2]'
    with pytest.raises(TypeError, match="run results must be JSON: got a PosixPath"):
        run_sweep(opaque_record, [{"seed": 0}], tmp_path / "b.jsonl", n_jobs=1, progress=False)
