"""Command-line helpers shared by the benchmark scripts: checked numbers, one-line errors."""

from __future__ import annotations

from sb3_swirl.cli import integer_arg
from sb3_swirl.cli import run_command as run_main

__all__ = ["integer_arg", "run_main", "seed_arg"]

#: a seed numpy accepts, checked before any run
seed_arg = integer_arg(0, 2**32, "2**32")
