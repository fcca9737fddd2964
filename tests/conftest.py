import os
import subprocess
import sys

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
# ... and in the subprocesses the tests start (the zoo's, the CLI's): beside the other test
# worker, more threads only contend for the 2 cores (zoo tests side by side: 150 s -> 54 s)
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest
import torch

# Tiny networks on a 2-core machine run several times slower with more than one thread.
torch.set_num_threads(1)


@pytest.fixture
def zoo_cli(tmp_path):
    """``zoo_cli(*args)`` runs ``sb3-swirl zoo ARGS`` in ``tmp_path``, asserts that it succeeds
    and returns its stdout."""

    def run(*args: str) -> str:
        cli = [sys.executable, "-m", "sb3_swirl.cli", "zoo", *args]
        result = subprocess.run(
            cli, cwd=tmp_path, capture_output=True, text=True, timeout=600, check=False
        )
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        return result.stdout

    return run
