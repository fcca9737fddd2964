"""Gymnasium runtime of a SWIRL proxy task (needs only gymnasium and numpy)."""

from swirl_wrappers.task import SCHEMA_VERSION, QuadraticReward, RBFFeatures, Region, TaskModel

__all__ = ["SCHEMA_VERSION", "QuadraticReward", "RBFFeatures", "Region", "TaskModel"]
__version__ = "0.1.0"
