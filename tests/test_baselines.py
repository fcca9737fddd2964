"""The comparison methods (sb3_swirl.baselines): one interface, one result format."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from sb3_swirl.baselines import GOAL_ENV_METHODS, METHODS, BCPolicy, run_method
from sb3_swirl.demos import Demonstration
from sb3_swirl.experiments import PRESETS
from sb3_swirl.supervisors import collect_demos

PRESET = dataclasses.replace(PRESETS["parking"], eval_freq=250, n_eval_episodes=2)
FIELDS = {
    "algo",
    "method",
    "curve",
    "final_success",
    "best_success",
    "rollouts_to_target",
    "wall_time_s",
}


@pytest.fixture(scope="module")
def demos():
    return collect_demos(PRESET.env_id, 5, seed=0)


# HER needs a goal env: tests/test_fetch.py runs those methods on the Fetch tasks
@pytest.mark.parametrize("method", sorted(set(METHODS) - set(GOAL_ENV_METHODS)))
def test_every_method_runs_on_a_tiny_budget_with_the_shared_fields(method, demos):
    steps = 1024 if method == "gail" else 500
    result = run_method(method, PRESET, demos, seed=0, total_timesteps=steps)
    assert FIELDS <= set(result) and result["method"] == method
    point = result["curve"][-1]
    assert set(point) == {"timesteps", "episodes", "success_rate", "task_return"}
    assert 0.0 <= result["final_success"] <= result["best_success"] <= 1.0
    if method.startswith("bc_"):
        assert point["timesteps"] == 0  # cloning uses no env steps
        assert result["final_success"] > 0  # a clone of 5 parking demos parks at times
    else:
        assert point["timesteps"] >= 500


def test_linear_svm_clones_the_parking_supervisor(demos):
    """The paper's parking BC baseline (hinge loss, L2 alpha 5e-3) fits the demos well."""
    x = np.concatenate([d.observations[:-1] for d in demos])
    y = np.concatenate([d.actions for d in demos])
    with pytest.raises(NotFittedError, match="BCPolicy instance is not fitted yet"):
        BCPolicy("linear_svm").predict(x)
    policy = BCPolicy("linear_svm", random_state=0).fit(x, y)
    assert np.mean(policy.predict(x)[0] == y) >= 0.9
    assert policy.predict(x[3])[0] == policy.predict(x)[0][3]  # one observation, one action
    with pytest.raises(ValueError, match=r"shape \(4,\) or \(n, 4\) .*, got \(2, 5, 4\)"):
        policy.predict(np.stack([x[:5], x[5:10]]))  # never a silent first action of a stack
    with pytest.raises(ValueError, match=r"shape \(4,\) or \(n, 4\) .*, got \(5, 3\)"):
        policy.predict(x[:5, :3])  # not sklearn's StandardScaler message
    for bad_x, bad_y, said in (
        (np.where(np.arange(len(x))[:, None] == 7, np.nan, x), y, "NaN or inf .*row 7"),
        (x, y + 0.5, "integers of a Discrete action space"),
        (x, np.zeros_like(y), "one action only"),
        (x[:0], y[:0], "got no observations"),
    ):
        with pytest.raises(ValueError, match=said):
            BCPolicy("svm", random_state=0).fit(bad_x, bad_y)
    # settings sklearn checked only at fit, naming MLPClassifier; a NaN or a Dict without the
    # key reached sklearn's and a bare KeyError
    for kwargs, said in (
        ({"hidden_layer_sizes": "64"}, "hidden_layer_sizes must be a list of layer widths"),
        ({"max_iter": 0}, "max_iter must be an integer >= 1"),
        ({"random_state": "a"}, r"random_state must be an integer in \[0, 4294967295\]"),
    ):
        with pytest.raises(ValueError, match=said):
            BCPolicy(**kwargs)
    with pytest.raises(ValueError, match="observation contains NaN or inf"):
        policy.predict(np.full(4, np.nan))
    with pytest.raises(ValueError, match=r"has no \['observation'\] \(keys: \['pos'\]\)"):
        policy.predict({"pos": x[0]})


def test_methods_that_need_actions_say_so(demos):
    state_only = [Demonstration(d.observations) for d in demos]
    with pytest.raises(ValueError, match=r"demo 0 has no actions: method 'bc_linear_svm'"):
        run_method("bc_linear_svm", PRESET, state_only, seed=0, total_timesteps=100)
    with pytest.raises(ValueError, match="unknown method 'svm'"):
        run_method("svm", PRESET, demos, seed=0, total_timesteps=100)
    with pytest.raises(ValueError, match="HER needs a goal env with Dict observations"):
        run_method("dqn_her", PRESET, [], seed=0, total_timesteps=100)
    with pytest.raises(ValueError, match="HER needs a goal env with Dict observations"):
        run_method("swirl_her", PRESET, demos, seed=0, total_timesteps=100)
    with pytest.raises(ValueError, match="gail needs total_timesteps >= 1024"):
        run_method("gail", PRESET, demos, seed=0, total_timesteps=100)
