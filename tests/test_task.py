"""TaskModel: the proxy task's maths, validation and JSON format."""

from __future__ import annotations

import json
import pickle
import types

import numpy as np
import pytest

from swirl_wrappers import (
    SCHEMA_VERSION,
    QuadraticReward,
    RBFFeatures,
    Region,
    RewardConfig,
    TaskModel,
)
from swirl_wrappers.task import angle_features


def random_task(
    seed: int, k: int = 3, p: int = 4, dims=None, timed: bool = False, features=None
) -> TaskModel:
    rng = np.random.default_rng(seed)
    regions, rewards = [], []
    for i in range(k):
        a = rng.normal(size=(p, p))
        b = rng.normal(size=(p, p - 1))  # rank-deficient: Psi only positive semi-definite
        bounds = (2.0 * i, 2.0 * i + 20.0) if timed else None
        regions.append(Region(rng.normal(size=p), a @ a.T + 0.1 * np.eye(p), 3.0, bounds))
        rewards.append(QuadraticReward(rng.normal(size=p), b @ b.T))
    return TaskModel(regions, rewards, dims=dims, features=features, metadata={"seed": seed})


def reference(task: TaskModel, x: np.ndarray, t, index: np.ndarray):
    """Rewards and next indices straight from the definitions, one state at a time."""
    z = task.featurize(x)
    rewards, nxt = [], []
    for zi, ti, i in zip(z, t, index, strict=True):
        w = task.rewards[min(i, task.n_segments - 1)]
        d = zi - w.target
        rewards.append(-d @ w.weight @ d)
        inside = i < task.n_segments and bool(task.regions[i].contains(zi, ti))
        nxt.append(i + 1 if inside else i)
    return np.array(rewards), np.array(nxt)


def rbf_task(seed: int = 0) -> TaskModel:
    rng = np.random.default_rng(seed)
    features = RBFFeatures(
        landmarks=rng.normal(size=(6, 3)),
        gamma=0.7,
        projection=rng.normal(size=(6, 2)),
        offset=rng.normal(size=2),
    )
    return random_task(seed, k=2, p=2, dims=(4, 0, 2), features=features)


TASKS = {
    "plain": lambda: random_task(0),
    "dims": lambda: random_task(1, dims=(5, 1, 0, 3)),
    "timed": lambda: random_task(2, timed=True),
    "rbf": lambda: rbf_task(3),
}


def random_batch(task: TaskModel, seed: int, n: int = 400):
    rng = np.random.default_rng(seed)
    if task.dims is not None:
        obs_dim = max(task.dims) + 2  # the task reads only some of the observation
    elif task.features is not None:
        obs_dim = task.features.input_dim
    else:
        obs_dim = task.task_dim
    x = rng.normal(size=(n, obs_dim))
    if task.features is None:
        # Put a third of the states near a region centre so both branches of M are exercised.
        centres = np.array([r.mean for r in task.regions])
        pick = rng.integers(0, task.n_segments, n // 3)
        near = centres[pick] + 0.05 * rng.normal(size=(n // 3, task.task_dim))
        cols = list(task.dims) if task.dims is not None else list(range(task.task_dim))
        x[: n // 3, cols] = near
        index = rng.integers(0, task.n_indices, n)
        index[: n // 3] = pick
    else:
        index = rng.integers(0, task.n_indices, n)
    t = rng.integers(0, 30, n)
    return x, t, index


@pytest.mark.parametrize("name", sorted(TASKS))
def test_batch_single_and_reference_agree(name):
    task = TASKS[name]()
    x, t, index = random_batch(task, seed=10)
    want_r, want_i = reference(task, x, t, index)
    assert 0 < (want_i > index).sum() or task.features is not None
    r = task.reward(x, index)
    i = task.next_segment(x, t, index)
    np.testing.assert_allclose(r, want_r, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(i, want_i)
    rb, inside = task.evaluate(task.featurize(x), t, index)
    np.testing.assert_array_equal(rb, r)
    np.testing.assert_array_equal(index + inside, i)
    for row in range(0, len(x), 7):
        # One state: Python numbers, bit for bit the batch's (the wrappers rely on it).
        r1, in1 = task.evaluate(task.featurize(x[row]), int(t[row]), int(index[row]))
        assert type(r1) is float and type(in1) is bool
        assert r1 == rb[row] and in1 == inside[row]
        assert task.reward(x[row], index[row]) == r1
        assert int(task.next_segment(x[row], t[row], index[row])) == want_i[row]


def test_a_state_gets_the_same_values_in_every_batch():
    """Per row the same BLAS calls: values do not depend on the batch a state is in."""
    task = random_task(0)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(64, 4)) * rng.uniform(0.01, 100.0, size=(64, 1))
    index = rng.integers(0, task.n_indices, 64)
    reward, inside = task.evaluate(x, 3, index)
    for size in (1, 2, 7, 33):
        for start in range(0, 64 - size + 1, size):
            rows = slice(start, start + size)
            r, i = task.evaluate(x[rows].copy(), 3, index[rows].copy())
            np.testing.assert_array_equal(r, reward[rows])
            np.testing.assert_array_equal(i, inside[rows])


def test_membership_is_exact_at_the_boundary():
    # A 1-D region of radius 0.5: the folded maths must keep the inclusive edge.
    task = TaskModel([Region([1.0], [[0.25]], 1.0)], [QuadraticReward([1.0], [[1.0]])])
    assert task.evaluate(np.array([1.5]), 0, 0)[1] is True
    assert task.evaluate(np.array([1.5001]), 0, 0)[1] is False
    assert task.next_segment(np.array([[0.5], [0.4999]]), None, [0, 0]).tolist() == [1, 0]


def test_time_bounds_gate_the_region():
    task = TaskModel(
        [Region([0.0], [[1.0]], 1.0, time_bounds=(5, 10))], [QuadraticReward([0.0], [[1.0]])]
    )
    x = np.zeros((4, 1))
    assert task.next_segment(x, [4, 5, 10, 11], 0).tolist() == [0, 1, 1, 0]
    assert task.next_segment(x, None, 0).tolist() == [1, 1, 1, 1]
    assert task.segment_indices(np.zeros((8, 1))).tolist() == [0, 0, 0, 0, 0, 1, 1, 1]


def test_reward_after_completion_is_last_segments():
    task = random_task(4, k=2, p=2)
    x = np.random.default_rng(0).normal(size=(5, 2))
    np.testing.assert_array_equal(task.reward(x, 2), task.reward(x, 1))
    np.testing.assert_array_equal(task.next_segment(x, 0, 2), [2] * 5)


@pytest.mark.parametrize("name", sorted(TASKS))
def test_segment_indices_matches_stepping(name):
    task = TASKS[name]()
    x, _, _ = random_batch(task, seed=5, n=60)
    rng = np.random.default_rng(1)
    # A trajectory that visits the regions in order, with noise states in between.
    if task.features is None:
        cols = list(task.dims) if task.dims is not None else list(range(task.task_dim))
        for j, region in enumerate(task.regions):
            x[10 + 15 * j, cols] = region.mean + 1e-3 * rng.normal(size=task.task_dim)
    got = task.segment_indices(x)
    i, want = 0, []
    for t, state in enumerate(x):
        i = int(task.next_segment(state, t, i))
        want.append(i)
    np.testing.assert_array_equal(got, want)
    assert np.all(np.diff(got) >= 0)
    held = types.SimpleNamespace(observations=x)  # a demo object (Demonstration, Minari's)
    np.testing.assert_array_equal(task.segment_indices(held), got)
    if task.features is None and task.regions[0].time_bounds is None:
        assert got[-1] == task.n_segments


@pytest.mark.parametrize("name", sorted(TASKS))
def test_json_round_trip_is_exact(name, tmp_path):
    task = TASKS[name]()
    text = task.to_json(tmp_path / "task.json")
    for loaded in (TaskModel.from_json(text), TaskModel.from_json(tmp_path / "task.json")):
        assert loaded.to_dict() == task.to_dict()
        x, t, index = random_batch(task, seed=7)
        np.testing.assert_array_equal(loaded.reward(x, index), task.reward(x, index))
        np.testing.assert_array_equal(
            loaded.next_segment(x, t, index), task.next_segment(x, t, index)
        )
    assert json.loads(text)["schema_version"] == SCHEMA_VERSION
    assert loaded.metadata == task.metadata
    assert TaskModel.from_json(text.encode()).to_dict() == task.to_dict()  # read as bytes


def test_pickle_round_trip():
    task = rbf_task()
    loaded = pickle.loads(pickle.dumps(task))
    x, t, index = random_batch(task, seed=2)
    np.testing.assert_array_equal(loaded.reward(x, index), task.reward(x, index))
    np.testing.assert_array_equal(loaded.next_segment(x, t, index), task.next_segment(x, t, index))


def test_rbf_features_are_the_documented_map():
    task = rbf_task()
    f = task.features
    s = np.random.default_rng(3).normal(size=(10, 6))
    sel = s[:, [4, 0, 2]]
    sq = ((sel[:, None, :] - f.landmarks[None]) ** 2).sum(-1)
    want = np.exp(-f.gamma * sq) @ f.projection - f.offset
    np.testing.assert_allclose(task.featurize(s), want, rtol=1e-12)
    np.testing.assert_allclose(task.featurize(s[0]), want[0], rtol=1e-12)


def _corrupt(text: str) -> str:
    return text.replace('"regions"', '"regions" [', 1)


@pytest.mark.parametrize(
    ("make_text", "message"),
    [
        (_corrupt, "not valid JSON"),
        (lambda text: text[: len(text) // 2], "not valid JSON"),
        (lambda text: "[1, 2]", "must be a JSON object"),
        (
            lambda text: text.replace(
                f'"schema_version": {SCHEMA_VERSION}', '"schema_version": 99'
            ),
            "version 99",
        ),
        (lambda text: text.replace('"swirl_task"', '"other"'), "'other'"),
        (lambda text: json.dumps({**json.loads(text), "metadata": []}), "metadata must be a dict"),
    ],
)
def test_bad_json_is_a_clear_value_error(make_text, message, tmp_path):
    text = random_task(0).to_json()
    with pytest.raises(ValueError, match=message):
        TaskModel.from_json(make_text(text))
    path = tmp_path / "task.json"
    path.write_text(make_text(text))
    with pytest.raises(ValueError, match=message) as info:  # from a file: named
        TaskModel.from_json(path)
    assert str(path) in str(info.value)


def test_metadata_that_json_cannot_write_is_refused_at_construction():
    task = random_task(0)
    with pytest.raises(ValueError, match=r"metadata must be JSON-serialisable: .*float32"):
        TaskModel(task.regions, task.rewards, metadata={"x": np.float32(1.0)})
    with pytest.raises(ValueError, match=r"metadata must be JSON-serialisable: .*float values"):
        TaskModel(task.regions, task.rewards, metadata={"score": float("nan")})  # no JSON
    with pytest.raises(ValueError, match="metadata must be a dict, got str"):
        TaskModel(task.regions, task.rewards, metadata="fitted by hand")


def test_binary_file_is_a_value_error_naming_it(tmp_path):
    path = tmp_path / "plot.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    with pytest.raises(ValueError, match=r"task model file .*plot\.png: it is a binary file"):
        TaskModel.from_json(path)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("regions"), "task model is missing 'regions'"),
        (lambda d: d.pop("rewards"), "task model is missing 'rewards'"),
        (lambda d: d["regions"][0].pop("covariance"), r"regions\[0\]: .*missing 'covariance'"),
        (lambda d: d["rewards"][1].pop("target"), r"rewards\[1\]: .*missing 'target'"),
        (lambda d: d.update(regions=5), "regions must be a list"),
        (lambda d: d["regions"][0].update(threshold="big"), r"regions\[0\]: .*threshold must"),
        # Not numbers that float() would take: a hand-edited file names the key.
        (lambda d: d["regions"][1].update(threshold=True), r"regions\[1\]: .*threshold .*True"),
        (lambda d: d["regions"][0].update(time_bounds=[0, False]), "time_bounds"),
        (lambda d: d.update(dims=[True, 1, 2, 3]), "dims must be a sequence of ints"),
        # Python ints beyond int64 or float: numpy and float() overflowed (OverflowError)
        (lambda d: d.update(dims=[0, 1, 2, 10**30]), r"dims holds the index 10{30}, beyond"),
        (lambda d: d["regions"][0].update(threshold=10**400), "threshold must be a finite"),
        (lambda d: d.update(treshold=3), "unknown key.*'treshold'"),
        (lambda d: d["regions"][0].update(radius=3), r"regions\[0\]: .*unknown key.*'radius'"),
        (lambda d: d["reward_config"].update(bonus=1), "reward_config: .*unknown key.*'bonus'"),
        (lambda d: d["reward_config"].update(scale=-1), "reward_config: .*scale"),
        (lambda d: d["reward_config"].update(mode="linear"), "reward_config: .*mode"),
        # Finite but absurd: the quadratic forms would overflow, so no silent segmentation.
        (lambda d: d["regions"][0].update(threshold=1e150), "threshold"),
        (lambda d: d["regions"][0]["mean"].__setitem__(0, 1e150), r"Region\.mean .*1e\+150"),
        (lambda d: d["rewards"][0]["weight"][0].__setitem__(0, -1e150), r"weight .*1e\+150"),
        (lambda d: d["regions"][0].update(covariance=(np.eye(4) * 1e-250).tolist()), "singular"),
        (lambda d: d["regions"][0].update(mean=[1.0, None, 0.0, 0.0]), "mean"),
        (lambda d: d["regions"][0].update(mean=[True] * 4), "mean must be real"),
        (lambda d: d["rewards"][0].update(target=["1.5", 0, 0, 0]), "target must be real"),
        (lambda d: d["rewards"].pop(), "one reward per region"),
        (lambda d: d.update(dims=[0, 1]), "dims selects 2 values"),
        (lambda d: d.update(dims=[0, 2, 0, 1]), r"dims lists \[0\] more than once"),
        (lambda d: d["regions"][1]["mean"].pop(), r"shape \(3, 3\) to match Region\.mean \(3"),
        (lambda d: d.update(features={"type": "poly"}), "unknown feature map type"),
    ],
)
def test_bad_fields_are_clear_value_errors(edit, message):
    data = random_task(0).to_dict()
    edit(data)
    with pytest.raises(ValueError, match=message):
        TaskModel.from_json(json.dumps(data))


def test_json_nested_too_deeply_is_a_value_error():
    """json and the fields' checks recursed until Python's RecursionError."""
    text = random_task(0).to_json().replace('"features": null', '"features": ' + "[" * 10**4)
    with pytest.raises(ValueError, match="nests its JSON too deeply to be a task model"):
        TaskModel.from_json(text)


def test_paths_that_look_like_json_are_read_as_files(tmp_path, monkeypatch):
    task = TASKS[sorted(TASKS)[0]]()
    (tmp_path / "[run 1]").mkdir()
    task.to_json(tmp_path / "[run 1]" / "task.json")
    monkeypatch.chdir(tmp_path)
    for source in ("[run 1]/task.json", tmp_path / "[run 1]" / "task.json"):
        assert TaskModel.from_json(source).to_dict() == task.to_dict()
    with pytest.raises(ValueError, match="cannot read task model file"):
        TaskModel.from_json(tmp_path / "{absent}.json")


def test_a_task_saved_with_a_byte_order_mark_reads(tmp_path):
    """An editor (Notepad) may save the JSON with a UTF-8 byte-order mark: file and text read."""
    task = TASKS[sorted(TASKS)[0]]()
    (tmp_path / "task.json").write_text(task.to_json(), encoding="utf-8-sig")
    assert TaskModel.from_json(tmp_path / "task.json").to_dict() == task.to_dict()
    assert TaskModel.from_json("\ufeff" + task.to_json()).to_dict() == task.to_dict()
    # bytes too, as a file read in binary mode gives them (with the mark, or without UTF-8)
    assert TaskModel.from_json(task.to_json().encode("utf-8-sig")).to_dict() == task.to_dict()
    with pytest.raises(ValueError, match="bytes that are not UTF-8 text"):  # UnicodeDecodeError
        TaskModel.from_json(b"\xff\xfe")


def test_missing_file_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read task model file"):
        TaskModel.from_json(tmp_path / "absent.json")
    for source in (None, 5, {"regions": []}):
        with pytest.raises(ValueError, match="JSON text or the path of a JSON file, got"):
            TaskModel.from_json(source)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"covariance": [[1.0, 2.0], [2.0, 1.0]]}, "positive definite"),
        ({"covariance": [[1.0, 0.5], [0.0, 1.0]]}, "symmetric"),
        ({"covariance": [[np.nan, 0.0], [0.0, 1.0]]}, "NaN or inf"),
        ({"mean": [np.nan, 0.0]}, "NaN or inf"),
        ({"mean": [0.0, 0.0, 0.0]}, r"shape \(3, 3\) to match Region\.mean \(3 entries\)"),
        ({"threshold": -1.0}, "threshold"),
        ({"threshold": np.inf}, "threshold"),
        ({"time_bounds": (5, 1)}, "time_bounds"),
        ({"time_bounds": (1,)}, "time_bounds"),
    ],
)
def test_invalid_region(kwargs, message):
    args = {"mean": [0.0, 0.0], "covariance": np.eye(2), "threshold": 1.0} | kwargs
    with pytest.raises(ValueError, match=message):
        Region(**args)


@pytest.mark.parametrize(
    ("weight", "message"),
    [
        ([[1.0, 0.0], [0.0, -1.0]], "semi-definite"),
        ([[1.0, 1.0], [0.0, 1.0]], "symmetric"),
        ([[np.inf, 0.0], [0.0, 1.0]], "NaN or inf"),
    ],
)
def test_invalid_reward(weight, message):
    with pytest.raises(ValueError, match=message):
        QuadraticReward([0.0, 0.0], weight)


def test_invalid_task_and_calls():
    region, reward = Region([0.0, 0.0], np.eye(2), 1.0), QuadraticReward([0.0, 0.0], np.eye(2))
    with pytest.raises(ValueError, match="at least one region"):
        TaskModel([], [])
    with pytest.raises(ValueError, match="expected Region"):
        TaskModel([reward], [reward])
    with pytest.raises(ValueError, match="non-negative"):
        TaskModel([region], [reward], dims=(0, -1))
    with pytest.raises(ValueError, match="expected RBFFeatures"):
        TaskModel([region], [reward], features="rbf")
    task = TaskModel([region], [reward], dims=(3, 1))
    with pytest.raises(ValueError, match="uses index 3"):
        task.reward(np.zeros(3), 0)
    with pytest.raises(ValueError, match=r"segment index must lie in \[0, 1\]"):
        task.next_segment(np.zeros(4), 0, 2)
    with pytest.raises(ValueError, match="integer"):
        task.reward(np.zeros(4), 0.5)
    with pytest.raises(ValueError, match="shape"):
        task.segment_indices(np.zeros(4))


# ---------------------------------------------------------------------------- angle features
def angle_task(seed: int = 0, features: RBFFeatures | None = None) -> TaskModel:
    """Absolute link angles of a 2-link chain (obs[1], obs[1] + obs[3]) plus obs[0] and obs[4]."""
    rng = np.random.default_rng(seed)
    angles, dims = ((1,), (1, 3)), (4, 0)
    p = 2 * len(angles) + len(dims) if features is None else features.output_dim
    regions, rewards = [], []
    for _ in range(3):
        a = rng.normal(size=(p, p))
        regions.append(Region(rng.normal(size=p), a @ a.T + 0.5 * np.eye(p), 4.0))
        rewards.append(QuadraticReward(rng.normal(size=p), a.T @ a))
    return TaskModel(regions, rewards, dims=dims, features=features, angles=angles)


def angle_rbf_task(seed: int = 1) -> TaskModel:
    rng = np.random.default_rng(seed)
    features = RBFFeatures(rng.normal(size=(5, 6)), 0.3, rng.normal(size=(5, 3)))
    return angle_task(seed, features=features)


ANGLE_TASKS = {"angles": angle_task, "angles+rbf": angle_rbf_task}


def _angle_batch(seed: int, n: int = 300):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-4.0, 4.0, size=(n, 6))
    return x, rng.integers(0, 30, n), rng.integers(0, 4, n)


def test_angle_features_are_the_documented_map():
    task = angle_task()
    x = np.random.default_rng(0).uniform(-4, 4, size=(20, 5))
    a1, a2 = x[:, 1], x[:, 1] + x[:, 3]
    want = np.column_stack([np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2), x[:, 4], x[:, 0]])
    np.testing.assert_allclose(task.featurize(x), want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(task.featurize(x[3]), want[3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(angle_features(x, task.angles), want[:, :4], rtol=0, atol=1e-12)
    rbf = angle_rbf_task()
    np.testing.assert_allclose(rbf.featurize(x), rbf.features(want), atol=1e-12)


@pytest.mark.parametrize("name", sorted(ANGLE_TASKS))
def test_angle_task_batch_single_and_reference_agree(name):
    task = ANGLE_TASKS[name]()
    x, t, index = _angle_batch(1)
    want_r, want_i = reference(task, x, t, index)
    r, inside = task.evaluate(task.featurize(x), t, index)
    np.testing.assert_allclose(r, want_r, rtol=1e-10, atol=1e-10)
    np.testing.assert_array_equal(index + inside, want_i)
    for k in range(0, len(x), 37):
        rk, ik = task.evaluate(task.featurize(x[k]), int(t[k]), int(index[k]))
        assert rk == r[k] and ik == inside[k]


def test_angle_task_is_continuous_across_the_wrap():
    task = angle_task()
    x, _, index = _angle_batch(2)
    shifted = x.copy()
    shifted[:, 1] += 2 * np.pi
    shifted[:, 3] -= 4 * np.pi
    np.testing.assert_allclose(task.reward(shifted, index), task.reward(x, index), atol=1e-9)
    # Just below +pi and just above -pi are neighbours: nearly equal rewards.
    below, above = np.zeros(6), np.zeros(6)
    below[1], above[1] = np.pi - 1e-6, -np.pi + 1e-6
    assert task.reward(below, 0) == pytest.approx(task.reward(above, 0), abs=1e-4)


def test_angle_task_segment_indices_match_stepping():
    task = angle_task(3)
    rng = np.random.default_rng(3)
    x = rng.uniform(-4, 4, size=(200, 6))
    # Visit every region in order, through a state whose angle features hit its centre.
    for j, region in enumerate(task.regions):
        s = x[20 + 50 * j]
        c1, s1, c2, s2, d4, d0 = region.mean
        s[1] = np.arctan2(s1, c1)
        s[3] = np.arctan2(s2, c2) - s[1]
        s[4], s[0] = d4, d0
    index = task.segment_indices(x)
    assert index[-1] == task.n_segments
    i = 0
    for k, s in enumerate(x):
        i = int(task.next_segment(s, k, i))
        assert i == index[k]


@pytest.mark.parametrize("name", sorted(ANGLE_TASKS))
def test_angle_task_json_round_trip(name):
    task = ANGLE_TASKS[name]()
    loaded = TaskModel.from_json(task.to_json())
    assert loaded.angles == ((1,), (1, 3)) and loaded.to_dict() == task.to_dict()
    x, t, index = _angle_batch(4)
    np.testing.assert_array_equal(loaded.reward(x, index), task.reward(x, index))
    np.testing.assert_array_equal(loaded.next_segment(x, t, index), task.next_segment(x, t, index))


def test_task_json_without_angles_still_loads():
    data = random_task(0).to_dict()
    assert data.pop("angles") is None  # files written before the field existed lack it
    loaded = TaskModel.from_json(json.dumps(data))
    assert loaded.angles is None and loaded.to_dict() == random_task(0).to_dict()


def test_version_1_files_load_with_the_default_reward_settings():
    data = random_task(0).to_dict()
    del data["reward_config"]
    data["schema_version"] = 1
    loaded = TaskModel.from_json(json.dumps(data))
    assert loaded.reward_config == RewardConfig()
    assert loaded.to_dict()["schema_version"] == SCHEMA_VERSION == 2
    data["reward_config"] = RewardConfig().to_dict()  # a key version 1 did not know
    with pytest.raises(ValueError, match=r"unknown key.*'reward_config'"):
        TaskModel.from_json(json.dumps(data))


def test_reward_config_round_trips_with_the_task(tmp_path):
    base = random_task(0)
    config = RewardConfig(mode="potential", scale=0.5, task_reward_weight=10.0, gamma=0.9)
    task = TaskModel(base.regions, base.rewards, reward_config=config)
    assert TaskModel.from_json(task.to_json(tmp_path / "t.json")).reward_config == config
    as_dict = TaskModel(base.regions, base.rewards, reward_config={"region_bonus": 2})
    assert as_dict.reward_config == RewardConfig(region_bonus=2.0)


def test_a_wrappers_reward_config_dict_changes_only_the_fields_it_names():
    from swirl_wrappers import SegmentTracker

    base = random_task(0)
    shaped = RewardConfig(mode="potential", region_bonus=1.0, task_reward_weight=10.0)
    task = TaskModel(base.regions, base.rewards, reward_config=shaped)
    assert SegmentTracker(task).config == shaped
    assert SegmentTracker(task, {"gamma": 0.9}).config == RewardConfig(
        mode="potential", region_bonus=1.0, task_reward_weight=10.0, gamma=0.9
    )
    # a new mode takes its own default weight unless the dict names one
    assert SegmentTracker(task, {"mode": "quadratic"}).config.task_reward_weight == 0.0
    assert SegmentTracker(task, {"mode": "quadratic", "task_reward_weight": 2}).config == (
        RewardConfig(region_bonus=1.0, task_reward_weight=2.0)
    )
    assert SegmentTracker(task, RewardConfig()).config == RewardConfig()  # replaced whole
    with pytest.raises(ValueError, match=r"unknown key.*'reward_scale'"):
        SegmentTracker(task, {"reward_scale": 2.0})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"mode": "exp"}, "reward_config mode must be one of"),
        ({"mode": "potential", "task_reward_weight": 0.0}, "task_reward_weight > 0"),
        ({"gamma": 1.5}, r"gamma must be a finite number in \[0, 1\]"),
        ({"scale": np.nan}, "reward scale"),
        ({"scale": True}, "reward scale"),
        ({"region_bonus": "1"}, "region_bonus"),
        ({"region_bonus": -2}, r"region_bonus .*>= 0"),
        ({"task_reward_weight": "a lot"}, "task_reward_weight"),
    ],
)
def test_invalid_reward_config(kwargs, message):
    with pytest.raises(ValueError, match=message):
        RewardConfig(**kwargs)


def test_reward_config_defaults_the_env_reward_weight_by_mode():
    assert RewardConfig().task_reward_weight == 0.0
    assert RewardConfig(mode="potential").task_reward_weight == 1.0
    with pytest.raises(ValueError, match=r"unknown key.*'reward_scale'"):
        RewardConfig.from_dict({"reward_scale": 2.0})
    with pytest.raises(ValueError, match="RewardConfig or a dict"):
        RewardConfig.coerce("potential")


def test_invalid_angles():
    p = 6
    region, reward = Region(np.zeros(p), np.eye(p), 1.0), QuadraticReward(np.zeros(p), np.eye(p))
    with pytest.raises(ValueError, match="dims must be given with angles"):
        TaskModel([region], [reward], angles=[[0], [0, 1]])
    for bad in ([], [[]], [[0, -1]], [["a"]], 3):
        with pytest.raises(ValueError, match=r"TaskModel\.angles"):
            TaskModel([region], [reward], dims=(2, 3), angles=bad)
    with pytest.raises(ValueError, match="dims and angles give 5 values"):
        TaskModel([region], [reward], dims=(2,), angles=[[0], [0, 1]])
    task = TaskModel([region], [reward], dims=(2, 3), angles=[[0], [0, 5]])
    with pytest.raises(ValueError, match="uses index 5"):
        task.reward(np.zeros(5), 0)
    only_angles = TaskModel(
        [Region(np.zeros(2), np.eye(2), 1.0)],
        [QuadraticReward(np.zeros(2), np.eye(2))],
        dims=(),
        angles=[[0]],
    )
    assert only_angles.featurize(np.array([np.pi, 7.0])) == pytest.approx([-1.0, 0.0], abs=1e-12)
    with pytest.raises(ValueError, match="angles use index 2"):
        angle_features(np.zeros(2), [[2]])


def test_checked_calls_refuse_nan_and_take_one_trajectory_in_any_holder():
    task = random_task(4, k=2, p=2)
    x = np.random.default_rng(0).normal(size=(6, 2))
    bad = x.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf at step 3"):
        task.segment_indices(bad)
    with pytest.raises(ValueError, match="obs holds NaN or inf"):
        task.reward(bad[3], 0)
    with pytest.raises(ValueError, match="obs holds NaN or inf"):
        task.next_segment(np.full(2, np.inf), 0, 0)
    want = task.segment_indices(x)
    # an imitation Trajectory holds them as .obs
    np.testing.assert_array_equal(task.segment_indices(types.SimpleNamespace(obs=x)), want)
    with pytest.raises(ValueError, match=r"one trajectory of shape .* for many, segment each"):
        task.segment_indices([x, x[:4]])
