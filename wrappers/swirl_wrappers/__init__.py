"""Gymnasium runtime of a SWIRL proxy task (needs only gymnasium and numpy; numba optional)."""

from swirl_wrappers.task import SCHEMA_VERSION, QuadraticReward, RBFFeatures, Region, TaskModel
from swirl_wrappers.wrappers import (
    REWARD_MODES,
    SegmentTracker,
    SwirlVectorWrapper,
    SwirlWrapper,
    lift_observation,
    lift_observation_space,
    progress_potential,
)

__all__ = [
    "REWARD_MODES",
    "SCHEMA_VERSION",
    "QuadraticReward",
    "RBFFeatures",
    "Region",
    "SegmentTracker",
    "SwirlVectorWrapper",
    "SwirlWrapper",
    "TaskModel",
    "lift_observation",
    "lift_observation_space",
    "progress_potential",
]
__version__ = "0.1.0"
