"""The paper's simulated tasks, registered with gymnasium under the ``sb3_swirl/`` namespace."""

from gymnasium.envs.registration import register

from sb3_swirl.envs.acrobot import NoisyAcrobotEnv
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

__all__ = ["NoisyAcrobotEnv", "ParallelParkingEnv"]
