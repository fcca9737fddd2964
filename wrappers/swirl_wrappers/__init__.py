"""Gymnasium runtime of a SWIRL proxy task (needs only gymnasium and numpy)."""

from swirl_wrappers.task import (
    REWARD_MODES,
    SCHEMA_VERSION,
    QuadraticReward,
    RBFFeatures,
    Region,
    RewardConfig,
    TaskModel,
)
from swirl_wrappers.tracker import SegmentTracker, progress_potential
from swirl_wrappers.wrappers import (
    Lifter,
    SwirlVectorWrapper,
    SwirlWrapper,
    lift_observation_space,
    observation_state,
    state_space,
)

__all__ = [
    "REWARD_MODES",
    "SCHEMA_VERSION",
    "Lifter",
    "QuadraticReward",
    "RBFFeatures",
    "Region",
    "RewardConfig",
    "SegmentTracker",
    "SwirlVectorWrapper",
    "SwirlWrapper",
    "TaskModel",
    "lift_observation_space",
    "observation_state",
    "progress_potential",
    "state_space",
]
__version__ = "0.1.0"
