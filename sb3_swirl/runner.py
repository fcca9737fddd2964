"""Sweeps of runs (seeds x methods x settings) on one machine or a Ray cluster.

:func:`run_sweep` calls ``function(**job)`` for every job, in worker processes with joblib
(the default) or on a Ray cluster (``backend="ray"``, the optional ``ray`` extra): the same
experiment code either way. Each run's record is appended to a JSON-lines file as soon as it
finishes, so an interrupted sweep resumes where it stopped (``resume=True`` skips the jobs the
file already holds). A rich progress bar counts the runs.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_int, check_option

__all__ = ["BACKENDS", "run_sweep"]

#: ``run_sweep(backend=...)``
BACKENDS = ("joblib", "ray")


def _key(job: Mapping[str, Any]) -> str:
    return json.dumps(job, sort_keys=True, default=str)


def _jsonable(value: Any) -> Any:
    """numpy numbers and arrays as JSON numbers and lists; anything else is refused by name."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(
        f"run results must be JSON: got a {type(value).__name__} ({value!r:.60}); return "
        "numbers, strings, lists and dicts"
    )


def _call(function: Callable[..., Any], job: Mapping[str, Any]) -> tuple[dict, Any]:
    return dict(job), function(**job)


def _read_done(path: Path) -> dict[str, dict[str, Any]]:
    """The records already in ``path`` by job; a line cut short by a crash is ignored."""
    done: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return done
    for line in path.read_text().splitlines():
        if _is_record(line):  # not the last line of an interrupted write
            record = json.loads(line)
            done[_key(record["job"])] = record
    return done


def _resumed(path: Path, done: Mapping[str, Mapping[str, Any]]) -> None:
    """Say what a resumed sweep keeps from ``path``; drop a line cut short by a crash (it is
    rewritten atomically with the whole records, so the file stays one record per line)."""
    from rich.console import Console

    text = path.read_text()
    lines = [line for line in text.splitlines() if line.strip()]
    broken = sum(1 for line in lines if not _is_record(line))
    if broken or (text and not text.endswith("\n")):
        with atomic_write(path) as fh:
            fh.writelines(line + "\n" for line in lines if _is_record(line))
    Console(stderr=True).print(
        f"{path}: kept {len(done)} run{'s' * (len(done) != 1)} done before (--resume)"
        + (f"; dropped {broken} line{'s' * (broken != 1)} cut short by a crash" if broken else ""),
        soft_wrap=True,
    )


def _is_record(line: str) -> bool:
    """Whether ``line`` of a runs file is whole JSON (a crash can cut the last one short)."""
    try:
        json.loads(line)
    except json.JSONDecodeError:
        return False
    return True


def _warn_other_settings(
    done: Mapping[str, Mapping[str, Any]], keys: Sequence[str], stamp: Mapping[str, Any], path: Path
) -> None:
    """Warn when runs kept from ``path`` were made under another ``stamp`` (other code or
    configs): a resumed sweep reuses them as they are."""
    other = [done[key].get("stamp") or {} for key in keys if done[key].get("stamp") != stamp]
    if not other:
        return
    changed = sorted({name for old in other for name in stamp if old.get(name) != stamp[name]})
    warnings.warn(
        f"{len(other)} of the {len(keys)} runs kept from {path} were made with other settings "
        f"(not the same: {', '.join(changed)}); they are reused as they are. For runs with "
        "today's settings, choose another output",
        stacklevel=3,
    )


def _ignore_interrupts() -> None:
    """In a worker: leave Ctrl-C (sent to the whole process group) to the main process, which
    stops the sweep; a worker that took it would print its own traceback, or hang."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _joblib_runs(
    function: Callable[..., Any], jobs: Sequence[Mapping[str, Any]], n_jobs: int
) -> Iterator[tuple[dict, Any]]:
    from joblib import Parallel, delayed

    parallel = Parallel(
        n_jobs=n_jobs, return_as="generator_unordered", initializer=_ignore_interrupts
    )
    yield from parallel(delayed(_call)(function, job) for job in jobs)


def _check_reachable(address: str, timeout: float = 10.0) -> None:
    """Raise unless something listens at a ``host:port`` Ray address (Ray itself would retry
    the connection without end); ``"auto"`` and ``ray://`` addresses fail on their own."""
    host, _, port = address.rpartition(":")
    if address == "auto" or address.startswith("ray://") or not port.isdigit():
        return
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ValueError(
            f"no Ray cluster answers at {address} ({exc}): start its head node "
            "(`ray start --head`) or check the address"
        ) from None


def _ray_runs(
    function: Callable[..., Any],
    jobs: Sequence[Mapping[str, Any]],
    n_jobs: int,
    address: str | None,
) -> Iterator[tuple[dict, Any]]:
    try:
        import ray
    except ImportError:
        raise ImportError(
            "backend='ray' needs Ray: pip install 'sb3-swirl[ray]' (or use backend='joblib')"
        ) from None
    started = not ray.is_initialized()
    if started:
        if address is None:  # a local instance with n_jobs workers
            ray.init(num_cpus=n_jobs, include_dashboard=False, log_to_driver=False)
        else:
            _check_reachable(address)
            ray.init(address=address, log_to_driver=False)
    try:
        remote = ray.remote(_call)
        pending = [remote.remote(function, job) for job in jobs]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
    finally:
        if started:
            ray.shutdown()


def run_sweep(
    function: Callable[..., Any],
    jobs: Sequence[Mapping[str, Any]],
    path: str | os.PathLike,
    *,
    backend: str = "joblib",
    n_jobs: int = 2,
    address: str | None = None,
    resume: bool = False,
    progress: bool = True,
    stamp: Mapping[str, Any] | None = None,
) -> list[Any]:
    """Run ``function(**job)`` for every job; return the results in the order of ``jobs``.

    Parameters
    ----------
    function : callable
        Importable by name (a module-level function): it runs in other processes. Its
        result must be JSON-serialisable.
    jobs : sequence of mappings
        Keyword arguments of each run (JSON-serialisable; equal mappings are one job).
    path : path
        JSON-lines file of ``{"job": ..., "result": ...[, "stamp": ...]}``, one line appended
        per finished run.
    backend : {"joblib", "ray"}
    n_jobs : int
        Runs at once (joblib), or the CPUs of a local Ray instance.
    address : str, optional
        Ray cluster address (``"auto"``, ``"ray://host:10001"``); default: a local instance.
    resume : bool
        Keep the runs ``path`` already holds and run only the others. Without it, an existing
        ``path`` is an error (nothing a user saved is overwritten).
    progress : bool
        A progress bar over the runs.
    stamp : mapping, optional
        What the runs depend on beyond their arguments (the code's version, the configs'
        digest), JSON-serialisable: stored with each record, and a warning when ``resume``
        keeps records made under another stamp.

    Returns
    -------
    list
        ``function(**job)`` of each job, in the order of ``jobs`` (resumed ones from ``path``).

    Raises
    ------
    ValueError
        ``path`` exists and ``resume`` is False, or a bad ``backend`` / ``n_jobs``.
    ImportError
        ``backend="ray"`` without Ray installed, with the install command.
    """
    check_option("backend", backend, BACKENDS)
    check_int("n_jobs", n_jobs, low=1)
    path = Path(path)
    if path.exists() and not resume:
        raise ValueError(f"{path} exists: resume the sweep (--resume) or choose another output")
    made = [folder for folder in (path.parent, *path.parent.parents) if not folder.exists()]
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        return _run_sweep(function, jobs, path, backend, n_jobs, address, progress, stamp)
    except BaseException:  # a backend that fails to start leaves no empty folder behind
        for folder in made:  # the deepest first; rmdir keeps a folder that holds anything
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def _run_sweep(
    function: Callable[..., Any],
    jobs: Sequence[Mapping[str, Any]],
    path: Path,
    backend: str,
    n_jobs: int,
    address: str | None,
    progress: bool,
    stamp: Mapping[str, Any] | None,
) -> list[Any]:
    """:func:`run_sweep` once its folder exists."""
    if not os.access(path if path.exists() else path.parent, os.W_OK):  # before any run
        raise ValueError(f"cannot write {path}: no permission to append the runs' records")
    done = _read_done(path)
    if path.exists():
        _resumed(path, done)
    unique = {_key(job): dict(job) for job in jobs}
    pending = [job for key, job in unique.items() if key not in done]
    if stamp is not None:
        _warn_other_settings(done, [key for key in unique if key in done], stamp, path)
    if backend == "ray":
        runs = _ray_runs(function, pending, n_jobs, address)
    else:
        runs = _joblib_runs(function, pending, n_jobs)
    from rich.progress import Progress

    with Progress(disable=not progress, transient=True) as bar:
        task = bar.add_task(f"{len(pending)} runs ({len(done)} done before)", total=len(pending))
        for job, result in runs:
            record = {"job": job, "result": result} | ({} if stamp is None else {"stamp": stamp})
            line = json.dumps(record, default=_jsonable)
            # opened per run: a backend that fails to start leaves no empty file behind
            with path.open("a") as fh:
                fh.write(line + "\n")
            done[_key(job)] = json.loads(line)
            bar.advance(task)
    return [done[_key(job)]["result"] for job in jobs]
