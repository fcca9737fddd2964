"""sb3-swirl: SWIRL (Sequential Windowed Inverse Reinforcement Learning) for Stable-Baselines3."""

from sb3_swirl.demos import Demonstration

__all__ = ["Demonstration"]
__version__ = "0.1.0"
