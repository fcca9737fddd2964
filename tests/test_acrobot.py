"""NoisyAcrobotEnv: physics, success test, noise, seeding, checkers, pickling, rendering."""

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.classic_control.acrobot import AcrobotEnv, rk4
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_swirl.envs  # noqa: F401  (registers the env ids)
from sb3_swirl.envs.acrobot import NoisyAcrobotEnv

ENV_ID = "sb3_swirl/NoisyAcrobot-v0"


def rollout(env, actions, seed=0, start=None):
    obs, _ = env.reset(seed=seed)
    if start is not None:
        obs = env.set_state(*start)
    observations = [obs]
    for action in actions:
        obs, *_ = env.step(action)
        observations.append(obs)
    return np.array(observations)


def fine_env(**kwargs):
    """A noise-free env with a small time step, so integration error is negligible."""
    env = NoisyAcrobotEnv(torque_noise_std=0.0, **kwargs)
    env.dt = 0.005
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("link_length_2", [1.0, 1.6])
def test_energy_is_conserved_without_torque(link_length_2):
    env = fine_env(torque=0.0, link_length_2=link_length_2)
    env.set_state(1.0, -0.5, 0.5, 1.0)
    e0 = env.energy()
    energies = []
    for _ in range(200):
        env.step(0)
        energies.append(env.energy())
    assert abs(env.state[0] - 1.0) > 0.1  # it swung
    np.testing.assert_allclose(energies, e0, atol=1e-6)


@pytest.mark.parametrize("link_length_2", [1.0, 1.6])
@pytest.mark.parametrize("action", range(4))
def test_torque_work_equals_energy_change(link_length_2, action):
    # A constant torque tau on joint j does work tau * (change of theta_j): this checks that
    # the equations of motion put the torque on the right joint with the right sign.
    env = fine_env(torque=0.5, link_length_2=link_length_2)
    env.set_state(0.3, -0.2, 0.5, 1.0)
    before, e0 = env.state.copy(), env.energy()
    for _ in range(20):
        env.step(action)
    joint = 0 if action < 2 else 1
    sign = 1.0 if action % 2 == 0 else -1.0
    work = sign * 0.5 * (env.state[joint] - before[joint])
    assert abs(work) > 1e-3
    assert env.energy() - e0 == pytest.approx(work, rel=1e-4, abs=1e-7)


def test_dynamics_match_gymnasium_acrobot_for_a_torque_on_joint_2():
    ours = NoisyAcrobotEnv(torque=1.0, torque_noise_std=0.0)
    theirs = AcrobotEnv()
    rng = np.random.default_rng(0)
    for _ in range(10):
        state = rng.uniform(-2.0, 2.0, size=4)
        expected = rk4(theirs._dsdt, np.append(state, 1.0), [0, theirs.dt])
        np.testing.assert_allclose(ours._integrate(*state, 0.0, 1.0), expected, atol=1e-12)


def test_simulate_wraps_angles_and_clips_velocities():
    env = NoisyAcrobotEnv()
    t1, _, w1, w2 = env.simulate((math.pi - 0.01, 0.0, 12.5, 0.0), 0)
    assert -math.pi <= t1 < 0  # crossed the top and wrapped
    assert abs(w1) <= env.MAX_VEL_1 and abs(w2) <= env.MAX_VEL_2


@pytest.mark.parametrize("link_length_2", [1.0, 0.7, 1.5])
def test_tip_height_is_the_tip_y_coordinate(link_length_2):
    env = NoisyAcrobotEnv(link_length_2=link_length_2)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    for t1, t2 in rng.uniform(-math.pi, math.pi, size=(20, 2)):
        env.set_state(t1, t2)
        # the tip in the plane: pivot at the origin, link 1 straight down at theta1 = 0
        elbow = np.array([math.sin(t1), -math.cos(t1)])
        tip = elbow + link_length_2 * np.array([math.sin(t1 + t2), -math.cos(t1 + t2)])
        assert env.tip_height() == pytest.approx(tip[1])
    assert env.tip_height((0.0, 0.0, 0.0, 0.0)) == pytest.approx(-1.0 - link_length_2)
    assert env.tip_height((math.pi, 0.0, 0.0, 0.0)) == pytest.approx(1.0 + link_length_2)


def test_success_when_the_tip_is_above_the_line():
    env = gym.make(ENV_ID, torque_noise_std=0.0)
    env.reset(seed=0)
    env.unwrapped.set_state(math.pi, 0.0)  # straight up, tip at y = 2
    _, reward, terminated, truncated, info = env.step(0)
    assert (reward, terminated, truncated, info["is_success"]) == (1.0, True, False, True)
    assert env.unwrapped.tip_height() > 1.0

    env.reset(seed=0)
    env.unwrapped.set_state(math.pi / 2, 0.0)  # horizontal, tip at y = 0
    _, reward, terminated, _, info = env.step(0)
    assert (reward, terminated, info["is_success"]) == (0.0, False, False)
    assert env.unwrapped.tip_height() < 1.0


def test_hanging_down_is_not_a_success_and_info_has_is_success_every_step():
    env = gym.make(ENV_ID)
    _, info = env.reset(seed=0)
    assert info["is_success"] is False
    for action in [0, 1, 2, 3] * 5:
        _, reward, terminated, _, info = env.step(action)
        assert info["is_success"] is False
        assert (reward, terminated) == (0.0, False)


def test_time_limit_is_1000_steps():
    env = gym.make(ENV_ID)
    assert env.spec.max_episode_steps == 1000


def test_link_2_length_changes_the_dynamics_and_scales_the_rod():
    actions = [0, 2, 1, 3] * 10
    default = rollout(NoisyAcrobotEnv(), actions, seed=3)
    same = rollout(NoisyAcrobotEnv(link_length_2=1.0), actions, seed=3)
    longer = rollout(NoisyAcrobotEnv(link_length_2=1.5), actions, seed=3)
    np.testing.assert_array_equal(default, same)
    np.testing.assert_array_equal(default[0], longer[0])
    assert np.abs(default - longer).max() > 0.1
    env = NoisyAcrobotEnv(link_length_2=1.5)
    assert (env.LINK_LENGTH_2, env.LINK_MASS_2, env.LINK_COM_POS_2) == (1.5, 1.5, 0.75)
    assert env.LINK_MOI_2 == pytest.approx(1.5**3)


def test_torque_noise_makes_trajectories_differ_between_seeds():
    actions = [0, 1, 2, 3] * 10
    start = (0.1, -0.1, 0.0, 0.0)
    noisy = NoisyAcrobotEnv()
    a = rollout(noisy, actions, seed=0, start=start)
    b = rollout(noisy, actions, seed=1, start=start)
    assert np.abs(a - b).max() > 1e-3
    quiet = NoisyAcrobotEnv(torque_noise_std=0.0)
    c = rollout(quiet, actions, seed=0, start=start)
    d = rollout(quiet, actions, seed=1, start=start)
    np.testing.assert_array_equal(c, d)
    assert np.abs(a - c).max() > 1e-3


def test_seeded_reset_is_reproducible():
    actions = np.random.default_rng(0).integers(4, size=300).tolist()
    env = NoisyAcrobotEnv()
    a = rollout(env, actions, seed=42)
    b = rollout(env, actions, seed=42)
    c = rollout(NoisyAcrobotEnv(), actions, seed=42)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    assert np.abs(a[0]).max() <= 0.1  # hanging down
    assert not np.array_equal(a[0], rollout(env, [], seed=43)[0])


def test_observations_stay_in_the_observation_space():
    env = NoisyAcrobotEnv(torque=2.0)  # strong enough to spin and hit the velocity limits
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    seen_fast = False
    for _ in range(2000):
        obs, _, terminated, _, _ = env.step(int(rng.integers(4)))
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        seen_fast |= abs(obs[2]) > 4.0
        if terminated:
            obs, _ = env.reset()
    assert seen_fast


def test_checkers_pass():
    check_env(gym.make(ENV_ID, render_mode="rgb_array").unwrapped, skip_render_check=False)
    sb3_check_env(NoisyAcrobotEnv(), warn=True)


def test_pickle_round_trip_continues_identically():
    env = NoisyAcrobotEnv()
    env.reset(seed=5)
    for action in [0, 2, 1]:
        env.step(action)
    clone = pickle.loads(pickle.dumps(env))
    for action in [3, 0, 0, 2] * 5:
        np.testing.assert_array_equal(env.step(action)[0], clone.step(action)[0])


def test_render_draws_the_arm():
    env = NoisyAcrobotEnv(render_mode="rgb_array")
    env.reset(seed=0)
    down = env.render()
    assert down.dtype == np.uint8 and down.shape == (500, 500, 3)
    link = np.all(down == (0, 204, 204), axis=-1)
    assert 1000 < link.sum() < 0.5 * link.size
    # hanging down, the link colour is below the pivot (image centre), not above it
    assert link[260:].sum() > 0 and link[:240].sum() == 0
    env.set_state(math.pi, 0.0)
    up = np.all(env.render() == (0, 204, 204), axis=-1)
    assert up[:240].sum() > 0 and up[260:].sum() == 0
    env.close()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"link_length_2": 0.0},
        {"link_length_2": float("nan")},
        {"torque": -1.0},
        {"torque_noise_std": -0.1},
        {"render_mode": "ansi"},
    ],
)
def test_bad_constructor_arguments(kwargs):
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        NoisyAcrobotEnv(**kwargs)


def test_bad_action_and_state():
    env = NoisyAcrobotEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(4)
    with pytest.raises(ValueError, match="finite"):
        env.set_state(0.0, float("inf"))


UNDER = "sb3_swirl/UnderactuatedAcrobot-v0"


def test_underactuated_variant_is_gymnasiums_acrobot_with_noise():
    """Torque on joint 2 only, three actions (-, 0, +) as in Acrobot-v1, gymnasium's torque."""
    env = gym.make(UNDER).unwrapped
    assert env.action_space.n == 3 and env.actuation == "second" and env.torque == 1.0
    theirs = AcrobotEnv()
    quiet = NoisyAcrobotEnv(actuation="second", torque=1.0, torque_noise_std=0.0)
    rng = np.random.default_rng(1)
    for action in range(3):
        state = rng.uniform(-2.0, 2.0, size=4)
        expected = rk4(theirs._dsdt, np.append(state, action - 1.0), [0, theirs.dt])
        np.testing.assert_allclose(
            quiet._integrate(*state, 0.0, action - 1.0), expected, atol=1e-12
        )
        assert quiet.noise_free_step(state, action).shape == (4,)
    check_env(gym.make(UNDER, render_mode="rgb_array").unwrapped, skip_render_check=False)
    sb3_check_env(gym.make(UNDER).unwrapped, warn=True)
    with pytest.raises(ValueError, match=r"action must be an integer in \[0, 3\)"):
        env.reset(seed=0)
        env.step(3)
    with pytest.raises(ValueError, match="actuation"):
        NoisyAcrobotEnv(actuation="first")


def test_underactuated_variant_is_seeded_and_its_supervisor_swings_up():
    from sb3_swirl.supervisors import collect_demos

    first = rollout(gym.make(UNDER), [0, 2, 1] * 10, seed=4)
    again = rollout(gym.make(UNDER), [0, 2, 1] * 10, seed=4)
    other = rollout(gym.make(UNDER), [0, 2, 1] * 10, seed=5)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    demos = collect_demos(UNDER, 5, seed=0)  # every episode must succeed, or this raises
    assert all(len(d) < 1000 for d in demos)
