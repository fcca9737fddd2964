"""The paper's tasks, registered with gymnasium under the ``sb3_swirl/`` namespace.

The dVRK tasks (:mod:`sb3_swirl.envs.dvrk`) need the ``robosuite`` extra; their ids are
registered here all the same, and robosuite is imported only when one is made.
"""

from gymnasium.envs.registration import register

from sb3_swirl.envs.acrobot import NoisyAcrobotEnv
from sb3_swirl.envs.dvrk import DVRKLineCuttingEnv, DVRKTensioningEnv
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

__all__ = ["DVRKLineCuttingEnv", "DVRKTensioningEnv", "NoisyAcrobotEnv", "ParallelParkingEnv"]
