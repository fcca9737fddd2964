"""Model-based local rewards: MaxEnt IRL per segment (paper §6.2)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from scipy.special import logsumexp

import sb3_swirl
from sb3_swirl.demos import Demonstration
from sb3_swirl.fitting import fit_task
from sb3_swirl.rewards import MaxEntIRLRewardLearner, segment_transitions
from sb3_swirl.supervisors import collect_demos
from swirl_wrappers import Region, TaskModel

PARKING = "sb3_swirl/ParallelParking-v0"


def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    return float((a * b).sum() / np.linalg.norm(a) / np.linalg.norm(b))


def _soft_lqr(a, b, psi, mu, action_cost, gamma):
    """An independent solver for the generator: the gain and action covariance of the
    maximum-entropy policy of x' = A x + B u with reward -(x - mu)^T Psi (x - mu) - c |u|^2,
    from the discounted Riccati recursion on (x, 1)."""
    p, m = b.shape
    abar = np.block([[a, np.zeros((p, 1))], [np.zeros((1, p)), np.ones((1, 1))]])
    bbar = np.vstack([b, np.zeros((1, m))])
    shift = np.hstack([np.eye(p), -mu[:, None]])  # x - mu = shift @ (x, 1)
    qbar = shift.T @ psi @ shift
    r = action_cost * np.eye(m)
    pbar = qbar
    for _ in range(1000):
        mmat = r + gamma * bbar.T @ pbar @ bbar
        gain = gamma * np.linalg.solve(mmat, bbar.T @ pbar @ abar)
        pbar = qbar + gamma * abar.T @ pbar @ abar - gamma * abar.T @ pbar @ bbar @ gain
    mmat = r + gamma * bbar.T @ pbar @ bbar
    return gamma * np.linalg.solve(mmat, bbar.T @ pbar @ abar), np.linalg.inv(2 * mmat)


@pytest.mark.parametrize("known_model", [False, True])
def test_linear_gaussian_maxent_recovers_psi_up_to_scale(known_model):
    """20 demos of the soft-optimal policy of a 4-D linear-quadratic problem (fixed action
    cost): the learned Psi matches the true one (cosine >= 0.9, flattened)."""
    rng = np.random.default_rng(0)
    p = m = 4
    a = np.eye(p) + 0.1 * rng.normal(size=(p, p))
    b = 0.5 * rng.normal(size=(p, m))
    low = rng.normal(size=(p, p))
    psi = low @ low.T / p + 0.1 * np.eye(p)
    mu = rng.normal(size=p)
    gain, cov = _soft_lqr(a, b, psi, mu, 1.0, 0.9)
    demos = []
    for _ in range(20):
        x = 2 * rng.normal(size=p)
        states, actions = [x], []
        for _ in range(30):
            u = -gain @ np.append(x, 1.0) + rng.multivariate_normal(np.zeros(m), cov)
            x = a @ x + b @ u + 0.01 * rng.normal(size=p)
            states.append(x)
            actions.append(u)
        demos.append(Demonstration(np.array(states), np.array(actions)))
    never_reached = Region(mu, np.eye(p), 1e-9)  # one segment holding every transition
    learner = MaxEntIRLRewardLearner(normalize=False, dynamics=(a, b) if known_model else None)
    weight = learner.fit(demos, [never_reached]).rewards_[0].weight
    assert _cosine(weight, psi) >= 0.9
    assert np.all(np.linalg.eigvalsh(weight) >= 0)  # Psi stays positive semi-definite
    assert np.allclose(learner.rewards_[0].target, mu)
    if known_model:  # a model for other actions, or of other states, is named
        for bad, match in (((a, b[:, :2]), r"B has shape \(4, 2\)"), ((a,), "linear model")):
            with pytest.raises(ValueError, match=match):
                MaxEntIRLRewardLearner(dynamics=bad).fit(demos, [never_reached])


def _grid_demos(psi: np.ndarray, goal: np.ndarray, n: int = 9, seed: int = 0):
    """Demos of the tabular soft-optimal policy on an n x n grid (stay, +-x, +-y)."""
    moves = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]])

    def step(s, action):
        return np.clip(np.asarray(s) + moves[int(action)], 0, n - 1).astype(float)

    cells = np.array([[i, j] for i in range(n) for j in range(n)], dtype=float)
    index = {tuple(c): k for k, c in enumerate(cells)}
    reward = -np.einsum("ni,ij,nj->n", cells - goal, psi, cells - goal)
    successor = np.array([[index[tuple(step(c, a))] for a in range(5)] for c in cells])
    value = np.zeros(len(cells))
    for _ in range(300):
        q = reward[:, None] + 0.9 * value[successor]
        value = logsumexp(q, axis=1)
    policy = np.exp(q - value[:, None])
    rng = np.random.default_rng(seed)
    demos = []
    for _ in range(20):
        s = cells[rng.integers(len(cells))]
        states, actions = [s], []
        for _ in range(15):
            action = rng.choice(5, p=policy[index[tuple(s)]])
            s = step(s, action)
            states.append(s)
            actions.append(action)
        demos.append(Demonstration(np.array(states), np.array(actions)))
    return demos, step


@pytest.mark.parametrize("known_model", [False, True])
@pytest.mark.parametrize("value_function", ["quadratic", "tabular"])
def test_discrete_maxent_recovers_the_cost_shape_of_a_grid_task(known_model, value_function):
    """Discrete actions on a grid: the goal-seeking demonstrator cares 5x more about x than
    about y; MaxEnt (soft value iteration with a quadratic value, or on 9 x 9 bins with counted
    transitions) finds that shape."""
    psi, goal = np.diag([1.0, 0.2]), np.array([6.0, 2.0])
    demos, step = _grid_demos(psi, goal)
    learner = MaxEntIRLRewardLearner(
        normalize=False,
        dynamics=step if known_model else None,
        value_function=value_function,
        n_bins=9,
    )
    weight = learner.fit(demos, [Region(goal, np.eye(2), 1e-9)]).rewards_[0].weight
    assert _cosine(weight, psi) >= 0.9
    assert weight[0, 0] > 2 * weight[1, 1]


def test_a_constant_coordinate_or_collinear_actions_do_not_break_the_linear_model():
    """A coordinate no demo moves (a fixed goal entry) or action columns the segment holds
    constant and collinear made the linear model's normal equations singular (numpy's
    LinAlgError). The constant coordinate now gets no effect and weight 0, and the other
    coordinates read as without it."""
    psi, goal = np.diag([1.0, 0.2]), np.array([6.0, 2.0])
    demos, _ = _grid_demos(psi, goal)
    region = [Region(goal, np.eye(2), 1e-9)]
    plain = MaxEntIRLRewardLearner(normalize=False).fit(demos, region).rewards_[0].weight
    padded = [
        Demonstration(np.c_[d.observations, np.full(len(d.observations), 3.0)], d.actions)
        for d in demos
    ]
    with pytest.warns(UserWarning, match=r"dimensions \[2\] are constant"):
        weight = (
            MaxEntIRLRewardLearner(normalize=False)
            .fit(padded, [Region(np.r_[goal, 3.0], np.eye(3), 1e-9)])
            .rewards_[0]
            .weight
        )
    assert np.all(weight[2] == 0.0) and np.all(weight[:, 2] == 0.0)
    np.testing.assert_allclose(weight[:2, :2], plain, rtol=1e-3)
    # continuous actions, two columns that say the same (one constant value in the segment)
    rng = np.random.default_rng(0)
    steps = [
        Demonstration(np.cumsum(rng.normal(size=(20, 2)), axis=0), np.ones((19, 2)))
        for _ in range(5)
    ]
    reward = MaxEntIRLRewardLearner().fit(steps, [Region(np.zeros(2), np.eye(2), 1e-9)])
    assert np.all(np.isfinite(reward.rewards_[0].weight))


def test_fit_task_maxent_on_parking_gives_an_ordinary_task():
    """fit_task(reward="maxent") with estimated and with the env's known dynamics: PSD local
    rewards, a TaskModel that round-trips through JSON and drives the wrapper."""
    demos = collect_demos(PARKING, 5, seed=0)
    model = gym.make(PARKING).unwrapped.noise_free_step
    kwargs = {"reg_covar": 0.1, "normalize_time": False, "random_state": 0}
    base = fit_task(demos, **kwargs)
    for extra in ({}, {"dynamics": model}):
        task = fit_task(demos, reward="maxent", **kwargs, **extra)
        assert task.n_segments == base.n_segments
        assert task.metadata["reward"]["class"] == "MaxEntIRLRewardLearner"
        for reward, region in zip(task.rewards, task.regions, strict=True):
            assert np.all(np.linalg.eigvalsh(reward.weight) >= -1e-9)
            assert np.allclose(reward.target, region.mean)
        again = TaskModel.from_json(task.to_json())
        assert again.to_json() == task.to_json()
        env = sb3_swirl.SwirlWrapper(gym.make(PARKING), again)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (4 + task.n_indices,)


def test_segment_transitions_partition_the_demonstrated_steps():
    demos = collect_demos(PARKING, 3, seed=1)
    task = fit_task(demos, reg_covar=0.1, normalize_time=False, random_state=0)
    segments, _ = segment_transitions(demos, task)
    assert sum(len(s["actions"]) for s in segments) <= sum(len(d) for d in demos)
    for seg in segments:
        assert len(seg["x"]) == len(seg["next_x"]) == len(seg["actions"])


def test_state_only_demos_are_refused_naming_the_method():
    demos = [Demonstration(d.observations) for d in collect_demos(PARKING, 3, seed=0)]
    with pytest.raises(ValueError, match=r"demo 0 has no actions: MaxEnt IRL \(reward='maxent'"):
        fit_task(demos, reward="maxent", reg_covar=0.1, random_state=0)
    with pytest.raises(ValueError, match="reward must be one of"):
        fit_task(demos, reward="maxentt")
    shifted = [Demonstration(d.observations, d.actions - 1) for d in collect_demos(PARKING, 3)]
    with pytest.raises(
        ValueError, match=r"demo \d: action -1 at step \d+; .* numbered 0 \.\. n - 1"
    ):
        fit_task(shifted, reward="maxent", reg_covar=0.1, random_state=0)
    # one torque a step given as shape (T,): read as labels, so say how to give it
    torques = [Demonstration(d.observations, d.actions * 0.5) for d in collect_demos(PARKING, 3)]
    with pytest.raises(
        ValueError, match=r"demo \d: action \d\.5 at step \d+;.* actions\[:, None\]"
    ):
        fit_task(torques, reward="maxent", reg_covar=0.1, random_state=0)
    # sparse labels: every label up to the largest is modelled, so it says so (stopped there)
    sparse = [Demonstration(d.observations, d.actions * 20) for d in collect_demos(PARKING, 3)]
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="the demos' action labels reach 80 but only 5")
        with pytest.raises(UserWarning, match=r"number the actions 0 \.\. 4"):
            fit_task(sparse, reward="maxent", reg_covar=0.1, random_state=0)
    with pytest.raises(ValueError, match="makes 1000000 states"):
        rng = np.random.default_rng(0)
        MaxEntIRLRewardLearner(value_function="tabular", n_bins=10).fit(
            [Demonstration(rng.normal(size=(9, 6)), np.zeros(8, int)) for _ in range(2)],
            [Region(np.zeros(6), np.eye(6), 1e-9)],
        )


def test_a_known_model_refuses_task_states_it_cannot_tell_apart():
    """With dims (x, y, theta) a stopping car's states differ only in the speed left out."""
    demos = collect_demos(PARKING, 3, seed=0)
    model = gym.make(PARKING).unwrapped.noise_free_step
    with pytest.raises(ValueError, match=r"share their task-space values .* cannot tell which"):
        fit_task(demos, dims=[0, 1, 2], reward="maxent", dynamics=model, reg_covar=0.1)


def test_noise_free_models_match_the_envs_without_noise():
    for env_id, kwargs in (
        (PARKING, {"noise_probability": 0.0}),
        ("sb3_swirl/NoisyAcrobot-v0", {"torque_noise_std": 0.0}),
    ):
        env = gym.make(env_id, **kwargs)
        obs, _ = env.reset(seed=3)
        for t in range(20):
            action = t % env.action_space.n
            expected = env.unwrapped.noise_free_step(obs, action)
            obs, *_ = env.step(action)
            np.testing.assert_allclose(expected, obs, atol=1e-5)
    partial = gym.make("sb3_swirl/ParallelParkingPartial-v0").unwrapped
    with pytest.raises(ValueError, match="partial_observation hides"):
        partial.noise_free_step(np.zeros(3), 0)


def test_a_known_model_steps_raw_observations_when_the_fit_uses_angles_and_dims():
    """The acrobot's fit works on (cos, sin) features and two of its dims: its known model is
    still called on the observations the env produced, and its steps reach the learner in the
    fit's feature space."""
    env_id = "sb3_swirl/NoisyAcrobot-v0"
    demos = collect_demos(env_id, 4, seed=0)
    step = gym.make(env_id).unwrapped.noise_free_step
    seen = []

    def model(observation, action):
        seen.append(np.asarray(observation))
        return step(observation, action)

    settings = {"angles": [[0], [0, 1]], "dims": [2, 3], "reg_covar": 1e-3, "random_state": 0}
    task = fit_task(demos, reward="maxent", dynamics=model, **settings)
    recorded = np.concatenate([d.observations for d in demos])
    assert seen and all(s.shape == (4,) for s in seen)
    assert all(np.any(np.all(np.isclose(recorded, s), axis=1)) for s in seen[:50])
    assert task.metadata["reward"]["params"]["dynamics"].endswith("model")


def test_float_actions_of_shape_t_are_warned_to_be_read_as_labels():
    demos = sb3_swirl.collect_demos("sb3_swirl/ParallelParking-v0", 3, seed=0)
    floats = [Demonstration(d.observations, d.actions.astype(float)) for d in demos]
    with pytest.warns(UserWarning, match=r"demos \[0, 1, 2\] have float actions.*\[:, None\]"):
        fit_task(floats, reward="maxent", random_state=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit_task(demos, reward="maxent", random_state=0)
    assert not [w for w in caught if "float actions" in str(w.message)]


def test_the_fit_does_not_depend_on_torchs_threads_and_leaves_them_as_they_were():
    """Torch's sums depend on its thread count: with 2 threads and with 1 these demos' Psi
    differed by up to 4.4 before the fit ran on one thread (machines differ in cores)."""
    import torch as th

    demos = collect_demos(PARKING, 5, seed=0)
    kwargs = {"reg_covar": 0.1, "normalize_time": False, "random_state": 0}
    before, weights = th.get_num_threads(), []
    try:
        for threads in (2, 1):
            th.set_num_threads(threads)
            task = fit_task(demos, reward="maxent", **kwargs)
            assert th.get_num_threads() == threads
            weights.append(np.concatenate([r.weight.ravel() for r in task.rewards]))
    finally:
        th.set_num_threads(before)
    np.testing.assert_array_equal(weights[0], weights[1])
