"""ParallelParkingEnv: dynamics, success, collisions, noise, variants and the gymnasium contract."""

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_swirl.envs  # noqa: F401  (registers the ids)
from sb3_swirl.envs.parking import (
    ACCELERATE,
    DECELERATE,
    NOOP,
    STEER_LEFT,
    STEER_RIGHT,
    ParallelParkingEnv,
)

IDS = [
    "sb3_swirl/ParallelParking-v0",
    "sb3_swirl/ParallelParkingPartial-v0",
    "sb3_swirl/ParallelParkingPartialDisplacement-v0",
    "sb3_swirl/ParallelParkingPerturbed-v0",
]


def quiet_env(**kwargs) -> ParallelParkingEnv:
    env = ParallelParkingEnv(noise_probability=0.0, **kwargs)
    env.reset(seed=0)
    return env


def test_straight_drive_follows_the_model():
    env = quiet_env()
    env.set_state(-2.0, 3.0, 0.3, 0.5)
    obs, *_ = env.step(NOOP)
    x, y, theta, v = env.state
    assert (x, y) == pytest.approx((-2.0 + 0.5 * math.cos(0.3), 3.0 + 0.5 * math.sin(0.3)))
    assert (theta, v) == pytest.approx((0.3, 0.5))
    np.testing.assert_allclose(obs, [x, y, theta, v], rtol=1e-6)
    # The speed changes first, then the car drives a whole step at the new speed.
    env.step(ACCELERATE)
    x2, y2, theta2, v2 = env.state
    assert v2 == pytest.approx(0.6)
    assert (x2, y2) == pytest.approx((x + 0.6 * math.cos(0.3), y + 0.6 * math.sin(0.3)))
    assert theta2 == pytest.approx(0.3)


@pytest.mark.parametrize("action, v", [(STEER_LEFT, 0.4), (STEER_RIGHT, 0.4), (STEER_LEFT, -0.3)])
def test_turn_matches_integrated_bicycle_model(action, v):
    env = quiet_env()
    env.set_state(-1.0, 3.0, 0.2, v)
    env.step(action)
    # Kinematic bicycle about the centre (Kong et al. 2015), Euler-integrated finely.
    delta = env.max_steering if action == STEER_LEFT else -env.max_steering
    half = env.wheelbase / 2
    beta = math.atan(half * math.tan(delta) / env.wheelbase)
    x, y, theta = -1.0, 3.0, 0.2
    n = 20000
    h = env.dt / n
    for _ in range(n):
        x += h * v * math.cos(theta + beta)
        y += h * v * math.sin(theta + beta)
        theta += h * v * math.sin(beta) / half
    assert env.state[:3] == pytest.approx((x, y, theta), abs=1e-4)
    turned = env.state[2] - 0.2
    assert math.copysign(1, turned) == math.copysign(1, v) * (1 if action == STEER_LEFT else -1)


def test_steering_without_speed_does_not_turn():
    env = quiet_env()
    env.set_state(-1.0, 3.0, 0.2, 0.0)
    env.step(STEER_LEFT)
    assert env.state == (-1.0, 3.0, 0.2, 0.0)


def test_speed_stays_on_the_grid_and_reaches_zero_exactly():
    env = quiet_env()
    env.set_state(-8.0, 3.0, 0.0, 0.0)
    for action in [ACCELERATE] * 7 + [DECELERATE] * 10 + [ACCELERATE] * 3:
        env.step(action)
    assert env.state[3] == 0.0
    for _ in range(30):
        env.step(ACCELERATE)
    assert env.state[3] == pytest.approx(env.max_speed)


def park_attempt(x, y, theta_deg, v):
    """Put the car at a state and stop it with one deceleration (it moves 0 m on that step)."""
    env = quiet_env()
    env.set_state(x, y, math.radians(theta_deg), v)
    return env.step(DECELERATE)


def test_parked_car_succeeds():
    obs, reward, terminated, truncated, info = park_attempt(0.5, 0.5, 10.0, 0.1)
    assert obs[3] == 0.0
    assert (reward, terminated, truncated, info["is_success"]) == (1.0, True, False, True)


@pytest.mark.parametrize(
    "x, y, theta_deg, v, why",
    [
        (0.0, 0.0, 16.0, 0.1, "heading beyond 15 degrees"),
        (0.0, 0.0, -16.0, 0.1, "heading beyond -15 degrees"),
        (0.8, 0.7, 0.0, 0.1, "centre more than 1 m from the slot"),
        (0.0, 0.0, 0.0, 0.3, "still moving"),
        (0.0, 0.0, 0.0, -0.1, "still reversing"),
    ],
)
def test_each_success_tolerance(x, y, theta_deg, v, why):
    _, reward, terminated, _, info = park_attempt(x, y, theta_deg, v)
    assert (reward, terminated, info["is_success"]) == (0.0, False, False), why


def test_collision_with_obstacle_ends_the_episode():
    env = quiet_env()
    env.set_state(1.3, 0.0, 0.0, 0.3)  # front bumper reaches x = 2.6 > 2.5 (front obstacle)
    _, reward, terminated, truncated, info = env.step(NOOP)
    assert (reward, terminated, truncated) == (0.0, True, False)
    assert info["collision"] and not info["is_success"]


def test_collision_with_curb_ends_the_episode():
    env = quiet_env()
    env.set_state(6.0, -0.4, -0.3, 0.0)  # a front corner is below y = -1
    _, reward, terminated, _, info = env.step(NOOP)
    assert (reward, terminated, info["collision"]) == (0.0, True, True)


def test_collision_uses_the_rotated_rectangle():
    env = quiet_env()
    # Bounding boxes overlap the front obstacle's corner (4.5, 0.5) in both cases.
    assert not env.collides((5.3, 1.3, math.pi / 4, 0))
    assert env.collides((5.0, 1.0, math.pi / 4, 0))
    assert not env.collides((0.0, 0.0, 0.0, 0))
    assert env.collides((0.0, 0.0, 0.0, 0), margin=1.6)


def test_leaving_the_world_terminates_without_reward():
    env = quiet_env()
    env.set_state(9.8, 3.0, 0.0, 0.5)
    obs, reward, terminated, _, info = env.step(NOOP)
    assert (reward, terminated, info["is_success"]) == (0.0, True, False)
    assert env.observation_space.contains(obs)


def test_time_limit_truncates_at_200_steps():
    env = gym.make("sb3_swirl/ParallelParking-v0")
    env.reset(seed=3)
    for t in range(200):
        _, reward, terminated, truncated, info = env.step(NOOP)  # a stopped car stays put
        assert not terminated and reward == 0.0 and not info["is_success"]
        assert truncated == (t == 199)


def test_steering_noise_rate_and_size():
    env = ParallelParkingEnv()
    env.reset(seed=123)
    n, noisy = 20000, 0
    start = (-7.0, 3.0, 0.0, 0.5)
    env.set_state(*start)
    expected = env.simulate(env.raw_state, NOOP)
    kicks = {env.simulate(env.raw_state, NOOP, s * math.radians(2.5)) for s in (1, -1)}
    seen = set()
    for _ in range(n):
        env.set_state(*start)
        env.step(NOOP)
        if env.raw_state != expected:
            noisy += 1
            seen.add(env.raw_state)
    sigma = math.sqrt(0.1 * 0.9 / n)
    assert abs(noisy / n - 0.1) < 5 * sigma
    assert seen == kicks  # exactly ±2.5 degrees, both signs


def test_perturbed_right_turn_accelerates_forward():
    env = quiet_env(perturbed=True)
    env.set_state(-7.0, 3.0, 0.0, -0.2)
    env.step(STEER_RIGHT)
    assert env.state[3] == pytest.approx(-0.15)
    env.step(STEER_LEFT)
    assert env.state[3] == pytest.approx(-0.15)
    nominal = quiet_env()
    nominal.set_state(-7.0, 3.0, 0.0, -0.2)
    nominal.step(STEER_RIGHT)
    assert nominal.state[3] == pytest.approx(-0.2)


def test_partial_observation_hides_speed():
    env = gym.make("sb3_swirl/ParallelParkingPartial-v0")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3,) == env.observation_space.shape
    obs, *_ = env.step(ACCELERATE)
    np.testing.assert_allclose(obs, env.unwrapped.state[:3], rtol=1e-6)


def test_displacement_is_the_last_step_of_the_hidden_state():
    env = gym.make("sb3_swirl/ParallelParkingPartialDisplacement-v0")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (6,) == env.observation_space.shape
    np.testing.assert_array_equal(obs[3:], 0.0)
    before = np.array(env.unwrapped.state[:3])
    for action in (ACCELERATE, ACCELERATE, STEER_LEFT, DECELERATE):
        obs, *_ = env.step(action)
        after = np.array(env.unwrapped.state[:3])
        np.testing.assert_allclose(obs[:3], after, rtol=1e-6)
        np.testing.assert_allclose(obs[3:], after - before, atol=1e-6)
        before = after
    # the speed is read back from the displacement: v * dt along a straight step
    quiet = quiet_env(partial_observation=True, observe_displacement=True)
    np.testing.assert_array_equal(quiet.set_state(0.0, 2.0, 0.0, -0.3)[3:], 0.0)
    obs, *_ = quiet.step(NOOP)
    assert obs[3] == pytest.approx(-0.3, abs=1e-6) and obs[4] == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValueError, match="observe_displacement needs partial_observation"):
        ParallelParkingEnv(observe_displacement=True)


def test_start_distribution():
    env = ParallelParkingEnv()
    starts = np.array([env.reset(seed=s)[0] for s in range(200)])
    assert np.all(np.abs(starts[:, 0] + 4.0) <= 1.0)
    assert np.all(np.abs(starts[:, 1] - 2.0) <= 0.2)
    assert np.all(np.abs(starts[:, 2]) <= math.radians(5.0))
    assert np.all(starts[:, 3] == 0.0)
    assert starts[:, 0].std() > 0.3  # really spread, not a constant


@pytest.mark.parametrize("env_id", IDS)
def test_checkers(env_id):
    env = gym.make(env_id, render_mode="rgb_array").unwrapped
    gym_check_env(env, skip_render_check=False)
    sb3_check_env(env, warn=True)


def rollout(env, seed, actions):
    out = [env.reset(seed=seed)[0]]
    for a in actions:
        out.append(env.step(a)[0])
    return np.array(out)


def test_seeded_reset_is_reproducible():
    actions = np.random.default_rng(0).integers(0, 5, 60).tolist()
    a = rollout(gym.make(IDS[0]), 7, actions)
    b = rollout(gym.make(IDS[0]), 7, actions)
    c = rollout(gym.make(IDS[0]), 8, actions)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a[0], c[0])


def test_pickle_round_trip():
    env = ParallelParkingEnv(render_mode="rgb_array")
    env.reset(seed=5)
    env.render()
    for a in [ACCELERATE] * 3 + [STEER_LEFT] * 5:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.raw_state == env.raw_state
    for a in [STEER_RIGHT, NOOP, STEER_LEFT] * 10:
        assert np.array_equal(clone.step(a)[0], env.step(a)[0])


def test_rgb_render():
    env = ParallelParkingEnv(render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 5
    env.set_state(0.0, 0.0, 0.0, 0.0)
    assert not np.array_equal(img, env.render())  # the car is drawn where it is


def test_bad_input_raises():
    env = quiet_env()
    env.reset(seed=0)
    rng_state = env.np_random.bit_generator.state
    for action in (5, 1.7, "1", np.array([1]), None):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    assert env.np_random.bit_generator.state == rng_state  # a refused action draws no noise
    env.step(np.int64(1))  # integer numpy scalars are actions
    for kwargs in ({"max_speed": float("inf")}, {"steering_noise_deg": float("nan")}):
        with pytest.raises(ValueError, match="finite"):
            ParallelParkingEnv(**kwargs)
    with pytest.raises(ValueError, match="speed unit"):
        ParallelParkingEnv(max_speed=0.01)
    for name in ("partial_observation", "observe_displacement", "perturbed"):  # "no" was on
        with pytest.raises(ValueError, match=f"{name} must be True or False, got 'no'"):
            ParallelParkingEnv(**{name: "no"})
    with pytest.raises(ValueError, match="finite"):
        env.set_state(float("nan"), 0.0, 0.0)
    with pytest.raises(ValueError, match="multiple"):
        env.set_state(0.0, 0.0, 0.0, 0.12)
    with pytest.raises(ValueError, match="noise_probability"):
        ParallelParkingEnv(noise_probability=1.5)
    with pytest.raises(ValueError, match="render_mode"):
        ParallelParkingEnv(render_mode="ascii")
