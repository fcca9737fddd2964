"""Demonstrations: the typed input of SWIRL."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstration: a state sequence, optionally with the actions and rewards.

    Parameters
    ----------
    observations : array of shape (T + 1, d)
    actions : array of shape (T,) or (T, action_dim), optional
    rewards : array of shape (T,), optional
    """

    observations: np.ndarray
    actions: np.ndarray | None = None
    rewards: np.ndarray | None = None

    def __len__(self) -> int:
        """Number of transitions ``T``."""
        return len(self.observations) - 1
