"""ParkingSupervisor: every demo parks, with the human manoeuvre (forward, then reverse in)."""

import gymnasium as gym
import numpy as np
import pytest

import sb3_swirl.envs  # noqa: F401  (registers the ids)
from sb3_swirl.envs.parking import ParallelParkingEnv
from sb3_swirl.supervisors.parking import ParkingSupervisor


def demo(env, sup, seed):
    obs, info = env.reset(seed=seed)
    sup.reset(obs)
    speeds, actions = [env.unwrapped.state[3]], []
    done = False
    while not done:
        action = sup.act(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        actions.append(action)
        speeds.append(env.unwrapped.state[3])
        done = terminated or truncated
    return np.array(speeds), actions, reward, info


def longest_run(mask):
    best = run = 0
    for m in mask:
        run = run + 1 if m else 0
        best = max(best, run)
    return best


def test_twenty_demos_all_park_forward_then_reverse():
    env = gym.make("sb3_swirl/ParallelParking-v0")
    sup = ParkingSupervisor(env.unwrapped)
    for seed in range(20):
        speeds, actions, reward, info = demo(env, sup, seed)
        assert info["is_success"] and reward == 1.0, f"seed {seed} did not park"
        assert len(actions) < 200
        assert longest_run(speeds > 0) >= 5, f"seed {seed}: no forward phase"
        assert longest_run(speeds < 0) >= 5, f"seed {seed}: no reverse phase"
        assert np.argmax(speeds > 0) < np.argmax(speeds < 0), f"seed {seed}: reversed first"


@pytest.mark.parametrize(
    "env_id", ["sb3_swirl/ParallelParkingPerturbed-v0", "sb3_swirl/ParallelParkingPartial-v0"]
)
def test_variants_park(env_id):
    env = gym.make(env_id)
    sup = ParkingSupervisor(env.unwrapped)
    for seed in range(4):
        *_, info = demo(env, sup, 100 + seed)
        assert info["is_success"], f"{env_id} seed {seed}"


def test_demos_are_reproducible():
    env = gym.make("sb3_swirl/ParallelParking-v0")
    runs = [demo(env, ParkingSupervisor(env.unwrapped), 11)[1] for _ in range(2)]
    assert runs[0] == runs[1]


def test_without_noise_the_first_plan_is_followed_to_the_end():
    env = gym.make("sb3_swirl/ParallelParking-v0", noise_probability=0.0)
    sup = ParkingSupervisor(env.unwrapped)
    *_, info = demo(env, sup, 2)
    assert info["is_success"]
    assert sup.n_replans == 1


def test_noise_triggers_replanning():
    env = gym.make("sb3_swirl/ParallelParking-v0", noise_probability=0.5)
    sup = ParkingSupervisor(env.unwrapped)
    *_, info = demo(env, sup, 2)
    assert info["is_success"]
    assert sup.n_replans > 3


def test_bad_input_raises():
    with pytest.raises(ValueError, match="ParallelParkingEnv"):
        ParkingSupervisor(gym.make("CartPole-v1"))
    env = ParallelParkingEnv()
    obs, _ = env.reset(seed=0)
    sup = ParkingSupervisor(env)
    with pytest.raises(ValueError, match="does not match"):
        sup.reset(obs + 1.0)
    with pytest.raises(ValueError, match="reverse_speed"):
        ParkingSupervisor(env, reverse_speed=5.0)
