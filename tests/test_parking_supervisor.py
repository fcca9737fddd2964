"""ParkingSupervisor: every demo parks, with the human manoeuvre (forward, then reverse in)."""

import itertools

import gymnasium as gym
import numpy as np
import pytest

import sb3_swirl.envs  # noqa: F401  (registers the ids)
from sb3_swirl.envs.parking import (
    ACCELERATE,
    NOOP,
    STEER_LEFT,
    STEER_RIGHT,
    ParallelParkingEnv,
)
from sb3_swirl.supervisors.parking import ParkingSupervisor


def demo(env, sup, seed, states=None):
    """Run one episode; ``states`` (a list), if given, gets the raw state before each action."""
    obs, info = env.reset(seed=seed)
    sup.reset(obs)
    speeds, actions = [env.unwrapped.state[3]], []
    done = False
    while not done:
        if states is not None:
            states.append(env.unwrapped.raw_state)
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


@pytest.fixture(scope="module")
def twenty_demos():
    """(env, [(states, speeds, actions, reward, info)]) for seeds 0..19 of the nominal task."""
    env = gym.make("sb3_swirl/ParallelParking-v0")
    sup = ParkingSupervisor(env.unwrapped)
    runs = []
    for seed in range(20):
        states = []
        runs.append((states, *demo(env, sup, seed, states)))
    return env.unwrapped, runs


def test_twenty_demos_all_park_forward_then_reverse(twenty_demos):
    _, runs = twenty_demos
    for seed, (_, speeds, actions, reward, info) in enumerate(runs):
        assert info["is_success"] and reward == 1.0, f"seed {seed} did not park"
        assert len(actions) < 200
        assert longest_run(speeds > 0) >= 5, f"seed {seed}: no forward phase"
        assert longest_run(speeds < 0) >= 5, f"seed {seed}: no reverse phase"
        assert np.argmax(speeds > 0) < np.argmax(speeds < 0), f"seed {seed}: reversed first"


def test_no_demo_action_is_without_effect(twenty_demos):
    # A cloned policy that picks a no-effect action (steering at a standstill) in a state
    # repeats it forever, so the demos must never label one (no-ops excepted).
    env, runs = twenty_demos
    n_standstill = 0
    for seed, (states, _, actions, *_) in enumerate(runs):
        for t, (state, action) in enumerate(zip(states, actions, strict=True)):
            n_standstill += state[3] == 0
            if action != NOOP:
                assert env.simulate(state, action) != env.simulate(state, NOOP), (
                    f"seed {seed} step {t}: action {action} does nothing in state {state}"
                )
    assert n_standstill >= 2 * len(runs)  # the start and the stop before reversing


def test_steering_does_not_chatter(twenty_demos):
    # Left right after right is the one counter-steer of the reverse S-curve; any other change
    # of steering direction between consecutive steps is chatter (the deadband prevents it).
    _, runs = twenty_demos
    for seed, (_, _, actions, *_) in enumerate(runs):
        pairs = list(itertools.pairwise(actions))
        assert (STEER_LEFT, STEER_RIGHT) not in pairs, f"seed {seed}: left then right"
        assert pairs.count((STEER_RIGHT, STEER_LEFT)) == 1, f"seed {seed}: {actions}"


def test_speed_first_then_heading_hold_without_noise():
    # Pulling out, the car first speeds up to cruise speed (steering at walking pace is tiny
    # and ambiguous); without noise, a start heading within 5 degrees needs no steering at all
    # before reversing, whatever the lateral offset (no lane-keeping weave).
    env = gym.make("sb3_swirl/ParallelParking-v0", noise_probability=0.0)
    sup = ParkingSupervisor(env.unwrapped)
    for seed in range(5):
        speeds, actions, _, info = demo(env, sup, seed)
        assert info["is_success"]
        forward = actions[: int(np.argmax(speeds < 0))]
        assert forward[:3] == [ACCELERATE] * 3, f"seed {seed}: {forward}"
        assert not {STEER_LEFT, STEER_RIGHT} & set(forward), f"seed {seed}: {forward}"


@pytest.mark.parametrize(
    "env_id",
    [
        "sb3_swirl/ParallelParkingPerturbed-v0",
        "sb3_swirl/ParallelParkingPartial-v0",
        "sb3_swirl/ParallelParkingPartialDisplacement-v0",
    ],
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
    with pytest.raises(ValueError, match="deadband"):
        ParkingSupervisor(env, deadband=0.3)
