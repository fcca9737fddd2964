"""The ``sb3-swirl`` command line and the main job, run as a user would (tiny budgets)."""

import json
from pathlib import Path

import numpy as np
import pytest

from sb3_swirl.cli import main
from sb3_swirl.demos import load_demos, save_demos
from sb3_swirl.experiments import PRESETS, load_hyperparams, rollouts_to_success
from swirl_wrappers import TaskModel


def test_demos_fit_show_round_trip(tmp_path, capsys):
    demos_path, task_path = tmp_path / "demos.npz", tmp_path / "task.json"
    assert (
        main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "3", "-o", str(demos_path), "-q"]) == 0
    )
    demos = load_demos(demos_path)
    assert len(demos) == 3 and all(d.actions is not None for d in demos)

    assert main(["fit", str(demos_path), "-o", str(task_path), "--seed", "1"]) == 0
    task = TaskModel.from_json(task_path)
    assert task.n_segments >= 2
    printed = capsys.readouterr()
    assert f"SWIRL proxy task: {task.n_segments} segments" in printed.out
    # the switch steps, to check against transitions.png without Python
    first = task.segment_indices(demos[0].observations)
    steps = (np.flatnonzero(np.diff(first)) + 1)[: task.n_segments - 1].tolist()
    assert task.metadata["switches"][0] == steps
    assert f"demo 0: {steps}" in " ".join(printed.err.split())
    assert task.metadata["indicator"] in task.metadata["indicator_scores"]  # auto's choice

    figs = tmp_path / "figs"
    assert main(["show", str(task_path), "--plot", str(figs), "--demos", str(demos_path)]) == 0
    assert (figs / "rewards.png").stat().st_size > 0
    assert (figs / "segments.png").stat().st_size > 0
    # one demo: enough to draw, not to fit (the message names the file)
    one = tmp_path / "one.npz"
    save_demos(demos[:1], one)
    assert main(["show", str(task_path), "--plot", str(figs), "--demos", str(one)]) == 0
    assert main(["fit", str(one), "-o", str(tmp_path / "one.json")]) == 2
    assert "one.npz holds 1 demonstration: SWIRL needs at least 2" in capsys.readouterr().err
    # the fit's record (metadata) edited by hand: the task still shows (it raised TypeError)
    edited = json.loads(task_path.read_text())
    for garbage in (5, [{"a": 1}], "x"):
        edited["metadata"] |= {"dropped_regions": garbage, "cluster_dims": garbage}
        (tmp_path / "edited.json").write_text(json.dumps(edited))
        assert main(["show", str(tmp_path / "edited.json")]) == 0


def test_fit_with_angles_matches_the_python_api(tmp_path):
    from sb3_swirl.fitting import fit_task

    demos_path, task_path = tmp_path / "acro.npz", tmp_path / "acro.json"
    main(["demos", "sb3_swirl/NoisyAcrobot-v0", "-n", "4", "-o", str(demos_path), "-q"])
    code = main(
        ["fit", str(demos_path), "-o", str(task_path), "--angles", "0;0,1", "--dims", "2,3"]
    )
    assert code == 0
    from_cli = TaskModel.from_json(task_path)
    direct = fit_task(load_demos(demos_path), angles=[[0], [0, 1]], dims=[2, 3], random_state=0)
    assert from_cli.angles == direct.angles and from_cli.dims == direct.dims
    np.testing.assert_array_equal(from_cli.regions[0].mean, direct.regions[0].mean)


def test_fit_reg_covar_reaches_the_regions(tmp_path):
    from sb3_swirl.fitting import fit_task

    demos_path, task_path = tmp_path / "park.npz", tmp_path / "park.json"
    main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "5", "-o", str(demos_path), "-q"])
    assert main(["fit", str(demos_path), "-o", str(task_path), "--reg-covar", "0.1"]) == 0
    direct = fit_task(load_demos(demos_path), reg_covar=0.1, random_state=0)
    thin = fit_task(load_demos(demos_path), random_state=0)
    from_cli = TaskModel.from_json(task_path)
    np.testing.assert_array_equal(from_cli.regions[0].covariance, direct.regions[0].covariance)
    assert np.linalg.det(from_cli.regions[0].covariance) > np.linalg.det(thin.regions[0].covariance)
    # the fit of parking's zoo entry, and MaxEnt rewards, from the command line (neither could
    # be spelled: no flag for normalize_time or the reward learner)
    entry = [
        "--indicator",
        "gmm",
        "--reg-covar",
        "0.1",
        "--no-normalize-time",
        "--no-align-entries",
    ]
    for reward in ([], ["--reward", "maxent"]):
        assert main(["fit", str(demos_path), "-o", str(task_path), *entry, *reward]) == 0
        direct = fit_task(
            load_demos(demos_path),
            indicator="gmm",
            reg_covar=0.1,
            normalize_time=False,
            align_entries=False,
            reward=reward[-1] if reward else None,
            random_state=0,
        )
        assert TaskModel.from_json(task_path).to_dict() == direct.to_dict()
    assert (
        main(
            [
                "fit",
                str(demos_path),
                "-o",
                str(task_path),
                "--reward",
                "maxent",
                "--metric",
                "euclidean",
            ]
        )
        == 2
    )


def test_fit_flags_turn_off_nuisance_dims_and_merging(tmp_path, capsys):
    from sb3_swirl.datasets import make_switching_demos

    # 3 dims that move on their own split the transitions (see test_segmentation.py)
    demos, _ = make_switching_demos(
        "constant_velocity", n_demos=8, dim=3, nuisance_dims=3, random_state=8
    )
    path = tmp_path / "demos.npz"
    save_demos(demos, path)
    segments = {}
    gmm = ("--indicator", "gmm", "--no-align-entries")  # the paper's path, as measured there
    for flags in ((), ("--cluster-all-dims",), ("--cluster-all-dims", "--no-merge-fragments")):
        task_path = tmp_path / f"task{len(flags)}.json"
        assert main(["fit", str(path), "-o", str(task_path), *gmm, *flags]) == 0
        task = TaskModel.from_json(task_path)
        params = task.metadata["segmentation"]["params"]
        assert params["ignore_nuisance_dims"] is not bool(flags)
        assert params["merge_fragments"] is (len(flags) < 2)
        segments[flags] = task.n_segments
        said = capsys.readouterr().err
        assert ("without task-space dims [3, 4, 5]" in said) is not bool(flags)
        assert ("No transition region" in said) is (len(flags) == 2)
        # the advice names the flag to leave out
        assert ("without --no-merge-fragments" in said) is (len(flags) == 2)
    # the three phases; merging alone finds the first switch; as the paper, none
    assert list(segments.values()) == [3, 2, 1]
    assert main(["show", str(tmp_path / "task0.json")]) == 0  # the saved task says it too
    assert "without task-space dims [3, 4, 5]" in capsys.readouterr().err


def test_fit_merge_same_dynamics_flag_drops_cuts_within_a_phase(tmp_path, capsys):
    from sb3_swirl.datasets import make_switching_demos

    # goal reaching in 16 dims: the GMM also cuts where the motion slows (test_segmentation.py)
    demos, _ = make_switching_demos("goal_reaching", dim=16, random_state=0)
    path = tmp_path / "demos.npz"
    save_demos(demos, path)
    segments = []
    for flags in ((), ("--merge-same-dynamics",)):
        task_path = tmp_path / f"task{len(flags)}.json"
        gmm = ("--indicator", "gmm", "--no-align-entries")
        assert main(["fit", str(path), "-o", str(task_path), *gmm, *flags]) == 0
        task = TaskModel.from_json(task_path)
        assert task.metadata["segmentation"]["params"]["merge_same_dynamics"] is bool(flags)
        assert task.metadata["segmentation"]["params"]["align_entries"] is False
        segments.append(task.n_segments)
        said = " ".join(capsys.readouterr().err.split())  # rich wraps lines
        assert ("follow the same locally linear dynamics" in said) is bool(flags)
    assert segments == [5, 3]  # the truth: 3 phases


def test_bad_input_is_a_clear_error_not_a_traceback(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing.npz"), "-o", str(tmp_path / "t.json")]) == 2
    assert "missing.npz" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"kind": "swirl_task", "schema_version": 99}')
    assert main(["show", str(bad)]) == 2
    assert "schema version" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2"])  # -o is required
    # an output path that is a folder, and budgets that cannot run, before any work
    demos = tmp_path / "demos.npz"
    assert main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", str(demos), "-q"]) == 0
    assert main(["fit", str(demos), "-o", str(tmp_path)]) == 2
    assert "directory" in capsys.readouterr().err
    assert main(["fit", str(demos), "-o", ""]) == 2  # it said "the output  is a directory"
    assert "the output (-o) is empty" in capsys.readouterr().err
    # an output file that is a folder, inside the output folder: before the training (it was
    # found after it), and before a sweep's runs
    (tmp_path / "d" / "parking" / "learning_curve.png").mkdir(parents=True)
    assert main(["demo", "parking", "--out", str(tmp_path / "d"), "-q"]) == 2
    assert "learning_curve.png: it is a folder" in capsys.readouterr().err
    assert not (tmp_path / "d" / "parking" / "task.json").exists()
    (tmp_path / "r" / "fig2" / "figure_quick.png").mkdir(parents=True)
    figure = ["reproduce", "fig2", "--quick", "--panels", "parking", "--out", str(tmp_path / "r")]
    assert main([*figure, "-q"]) == 2
    assert "figure_quick.png: it is a folder" in capsys.readouterr().err
    assert not (tmp_path / "r" / "fig2" / "runs_quick.jsonl").exists()
    for option, value in (("--timesteps", "-5"), ("--n-demos", "1")):
        out = tmp_path / option
        assert main(["demo", "parking", option, value, "--out", str(out), "-q"]) == 2
        assert option[2:].replace("-", "_") in capsys.readouterr().err
        assert not out.exists()
    # option values argparse refuses, naming the option
    for option, value in (("--dims", "a,b"), ("--angles", "0;;1"), ("--seed", "-5")):
        with pytest.raises(SystemExit):
            main(["fit", str(demos), "-o", str(tmp_path / "t.json"), option, value])
        assert f"argument {option}: " in capsys.readouterr().err
    assert main(["show", str(bad), "--demos", str(demos)]) == 2  # nothing to draw them in
    assert "--plot" in capsys.readouterr().err
    task = tmp_path / "task.json"
    assert main(["fit", str(demos), "-o", str(task), "--reg-covar", "0.1"]) == 0
    figs = tmp_path / "figs"
    missing = ["show", str(task), "--plot", str(figs), "--demos", str(tmp_path / "no.npz")]
    assert main(missing) == 2
    assert "no.npz" in capsys.readouterr().err
    assert not figs.exists()  # nothing written before the error
    other = tmp_path / "other.npz"  # demos of another task: fewer dims than the task reads
    save_demos([d.observations[:, :1] for d in load_demos(demos)], other)
    assert main(["show", str(task), "--plot", str(figs), "--demos", str(other)]) == 2
    err = capsys.readouterr().err
    assert "other.npz: demo 0: observation has 1 dims" in err and "Traceback" not in err
    assert not figs.exists()


def test_every_preset_has_tuned_hyperparameters_for_both_methods():
    for preset in PRESETS.values():
        swirl = load_hyperparams("swirl_dqn", preset.env_id)
        dqn = load_hyperparams("dqn", preset.env_id)
        # the same network for both: MLPs (a Dict observation's keys concatenated on Fetch)
        assert swirl["policy"] == dqn["policy"] in ("MlpPolicy", "MultiInputPolicy")
        assert swirl["policy_kwargs"] == dqn["policy_kwargs"]


def test_demo_help_lists_every_tasks_defaults(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--help"])
    said = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    assert exit_.value.code == 0
    for name, preset in PRESETS.items():
        assert f"{name}: {preset.n_demos} demos, {preset.total_timesteps} steps" in said


def test_rollouts_to_success_is_the_first_evaluation_at_target():
    curve = [
        {"episodes": 10, "success_rate": 0.5},
        {"episodes": 20, "success_rate": 0.95},
        {"episodes": 30, "success_rate": 1.0},
    ]
    assert rollouts_to_success(curve, 0.95) == 20
    assert rollouts_to_success(curve[:1], 0.95) is None


def test_main_job_writes_its_results(tmp_path):
    code = main(
        ["demo", "parking", "--n-demos", "2", "--timesteps", "400", "--out", str(tmp_path), "-q"]
    )
    assert code == 0
    out = tmp_path / "parking"
    results = json.loads((out / "results.json").read_text())
    assert [run["algo"] for run in results["runs"]] == ["swirl_dqn", "dqn"]
    spec = results["runs"][0]["hyperparams"]["env_wrapper"][0]["sb3_swirl.zoo.SwirlTaskWrapper"]
    assert spec["demos"] == "2 demos given to the run"  # not the entry's n_demos: 5
    for run in results["runs"]:
        assert run["curve"], "at least one evaluation"
        assert all(0.0 <= p["success_rate"] <= 1.0 for p in run["curve"])
    for name in ("learning_curve.png", "segments.png", "task.json"):
        assert (out / name).stat().st_size > 0
    assert TaskModel.from_json(out / "task.json").n_segments == results["n_segments"]


def test_train_and_evaluate_scores_the_final_policy_and_checks_the_budget():
    from sb3_swirl.experiments import PRESETS, train_and_evaluate

    preset = PRESETS["parking"]
    steps = preset.eval_freq + preset.eval_freq // 5  # not a multiple of eval_freq
    run = train_and_evaluate("dqn", preset, total_timesteps=steps, seed=0, progress=False)
    # the last evaluation scores the policy at the end of training
    assert run["curve"][0]["timesteps"] == preset.eval_freq
    assert run["curve"][-1]["timesteps"] >= steps
    assert run["final_success"] == run["curve"][-1]["success_rate"]
    with pytest.raises(ValueError, match="total_timesteps"):
        train_and_evaluate("dqn", preset, total_timesteps=0, seed=0, progress=False)


# ---------------------------------------------------------------------- outputs and Ctrl-C
def test_fit_refuses_to_overwrite_its_own_input(tmp_path, capsys):
    demos = tmp_path / "demos.npz"
    assert main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", str(demos), "-q"]) == 0
    before = demos.read_bytes()
    (tmp_path / "link.npz").symlink_to(demos)
    for output in (demos, tmp_path / "." / "demos.npz", tmp_path / "link.npz"):
        assert main(["fit", str(demos), "-o", str(output)]) == 2
        assert "is the input" in capsys.readouterr().err
    assert demos.read_bytes() == before


@pytest.mark.parametrize(
    "command",
    [
        ["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", "{blocked}/demos.npz"],
        ["fit", "{demos}", "-o", "{blocked}/task.json"],
        ["fit", "{demos}", "-o", "{folder}"],
        ["show", "{task}", "--plot", "{blocked}/figs"],
        ["show", "{task}", "--plot", "{figs}"],
        ["demo", "parking", "--out", "{blocked}/results", "-q"],
    ],
    ids=[
        "demos",
        "fit",
        "fit into a folder",
        "show --plot",
        "a folder in the way",
        "demo --out",
    ],
)
def test_an_unwritable_output_is_refused_before_any_work(tmp_path, capsys, command, monkeypatch):
    """A path under a regular file cannot be written, even by root."""
    from sb3_swirl.fitting import fit_task

    demos = tmp_path / "demos.npz"
    main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", str(demos), "-q"])
    task = tmp_path / "task.json"
    fit_task(load_demos(demos), random_state=0).to_json(task)
    blocked = tmp_path / "a_file"
    blocked.write_text("")
    args = [
        a.format(
            blocked=blocked, demos=demos, task=task, folder=tmp_path / "dir", figs=tmp_path / "figs"
        )
        for a in command
    ]
    (tmp_path / "dir").mkdir()
    (tmp_path / "figs" / "rewards.png").mkdir(parents=True)  # a folder where a plot goes
    no_work_targets = (
        "sb3_swirl.supervisors.collect_demos",
        "sb3_swirl.fitting.fit_task",
        "sb3_swirl.demos.load_demos",
        "sb3_swirl.experiments.run_demo",
        "sb3_swirl.plotting.plot_rewards",
    )
    for target in no_work_targets:
        monkeypatch.setattr(target, lambda *a, **k: pytest.fail("work started"))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert any(m in err for m in ("not a folder", "is a directory", "is a folder")), err


def test_one_demo_is_refused_before_collecting(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("sb3_swirl.supervisors.collect_demos", lambda *a, **k: pytest.fail("work"))
    with pytest.raises(SystemExit) as exit_:
        main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "1", "-o", str(tmp_path / "x.npz")])
    assert exit_.value.code == 2 and "at least 2 demonstrations" in capsys.readouterr().err


def test_outputs_go_into_new_folders(tmp_path):
    demos, task = tmp_path / "new" / "demos.npz", tmp_path / "newer" / "deep" / "task.json"
    assert main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", str(demos), "-q"]) == 0
    assert main(["fit", str(demos), "-o", str(task)]) == 0
    assert demos.is_file() and task.is_file()


def test_ctrl_c_prints_one_line_exits_130_and_leaves_no_file(tmp_path, capsys, monkeypatch):
    demos = tmp_path / "demos.npz"
    assert main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "2", "-o", str(demos), "-q"]) == 0
    capsys.readouterr()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("sb3_swirl.fitting.fit_task", interrupted)
    assert main(["fit", str(demos), "-o", str(tmp_path / "task.json")]) == 130
    assert capsys.readouterr().err.strip() == "interrupted"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demos.npz"]


def test_ctrl_c_in_the_middle_of_a_real_run(tmp_path):
    """SIGINT to a running ``sb3-swirl demos``: exit 130, one line, no (partial) file."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "demos.npz"
    command = ["demos", "sb3_swirl/NoisyAcrobot-v0", "-n", "500", "-o", str(out), "-q"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sb3_swirl.cli", *command],
        stderr=subprocess.PIPE,
        text=True,
        # a shell's background job inherits SIGINT ignored, and Python then keeps it ignored
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    started = proc.stderr.readline()  # printed when the work starts, after the imports
    assert started.startswith("collecting 500 demos"), started
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read()
    assert proc.wait(timeout=30) == 130
    assert rest.strip() == "interrupted"
    assert list(tmp_path.iterdir()) == []


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux's /proc)."""
    children = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(line.split(":\t", 1) for line in status.read_text().splitlines())
        except (OSError, ValueError):  # gone meanwhile
            continue
        if int(fields.get("PPid", "0")) == pid:
            children.append(int(status.parent.name))
    return children


def _alive(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\tZ" not in status.split("State:", 1)[1][:4]  # a zombie has stopped


def test_sigterm_stops_a_sweep_and_its_workers(tmp_path):
    """``kill`` (or a scheduler's time limit) on a running sweep: exit 143, one line, and its
    joblib workers stop too (killed outright, they went on running their jobs, orphaned)."""
    import signal
    import subprocess
    import sys
    import time

    command = ["reproduce", "fig2", "--quick", "--panels", "parking", "--out", str(tmp_path)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sb3_swirl.cli", *command, "-q"],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert "Fig. 2" in proc.stderr.readline()  # the work starts after the imports
    workers: list[int] = []
    for _ in range(300):  # until the two workers have started (steps of 0.1 s)
        workers = [pid for pid in _children(proc.pid) if "LokyProcess" in _cmdline(pid)]
        if len(workers) == 2:
            break
        time.sleep(0.1)
    assert len(workers) == 2, workers
    time.sleep(1.0)  # at work on their runs
    proc.send_signal(signal.SIGTERM)
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == 143
    assert rest.strip().splitlines()[-1] == "terminated", rest
    for _ in range(100):
        if not any(_alive(pid) for pid in workers):
            break
        time.sleep(0.1)
    assert not any(_alive(pid) for pid in workers)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def test_fit_auto_prints_which_indicator_it_kept(tmp_path, capsys):
    from sb3_swirl.demos import make_piecewise_linear_demos

    path, task_path = tmp_path / "demos.npz", tmp_path / "task.json"
    save_demos(make_piecewise_linear_demos(n_demos=6, random_state=0)[0], path)
    assert main(["fit", str(path), "-o", str(task_path)]) == 0  # auto, the default
    task = TaskModel.from_json(task_path)
    chosen, scores = task.metadata["indicator"], task.metadata["indicator_scores"]
    assert list(scores) == ["gmm", "velocity", "linear", "phases"]
    assert chosen == min(scores, key=scores.__getitem__)
    assert f"indicator: {chosen} (dynamics error" in capsys.readouterr().err


def test_demos_of_a_dict_env_record_the_state_keys_and_env_settings(tmp_path, capsys):
    path = tmp_path / "reach.npz"
    keys = "observation,achieved_goal,desired_goal,goal_offset"
    argv = ["demos", "sb3_swirl/FetchReachDiscrete-v0", "-n", "2", "-o", str(path), "-q"]
    assert main([*argv, "--state-key", keys, "--env-kwarg", "goal_offset=true"]) == 0
    assert [d.observations.shape[1] for d in load_demos(path)] == [10 + 3 + 3 + 3] * 2
    assert main([*argv, "--env-kwarg", "no_such_setting=1"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "error: sb3_swirl/FetchReachDiscrete-v0 does not take the settings" in err
    with pytest.raises(SystemExit):
        main([*argv, "--env-kwarg", "goal_offset"])  # no value: argparse's usage error


def test_fit_says_when_another_indicator_nearly_ties_with_another_count(capsys):
    from sb3_swirl.cli import _print_near_ties

    segments = {"gmm": 13, "velocity": 2, "linear": 3, "phases": 3}
    scores = {"gmm": 1.0, "velocity": 1.5, "linear": 1.004, "phases": 1.003}
    _print_near_ties("gmm", scores, segments)
    said = " ".join(capsys.readouterr().err.split())
    assert "phases and linear explain the demos nearly as well (within 0.4%) with 3 segments" in (
        said
    )
    assert "against 13" in said and "--indicator phases" in said
    assert "velocity" not in said  # 50% worse is no tie
    # the same count, a failed fit, or a clear winner: nothing to say
    _print_near_ties("linear", {**scores, "gmm": 1.5, "linear": 1.0}, segments)
    _print_near_ties("gmm", {**scores, "linear": None, "phases": 1.02}, segments)
    assert capsys.readouterr().err == ""
    _print_near_ties("gmm", {**scores, "velocity": 1.001}, {**segments, "velocity": 1})
    assert "velocity explains the demos nearly as well (within 0.1%) with 1 segment against" in (
        " ".join(capsys.readouterr().err.split())
    )


def test_fit_reports_a_demo_at_another_rate_as_one_warning_line(tmp_path, capsys):

    path = tmp_path / "demos.npz"
    assert main(["demos", "sb3_swirl/ParallelParking-v0", "-n", "5", "-o", str(path), "-q"]) == 0
    states = [d.observations for d in load_demos(path)]
    save_demos([*states[:4], states[4][::7]], path)
    capsys.readouterr()
    assert main(["fit", str(path), "-o", str(tmp_path / "task.json"), "--reg-covar", "0.1"]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(warned) == 1 and warned[0].startswith("warning: demo 4: its typical step is")


def test_fit_prints_why_it_dropped_a_region(tmp_path, capsys):
    from sb3_swirl.demos import make_piecewise_linear_demos

    demos, switches = make_piecewise_linear_demos(n_demos=6, random_state=0)
    x = demos[5].observations.copy()
    x[switches[5][0] :] = 2 * x[switches[5][0]] - x[switches[5][0] :]  # skips the 2nd corner
    path = tmp_path / "demos.npz"
    save_demos([*demos[:5], x], path)
    assert main(["fit", str(path), "-o", str(tmp_path / "task.json")]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(warned) == 1 and "none from demos [5]" in warned[0]
    # worded in the command's flags, not in the Python arguments
    assert "--min-demo-fraction 1.0 needs 6 of 6 demos" in warned[0]
    assert "try --indicator ruptures" in warned[0] and "min_demo_fraction" not in warned[0]
    assert "'auto' tried gmm, velocity, linear, phases" in warned[0]


def test_reproduce_refuses_unknown_names_and_bad_seeds(capsys):
    for argv in (["reproduce", "table9"], ["reproduce", "table1", "--seeds", "-1"]):
        with pytest.raises(SystemExit):
            main(argv)
    assert "-1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["reproduce", "fig2", "--jobs", "0"])
    assert "argument --jobs: expected an integer >= 1, got '0'" in capsys.readouterr().err


def test_version(capsys):
    import sb3_swirl

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out == f"sb3-swirl {sb3_swirl.__version__}\n"


def test_reproduce_fig2_runs_end_to_end_and_resumes(tmp_path, capsys):
    """A tiny Fig. 2 (parking, one seed, 3000 steps per method) through the sweep runner."""
    from sb3_swirl.experiments import EXPERIMENTS, reproduce

    kwargs = {"quick": True, "panels": ["parking"], "out_dir": tmp_path, "progress": False}
    first = reproduce("fig2", **kwargs, methods=["swirl", "swirl"], seeds=[10, 10])
    assert [r["method"] for r in first["runs"]] == ["swirl"] and first["ratios"] == []
    assert first["seeds"] == [10]  # a repeated method or seed is one run, counted once
    with pytest.raises(ValueError, match="exists: resume the sweep"):
        reproduce("fig2", **kwargs)
    results = reproduce("fig2", **kwargs, resume=True)  # the other methods join the run made
    assert {r["method"] for r in results["runs"]} == set(EXPERIMENTS["fig2"].methods)
    assert [r for r in results["runs"] if r["method"] == "swirl"] == first["runs"]
    # a quick run's outputs have their own names: it never overwrites a full run's
    assert sorted(path.name for path in (tmp_path / "fig2").iterdir()) == [
        "figure_quick.png", "results_quick.json", "runs_quick.jsonl"
    ]  # fmt: skip
    assert (tmp_path / "fig2" / "figure_quick.png").stat().st_size > 10_000
    saved = json.loads((tmp_path / "fig2" / "results_quick.json").read_text())
    assert saved["summary"] == results["summary"]
    final = {row["method"]: row["final_success_mean"] for row in saved["summary"]}
    pairs = {(row["ours"], row["theirs"]): row for row in saved["ratios"]}
    assert set(pairs) == {("swirl", "dqn"), ("swirl", "dqn_rbf")}
    assert [seed["seed"] for seed in pairs["swirl", "dqn"]["seeds"]] == [10]
    assert all(isinstance(run["warnings"], list) for run in saved["runs"])  # kept, not printed
    assert final["swirl"] > 0  # SWIRL parks within 3000 steps; DQN does not
    again = reproduce("fig2", **kwargs, resume=True)  # every run done: nothing is retrained
    assert again["summary"] == results["summary"]
    capsys.readouterr()
    part = reproduce("fig2", **kwargs, methods=["swirl"], resume=True)  # says what it leaves out
    assert part["methods"] == ["swirl"] and part["runs"] == first["runs"]
    assert "runs_quick.jsonl also holds 2 runs this command did not ask for" in " ".join(
        capsys.readouterr().err.split()
    )
    assert main(["reproduce", "fig3", "--repeats", "5", "--out", str(tmp_path)]) == 2
    assert main(["reproduce", "fig7", "--panels", "nope", "--out", str(tmp_path)]) == 2
    assert main(["reproduce", "fig7", "--methods", "ppo", "--out", str(tmp_path)]) == 2
    assert main(["reproduce", "table2", "--methods", "swirl", "--out", str(tmp_path)]) == 2
    assert main(["reproduce", "fig2", "--address", "auto", "--out", str(tmp_path)]) == 2
    assert "--address is a Ray cluster's: add --backend ray" in _err(capsys)
    assert main(["reproduce", "table2", "--seeds", "3", "3", "--out", str(tmp_path)]) == 2
    assert "--seeds names 3 more than once" in _err(capsys)  # one seed ran, silently
    assert main(["reproduce", "fig9", "--repeats", "3", "--seeds", "1", "--out", "x"]) == 2
    assert "repeats sets Fig. 9's demo-set seeds (100, 101, ...): drop seeds" in _err(capsys)


def _err(capsys) -> str:
    """What the CLI printed to stderr since the last call, on one line."""
    return " ".join(capsys.readouterr().err.split())


def test_reproduce_all_checks_every_output_before_any_work(tmp_path, capsys):
    """A table's or a figure's runs already there, or results without their runs: one error
    up front, not after hours of other sweeps."""
    runs = tmp_path / "table2" / "runs_quick.jsonl"
    runs.parent.mkdir()
    runs.write_text("")
    assert main(["reproduce", "all", "--quick", "--out", str(tmp_path), "-q"]) == 2
    assert "table2/runs_quick.jsonl exists: resume (--resume" in _err(capsys)
    # results without their runs (an earlier version's table): --resume cannot go on from them
    (tmp_path / "fig3").mkdir()
    (tmp_path / "fig3" / "results_quick.json").write_text("{}")
    assert main(["reproduce", "all", "--quick", "--out", str(tmp_path), "-q", "--resume"]) == 2
    assert "fig3/results_quick.json exists without its runs (runs_quick.jsonl)" in _err(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig3", "table2"]  # nothing was made


@pytest.mark.parametrize("name", ["table1", "table2"])
def test_a_table_refuses_to_overwrite_its_results(tmp_path, capsys, name):
    """A table is a sweep: its runs already there need --resume, and results written without
    runs beside them (an older version's) are an error, with --resume too; nothing is
    touched."""
    folder = tmp_path / name
    folder.mkdir()
    runs = folder / "runs_quick.jsonl"
    runs.write_text("")
    assert main(["reproduce", name, "--quick", "--out", str(tmp_path), "-q"]) == 2
    assert "runs_quick.jsonl exists: resume the sweep (--resume)" in _err(capsys)
    runs.unlink()
    table = folder / "results_quick.json"
    table.write_text('{"kept": true}')
    for resume in ([], ["--resume"]):
        assert main(["reproduce", name, "--quick", "--out", str(tmp_path), "-q", *resume]) == 2
        assert (
            f"{name}/results_quick.json exists without its runs (runs_quick.jsonl), so --resume "
            "cannot go on from it: it is not overwritten" in _err(capsys)
        )
    assert table.read_text() == '{"kept": true}'
    assert sorted(p.name for p in folder.iterdir()) == ["results_quick.json"]


def test_transfer_runs_take_demos_on_one_env_and_learn_on_another():
    """Fig. 7's jobs: demos of the standard car, learning and evaluation on both; Fig. 8's
    swept link lengths reach gym.make; --quick shrinks demos, budgets and swept values."""
    from sb3_swirl.experiments import EXPERIMENTS, _jobs

    fig7, fig8 = EXPERIMENTS["fig7"], EXPERIMENTS["fig8"]
    labels, work = _jobs(fig7, ["parking"], list(fig7.methods), [10, 11], quick=False)
    assert len(work) == 2 * 2 * len(EXPERIMENTS["fig7"].methods)
    envs = {(x, job["env_id"]) for (_, _, x, _), job in zip(labels, work, strict=True)}
    assert envs == {
        ("standard", "sb3_swirl/ParallelParking-v0"),
        ("perturbed", "sb3_swirl/ParallelParkingPerturbed-v0"),
    }
    assert {job["demo_env_id"] for job in work} == {"sb3_swirl/ParallelParking-v0"}
    assert {(job["n_demos"], job["max_episodes"]) for job in work} == {(100, 500)}
    _, quick = _jobs(fig7, ["parking"], ["swirl"], [10], quick=True)
    assert {(job["n_demos"], job["steps"]) for job in quick} == {(20, 3_000)}
    labels, work = _jobs(fig8, ["acrobot"], list(fig8.methods), [10], quick=True)
    assert {x for _, _, x, _ in labels} == {1.0, 1.5}
    assert {job["env_kwargs"]["link_length_2"] for job in work} == {1.0, 1.5}


def test_a_panel_skips_the_methods_that_do_not_apply_to_it():
    """Fetch reach's task is the goal's offset, which HER's relabelling would leave stale."""
    from sb3_swirl.experiments import EXPERIMENTS, _jobs

    fetch = EXPERIMENTS["fetch"]
    labels, _ = _jobs(fetch, list(fetch.panels), list(fetch.methods), [10], quick=True)
    runs = {(panel, label) for panel, label, _, _ in labels}
    assert ("reach", "swirl_her") not in runs and ("push", "swirl_her") in runs
    assert len(runs) == 3 * len(fetch.methods) - 1


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", ["fig2", "fig3", "fig4", "fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "fetch"]
)
def test_every_figure_quick_has_every_panel_method_and_seed(name, tmp_path):
    from sb3_swirl.experiments import EXPERIMENTS, reproduce

    experiment = EXPERIMENTS[name]
    results = reproduce(name, quick=True, out_dir=tmp_path, progress=False)
    seeds = experiment.seeds[: experiment.quick_seeds]
    runs = {(r["panel"], r["label"], r["seed"]) for r in results["runs"]}
    assert runs == {
        (p, m, s)
        for p, panel in experiment.panels.items()
        for m in experiment.methods
        if m not in panel.skip
        for s in seeds
    }
    assert json.loads((tmp_path / name / "results_quick.json").read_text())["summary"]
    assert (tmp_path / name / "figure_quick.png").stat().st_size > 10_000
