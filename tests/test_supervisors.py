"""Supervisors and collect_demos: reliability, shapes, seeding, errors."""

import gymnasium as gym
import numpy as np
import pytest

import sb3_swirl.envs  # noqa: F401  (registers the env ids)
from sb3_swirl.demos import Demonstration
from sb3_swirl.supervisors import SUPERVISORS, AcrobotSupervisor, collect_demos, supervisor_for

ACROBOT = "sb3_swirl/NoisyAcrobot-v0"
PARKING = "sb3_swirl/ParallelParking-v0"


def supervised_episode(env, seed):
    """Run the acrobot supervisor for one episode; (success, steps)."""
    sup = AcrobotSupervisor(env.unwrapped)
    obs, _ = env.reset(seed=seed)
    sup.reset(obs)
    for step in range(1, 10_000):
        obs, _, terminated, truncated, info = env.step(sup.act(obs))
        if terminated or truncated:
            return info["is_success"], step
    raise AssertionError("the TimeLimit did not end the episode")


@pytest.fixture(scope="module")
def acrobot_demos():
    return collect_demos(ACROBOT, 3, seed=0)


def test_acrobot_supervisor_swings_up_from_every_start():
    env = gym.make(ACROBOT)
    results = [supervised_episode(env, seed) for seed in range(20)]
    assert all(success for success, _ in results), results
    # energy pumping with the default torque takes a few hundred of the 1000 steps
    steps = [n for _, n in results]
    assert 100 < np.mean(steps) < 600


@pytest.mark.slow
def test_acrobot_supervisor_100_starts_and_longer_link_2():
    env = gym.make(ACROBOT)
    assert all(supervised_episode(env, seed)[0] for seed in range(100, 200))
    longer = gym.make(ACROBOT, link_length_2=1.3)
    assert all(supervised_episode(longer, seed)[0] for seed in range(20))


def test_acrobot_supervisor_is_deterministic_and_rejects_other_envs():
    env = gym.make(ACROBOT, torque_noise_std=0.0)
    sup = AcrobotSupervisor(env)  # wrappers are looked through
    obs, _ = env.reset(seed=0)
    assert sup.act(obs) == AcrobotSupervisor(env.unwrapped, seed=123).act(obs)
    with pytest.raises(ValueError, match="NoisyAcrobotEnv"):
        AcrobotSupervisor(gym.make("CartPole-v1"))
    with pytest.raises(ValueError, match="obs"):
        sup.act(np.zeros(3))


def test_collect_demos_shapes_and_dtypes(acrobot_demos):
    assert len(acrobot_demos) == 3
    for demo in acrobot_demos:
        assert isinstance(demo, Demonstration)
        t = len(demo)
        assert demo.observations.shape == (t + 1, 4) and demo.observations.dtype == np.float64
        assert demo.actions.shape == (t,) and demo.actions.dtype == np.int64
        assert demo.rewards.shape == (t,) and demo.rewards.dtype == np.float64
        assert set(np.unique(demo.actions)) <= {0, 1, 2, 3}
        # sparse task reward: 1 on the last (successful) step only
        assert demo.rewards[-1] == 1.0 and demo.rewards[:-1].sum() == 0.0
        assert np.abs(demo.observations[0]).max() <= 0.1  # starts hanging down
        assert not demo.truncated  # it ends at the goal, a termination
        assert 1 < t < 1000


def test_collect_demos_is_reproducible_and_seed_dependent(acrobot_demos):
    again = collect_demos(ACROBOT, 2, seed=0)  # also: the first m demos do not depend on n
    for a, b in zip(acrobot_demos[:2], again, strict=True):
        np.testing.assert_array_equal(a.observations, b.observations)
        np.testing.assert_array_equal(a.actions, b.actions)
    other = collect_demos(ACROBOT, 1, seed=1)[0]
    assert not np.array_equal(other.observations[0], acrobot_demos[0].observations[0])
    assert len({len(d) for d in acrobot_demos}) > 1  # different starts and noise


def test_collect_demos_passes_env_kwargs():
    demo = collect_demos(ACROBOT, 1, seed=0, torque=0.5)[0]
    default = collect_demos(ACROBOT, 1, seed=0)[0]
    np.testing.assert_array_equal(demo.observations[0], default.observations[0])
    assert len(demo) < len(default)  # twice the torque swings up sooner


def test_failed_demo_is_an_error_naming_the_seed(acrobot_demos):
    # The first seed-0 episode needs more steps than this limit; the next two do not.
    limit = len(acrobot_demos[0]) - 1
    assert len(acrobot_demos[1]) <= limit and len(acrobot_demos[2]) <= limit
    first_seed = int(np.random.SeedSequence(0).spawn(1)[0].generate_state(2)[0])
    with pytest.raises(RuntimeError, match=str(first_seed)):
        collect_demos(ACROBOT, 2, seed=0, max_episode_steps=limit)
    # asked to, it skips the failure and keeps going
    kept = collect_demos(ACROBOT, 2, seed=0, max_attempts=3, max_episode_steps=limit)
    for got, want in zip(kept, acrobot_demos[1:], strict=True):
        np.testing.assert_array_equal(got.observations, want.observations)
    with pytest.raises(RuntimeError, match=r"1 of 2 demos.*attempts are spent"):
        collect_demos(ACROBOT, 2, seed=0, max_attempts=2, max_episode_steps=limit)


def test_collect_demos_on_parking():
    demos = collect_demos(PARKING, 2, seed=0)
    assert len(demos) == 2
    for demo in demos:
        assert demo.observations.shape == (len(demo) + 1, 4)
        assert demo.observations.dtype == np.float64 and demo.actions.dtype == np.int64
        assert demo.rewards[-1] == 1.0
        assert len(demo) <= 200


def test_collect_demos_returns_the_parking_supervisors_phases():
    demos, phases = collect_demos(PARKING, 2, seed=0, return_phases=True)
    again = collect_demos(PARKING, 2, seed=0)
    for demo, phase, same in zip(demos, phases, again, strict=True):
        np.testing.assert_array_equal(demo.observations, same.observations)
        assert phase.shape == (len(demo),) and phase.dtype == np.int64
        # forward, reverse in, reverse out, final, in that order (a late re-plan may restart)
        firsts = [int(np.argmax(phase == p)) for p in range(4) if (phase == p).any()]
        assert phase[0] == 0 and firsts == sorted(firsts) and len(firsts) >= 3
    with pytest.raises(ValueError, match="does not plan in phases"):
        collect_demos(ACROBOT, 1, seed=0, return_phases=True)


def test_collect_demos_progress_bar(capsys):
    demos = collect_demos(PARKING, 1, seed=0, progress=True)
    assert len(demos) == 1
    assert "demos" in capsys.readouterr().out


def test_unknown_env_id_lists_the_supported_ids():
    with pytest.raises(ValueError, match="supported ids") as err:
        collect_demos("CartPole-v1", 1)
    for env_id in SUPERVISORS:
        assert env_id in str(err.value)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n": 0}, "n must"),
        ({"n": 2.0}, "n must"),
        ({"n": 3, "max_attempts": 2}, "max_attempts"),
        ({"n": 2, "seed": -1}, "seed must"),
        ({"n": 2, "seed": 1.5}, "seed must"),
    ],
)
def test_bad_counts(kwargs, match):
    with pytest.raises(ValueError, match=match):
        collect_demos(ACROBOT, **kwargs)


def test_every_registered_id_has_a_supervisor_class():
    for env_id in SUPERVISORS:
        assert env_id in gym.registry
        cls = supervisor_for(env_id)
        assert callable(cls.act) and callable(cls.reset)
    assert supervisor_for(ACROBOT) is AcrobotSupervisor
