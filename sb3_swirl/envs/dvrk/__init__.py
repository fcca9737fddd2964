"""The da Vinci (dVRK) tasks of the paper's §10 on robosuite manipulators.

Importing this package does not import robosuite (slow, and it logs on import); the env
classes do when they are built.
"""

from sb3_swirl.envs.dvrk._robosuite import ROBOTS
from sb3_swirl.envs.dvrk.line_cutting import DVRKLineCuttingEnv
from sb3_swirl.envs.dvrk.tensioning import DVRKTensioningEnv

__all__ = ["ROBOTS", "DVRKLineCuttingEnv", "DVRKTensioningEnv"]
