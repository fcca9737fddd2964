"""rl_zoo3 with swirl_dqn: `sb3-swirl zoo train/enjoy`, YAML-described SWIRL runs, -optimize,
TensorBoard and the zoo's plots, on tiny budgets."""

from __future__ import annotations

import dataclasses
import re
import tomllib
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

pytest.importorskip("rl_zoo3")

import sb3_swirl
from sb3_swirl import zoo

ROOT = Path(__file__).resolve().parents[1]
PARKING = "sb3_swirl/ParallelParking-v0"


def _mountaincar_demos(path: Path, n: int = 10) -> None:
    """Demos of the energy-pumping policy (push the way the car moves), which reaches the goal."""
    env = gym.make("MountainCar-v0")
    demos = []
    for seed in range(n):
        obs, _ = env.reset(seed=seed)
        states, actions, rewards, done, terminated = [obs], [], [], False, False
        while not done:
            action = 2 if obs[1] >= 0 else 0
            obs, reward, terminated, truncated, _ = env.step(action)
            states.append(obs)
            actions.append(action)
            rewards.append(reward)
            done = terminated or truncated
        assert terminated
        demos.append(
            sb3_swirl.Demonstration(np.array(states), np.array(actions), np.array(rewards))
        )
    sb3_swirl.save_demos(demos, path)


MOUNTAINCAR_ENTRY = {
    "n_timesteps": 1500,
    "policy": "MlpPolicy",
    "policy_kwargs": "dict(net_arch=[64, 64])",
    "env_wrapper": [
        {
            "sb3_swirl.zoo.SwirlTaskWrapper": {
                "demos": "mountaincar_demos.npz",
                "reward_config": {"mode": "potential", "task_reward_weight": 10.0},
            }
        }
    ],
    "learning_rate": 0.0003,
    "learning_starts": 200,
    "batch_size": 64,
    "exploration_initial_eps": 0.1,
    "exploration_final_eps": 0.02,
    "target_update_interval": 500,
    "prefill_replay": True,
}


def test_rl_zoo3_is_the_pinned_version():
    import rl_zoo3

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert (
        f"rl_zoo3[plots]=={zoo.RL_ZOO3_VERSION}"
        in pyproject["project"]["optional-dependencies"]["zoo"]
    )
    assert rl_zoo3.__version__ == zoo.RL_ZOO3_VERSION


def test_register_adds_swirl_dqn_to_the_zoo_tables():
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER
    from rl_zoo3.utils import ALGOS

    zoo.register()
    assert ALGOS["swirl_dqn"] is sb3_swirl.SwirlDQN
    assert HYPERPARAMS_SAMPLER["swirl_dqn"] is zoo.sample_swirl_dqn_params
    assert HYPERPARAMS_CONVERTER["swirl_dqn"] is zoo.convert_swirl_dqn_params


@pytest.mark.parametrize("algo", ["swirl_dqn", "dqn"])
def test_shipped_configs_cover_every_registered_task(algo):
    from sb3_swirl.supervisors import SUPERVISORS

    entries = yaml.safe_load(zoo.shipped_config(algo).read_text())
    ours = {env_id for env_id in gym.registry if env_id.startswith("sb3_swirl/")}
    assert ours <= set(entries) and "default" in entries
    if algo == "swirl_dqn":  # every entry's demos: a supervisor we ship, or a file
        for env_id in ours:
            spec = entries[env_id]["env_wrapper"][0]["sb3_swirl.zoo.SwirlTaskWrapper"]
            assert spec["demos"]["n_demos"] >= 2 and env_id in SUPERVISORS
            assert spec["reward_config"]["gamma"] == entries[env_id]["gamma"]


def test_every_shipped_entry_names_the_segmentation_its_agent_was_tuned_with():
    """fit_task's defaults may change (they did: auto, aligned entries); an entry that left the
    indicator or the regions' construction to them would change its tuned agent silently."""
    from sb3_swirl.experiments import _swirl_spec

    entries = yaml.safe_load(zoo.shipped_config("swirl_dqn").read_text())
    fitted = {env_id: _swirl_spec(entry).get("fit") for env_id, entry in entries.items()}
    assert "default" in fitted and len(fitted) > 5
    for env_id, fit in fitted.items():
        assert fit["indicator"] in ("gmm", "velocity") and fit["align_entries"] is False, env_id


def test_train_enjoy_tensorboard_and_plots_swirl_dqn_and_dqn(tmp_path, zoo_cli):
    """The zoo's log folders (config, model, task), true-reward evaluations, swirl/ keys in
    TensorBoard, enjoy with the segment shown, and rl_zoo3's plots of both algorithms."""
    common = ["--env", PARKING, "-f", "logs", "-n", "2000", "--eval-freq", "1000"]
    common += ["--eval-episodes", "3"]
    zoo_cli("train", "--algo", "swirl_dqn", "--seed", "0", "-tb", "tb", *common)
    # a second seed of each: the zoo's plots aggregate over runs
    zoo_cli("train", "--algo", "swirl_dqn", "--seed", "1", *common)
    for seed in ("0", "1"):
        zoo_cli("train", "--algo", "dqn", "--seed", seed, *common)

    run = tmp_path / "logs/swirl_dqn/sb3_swirl-ParallelParking-v0_1"
    params = run / "sb3_swirl-ParallelParking-v0"
    for name in ("config.yml", "args.yml", "task.json"):
        assert (params / name).is_file(), name
    model = sb3_swirl.SwirlDQN.load(run / "sb3_swirl-ParallelParking-v0.zip", device="cpu")
    task = sb3_swirl.TaskModel.from_json(params / "task.json")
    # the model's task, with the reward settings it was trained with (the entry's)
    trained = dataclasses.replace(model.task, reward_config=model.reward_config)
    assert task.to_json() == trained.to_json() and task.n_segments >= 2
    assert task.reward_config.potential and task.reward_config.task_reward_weight == 10.0
    config = yaml.load((params / "config.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert dict(config)["prefill_replay"] is True

    # evaluations score the true reward (parking's is 1 on success, else 0), not the proxy one
    with np.load(run / "evaluations.npz") as npz:
        evaluations = dict(npz)
    assert set(np.unique(evaluations["results"])) <= {0.0, 1.0}
    assert evaluations["successes"][-1].mean() > 0  # the cloned and trained agent parks

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = (tmp_path / "tb").glob("*/SwirlDQN_1")
    accumulator = EventAccumulator(str(events))
    accumulator.Reload()
    scalars = set(accumulator.Tags()["scalars"])
    assert {"swirl/final_segment_mean", "swirl/reach_rate_seg0", "bc/accuracy"} <= scalars

    enjoy = ["--env", PARKING, "-f", "logs", "-n", "210", "--no-render"]  # > one episode
    out = zoo_cli("enjoy", "--algo", "swirl_dqn", *enjoy)
    assert f"the model's task, {task.n_segments} segments" in out
    assert re.search(r"step \d+: segment 1 \(of 0-", out)
    assert "true return" in out
    assert "Episode Length" in zoo_cli("enjoy", "--algo", "dqn", *enjoy)

    # the monitor file logs each episode's success, which plot_train -y success reads
    assert "is_success" in (run / "0.monitor.csv").read_text().splitlines()[1].split(",")
    out = zoo_cli(
        "plot_train", "-a", "swirl_dqn", "-e", "ParallelParking-v0", "-f", "logs", "-y", "success"
    )
    assert "No data" not in out

    plots = ["all_plots", "-a", "swirl_dqn", "dqn", "-e", "ParallelParking-v0", "-f", "logs"]
    zoo_cli(*plots, "--no-display", "-o", "curves", "-k", "results")
    zoo_cli("plot_from_file", "-i", "curves.pkl", "-o", "curves.png", "--format", "png")
    assert (tmp_path / "curves.png").stat().st_size > 1000


def test_enjoy_names_the_runs_with_a_model_when_the_latest_has_none(tmp_path, monkeypatch, capsys):
    """A refused or interrupted run leaves its folder, which rl_zoo3 takes as the latest."""
    monkeypatch.chdir(tmp_path)
    runs = tmp_path / "logs/swirl_dqn"
    (runs / "sb3_swirl-ParallelParking-v0_1").mkdir(parents=True)
    (runs / "sb3_swirl-ParallelParking-v0_1/sb3_swirl-ParallelParking-v0.zip").write_bytes(b"")
    (runs / "sb3_swirl-ParallelParking-v0_2").mkdir()
    enjoy = ["enjoy", "--algo", "swirl_dqn", "--env", PARKING, "-f", "logs", "--no-render"]
    assert zoo.main(enjoy) == 2
    error = capsys.readouterr().err
    assert "No model found" in error and "Runs that hold one: --exp-id 1" in error
    assert zoo.main([*enjoy, "--exp-id", "2"]) == 2  # asked for: no hint
    assert "Runs that hold one" not in capsys.readouterr().err
    assert zoo.main([*enjoy, "--exp-id", "latest"]) == 2  # rl_zoo3 said "invalid literal"
    assert "--exp-id 'latest': give a run's number" in capsys.readouterr().err


def test_yaml_for_a_plain_gymnasium_env_with_a_demo_file(tmp_path, monkeypatch):
    """MountainCar (no supervisor of ours): 10 demos from a file, SwirlDQN through the zoo."""
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz")
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({"MountainCar-v0": MOUNTAINCAR_ENTRY}))
    # rl_zoo3 draws a random seed unless given one: the test must not depend on it
    args = ["train", "--algo", "swirl_dqn", "--env", "MountainCar-v0", "-conf", "mine.yml"]
    args += ["--seed", "0"]
    assert zoo.main([*args, "-f", "logs", "--eval-freq", "1500", "--eval-episodes", "3"]) == 0
    with np.load(tmp_path / "logs/swirl_dqn/MountainCar-v0_1/evaluations.npz") as npz:
        evaluations = dict(npz)
    # plain DQN rarely reaches the flag in 1500 steps; the cloned agent does (true reward)
    assert evaluations["ep_lengths"][-1].max() < 200
    assert evaluations["results"][-1].mean() > -200


def test_a_tuned_trials_swirl_settings_are_given_with_params_and_saved(tmp_path, zoo_cli):
    """-params reg_covar:... task_reward_weight:... (the -optimize report's names) reach the
    SwirlTaskWrapper's fit and reward_config, and the run's config.yml says so."""
    zoo_cli("train", "--algo", "swirl_dqn", "--env", PARKING, "-f", "logs", "-n", "100",
            "-params", "reg_covar:0.3", "bc_epochs:1", "task_reward_weight:2.0",
            "gamma:0.98")  # fmt: skip
    params = tmp_path / "logs/swirl_dqn/sb3_swirl-ParallelParking-v0_1/sb3_swirl-ParallelParking-v0"
    config = dict(yaml.load((params / "config.yml").read_text(), Loader=yaml.UnsafeLoader))
    spec = config["env_wrapper"][0]["sb3_swirl.zoo.SwirlTaskWrapper"]
    assert spec["fit"]["reg_covar"] == 0.3 and spec["fit"]["indicator"] == "gmm"  # merged in
    assert (
        spec["reward_config"]["task_reward_weight"] == 2.0
        and spec["reward_config"]["mode"] == "potential"
    )
    assert config["bc_epochs"] == 1
    # gamma goes to the agent and to the shaping, as a trial's does (no mismatch warning)
    assert config["gamma"] == 0.98 and spec["reward_config"]["gamma"] == 0.98
    task = sb3_swirl.TaskModel.from_json(params / "task.json")
    assert task.metadata["segmentation"]["params"]["reg_covar"] == 0.3
    assert task.reward_config.task_reward_weight == 2.0 and task.reward_config.gamma == 0.98


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"learning_rat": 0.001}, "unknown key 'learning_rat' (did you mean 'learning_rate'?)"),
        ({"demos": "missing.npz"}, "demos: file 'missing.npz' not found"),
        ({"fitt": {}}, "SwirlTaskWrapper: unknown key 'fitt' (did you mean 'fit'?)"),
        ({"fit": {"reg_covr": 0.1}}, "unexpected keyword arguments ['reg_covr']"),
        ({"demos": {"n_demos": 3}}, "MountainCar-v0 ships no supervisor"),
        ({"env": "CartPole-v1"}, "observations have 2 dims, but CartPole-v1's observations have 4"),
        ({"env_wrapper": None}, "swirl_dqn needs the SWIRL task"),
        ({"terminate_on_completion": True}, "terminate_on_completion cannot be used in the zoo"),
        ({"fit": 0.1}, "SwirlTaskWrapper fit: expected a mapping of settings"),
        ({"env": "MountainCarContinuous-v0"}, "SwirlDQN needs discrete actions"),
        ({"frame_stack": 2}, "frame_stack: swirl_dqn clones the demos' single states"),
        # these failed inside rl_zoo3 (a KeyError), named the wrong thing, or came after the fit
        ({"n_timesteps": None}, "no n_timesteps (rl_zoo3 needs it; -n overrides it)"),
        ({"env_wrapper": "bare"}, "env_wrapper sb3_swirl.zoo.SwirlTaskWrapper has no settings"),
        ({"reward_config": {"mode": "potentail"}}, "mode must be one of"),
        ({"state_key": "observation"}, "state_key='observation' is only for Dict observation"),
        ({"fit": {"random_state": 5}}, "random_state is the wrapper's `seed:`"),
        ({"seed": "x"}, "SwirlTaskWrapper seed must be an integer"),
    ],
)
def test_bad_yaml_fails_before_training_naming_the_problem(
    tmp_path, monkeypatch, capsys, change, message
):
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=2)
    entry = dict(MOUNTAINCAR_ENTRY)
    change = dict(change)
    env_id = change.pop("env", "MountainCar-v0")
    spec = dict(entry["env_wrapper"][0]["sb3_swirl.zoo.SwirlTaskWrapper"])
    for key, value in change.items():
        if key in (
            "demos",
            "fit",
            "fitt",
            "terminate_on_completion",
            "reward_config",
            "state_key",
            "seed",
        ):
            spec[key] = value
        elif key == "n_timesteps":
            del entry[key]
        else:
            entry[key] = value
    if entry.get("env_wrapper") == "bare":  # the wrapper's name without its settings
        entry["env_wrapper"] = ["sb3_swirl.zoo.SwirlTaskWrapper"]
    elif entry.get("env_wrapper"):
        entry["env_wrapper"] = [{"sb3_swirl.zoo.SwirlTaskWrapper": spec}]
    (tmp_path / "bad.yml").write_text(yaml.safe_dump({env_id: entry}))
    args = ["train", "--algo", "swirl_dqn", "--env", env_id, "-conf", "bad.yml", "-f", "logs"]
    assert zoo.main(args) == 2
    err = capsys.readouterr().err
    assert message in err and "bad.yml" in err
    assert not (tmp_path / "logs").exists()  # nothing started


def test_options_are_read_as_rl_zoo3_reads_them(tmp_path, monkeypatch, capsys):
    """rl_zoo3's argparse takes --name=value and abbreviations: sb3-swirl read its options
    verbatim, so `--conf mine.yml` trained the shipped config (appended after it), and
    --hyperparams=... / -params=... failed deep inside (StopIteration)."""
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=2)
    entry = dict(MOUNTAINCAR_ENTRY) | {"learning_rat": 0.001}
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({"MountainCar-v0": entry}))
    base = ["train", "--env", "MountainCar-v0", "-f", "logs"]
    assert zoo.main([*base, "--algo=swirl_dqn", "--conf-file=mine.yml"]) == 2
    assert "mine.yml, entry 'MountainCar-v0': unknown key 'learning_rat'" in capsys.readouterr().err
    for params in ("--hyperparams=learning_rat:1", "-params=learning_rat:1"):
        assert zoo.main([*base, "--algo", "swirl_dqn", params]) == 2
        assert "-params: unknown key 'learning_rat'" in capsys.readouterr().err
    # an abbreviation of an option sb3-swirl reads is refused, not read as something else
    assert zoo.main([*base, "--algo", "swirl_dqn", "--conf", "mine.yml"]) == 2
    assert "--conf abbreviates --conf-file? " in capsys.readouterr().err
    assert zoo.main([*base, "--algo", "swirl_dqn", "--v", "1"]) == 2  # --verbose or --vec-env
    assert "write the option in full" in capsys.readouterr().err
    assert not (tmp_path / "logs").exists()


def test_another_algorithm_on_a_swirl_task_keeps_the_task_for_enjoy(tmp_path, monkeypatch, capsys):
    """PPO with the SwirlTaskWrapper: the run keeps its task, and enjoy runs with it even where
    the demos it was fitted on are gone."""
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=4)
    wrapper = MOUNTAINCAR_ENTRY["env_wrapper"]
    entry = {"n_timesteps": 128, "policy": "MlpPolicy", "n_steps": 64, "env_wrapper": wrapper}
    (tmp_path / "ppo.yml").write_text(yaml.safe_dump({"MountainCar-v0": entry}))
    args = ["--algo", "ppo", "--env", "MountainCar-v0", "-f", "logs"]
    assert zoo.main(["train", *args, "-conf", "ppo.yml", "--seed", "0"]) == 0
    saved = sb3_swirl.TaskModel.from_json(
        tmp_path / "logs/ppo/MountainCar-v0_1/MountainCar-v0/task.json"
    )
    assert saved.reward_config.potential and saved.reward_config.task_reward_weight == 10.0
    (tmp_path / "mountaincar_demos.npz").unlink()
    capsys.readouterr()
    assert zoo.main(["enjoy", *args, "-n", "210", "--no-render"]) == 0
    out = capsys.readouterr().out
    assert f"the model's task, {saved.n_segments} segments" in out and "true return" in out


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (["bc_epoch:3"], "-params: unknown key 'bc_epoch' (did you mean 'bc_epochs'?)"),
        (["learning_rate:abc"], "-params: name 'abc' is not defined; give key:value pairs"),
        (["bc_epochs:-3"], "bc_epochs must be an integer >= 0, got -3"),
    ],
)
def test_bad_params_are_one_line_naming_the_option(tmp_path, monkeypatch, capsys, params, message):
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=2)
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({"MountainCar-v0": MOUNTAINCAR_ENTRY}))
    args = ["train", "--algo", "swirl_dqn", "--env", "MountainCar-v0", "-conf", "mine.yml"]
    assert zoo.main([*args, "-f", "logs", "-n", "100", "-params", *params]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and "mine.yml" not in err, err


def test_logging_an_info_key_the_env_lacks_is_one_line(tmp_path, monkeypatch, capsys):
    """An entry copied from a shipped one logs is_success, which MountainCar does not give:
    SB3's Monitor fails at the first episode's end, said in one line naming the key."""
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=2)
    entry = MOUNTAINCAR_ENTRY | {"monitor_kwargs": "dict(info_keywords=('is_success',))"}
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({"MountainCar-v0": entry}))
    args = ["train", "--algo", "swirl_dqn", "--env", "MountainCar-v0", "-conf", "mine.yml"]
    params = ["-params", "bc_epochs:1", "pretrain_td_steps:0", "learning_starts:1000"]
    assert zoo.main([*args, "-f", "logs", "-n", "300", "--eval-freq", "-1", *params]) == 2
    err = capsys.readouterr().err
    assert "monitor_kwargs: the entry logs info key 'is_success'" in err, err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--env", "ParallelParking-v0"], "Did you mean 'sb3_swirl/ParallelParking-v0'?"),
        (["--env", "Mine-v0", "--gym-packages", "no_such_module"], "--gym-packages no_such_module"),
    ],
)
def test_unknown_env_id_fails_before_training(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    assert zoo.main(["train", "--algo", "swirl_dqn", *argv, "-f", "logs"]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "logs").exists()


def test_optimize_two_trials_writes_the_study(tmp_path, zoo_cli):
    args = [
        "train",
        "--algo",
        "swirl_dqn",
        "--env",
        PARKING,
        "-f",
        "logs",
        "-n",
        "400",
        "--seed",
        "0",
    ]
    args += ["-optimize", "--n-trials", "2", "--n-evaluations", "1", "--eval-episodes", "2"]
    study = ["--storage", "sqlite:///study.db", "--study-name", "s"]
    zoo_cli(*args, *study, "--no-optim-plots", "--sampler", "random", "--pruner", "none")
    (report,) = (tmp_path / "logs/swirl_dqn").glob("report_*.csv")
    text = report.read_text()
    assert "params_reg_covar" in text and "params_bc_epochs" in text
    assert len(text.strip().splitlines()) == 3  # header + 2 trials
    # trial 0 trains its own settings (rl_zoo3 alone took id 0 for none, and trained the
    # entry's); -params still override it
    base = ["train", "--algo", "swirl_dqn", "--env", PARKING, "-f", "logs", "-n", "100"]
    given = ["-params", "bc_epochs:1", "reg_covar:0.05"]
    out = zoo_cli(*base, *study, "--trial-id", "0", *given)
    assert "loading trial 0 from the Optuna study" in out
    import optuna

    trial = optuna.load_study(study_name="s", storage=f"sqlite:///{tmp_path}/study.db").trials[0]
    runs = (tmp_path / "logs/swirl_dqn").glob("*_[0-9]*/sb3_swirl-ParallelParking-v0")
    run = max(runs, key=lambda p: int(p.parent.name.rsplit("_", 1)[1]))  # the latest
    config = dict(yaml.load((run / "config.yml").read_text(), Loader=yaml.UnsafeLoader))
    assert config["learning_rate"] == trial.params["learning_rate"] and config["bc_epochs"] == 1
    task = sb3_swirl.TaskModel.from_json(run / "task.json")
    # -params' reg_covar overrides the trial's, as the config says (the trial's won, and
    # config.yml recorded a value the run did not use); the trial's other SWIRL settings hold
    assert task.metadata["segmentation"]["params"]["reg_covar"] == 0.05
    (wrapper,) = config["env_wrapper"]
    assert wrapper["sb3_swirl.zoo.SwirlTaskWrapper"]["fit"]["reg_covar"] == 0.05
    assert task.reward_config.task_reward_weight == trial.params["task_reward_weight"]


def test_a_trials_swirl_settings_reach_the_wrapper_and_the_agent():
    """The sampled reg_covar and gamma reach the wrapper (the fit, the shaping) and the demos
    the wrapper loaded reach SwirlDQN."""
    import optuna
    from stable_baselines3.common.vec_env import DummyVecEnv

    trial = optuna.trial.FixedTrial(
        {
            "one_minus_gamma": 0.02,
            "batch_size_pow": 5,
            "learning_rate": 1e-3,
            "train_freq": 4,
            "subsample_steps": 2,
            "exploration_final_eps": 0.05,
            "exploration_fraction": 0.2,
            "target_update_interval": 100,
            "net_arch": "small",
            "reg_covar": 0.05,
            "task_reward_weight": 3.0,
            "bc_epochs": 0,
            "demo_loss_coef": 0.5,
        }
    )
    try:
        params = zoo.sample_swirl_dqn_params(trial, 0, 1, {"using_her_replay_buffer": False})
        assert "reg_covar" not in params and params["bc_epochs"] == 0
        env = DummyVecEnv([lambda: zoo.SwirlTaskWrapper(gym.make(PARKING), demos={"n_demos": 3})])
    finally:
        zoo._TRIAL.__dict__.clear()
    config = env.get_attr("reward_config")[0]
    assert config.gamma == pytest.approx(0.98) and config.task_reward_weight == 3.0
    task = env.get_attr("task")[0]
    assert task.metadata["segmentation"]["params"]["reg_covar"] == 0.05
    model = sb3_swirl.SwirlDQN("MlpPolicy", env, **params)
    assert len(model.demonstrations) == 3


def test_an_entry_with_a_fitted_task_is_tuned_without_refitting(tmp_path, monkeypatch, capsys):
    """-optimize does not sample reg_covar for an entry that reads a fitted task (it would not
    refit it, and the wrapper refuses a fit beside a task); -params reg_covar is refused."""
    import optuna

    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=3)
    demos = sb3_swirl.load_demos(tmp_path / "mountaincar_demos.npz")
    sb3_swirl.fit_task(demos, indicator="velocity").to_json(tmp_path / "task.json")
    spec = {"demos": "mountaincar_demos.npz", "task": "task.json"}
    entry = MOUNTAINCAR_ENTRY | {"env_wrapper": [{"sb3_swirl.zoo.SwirlTaskWrapper": spec}]}
    (tmp_path / "mine.yml").write_text(yaml.safe_dump({"MountainCar-v0": entry}))
    args = ["train", "--algo", "swirl_dqn", "--env", "MountainCar-v0", "-conf", "mine.yml"]
    assert zoo.main([*args, "-f", "logs", "-n", "100", "-params", "reg_covar:0.3"]) == 2
    err = capsys.readouterr().err
    assert "-params reg_covar: mine.yml, entry 'MountainCar-v0' reads a fitted task" in err
    # the flag _train sets from the entry: the sampler then asks for no reg_covar
    sampled = {"learning_rate": 1e-3, "exploration_final_eps": 0.1, "exploration_fraction": 0.1}
    sampled |= {"one_minus_gamma": 0.01, "batch_size_pow": 5, "train_freq": 4}
    sampled |= {"subsample_steps": 1, "target_update_interval": 100, "net_arch": "small"}
    sampled |= {"task_reward_weight": 3.0, "bc_epochs": 0, "demo_loss_coef": 0.5}
    her = {"using_her_replay_buffer": False}
    monkeypatch.setitem(zoo._SAMPLED, "reg_covar", False)
    try:  # a FixedTrial fails on a parameter it does not hold
        zoo.sample_swirl_dqn_params(optuna.trial.FixedTrial(sampled), 0, 1, her)
        assert zoo._TRIAL.fit == {} and zoo._TRIAL.reward_config["task_reward_weight"] == 3.0
    finally:
        zoo._TRIAL.__dict__.clear()
    with pytest.raises(ValueError, match="reg_covar"):
        monkeypatch.setitem(zoo._SAMPLED, "reg_covar", True)
        zoo.sample_swirl_dqn_params(optuna.trial.FixedTrial(sampled), 0, 1, her)
    zoo._TRIAL.__dict__.clear()


def test_an_unknown_zoo_script_is_named(capsys):
    assert zoo.main(["bogus"]) == 2
    assert "unknown script 'bogus'; choose one of train, enjoy" in capsys.readouterr().err
    assert zoo.main(["tune"]) == 2
    assert "unknown script 'tune' (to tune: train -optimize)" in capsys.readouterr().err
    assert zoo.main(["-h"]) == 0
    assert "-optimize tunes" in capsys.readouterr().out


def test_only_errors_before_training_are_shortened():
    """A ValueError from inside ``learn`` keeps its traceback (a failure mid-run is not a
    setting the user mistyped)."""

    def learn():
        raise ValueError("mid-run")

    def __init__():
        raise ValueError("bad setting")

    for function, inside in ((learn, True), (__init__, False)):
        with pytest.raises(ValueError) as error:
            function()
        assert zoo._raised_in_learn(error.value) is inside


def test_another_algorithm_is_warned_when_the_shaping_discounts_otherwise(tmp_path, monkeypatch):
    """SwirlDQN checks its gamma against the wrapper's itself; PPO never sees the wrapper's."""
    monkeypatch.chdir(tmp_path)
    _mountaincar_demos(tmp_path / "mountaincar_demos.npz", n=2)
    spec = MOUNTAINCAR_ENTRY["env_wrapper"][0]["sb3_swirl.zoo.SwirlTaskWrapper"]
    entry = {
        "policy": "MlpPolicy",
        "n_timesteps": 1000,
        "env_wrapper": [{"sb3_swirl.zoo.SwirlTaskWrapper": spec}],
    }
    for gamma, warned in ((0.9, True), (0.99, False)):  # the wrapper shapes with 0.99
        (tmp_path / "ppo.yml").write_text(
            yaml.safe_dump({"MountainCar-v0": entry | {"gamma": gamma}})
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            zoo.check_config("ppo", "MountainCar-v0", tmp_path / "ppo.yml")
        said = [str(w.message) for w in caught if "discounts with gamma" in str(w.message)]
        assert bool(said) == warned, said
        assert not said or "ppo.yml, entry 'MountainCar-v0': the SWIRL wrapper shapes" in said[0]


def test_the_fits_warnings_print_on_one_line_during_a_script():
    """They printed as Python shows them, with the file and line of fit_task that raised them;
    warnings of others keep Python's format, and recorded warnings are still recorded."""
    from sb3_swirl.segmentation import SegmentationWarning

    with zoo._fit_warnings_on_one_line():
        ours = warnings.formatwarning("fewer regions", SegmentationWarning, "fitting.py", 255)
        theirs = warnings.formatwarning("deprecated", DeprecationWarning, "x.py", 1)
        with pytest.warns(SegmentationWarning, match="kept"):
            warnings.warn("kept", SegmentationWarning, stacklevel=1)
    assert ours == "sb3-swirl: warning: fewer regions\n"
    assert theirs.startswith("x.py:1: DeprecationWarning: deprecated")
    assert warnings.formatwarning("a", SegmentationWarning, "f.py", 2).startswith("f.py:2")
