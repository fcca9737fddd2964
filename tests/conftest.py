import os

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")

import torch

# Tiny networks on a 2-core machine run several times slower with more than one thread.
torch.set_num_threads(1)
