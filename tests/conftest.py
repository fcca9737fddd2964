import os

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
# ... and in the subprocesses the tests start (the zoo's, the CLI's): beside the other test
# worker, more threads only contend for the 2 cores (zoo tests side by side: 150 s -> 54 s)
os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch

# Tiny networks on a 2-core machine run several times slower with more than one thread.
torch.set_num_threads(1)
