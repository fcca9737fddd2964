"""The paper's tasks, registered with gymnasium under the ``sb3_swirl/`` namespace.

The dVRK tasks (:mod:`sb3_swirl.envs.dvrk`) need the ``robosuite`` extra and the Fetch tasks
(:mod:`sb3_swirl.envs.fetch`) the ``fetch`` extra; their ids are registered here all the same,
and robosuite or gymnasium-robotics is imported only when one is made.
"""

from gymnasium.envs.registration import register

from sb3_swirl.envs.acrobot import NoisyAcrobotEnv
from sb3_swirl.envs.dvrk import DVRKLineCuttingEnv, DVRKTensioningEnv
from sb3_swirl.envs.fetch import FetchDiscreteEnv
from sb3_swirl.envs.parking import ParallelParkingEnv

register(
    id="sb3_swirl/ParallelParking-v0",
    entry_point="sb3_swirl.envs.parking:ParallelParkingEnv",
    max_episode_steps=200,
)
register(
    id="sb3_swirl/ParallelParkingPartial-v0",
    entry_point="sb3_swirl.envs.parking:ParallelParkingEnv",
    max_episode_steps=200,
    kwargs={"partial_observation": True},
)
# an ablation of §9.8, not in the paper: the velocity hidden, the last step's displacement seen
register(
    id="sb3_swirl/ParallelParkingPartialDisplacement-v0",
    entry_point="sb3_swirl.envs.parking:ParallelParkingEnv",
    max_episode_steps=200,
    kwargs={"partial_observation": True, "observe_displacement": True},
)
register(
    id="sb3_swirl/ParallelParkingPerturbed-v0",
    entry_point="sb3_swirl.envs.parking:ParallelParkingEnv",
    max_episode_steps=200,
    kwargs={"perturbed": True},
)
register(
    id="sb3_swirl/NoisyAcrobot-v0",
    entry_point="sb3_swirl.envs.acrobot:NoisyAcrobotEnv",
    max_episode_steps=1000,
)
# gymnasium's Acrobot-v1 actuation (joint 2 only) and torque, with the paper's Gaussian noise
# (20% of the torque, as NoisyAcrobot) and 1000-step horizon
register(
    id="sb3_swirl/UnderactuatedAcrobot-v0",
    entry_point="sb3_swirl.envs.acrobot:NoisyAcrobotEnv",
    max_episode_steps=1000,
    kwargs={"actuation": "second", "torque": 1.0, "torque_noise_std": 0.2},
)

register(
    id="sb3_swirl/DVRKLineCutting-v0",
    entry_point="sb3_swirl.envs.dvrk.line_cutting:DVRKLineCuttingEnv",
    max_episode_steps=150,
)
register(
    id="sb3_swirl/DVRKTensioning-v0",
    entry_point="sb3_swirl.envs.dvrk.tensioning:DVRKTensioningEnv",
    max_episode_steps=100,
)

# gymnasium-robotics' Fetch tasks in 2 cm end-effector steps; the horizons are at least 2x
# the longest of 300 supervised episodes (18, 73 and 63 steps)
for _task, _steps in (("Reach", 50), ("Push", 150), ("PickAndPlace", 150)):
    register(
        id=f"sb3_swirl/Fetch{_task}Discrete-v0",
        entry_point="sb3_swirl.envs.fetch:FetchDiscreteEnv",
        max_episode_steps=_steps,
        kwargs={"task": _task},
    )

__all__ = [
    "DVRKLineCuttingEnv",
    "DVRKTensioningEnv",
    "FetchDiscreteEnv",
    "NoisyAcrobotEnv",
    "ParallelParkingEnv",
]
