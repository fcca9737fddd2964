"""Command-line helpers shared by the benchmark scripts: checked numbers, one-line errors."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable


def integer(low: int) -> Callable[[str], int]:
    """An argparse type: an integer of at least ``low``, or argparse's usage error."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {value}")
        return value

    return parse


def run_main(main: Callable[[], int | None]) -> int:
    """Run a script's ``main``; a bad setting or path (``ValueError``, ``OSError``,
    ``ImportError``) is one ``error:`` line and exit status 2, as with ``sb3-swirl``."""
    try:
        return main() or 0
    except (ValueError, OSError, ImportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
