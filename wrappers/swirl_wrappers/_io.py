"""Atomic file writes: a reader sees the old file or the new one, never half of one."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from typing import IO

# Read once at import (os.umask can only be read by setting it): new files get the usual mode.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w") -> Iterator[IO]:
    """Open a temporary file beside ``path``; on success it replaces ``path`` in one step.

    The data is written to a temporary file in the same folder, flushed to disk, then moved over
    ``path`` with ``os.replace``. If anything fails before that (an exception, a full disk,
    Ctrl-C), the temporary file is removed and ``path`` keeps its previous content.

    Parameters
    ----------
    path : str or path-like
    mode : {"w", "wb"}
        Text (UTF-8) or binary.

    Raises
    ------
    IsADirectoryError, NotADirectoryError, FileNotFoundError, PermissionError
        If ``path`` is a folder, its folder is a file, its folder does not exist, or it or its
        folder is read-only (named, before anything is written). A symbolic link is written
        through: its target gets the new content.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "out.txt")
    >>> with atomic_write(path) as fh:
    ...     _ = fh.write("done")
    >>> open(path).read()
    'done'
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = os.fspath(path)
    # a link: write its target (replacing the link by a file would cut it)
    folder, name = os.path.split(os.path.realpath(path))
    if os.path.isdir(path):
        raise IsADirectoryError(f"cannot write {path}: it is a folder")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise NotADirectoryError(f"cannot write {path}: {folder} is not a folder")
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write {path}: the folder {folder} does not exist")
    target = os.path.join(folder, name)
    if os.path.exists(target) and not os.access(target, os.W_OK):
        raise PermissionError(f"cannot write {path}: the file is read-only")
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
    except PermissionError:  # named as the file asked for, not the temporary one
        raise PermissionError(f"cannot write {path}: the folder {folder} is read-only") from None
    try:
        with os.fdopen(fd, mode, encoding="utf-8" if mode == "w" else None) as fh:
            os.chmod(tmp, 0o666 & ~_UMASK)
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
