"""Atomic saves: a failure halfway through a write leaves the previous file intact."""

from __future__ import annotations

import errno
import json
import os
import traceback

import numpy as np
import pytest

from swirl_wrappers import QuadraticReward, Region, TaskModel
from swirl_wrappers._io import atomic_write


class _HalfWriter:
    """A file that writes half of what it is given, then fails as ``error`` says."""

    def __init__(self, fh, error: BaseException) -> None:
        self._fh, self._error = fh, error

    def write(self, data):
        self._fh.write(data[: len(data) // 2])
        self._fh.flush()
        raise self._error

    def __getattr__(self, name):
        return getattr(self._fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return self._fh.__exit__(*exc)


@pytest.fixture(params=["disk full", "ctrl-c"])
def failing_writes(request, monkeypatch):
    """Make every atomic write fail halfway through its first write call."""
    error = (
        OSError(errno.ENOSPC, "No space left on device")
        if request.param == "disk full"
        else KeyboardInterrupt()
    )
    real = os.fdopen

    def fdopen(fd, *args, **kwargs):
        return _HalfWriter(real(fd, *args, **kwargs), error)

    def install():
        monkeypatch.setattr("swirl_wrappers._io.os.fdopen", fdopen)
        return type(error)

    return install


def _task(centre: float) -> TaskModel:
    return TaskModel([Region([centre], [[1.0]], 4.0)], [QuadraticReward([centre], [[1.0]])])


def test_atomic_write_replaces_the_file_only_when_done(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with atomic_write(path) as fh:
        fh.write("new")
        assert path.read_text() == "old"  # a reader meanwhile sees the old file
    assert path.read_text() == "new" and os.listdir(tmp_path) == ["out.txt"]
    assert oct(path.stat().st_mode & 0o777) != oct(0o600)  # the usual mode, not mkstemp's
    with pytest.raises(ValueError, match="mode"):
        with atomic_write(path, "a"):
            pass
    # the path given is named, not the temporary file's
    with pytest.raises(FileNotFoundError, match=r"missing.out\.txt: the folder .*missing"):
        _task(0.0).to_json(tmp_path / "missing" / "out.txt")
    with pytest.raises(IsADirectoryError, match="it is a folder"):
        _task(0.0).to_json(tmp_path)
    with pytest.raises(NotADirectoryError, match=r"out\.txt is not a folder"):
        _task(0.0).to_json(path / "inside.json")  # under a file


def test_a_failed_write_leaves_the_previous_file_and_no_temporary_file(tmp_path, failing_writes):
    path = tmp_path / "out.bin"
    path.write_bytes(b"previous")
    error = failing_writes()
    with pytest.raises(error):
        with atomic_write(path, "wb") as fh:
            fh.write(b"0123456789" * 100)
    assert path.read_bytes() == b"previous"
    assert os.listdir(tmp_path) == ["out.bin"]


def test_task_json_survives_a_failed_save(tmp_path, failing_writes):
    path = tmp_path / "task.json"
    _task(1.0).to_json(path)
    before = path.read_bytes()
    error = failing_writes()
    with pytest.raises(error):
        _task(2.0).to_json(path)
    assert path.read_bytes() == before
    assert TaskModel.from_json(path).regions[0].mean.tolist() == [1.0]
    assert os.listdir(tmp_path) == ["task.json"]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # numpy's zip
def test_evaluation_log_survives_a_failed_save(tmp_path, failing_writes):
    """TaskEvalCallback's evaluations.npz is written atomically too."""
    import gymnasium as gym
    from stable_baselines3 import DQN
    from test_dqn import PointEnv

    from sb3_swirl.callbacks import TaskEvalCallback

    def env():
        return gym.wrappers.TimeLimit(PointEnv(), 5)

    callback = TaskEvalCallback(
        env(), n_eval_episodes=1, eval_freq=5, log_path=str(tmp_path), verbose=0
    )
    model = DQN("MlpPolicy", env(), learning_starts=100, seed=0)
    model.learn(5, callback=callback)
    saved = (tmp_path / "evaluations.npz").read_bytes()
    error = failing_writes()
    with pytest.raises(error) as excinfo:
        model.learn(5, callback=callback, reset_num_timesteps=False)
    # numpy's half-written zip object, held by the traceback's frames, complains when it is
    # collected: let it go here, where the mark above ignores it, not at the end of the run
    traceback.clear_frames(excinfo.tb)
    assert (tmp_path / "evaluations.npz").read_bytes() == saved
    assert np.load(tmp_path / "evaluations.npz")["timesteps"].tolist() == [5]
    assert os.listdir(tmp_path) == ["evaluations.npz"]


def test_results_json_of_the_main_job_is_written_atomically(tmp_path, failing_writes):
    """run_demo's results.json: the previous run's file survives a failure at the end."""
    from sb3_swirl import experiments

    out = tmp_path / "parking"
    out.mkdir()
    (out / "results.json").write_text(json.dumps({"previous": True}))
    error = failing_writes()
    with pytest.raises(error):
        experiments.write_results({"new": True}, out / "results.json")
    assert json.loads((out / "results.json").read_text()) == {"previous": True}
    assert os.listdir(out) == ["results.json"]


def test_atomic_write_writes_through_a_link_and_refuses_a_read_only_file(tmp_path, monkeypatch):
    (tmp_path / "real.txt").write_text("old")
    (tmp_path / "link.txt").symlink_to(tmp_path / "real.txt")
    with atomic_write(tmp_path / "link.txt") as fh:
        fh.write("new")
    assert (tmp_path / "link.txt").is_symlink() and (tmp_path / "real.txt").read_text() == "new"
    # os.access as the file's owner would answer; a root user may write any file
    monkeypatch.setattr(os, "access", lambda path, how: not str(path).endswith("real.txt"))
    with pytest.raises(PermissionError, match=r"link\.txt: the file is read-only"):
        with atomic_write(tmp_path / "link.txt") as fh:
            fh.write("lost")
    assert (tmp_path / "real.txt").read_text() == "new"


def test_a_read_only_folder_is_named_not_the_temporary_file(tmp_path, monkeypatch):
    import tempfile

    def refused(*args, **kwargs):  # what a folder the user may not write gives (not root)
        raise PermissionError(13, "Permission denied", str(tmp_path / ".out.json.x.tmp"))

    monkeypatch.setattr(tempfile, "mkstemp", refused)
    with pytest.raises(PermissionError, match=r"out\.json: the folder .* is read-only$"):
        with atomic_write(tmp_path / "out.json") as fh:
            fh.write("lost")
