"""Demonstration conversion, validation and (de)serialisation."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from sb3_swirl.demos import (
    Demonstration,
    as_demonstrations,
    load_demos,
    make_piecewise_linear_demos,
    save_demos,
    to_imitation,
    to_minari,
)


def _arrays(n=3, lengths=(10, 12, 15), d=2, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.normal(size=(lengths[i % len(lengths)], d)) for i in range(n)]


def test_arrays_become_float64_demonstrations_with_ragged_lengths():
    arrays = [a.astype(np.float32) for a in _arrays()]
    demos = as_demonstrations(arrays)
    assert [len(d) for d in demos] == [9, 11, 14]
    for demo, arr in zip(demos, arrays, strict=True):
        assert demo.observations.dtype == np.float64
        np.testing.assert_array_equal(demo.observations, arr.astype(np.float64))
        assert demo.actions is None and demo.rewards is None


def test_three_d_array_is_split_into_demonstrations():
    data = np.arange(2 * 5 * 3, dtype=float).reshape(2, 5, 3)
    demos = as_demonstrations(data)
    assert len(demos) == 2
    np.testing.assert_array_equal(demos[1].observations, data[1])


def test_imitation_style_and_minari_style_objects_are_read_by_their_fields():
    obs = _arrays()
    traj = [
        SimpleNamespace(
            obs=o, acts=np.arange(len(o) - 1), rews=np.ones(len(o) - 1), infos=None, terminal=True
        )
        for o in obs
    ]
    episodes = [
        SimpleNamespace(
            observations=o, actions=np.zeros((len(o) - 1, 2)), rewards=np.zeros(len(o) - 1)
        )
        for o in obs
    ]
    mappings = [{"observations": o, "actions": np.arange(len(o) - 1)} for o in obs]
    for source in (traj, episodes, mappings):
        demos = as_demonstrations(source)
        assert [len(d) for d in demos] == [len(o) - 1 for o in obs]
        assert demos[0].actions is not None
    assert as_demonstrations(traj)[0].actions.dtype.kind == "i"  # discrete actions keep dtype
    np.testing.assert_array_equal(as_demonstrations(traj)[2].rewards, np.ones(14))


def test_real_imitation_trajectories_round_trip():
    from imitation.data.types import Trajectory, TrajectoryWithRew

    rng = np.random.default_rng(1)
    demos = [
        Demonstration(rng.normal(size=(n + 1, 3)), rng.integers(0, 4, size=n), rng.normal(size=n))
        for n in (6, 9)
    ]
    demos[1] = Demonstration(demos[1].observations, demos[1].actions, truncated=True)
    trajs = to_imitation(demos)
    assert isinstance(trajs[0], TrajectoryWithRew) and type(trajs[1]) is Trajectory
    assert [t.terminal for t in trajs] == [True, False]  # a truncated demo: not terminal
    back = as_demonstrations(trajs)
    assert [d.truncated for d in back] == [False, True]
    for a, b in zip(demos, back, strict=True):
        np.testing.assert_array_equal(a.observations, b.observations)
        np.testing.assert_array_equal(a.actions, b.actions)
        assert (a.rewards is None) == (b.rewards is None)
        if a.rewards is not None:
            np.testing.assert_array_equal(a.rewards, b.rewards)
    no_rew = to_imitation([Demonstration(d.observations, d.actions) for d in demos])
    assert type(no_rew[0]) is Trajectory
    with pytest.raises(ValueError, match="demo 1 has no actions"):
        to_imitation([demos[0], Demonstration(demos[1].observations)])


def test_npz_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(2)
    demos = [
        Demonstration(rng.normal(size=(8, 2))),
        Demonstration(rng.normal(size=(5, 2)), np.array([0, 3, 1, 2], dtype=np.int64)),
        Demonstration(rng.normal(size=(4, 2)), rng.normal(size=3), rng.normal(size=3)),
        Demonstration(rng.normal(size=(4, 2)), state_key=("observation", "desired_goal")),
        Demonstration(rng.normal(size=(3, 2)), truncated=True),
    ]
    path = tmp_path / "demos.npz"
    with pytest.raises(TypeError, match="demos first"):
        save_demos(path, demos)
    save_demos(demos, path)
    for loaded in (load_demos(path), as_demonstrations(path), as_demonstrations(str(path))):
        assert len(loaded) == 5
        for a, b in zip(demos, loaded, strict=True):
            assert a.state_key == b.state_key and a.truncated is b.truncated
            np.testing.assert_array_equal(a.observations, b.observations)
            for x, y in ((a.actions, b.actions), (a.rewards, b.rewards)):
                assert (x is None) == (y is None)
                if x is not None:
                    assert x.dtype == y.dtype
                    np.testing.assert_array_equal(x, y)


def test_truncation_is_read_from_each_format_and_checked():
    """imitation's terminal=False and Minari's last step not a termination read as truncated;
    a flag that is not one bool is named."""
    states = np.zeros((3, 1))
    records = [
        SimpleNamespace(obs=states, acts=np.zeros(2), terminal=False),
        SimpleNamespace(obs=states, acts=np.zeros(2), terminal=None),  # imitation: unknown
        SimpleNamespace(observations=states, actions=np.zeros(2), terminations=[0, 0]),
        SimpleNamespace(observations=states, actions=np.zeros(2), terminations=[0, 1]),
        {"observations": states, "truncated": np.True_},
        states,
    ]
    read = [d.truncated for d in as_demonstrations(records)]
    assert read == [True, False, True, False, True, False]
    for flag in ("yes", [True, False], 2):
        with pytest.raises(ValueError, match="demo 1: truncated must be one bool, got"):
            as_demonstrations([states, {"observations": states, "truncated": flag}])


def test_demos_that_join_other_keys_are_refused():
    a = Demonstration(np.zeros((5, 2)), state_key=("observation", "desired_goal"))
    b = Demonstration(np.ones((5, 2)), state_key=("desired_goal", "observation"))
    with pytest.raises(ValueError, match=r"demo 1 joins the keys \['desired_goal', 'observation'"):
        as_demonstrations([a, b])
    with pytest.raises(ValueError, match="demo 0: state_key must be a key or a list of keys"):
        as_demonstrations([{"observations": np.zeros((5, 2)), "state_key": [3]}, b])
    one = as_demonstrations(
        [{"observations": np.zeros((5, 2)), "state_key": "obs"}, b.observations]
    )
    assert one[0].state_key == ("obs",) and one[1].state_key is None  # not recorded: not checked
    # a state_key given that is not the one recorded: it was ignored silently
    with pytest.raises(
        ValueError, match=r"demo 0 joins the keys \['observation', 'desired_goal'\]"
    ):
        as_demonstrations([a, a], state_key=["desired_goal", "observation"])


def test_imitation_dict_observations_and_transitions():
    from imitation.data import rollout
    from imitation.data.types import DictObs, Trajectory

    rng = np.random.default_rng(0)
    obs = DictObs({"a": rng.normal(size=(11, 2)), "b": rng.normal(size=(11, 1))})
    trajectory = Trajectory(obs, np.zeros(10, dtype=int), None, True)
    demos = as_demonstrations([trajectory] * 2, state_key=["b", "a"])  # it asked for state_key
    assert demos[0].state_key == ("b", "a")
    np.testing.assert_array_equal(demos[0].observations[:, 1:], obs.get("a"))
    flat = rollout.flatten_trajectories(
        [Trajectory(rng.normal(size=(5, 2)), np.zeros(4), None, True)]
    )
    with pytest.raises(ValueError, match=r"demo 0 is a single transition .*flatten_traj"):
        as_demonstrations(flat)  # said: reshape a 1-D state sequence with x[:, None]


def test_a_step_missing_a_key_is_named():
    steps = [{"a": np.zeros(2), "b": np.zeros(1)} for _ in range(6)]
    steps[3] = {"a": np.zeros(2)}
    with pytest.raises(ValueError, match=r"demo 0: the observation at step 3 has no \['b'\]"):
        as_demonstrations([steps, steps], state_key=["a", "b"])


def test_dict_observations_are_joined_in_the_order_of_state_key():
    """Minari stores a goal env's episodes as dicts of per-key arrays."""
    rng = np.random.default_rng(0)
    episodes = [
        {
            "observations": {"observation": rng.normal(size=(6, 4)), "goal": rng.normal(size=6)},
            "actions": np.arange(5) % 2,
        }
        for _ in range(2)
    ]
    demos = as_demonstrations(episodes, state_key=["goal", "observation"])
    np.testing.assert_array_equal(
        demos[1].observations[:, 1:], episodes[1]["observations"]["observation"]
    )
    np.testing.assert_array_equal(demos[1].observations[:, 0], episodes[1]["observations"]["goal"])
    assert demos[0].state_key == ("goal", "observation")
    with pytest.raises(ValueError, match=r"demo 0: observations have no key 'desired_goal'"):
        as_demonstrations(episodes, state_key=["observation", "desired_goal"])
    short = [{"observations": {"a": np.zeros((6, 2)), "b": np.zeros((5, 1))}}] * 2
    with pytest.raises(ValueError, match=r"observations\['b'\] must be a \(T\+1, k\) array"):
        as_demonstrations(short, state_key=["a", "b"])
    with pytest.raises(ValueError, match="observations are a dict; pass state_key="):
        as_demonstrations(episodes)


def test_save_demos_joins_dict_observations_with_state_key(tmp_path):
    """Its error said "pass state_key=", which save_demos did not take."""
    steps = [{"a": np.full(2, t), "b": np.full(1, -t)} for t in range(6)]
    save_demos([steps, steps], tmp_path / "d.npz", state_key=["b", "a"])
    back = load_demos(tmp_path / "d.npz")
    assert back[0].state_key == ("b", "a") and back[0].observations[3].tolist() == [-3, 3, 3]


def test_load_rejects_foreign_and_missing_files(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, x=np.zeros(3))
    with pytest.raises(ValueError, match="not an sb3-swirl demonstration file"):
        load_demos(path)
    with pytest.raises(ValueError, match=r"cannot read demonstrations.*No such file.*npz'$"):
        load_demos(tmp_path / "missing.npz")
    with pytest.raises(ValueError, match=r"Minari dataset id\? In Python pass minari.load_dataset"):
        as_demonstrations("D4RL/door/human-v2")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_minari_dataset_round_trip(tmp_path, monkeypatch):
    """Demos written with to_minari load back from Minari unchanged (a local dataset only)."""
    import minari  # the dev extra installs it

    from sb3_swirl.supervisors import collect_demos

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    demos = collect_demos("sb3_swirl/ParallelParking-v0", 2, seed=0)
    demos[1] = dataclasses.replace(demos[1], truncated=True)
    to_minari(demos, "swirl/parking/test-v0", env="sb3_swirl/ParallelParking-v0")
    episodes = list(minari.load_dataset("swirl/parking/test-v0").iterate_episodes())
    assert [(e.terminations[-1], e.truncations[-1]) for e in episodes] == [(1, 0), (0, 1)]
    back = as_demonstrations(episodes)
    assert [d.truncated for d in back] == [False, True]
    for ours, theirs in zip(demos, back, strict=True):
        np.testing.assert_array_equal(ours.observations, theirs.observations)
        np.testing.assert_array_equal(ours.actions, theirs.actions)
        np.testing.assert_allclose(ours.rewards, theirs.rewards)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_to_minari_writes_what_the_spaces_hold(tmp_path, monkeypatch):
    """Joined Dict states are split back into the env's keys (Minari could not read them),
    values cast to the spaces' dtypes, and demos that do not fit the env are refused."""
    import minari

    from sb3_swirl.supervisors import collect_demos

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    reach, keys = (
        "sb3_swirl/FetchReachDiscrete-v0",
        ["observation", "achieved_goal", "desired_goal"],
    )
    demos = collect_demos(reach, 2, seed=0, state_key=keys)
    dataset = to_minari(demos, "swirl/reach/test-v0", env=reach)
    episodes = list(minari.load_dataset("swirl/reach/test-v0").iterate_episodes())
    assert dataset.observation_space.contains(
        {k: v[0] for k, v in episodes[0].observations.items()}
    )
    back = as_demonstrations(episodes, state_key=keys)
    np.testing.assert_array_equal(back[1].observations, demos[1].observations)
    with pytest.raises(
        ValueError, match=r"demo 0 joins the keys \('observation', 'desired_goal'\)"
    ):
        to_minari(collect_demos(reach, 1, seed=0, state_key=keys[::2]), "x/r/a-v0", env=reach)
    parked = collect_demos("sb3_swirl/ParallelParking-v0", 1, seed=0)
    cut = [Demonstration(parked[0].observations[:, :3], parked[0].actions)]
    shifted = [Demonstration(parked[0].observations, parked[0].actions + 10)]
    for wrong, message in [(cut, "observations have 3 dims, the env's"), (shifted, "action")]:
        with pytest.raises(ValueError, match=f"demo 0: {message}"):
            to_minari(wrong, "x/p/b-v0", env="sb3_swirl/ParallelParking-v0")
    assert not (tmp_path / "x").exists()


def test_to_minari_needs_actions():
    with pytest.raises(ValueError, match="demo 0 has no actions"):
        to_minari(_arrays(), "swirl/test/demo-v0", env="sb3_swirl/ParallelParking-v0")


def _bad(index, array):
    good = _arrays(4)
    good[index] = array
    return good


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ([], "no demonstrations"),
        (_arrays(1), "at least 2 demonstrations, got 1"),
        (_bad(2, np.array([["a", "b"]] * 5)), "demo 2: observations have non-numeric dtype"),
        (
            _bad(1, np.where(np.arange(20).reshape(10, 2) == 7, np.nan, 1.0)),
            r"demo 1: observations contain NaN or inf \(first at step 3\)",
        ),
        (_bad(3, np.full((6, 2), np.inf)), r"demo 3: .*NaN or inf \(first at step 0\)"),
        (
            _bad(1, np.where(np.arange(20).reshape(10, 2) == 9, -1e200, 1.0)),
            r"demo 1: observations reach 1e\+200 \(first above 1e\+150 at step 4\).*rescale",
        ),
        (_bad(2, np.zeros((9, 3))), "demo 2 has state dimension 3 but demo 0 has 2"),
        (_bad(1, np.zeros(9)), r"demo 1: observations must be 2-D .*shape \(9,\)"),
        (_bad(0, np.zeros((3, 2, 2))), "demo 0: observations must be 2-D"),
        (_bad(3, [[0.0, 1.0], [1.0]]), "demo 3: observations cannot be read"),
        (
            _bad(0, {"observations": np.zeros((5, 2)), "actions": np.zeros(5)}),
            r"demo 0: actions must have length T = 4",
        ),
        (
            _bad(1, {"obs": np.zeros((5, 2)), "acts": np.zeros(4), "rews": np.zeros(3)}),
            r"demo 1: rewards must have shape",
        ),
        (
            _bad(2, {"observations": {"a": np.zeros((5, 2))}}),
            "demo 2: observations are a dict; pass state_key= .* to join its values in that order",
        ),
        (
            _bad(1, {"observations": [{"a": np.zeros(2)}] * 5}),
            "demo 1: observations are a list of dicts, one per step",
        ),
        (
            _bad(1, {"states": np.zeros((5, 2)), "act": np.zeros(4)}),
            r"demo 1 is a mapping without 'observations' or 'obs' \(its keys: \['act', 'states'\]",
        ),
        (_bad(2, np.zeros((1, 2))), "demo 2: needs at least 2 states"),
        (
            [
                Demonstration(np.zeros((5, 2)), np.zeros((4, 1))),
                _arrays(1)[0],
                Demonstration(np.zeros((5, 2)), np.zeros(4)),
            ],
            r"demo 2 has actions of shape \(4,\) but demo 0 has \(4, 1\).*actions\.ravel\(\)",
        ),
        (
            _bad(1, (np.zeros((5, 2)), np.zeros(4))),
            r"demo 1 is a tuple of 2 arrays .*Demonstration\(observations, actions\)",
        ),
    ],
)
def test_malformed_input_names_the_demo_and_problem(data, match):
    with pytest.raises(ValueError, match=match):
        as_demonstrations(data)


def test_demo_shorter_than_window_reports_lengths():
    data = _arrays(3, lengths=(20, 4, 20))
    with pytest.raises(ValueError, match="demo 1 is shorter than the window: it has 4 states"):
        as_demonstrations(data, window=3)
    assert len(as_demonstrations(data, window=2)) == 3  # 4 states suffice for window 2


def _damaged_demo_files(tmp_path):
    """(path, expected message) for each way a demonstration file can be damaged."""
    good = tmp_path / "good.npz"
    save_demos([np.zeros((6, 2)), np.ones((5, 2))], good)
    data = dict(np.load(good))

    def write(name, **changes):
        path = tmp_path / name
        np.savez(path, **{**data, **changes})
        return path

    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    np.save(tmp_path / "array.npy", np.zeros((3, 2)))
    text = tmp_path / "text.npz"
    text.write_text("obs,0.0,1.0\n")
    nan = data["obs_1"].copy()
    nan[3, 0] = np.nan
    return [
        (truncated, r"cannot read demonstrations.*\(a truncated or damaged file\?\)"),
        (text, "cannot read demonstrations .*: not a NumPy .npz archive"),
        (tmp_path / "array.npy", "holds a single array"),
        (write("v99.npz", format=np.array("sb3_swirl.demos/99")), "unsupported .* format"),
        (write("count.npz", n_demos=np.array(1)), "unexpected keys"),
        (write("shape.npz", n_demos=np.array([2, 2])), "one integer"),
        (write("nan.npz", obs_1=nan), r"demo 1: .*NaN .*step 3"),
    ]


def test_load_rejects_damaged_files_naming_the_file_and_problem(tmp_path):
    for path, match in _damaged_demo_files(tmp_path):
        with pytest.raises(ValueError, match=match) as info:
            load_demos(path)
        assert path.name in str(info.value), path


def test_not_a_sequence_is_rejected():
    with pytest.raises(ValueError, match="expected a sequence"):
        as_demonstrations(Demonstration(np.zeros((5, 2))))
    with pytest.raises(ValueError, match=r"shape \(n_demos, T\+1, d\)"):
        as_demonstrations(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="pass a list"):
        as_demonstrations({"observations": np.zeros((5, 2))})


def test_piecewise_linear_demos_switch_where_the_direction_changes():
    demos, switches = make_piecewise_linear_demos(n_demos=4, n_phases=3, noise=0.0, random_state=3)
    assert len({len(d) for d in demos}) > 1  # ragged
    for demo, sw in zip(demos, switches, strict=True):
        v = np.diff(demo.observations, axis=0)
        changes = np.flatnonzero(np.linalg.norm(np.diff(v, axis=0), axis=1) > 1e-9) + 1
        np.testing.assert_array_equal(changes, sw)


# ---------------------------------------------------------------------- hostile and failed files
def _archive(path, arrays: dict, raw: dict | None = None) -> None:
    """An .npz written member by member: ``raw`` members are given as header + bytes."""
    import io
    import zipfile

    with zipfile.ZipFile(path, "w") as archive:
        for key, value in arrays.items():
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asarray(value))
            archive.writestr(f"{key}.npy", buffer.getvalue())
        for key, (header, data) in (raw or {}).items():
            buffer = io.BytesIO()
            np.lib.format.write_array_header_1_0(buffer, header)
            archive.writestr(f"{key}.npy", buffer.getvalue() + data)


def test_a_file_claiming_a_billion_demos_is_refused_without_allocating(tmp_path):
    path = tmp_path / "huge.npz"
    obs = np.zeros((5, 2))
    _archive(path, {"format": "sb3_swirl.demos/1", "n_demos": 10**9, "obs_0": obs, "obs_1": obs})
    with pytest.raises(ValueError, match=r"huge\.npz: n_demos=1000000000 but the file holds 2"):
        load_demos(path)


def test_an_array_header_claiming_more_than_the_file_holds_is_refused(tmp_path):
    path = tmp_path / "bomb.npz"
    header = {"descr": "<f8", "fortran_order": False, "shape": (10**6, 10**6)}
    _archive(
        path,
        {"format": "sb3_swirl.demos/1", "n_demos": 2, "obs_0": np.zeros((5, 2))},
        raw={"obs_1": (header, b"\x00" * 80)},
    )
    with pytest.raises(ValueError, match=r"bomb\.npz: cannot read obs_1 .*claims shape"):
        load_demos(path)


def test_save_demos_keeps_the_previous_file_when_a_write_fails(tmp_path, monkeypatch):
    import os

    path = tmp_path / "demos.npz"
    first = [np.zeros((6, 2)), np.ones((7, 2))]
    save_demos(first, path)
    before = path.read_bytes()

    def disk_full(fh, **arrays):  # half an archive goes out, then the disk is full
        fh.write(before[: len(before) // 2])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", disk_full)
    with pytest.raises(OSError, match="No space left"):
        save_demos([np.full((6, 2), 5.0), np.ones((7, 2))], path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["demos.npz"]
    np.testing.assert_array_equal(load_demos(path)[0].observations, first[0])


def test_an_archive_lying_about_its_member_sizes_is_refused(tmp_path):
    """The directory of the zip claims a member far larger than the file could unpack to."""
    import struct

    path = tmp_path / "liar.npz"
    header = {"descr": "<f8", "fortran_order": False, "shape": (20_000, 20_000)}
    _archive(
        path,
        {"format": "sb3_swirl.demos/1", "n_demos": 2, "obs_0": np.zeros((5, 2))},
        raw={"obs_1": (header, b"\x00" * 80)},
    )
    data = bytearray(path.read_bytes())
    entry = data.rindex(b"PK\x01\x02")  # the last member's central directory entry: obs_1
    data[entry + 24 : entry + 28] = struct.pack("<I", 0xFFFFFFFE)  # its unpacked size
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"liar\.npz: cannot read obs_1 .*impossible"):
        load_demos(path)
