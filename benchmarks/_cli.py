"""Command-line helpers shared by the benchmark scripts: checked numbers, one-line errors."""

from __future__ import annotations

import sys
from collections.abc import Callable

from sb3_swirl.cli import integer_arg

__all__ = ["integer_arg", "run_main", "seed_arg"]

#: a seed numpy accepts, checked before any run
seed_arg = integer_arg(0, 2**32, "2**32")


def run_main(main: Callable[[], int | None]) -> int:
    """Run a script's ``main``; a bad setting or path (``ValueError``, ``OSError``,
    ``ImportError``) is one ``error:`` line and exit status 2, as ``sb3-swirl`` does."""
    try:
        return main() or 0
    except (ValueError, OSError, ImportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
