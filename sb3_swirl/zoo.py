"""RL Baselines3 Zoo with SWIRL: ``sb3-swirl zoo train|enjoy|plot_train|all_plots|plot_from_file``.

rl_zoo3 has no plugin hook for algorithms, so this entry point adds ``swirl_dqn``
(:class:`~sb3_swirl.SwirlDQN`) to rl_zoo3's algorithm table and Optuna sampler tables
(:func:`register`) and then hands over to rl_zoo3's own ``train`` / ``enjoy`` / plotting, with
rl_zoo3's own arguments. ``python -m sb3_swirl.zoo ...`` is the same.

One YAML entry describes a SWIRL run. The SWIRL part is the env wrapper
:class:`SwirlTaskWrapper`: where the demos come from, how the task is fitted, the proxy reward;
every other key is rl_zoo3's (``n_timesteps``, ``policy``, ...) or a ``SwirlDQN`` argument::

    sb3_swirl/ParallelParking-v0:
      n_timesteps: 30000
      policy: MlpPolicy
      env_wrapper:
        - sb3_swirl.zoo.SwirlTaskWrapper:
            demos: {n_demos: 5, seed: 0}   # the env's supervisor; or a demo file path
            fit: {reg_covar: 0.1}          # fit_task settings
            reward_config: {mode: potential, task_reward_weight: 10.0, gamma: 0.99}
      learning_rate: 0.0003
      prefill_replay: true

``sb3-swirl zoo train`` checks the entry before rl_zoo3 starts (unknown keys, missing files,
demos that do not match the env) and fits the task once; ``enjoy`` runs a trained SwirlDQN with
the task saved in the model and prints the segment it is in.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import importlib
import inspect
import io
import json
import os
import sys
import tempfile
import threading
import traceback
import warnings
from collections.abc import Iterator, Mapping
from importlib.resources import files
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from sb3_swirl.demos import (
    Demonstration,
    DemoWarning,
    check_demos_fit_spaces,
    check_demos_state_key,
    joined_state_note,
    load_demos,
)
from sb3_swirl.vec_env import swirl_task, trained_task
from swirl_wrappers import RewardConfig, SwirlWrapper, TaskModel
from swirl_wrappers._validation import check_int
from swirl_wrappers.wrappers import StateKey, check_state_key_space, state_space

__all__ = ["RL_ZOO3_VERSION", "SwirlTaskWrapper", "check_config", "main", "register"]

#: The rl_zoo3 release whose tables :func:`register` extends (pinned by the ``zoo`` extra).
RL_ZOO3_VERSION = "2.9.2"

#: Set by ``enjoy``: a task JSON that :class:`SwirlTaskWrapper` uses instead of fitting (the
#: task saved with the model). An environment variable, so ``--n-envs`` subprocesses see it.
TASK_FILE_ENV = "SB3_SWIRL_ZOO_TASK"

# rl_zoo3 keys that never reach the algorithm's constructor (ExperimentManager pops them)
_ZOO_KEYS = {
    "n_timesteps",
    "n_envs",
    "policy",
    "env_wrapper",
    "vec_env_wrapper",
    "callback",
    "normalize",
    "frame_stack",
    "env_kwargs",
    "monitor_kwargs",
    "noise_type",
    "noise_std",
}
_DEMO_KEYS = ("n_demos", "seed", "env_kwargs")

# fitted tasks (and their demos) by spec: one fit for the train env, the eval env, every trial
_FITTED: dict[str, tuple[TaskModel, list[Demonstration] | None]] = {}
# -optimize: the sampled SWIRL settings of the current trial (the sampler, the env creation and
# the model of a trial run in one thread; Optuna's n_jobs runs trials in threads)
_TRIAL = threading.local()


def _closest(name: str, options: Any) -> str:
    match = difflib.get_close_matches(name, sorted(options), n=1)
    return f" (did you mean {match[0]!r}?)" if match else ""


def _check_keys(where: str, given: Mapping[str, Any], allowed: Any) -> None:
    for key in given:
        if key not in allowed:
            raise ValueError(
                f"{where}: unknown key {key!r}{_closest(str(key), allowed)}; known keys: "
                f"{', '.join(sorted(allowed))}"
            )


def _load_demos(
    spec: Any, env: gym.Env, seed: int, state_key: StateKey
) -> tuple[list[Demonstration], str]:
    """The demos of a ``demos:`` value and a description for messages."""
    if isinstance(spec, str | os.PathLike):
        path = Path(spec).expanduser()
        if not path.is_file():
            raise ValueError(
                f"SwirlTaskWrapper demos: file {os.fspath(spec)!r} not found (relative paths "
                f"start from the working folder, {os.getcwd()})"
            )
        return load_demos(path), f"demo file {os.fspath(spec)}"
    if not isinstance(spec, Mapping):
        raise ValueError(
            "SwirlTaskWrapper demos: expected a demo file path or a mapping "
            f"{{n_demos: N, seed: S, env_kwargs: {{...}}}} for the env's supervisor, got {spec!r}"
        )
    _check_keys("SwirlTaskWrapper demos", spec, _DEMO_KEYS)
    if "n_demos" not in spec:
        raise ValueError("SwirlTaskWrapper demos: n_demos is required (demos of the supervisor)")
    from sb3_swirl.supervisors import SUPERVISORS, collect_demos

    env_id = env.spec.id if env.spec is not None else None
    if env_id not in SUPERVISORS:
        raise ValueError(
            f"SwirlTaskWrapper demos: {env_id} ships no supervisor to collect demos from; give "
            "a demo file (`demos: path/to/demos.npz`, written by sb3_swirl.save_demos)"
        )
    demos = collect_demos(
        env_id,
        spec["n_demos"],
        seed=spec.get("seed", seed),
        state_key=state_key if isinstance(env.observation_space, gym.spaces.Dict) else None,
        **spec.get("env_kwargs", {}),
    )
    return list(demos), f"{spec['n_demos']} supervisor demos of {env_id}"


def _check_demos_fit_env(
    demos: list[Demonstration], source: str, env: gym.Env, state_key: StateKey
) -> None:
    """Refuse demos whose states or actions do not match ``env``'s spaces, naming ``source``."""
    space = env.observation_space
    if isinstance(space, gym.spaces.Dict):
        state, keys = state_space(space, state_key)
        size = int(np.prod(state.shape))
        keys = [keys] if isinstance(keys, str) else list(keys)
        check_demos_state_key(demos, keys, f"{source}, demo")
        hint = joined_state_note({key: int(np.prod(space[key].shape)) for key in keys})
    else:
        size, hint = int(np.prod(space.shape)), f" ({space})"
    name = env.spec.id if env.spec is not None else "the env"
    check_demos_fit_spaces(
        demos,
        size,
        env.action_space,
        f"{source}, demo",
        f"but {name}'s observations",
        hint,
    )


def _fitted_task(
    env: gym.Env,
    demos: Any,
    task: Any,
    fit: Mapping[str, Any],
    seed: int,
    state_key: StateKey,
) -> tuple[TaskModel, list[Demonstration] | None]:
    """The task (fitted, or read from ``task``) and the demos, once per spec."""
    from sb3_swirl.fitting import fit_task

    if demos is None and task is None:
        raise ValueError(
            "SwirlTaskWrapper needs `demos` (a demo file, or {n_demos: N} for the env's "
            "supervisor) or `task` (a task JSON saved by `sb3-swirl fit` or TaskModel.to_json)"
        )
    if task is not None and fit:
        raise ValueError("SwirlTaskWrapper: give `fit` or a fitted `task`, not both")
    if not isinstance(fit, Mapping):
        raise ValueError(f"SwirlTaskWrapper fit: expected fit_task settings, got {fit!r}")
    if "random_state" in fit:
        raise ValueError(
            "SwirlTaskWrapper fit: random_state is the wrapper's `seed:` (beside `fit:`), "
            f"not a fit setting; write seed: {fit['random_state']!r}"
        )
    seed = check_int("SwirlTaskWrapper seed", seed, low=0, high=2**32 - 1)
    env_id = env.spec.id if env.spec is not None else repr(env)
    key = json.dumps([env_id, demos, task, dict(fit), seed, state_key], sort_keys=True, default=str)
    if key in _FITTED:
        return _FITTED[key]
    demonstrations = None
    if demos is not None:
        demonstrations, source = _load_demos(demos, env, seed, state_key)
        _check_demos_fit_env(demonstrations, source, env, state_key)
    if task is not None:
        path = Path(task).expanduser()
        if not path.is_file():
            raise ValueError(f"SwirlTaskWrapper task: file {os.fspath(task)!r} not found")
        model = TaskModel.from_json(path)
    else:
        try:
            model = fit_task(demonstrations, random_state=seed, **fit)
        except TypeError as exc:  # unknown settings: fit_task names them and the known ones
            raise ValueError(f"SwirlTaskWrapper fit: {exc}") from None
    _FITTED[key] = (model, demonstrations)
    return _FITTED[key]


class SwirlTaskWrapper(SwirlWrapper):
    """:class:`~swirl_wrappers.SwirlWrapper` that builds its task from a config (rl_zoo3's
    ``env_wrapper``).

    It loads or collects the demos, fits the task with :func:`sb3_swirl.fit_task` (once per
    process for the same settings: the training env, the evaluation env and every sub-env
    share it) and lifts the env with it. The demos ride along as :attr:`demonstrations`, which
    :class:`~sb3_swirl.SwirlDQN` clones when it is given none. The env's own reward stays in
    ``info["task_reward"]``, and an rl_zoo3 ``Monitor`` (inside this wrapper) records it, so
    the zoo's evaluations, logs and plots report the true task reward and success.

    Parameters
    ----------
    env : gymnasium.Env
    demos : str or mapping, optional
        A demo file in any format :func:`sb3_swirl.load_demos` reads, or
        ``{n_demos: N, seed: S, env_kwargs: {...}}``: ``N`` demos of the env's shipped
        supervisor (``seed`` defaults to ``seed``; ``env_kwargs`` go to ``gym.make`` for the
        demonstrations only).
    task : str, optional
        A fitted task JSON (``sb3-swirl fit``, ``TaskModel.to_json``) instead of fitting one;
        ``demos`` are then only cloned.
    fit : mapping, optional
        :func:`sb3_swirl.fit_task` settings (``reg_covar``, ``indicator``, ``dims``, ...).
    seed : int
        The fit's ``random_state`` (and the supervisor's default seed).
    reward_config, state_key :
        As in :class:`~swirl_wrappers.SwirlWrapper`.
    terminate_on_completion : bool
        Refused: rl_zoo3 puts its ``Monitor`` below this wrapper, which would never see the
        episodes it ends (in Python, :func:`sb3_swirl.make_swirl_env` puts ``Monitor`` outside).

    Attributes
    ----------
    demonstrations : list of Demonstration or None
    """

    def __init__(
        self,
        env: gym.Env,
        demos: str | Mapping[str, Any] | None = None,
        task: str | None = None,
        fit: Mapping[str, Any] | None = None,
        seed: int = 0,
        reward_config: Mapping[str, Any] | None = None,
        terminate_on_completion: bool = False,
        state_key: StateKey = None,
    ) -> None:
        if terminate_on_completion:  # before the fit: check_config builds this wrapper too
            raise ValueError(
                "terminate_on_completion cannot be used in the zoo: rl_zoo3 puts its Monitor "
                "below the SWIRL wrapper, and the Monitor would never see the episodes it ends. "
                "In Python, make_swirl_env(env_id, task, wrapper_kwargs={'terminate_on_completion'"
                ": True}) puts Monitor outside"
            )
        for name, value, example in (
            ("fit", fit, "{reg_covar: 0.1}"),
            ("reward_config", reward_config, "{mode: potential, task_reward_weight: 1.0}"),
        ):
            if value is not None and not isinstance(value, Mapping):
                raise ValueError(
                    f"SwirlTaskWrapper {name}: expected a mapping of settings ({example}), "
                    f"got {value!r}"
                )
        saved = os.environ.get(TASK_FILE_ENV)
        reward = {**(reward_config or {}), **getattr(_TRIAL, "reward_config", {})}
        # settings that cannot work, before the fit takes its time
        RewardConfig().updated(reward)
        check_state_key_space(env.observation_space, state_key)
        if saved:  # enjoy: the task the model was trained with
            model, demonstrations = TaskModel.from_json(Path(saved)), None
        else:
            model, demonstrations = _fitted_task(
                env, demos, task, {**(fit or {}), **getattr(_TRIAL, "fit", {})}, seed, state_key
            )
        super().__init__(
            env,
            model,
            reward_config=reward,
            terminate_on_completion=terminate_on_completion,
            state_key=state_key,
        )
        self.demonstrations = demonstrations
        self._announce = bool(saved)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._steps, self._task_return = 0, 0.0
        return super().reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        before = self.segment
        obs, reward, terminated, truncated, info = super().step(action)
        if self._announce:  # enjoy: say where the agent is in the task
            self._steps += 1
            self._task_return += float(info["task_reward"])
            k = self.task.n_segments
            if self.segment != before:
                where = (
                    f"segment {self.segment} (of 0-{k - 1})"
                    if self.segment < k
                    else "every region reached"
                )
                print(f"step {self._steps}: {where}")
            if terminated or truncated:
                success = f", success {info['is_success']}" if "is_success" in info else ""
                print(
                    f"episode ends at step {self._steps}, {self.segment} of {k} regions "
                    f"reached: true return {self._task_return:.2f}{success} (the episode reward "
                    "below is the proxy reward)",
                    flush=True,
                )
        return obs, reward, terminated, truncated, info


# ---------------------------------------------------------------------- Optuna (-optimize)
# SWIRL's own settings: in the wrapper (fit, reward) and in SwirlDQN (BC)
_WRAPPER_PARAMS = {"reg_covar": "fit", "task_reward_weight": "reward_config"}
_SWIRL_PARAMS = {*_WRAPPER_PARAMS, "bc_epochs", "demo_loss_coef"}
# the settings -optimize samples beyond DQN's; without reg_covar for an entry that reads a
# fitted task (``task:``), which is not refitted (set by ``_train``)
_SAMPLED = {"reg_covar": True}
# the keys -params gives (set by ``_train``): with --trial-id they override the trial's, as
# rl_zoo3's custom hyperparameters override a loaded trial's
_GIVEN: set[str] = set()


def _route_trial_params(params: dict[str, Any]) -> dict[str, Any]:
    """Put a trial's wrapper settings where :class:`SwirlTaskWrapper` reads them; return the
    algorithm's."""
    _TRIAL.fit, _TRIAL.reward_config = {}, {}
    agent = {}
    for key, value in params.items():
        if key in _WRAPPER_PARAMS:
            getattr(_TRIAL, _WRAPPER_PARAMS[key])[key] = value
        else:
            agent[key] = value
    if "gamma" in agent:  # potential shaping is policy-invariant only with the agent's gamma
        _TRIAL.reward_config["gamma"] = agent["gamma"]
    return agent


def sample_swirl_dqn_params(
    trial: Any, n_actions: int, n_envs: int, additional_args: dict[str, Any]
) -> dict[str, Any]:
    """rl_zoo3's DQN search space plus SWIRL's: the region covariance floor ``reg_covar``, the
    weight of the true reward in the proxy reward, BC epochs and the demo loss weight."""
    from rl_zoo3.hyperparams_opt import sample_dqn_params

    params = sample_dqn_params(trial, n_actions, n_envs, additional_args)
    if _SAMPLED["reg_covar"]:
        params["reg_covar"] = trial.suggest_float("reg_covar", 1e-4, 1.0, log=True)
    params["task_reward_weight"] = trial.suggest_float("task_reward_weight", 1.0, 100.0, log=True)
    params["bc_epochs"] = trial.suggest_categorical("bc_epochs", [0, 100, 300])
    params["demo_loss_coef"] = trial.suggest_float("demo_loss_coef", 0.0, 2.0)
    return _route_trial_params(params)


def convert_swirl_dqn_params(sampled: dict[str, Any]) -> dict[str, Any]:
    """A finished trial's parameters as hyperparameters (``--trial-id``), SWIRL's included."""
    from rl_zoo3.hyperparams_opt import convert_offpolicy_params

    swirl = {k: v for k, v in sampled.items() if k in _SWIRL_PARAMS}
    dqn = convert_offpolicy_params({k: v for k, v in sampled.items() if k not in swirl})
    agent = _route_trial_params(dqn | swirl)
    for key in _GIVEN & _WRAPPER_PARAMS.keys():  # -params reach the wrapper's own settings
        getattr(_TRIAL, _WRAPPER_PARAMS[key]).pop(key, None)
    if "gamma" in _GIVEN:  # and -params' gamma the shaping, as the agent
        _TRIAL.reward_config.pop("gamma", None)
    return agent


def register() -> None:
    """Add ``swirl_dqn`` to rl_zoo3's ``ALGOS``, ``HYPERPARAMS_SAMPLER`` and
    ``HYPERPARAMS_CONVERTER`` (idempotent), and register the ``sb3_swirl/`` envs."""
    import rl_zoo3
    from rl_zoo3 import hyperparams_opt, utils

    from sb3_swirl.dqn import SwirlDQN

    if rl_zoo3.__version__ != RL_ZOO3_VERSION:
        import warnings

        warnings.warn(
            f"sb3-swirl extends rl_zoo3 {RL_ZOO3_VERSION}, found {rl_zoo3.__version__}: "
            f'install the pinned one (pip install "sb3-swirl[zoo]")',
            stacklevel=2,
        )
    utils.ALGOS["swirl_dqn"] = SwirlDQN
    hyperparams_opt.HYPERPARAMS_SAMPLER["swirl_dqn"] = sample_swirl_dqn_params
    hyperparams_opt.HYPERPARAMS_CONVERTER["swirl_dqn"] = convert_swirl_dqn_params


# ---------------------------------------------------------------------- config checks
def shipped_config(algo: str) -> Path:
    """The path of ``zoo_configs/{algo}.yml`` as installed with the package."""
    return Path(str(files("sb3_swirl.zoo_configs") / f"{algo}.yml"))


def check_config(
    algo: str,
    env_id: str,
    config: str | os.PathLike,
    overrides: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Check the rl_zoo3 entry for ``env_id`` in ``config`` before anything trains.

    An unregistered ``env_id``, unknown keys (neither rl_zoo3's nor the algorithm's), unknown
    ``SwirlTaskWrapper`` keys, missing demo or task files and demos that do not match the env
    fail with a message naming the file, the entry and the key. The SWIRL task is fitted here
    (and cached for the run). ``overrides`` (``-params``) may hold the SwirlTaskWrapper's
    ``reg_covar`` and ``task_reward_weight`` under the names the ``-optimize`` report gives
    them: the returned entry has them in the wrapper's ``fit`` and ``reward_config``.

    Returns
    -------
    dict
        The entry (``default`` if the file has none for ``env_id``).
    """
    from rl_zoo3.utils import ALGOS

    try:
        gym.spec(env_id)
    except gym.error.Error as exc:
        close = difflib.get_close_matches(env_id, list(gym.registry), n=1)
        hint = f"Did you mean {close[0]!r}? Or register it" if close else "Register it"
        raise ValueError(
            f"{exc} {hint}: pass --gym-packages with the module that registers it"
        ) from None
    path = os.fspath(config)
    if not path.endswith((".yml", ".yaml")):
        return {}  # a .py or module config: rl_zoo3 reads it, nothing to check here
    if not Path(path).is_file():
        raise ValueError(f"config file {path} not found")
    with open(path) as fh:
        try:
            entries = yaml.safe_load(fh) or {}
        except yaml.YAMLError as exc:
            raise ValueError(f"{path} is not valid YAML: {exc}") from None
    name = env_id if env_id in entries else "default"
    if name not in entries:
        raise ValueError(f"{path} has no entry for {env_id} and no default entry")
    entry = entries[name]
    where = f"{path}, entry {name!r}"
    if not isinstance(entry, Mapping):
        raise ValueError(f"{where}: expected a mapping of hyperparameters, got {entry!r}")
    # rl_zoo3 passes env, seed, verbose, device and tensorboard_log itself
    passed = {"self", "env", "seed", "verbose", "device", "tensorboard_log", "_init_setup_model"}
    allowed = _ZOO_KEYS | set(inspect.signature(ALGOS[algo]).parameters) - passed
    overrides = dict(overrides or {})
    # a tuned trial's SWIRL settings (the -optimize report's reg_covar, task_reward_weight)
    swirl = {key: overrides.pop(key) for key in _WRAPPER_PARAMS if key in overrides}
    _check_keys("-params", overrides, allowed | _WRAPPER_PARAMS.keys())  # for "did you mean"
    _check_keys(where, entry, allowed)
    if "n_timesteps" not in entry:  # rl_zoo3 reads it even with -n (a KeyError deep inside)
        raise ValueError(f"{where}: no n_timesteps (rl_zoo3 needs it; -n overrides it)")
    bare = [w for w in _listed(entry.get("env_wrapper")) if str(w).endswith(".SwirlTaskWrapper")]
    if bare:
        raise ValueError(
            f"{where}: env_wrapper {bare[0]} has no settings: give them as "
            f"`- {bare[0]}: {{demos: ..., fit: {{...}}}}` (see zoo_configs/)"
        )
    entry = {**entry, **overrides}
    wrappers, ours, specs = _swirl_wrappers(entry)
    if swirl:
        if not specs:
            raise ValueError(
                f"-params {', '.join(swirl)}: settings of the SwirlTaskWrapper, which {where} "
                "does not have"
            )
        if "reg_covar" in swirl and any(spec.get("task") for spec in specs):
            raise ValueError(
                f"-params reg_covar: {where} reads a fitted task (task: ...), which is not "
                "refitted; fit it again with `sb3-swirl fit --reg-covar`, or give the entry "
                "demos and fit: {reg_covar: ...} instead of task"
            )
    if specs and "gamma" in overrides:  # potential shaping keeps the policy only with the
        swirl["gamma"] = overrides["gamma"]  # agent's gamma (-optimize's trials do the same)
    if swirl and specs:
        for i, spec in zip(ours, specs, strict=True):
            for key, value in swirl.items():
                section = _WRAPPER_PARAMS.get(key, "reward_config")
                spec[section] = {**(spec.get(section) or {}), key: value}
            wrappers[i] = {next(iter(wrappers[i])): spec}
        entry["env_wrapper"] = wrappers  # what rl_zoo3 gets and saves in config.yml
    if algo == "swirl_dqn" and not specs:
        raise ValueError(
            f"{where}: swirl_dqn needs the SWIRL task: add an env_wrapper entry "
            "`sb3_swirl.zoo.SwirlTaskWrapper: {demos: ..., fit: {...}}` (see zoo_configs/)"
        )
    if algo == "swirl_dqn" and entry.get("frame_stack"):
        raise ValueError(
            f"{where}: frame_stack: swirl_dqn clones the demos' single states, so it cannot "
            "train on stacked frames (other algorithms can)"
        )
    if not specs:  # nothing of ours to check: rl_zoo3 builds the env
        return dict(entry)
    try:
        env = gym.make(env_id, **(entry.get("env_kwargs") or {}))
    except gym.error.Error as exc:  # a dependency not installed, say
        raise ValueError(f"{where}: {env_id}: {exc}") from None
    try:
        if algo == "swirl_dqn":
            from sb3_swirl.dqn import check_discrete_actions

            with _reraise_in(where):  # the entry's other wrappers may shift the actions:
                check_discrete_actions(env.action_space, from_zero=False)  # SwirlDQN checks
        for spec in specs:
            allowed = set(inspect.signature(SwirlTaskWrapper).parameters) - {"env"}
            _check_keys(f"{where}, SwirlTaskWrapper", spec, allowed)
            with _reraise_in(where):
                if algo == "swirl_dqn" and isinstance(env.observation_space, gym.spaces.Dict):
                    from sb3_swirl.dqn import check_state_key_covers

                    # before the wrapper collects demos and fits
                    keys = state_space(env.observation_space, spec.get("state_key"))[1]
                    check_state_key_covers(env.observation_space, keys)
                wrapped = SwirlTaskWrapper(env, **spec)
            default = inspect.signature(ALGOS[algo]).parameters.get("gamma")  # ars: none
            gamma = entry.get("gamma", default and default.default)
            # SwirlDQN checks it itself, when it takes the env
            if algo != "swirl_dqn" and isinstance(gamma, float | int):
                mismatch = wrapped.reward_config.discount_mismatch(gamma, algo)
                if mismatch:
                    warnings.warn(f"{where}: {mismatch}", stacklevel=2)
    finally:
        env.close()
    return dict(entry)


def _listed(wrappers: Any) -> list[Any]:
    """An entry's ``env_wrapper`` as a list (rl_zoo3 takes one wrapper or a list)."""
    return list(wrappers) if isinstance(wrappers, list) else [wrappers] if wrappers else []


def _swirl_wrappers(entry: Mapping[str, Any]) -> tuple[list[Any], list[int], list[dict]]:
    """An entry's ``env_wrapper`` list, the positions of its SwirlTaskWrappers in it, and
    (copies of) their settings."""
    wrappers = _listed(entry.get("env_wrapper"))
    ours = [
        i
        for i, w in enumerate(wrappers)
        if isinstance(w, Mapping) and str(next(iter(w))).endswith(".SwirlTaskWrapper")
    ]
    return wrappers, ours, [dict(next(iter(wrappers[i].values())) or {}) for i in ours]


@contextlib.contextmanager
def _reraise_in(where: str) -> Iterator[None]:
    try:
        yield
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


# ---------------------------------------------------------------------- entry points
# the options of rl_zoo3's scripts that sb3-swirl reads itself, before rl_zoo3 does: the
# long ones, and the short ones a value may follow with "="
_READ = {
    "train": {
        "long": (
            "--algo",
            "--env",
            "--conf-file",
            "--hyperparams",
            "--optimize-hyperparameters",
            "--vec-env",
            "--gym-packages",
            "--env-kwargs",
            "--trained-agent",
        ),
        "short": ("-conf", "-params", "-optimize", "-i"),
    },
    "enjoy": {
        "long": (
            "--algo",
            "--env",
            "--exp-id",
            "--folder",
            "--load-best",
            "--load-checkpoint",
            "--load-last-checkpoint",
        ),
        "short": ("-f",),
    },
}


def _spelled_out(argv: list[str], script: str) -> list[str]:
    """``argv`` with the options sb3-swirl reads spelled as it reads them (``--name=value`` as
    ``--name value``); an abbreviation of one (``--conf`` for ``--conf-file``, which rl_zoo3's
    argparse may take) is a ValueError. Read verbatim, ``--conf mine.yml`` trained the shipped
    config, and ``--hyperparams=...`` failed deep inside."""
    names, short = _READ[script]["long"], _READ[script]["short"]
    out = []
    for arg in argv:
        name, eq, value = arg.partition("=")
        if name.startswith("--") and name not in names:
            matches = [full for full in names if full.startswith(name)]
            if matches and len(name) > 2:
                raise ValueError(
                    f"{name} abbreviates {' or '.join(matches)}? sb3-swirl reads "
                    f"{'it' if len(matches) == 1 else 'them'} before rl_zoo3, by the whole "
                    "name: write the option in full"
                )
        out += [name, value] if eq and name in names + short else [arg]
    return out


def _option(argv: list[str], *names: str, default: str | None = None) -> str | None:
    """The value of the last ``--name value`` among ``names`` in ``argv`` (spelled out by
    :func:`_spelled_out`: ``--name=value`` is split there)."""
    value = default
    for i, arg in enumerate(argv[:-1]):
        if arg in names:
            value = argv[i + 1]
    return value


def _train(argv: list[str]) -> int:
    from rl_zoo3.train import train
    from rl_zoo3.utils import ALGOS, StoreDict

    _GIVEN.clear()
    algo = str(_option(argv, "--algo", default="ppo"))
    env_id = _option(argv, "--env", default="CartPole-v1")
    config = _option(argv, "-conf", "--conf-file")
    shipped = shipped_config(algo)
    ours = algo == "swirl_dqn" or str(env_id).startswith("sb3_swirl/")
    if config is None and ours and shipped.is_file():
        config = os.fspath(shipped)
        argv = [*argv, "--conf-file", config]
        print(f"sb3-swirl: hyperparameters from {config}", flush=True)
    elif config is None and ours:
        print(
            f"sb3-swirl: no {shipped.name} ships with sb3-swirl: {algo} trains with rl_zoo3's "
            "own hyperparameters, without the SWIRL wrapper (give -conf with a SwirlTaskWrapper "
            "entry, as in zoo_configs/swirl_dqn.yml)",
            flush=True,
        )
    if config is not None and algo in ALGOS:
        try:
            # import the modules that register envs, as rl_zoo3 does: the check sees their ids
            for module in _parsed(argv, "--gym-packages", nargs="+", default=[]):
                try:
                    importlib.import_module(module)
                except ImportError as exc:
                    raise ValueError(f"--gym-packages {module}: {exc}") from None
            if (
                algo == "swirl_dqn"
                and _option(argv, "--vec-env") == "subproc"
                and ("-optimize" in argv or "--optimize-hyperparameters" in argv)
            ):
                raise ValueError(
                    "-optimize with --vec-env subproc: a trial's SWIRL settings (reg_covar, "
                    "task_reward_weight) would not reach the sub-processes; use the default "
                    "--vec-env dummy (Optuna's --n-jobs runs trials in parallel)"
                )
            # rl_zoo3's -params key:value ... overrides (each value eval'd, as rl_zoo3 does)
            try:
                overrides = _parsed(argv, "-params", "--hyperparams", nargs="+", action=StoreDict)
            except Exception as exc:  # rl_zoo3 eval()s each value: any error is the user's text
                raise ValueError(
                    f"-params: {exc}; give key:value pairs, each value a Python expression "
                    "(learning_rate:1e-4 exploration_fraction:0.2 "
                    'policy_kwargs:"dict(net_arch=[64, 64])")'
                ) from None
            entry = check_config(algo, str(env_id), config, overrides)
        except ValueError as exc:  # before anything trains: one clear line, no traceback
            print(f"error: {exc}", file=sys.stderr)
            return 2
        given = (overrides or {}).keys()
        _GIVEN.update(given)
        specs = _swirl_wrappers(entry)[2]
        if specs and (_WRAPPER_PARAMS.keys() | {"gamma"}) & given:
            argv = _wrapper_params_routed(argv, entry["env_wrapper"])
        _SAMPLED["reg_covar"] = not any(spec.get("task") for spec in specs)
        # rl_zoo3 2.9 gives an entry's env_kwargs to the training env only (its eval env and
        # `enjoy` get those of the command line): pass them on the command line too
        if entry.get("env_kwargs") and _option(argv, "--env-kwargs") is None:
            argv = [*argv, "--env-kwargs", *(f"{k}:{v!r}" for k, v in entry["env_kwargs"].items())]
        elif entry.get("env_kwargs"):
            print(
                f"sb3-swirl: --env-kwargs replaces the entry's env_kwargs {entry['env_kwargs']} "
                "(rl_zoo3 does not merge them): repeat those you want to keep",
                flush=True,
            )
    try:
        with _task_saved_with_each_run(), _trial_zero_loaded():
            _run(train, "train", argv)
    # a setting the algorithm refuses (SB3 asserts some), before training: one line
    except (ValueError, AssertionError) as exc:
        if _raised_in_learn(exc):
            raise
        hint = ""
        if _option(argv, "-i", "--trained-agent") is not None:
            hint = (
                " (with -i: if the entry's demos or fit changed, they must still give the task "
                "the model was trained with)"
            )
        print(f"error: {str(exc) or type(exc).__name__}{hint}", file=sys.stderr)
        return 2
    except KeyError as exc:  # SB3's Monitor logs an info key the env does not give
        frames = traceback.extract_tb(exc.__traceback__)
        if not frames or Path(frames[-1].filename).parts[-2:] != ("common", "monitor.py"):
            raise
        print(
            f"error: monitor_kwargs: the entry logs info key {exc} at each episode's end, "
            f"which {env_id} does not put in its info: drop it from info_keywords (an entry "
            "merged from a shipped one, <<: *parking, inherits ('is_success',))",
            file=sys.stderr,
        )
        return 2
    return 0


def _wrapper_params_routed(argv: list[str], wrappers: list[Any]) -> list[str]:
    """``argv`` with ``-params reg_covar:x task_reward_weight:y`` given as the env_wrapper
    entry that holds them (``check_config`` put them there), so that rl_zoo3 builds the
    wrapper with them and saves them in the run's ``config.yml``."""
    start = next(i for i, arg in enumerate(argv) if arg in ("-params", "--hyperparams")) + 1
    end = next((i for i in range(start, len(argv)) if argv[i].startswith("-")), len(argv))
    kept = [arg for arg in argv[start:end] if arg.split(":")[0] not in _WRAPPER_PARAMS]
    return [*argv[:start], *kept, f"env_wrapper:{wrappers!r}", *argv[end:]]


def _raised_in_learn(exc: BaseException) -> bool:
    """Whether ``exc`` came from inside an algorithm's ``learn`` (training had started)."""
    return any(frame.name == "learn" for frame in traceback.extract_tb(exc.__traceback__))


def _parsed(argv: list[str], *names: str, **kwargs: Any) -> Any:
    """The value of the option ``names`` in ``argv``, parsed with ``kwargs`` (as rl_zoo3
    declares it)."""
    import argparse

    parser = argparse.ArgumentParser(add_help=False)
    option = parser.add_argument(*names, **kwargs)
    return getattr(parser.parse_known_args(argv)[0], option.dest)


def _model_path(argv: list[str], env_id: str) -> tuple[str, str]:
    """rl_zoo3's (model path, log path) for the ``enjoy``-style options in ``argv``."""
    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_model_path

    with contextlib.redirect_stdout(io.StringIO()):  # rl_zoo3's enjoy says it again
        _, model_path, log_path = get_model_path(
            int(_option(argv, "--exp-id", default="0")),
            str(_option(argv, "-f", "--folder", default="rl-trained-agents")),
            str(_option(argv, "--algo", default="ppo")),
            EnvironmentName(env_id),
            "--load-best" in argv,
            _option(argv, "--load-checkpoint"),
            "--load-last-checkpoint" in argv,
        )
    return model_path, log_path


@contextlib.contextmanager
def _task_saved_with_each_run() -> Iterator[None]:
    """While rl_zoo3 trains, write the training env's task (with the reward settings it pays
    by) as ``task.json`` beside the run's ``config.yml`` when the run starts to learn, for any
    algorithm: ``enjoy`` runs the agent with it."""
    from rl_zoo3.exp_manager import ExperimentManager

    learn = ExperimentManager.learn

    def learn_with_the_task_saved(manager: Any, model: Any, *args: Any, **kwargs: Any) -> None:
        env, folder = model.get_env(), getattr(manager, "params_path", None)
        if swirl_task(env) is not None and folder is not None:
            trained_task(env).to_json(Path(folder) / "task.json")
        learn(manager, model, *args, **kwargs)

    ExperimentManager.learn = learn_with_the_task_saved
    try:
        yield
    finally:
        ExperimentManager.learn = learn


@contextlib.contextmanager
def _trial_zero_loaded() -> Iterator[None]:
    """``--trial-id 0`` trains Optuna's first trial: rl_zoo3 2.9.2 tests the id as a truth
    value, so it trained the entry's own settings, silently. Its trial goes in as rl_zoo3
    would put it (before ``-params``, which still override it)."""
    from rl_zoo3.exp_manager import ExperimentManager

    read = ExperimentManager.read_hyperparameters

    def read_with_trial_zero(manager: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        if manager.trial_id != 0 or not (manager.storage and manager.study_name):
            return read(manager)
        print("sb3-swirl: loading trial 0 from the Optuna study", flush=True)
        custom = manager.custom_hyperparams
        trial = manager.load_trial(manager.storage, manager.study_name, 0)
        manager.custom_hyperparams = {**trial, **(custom or {})}
        try:
            return read(manager)
        finally:
            manager.custom_hyperparams = custom

    ExperimentManager.read_hyperparameters = read_with_trial_zero
    try:
        yield
    finally:
        ExperimentManager.read_hyperparameters = read


def _saved_task(model_path: str) -> TaskModel:
    from stable_baselines3.common.save_util import load_from_zip_file

    data, _, _ = load_from_zip_file(model_path, load_data=True, device="cpu")
    if not data or not data.get("task_json"):
        raise ValueError(f"{model_path} holds no SWIRL task (not a SwirlDQN model?)")
    task = TaskModel.from_json(data["task_json"])
    if isinstance(data.get("reward_config"), RewardConfig):  # the reward it was trained with
        task = dataclasses.replace(task, reward_config=data["reward_config"])
    return task


def _runs_with_a_model(argv: list[str], env_id: str) -> str:
    """A hint for ``enjoy`` without ``--exp-id`` when the latest run holds no final model
    (a run refused or stopped before it ended leaves its folder): the runs that hold one."""
    from huggingface_sb3 import EnvironmentName

    loads = ("--load-best", "--load-checkpoint", "--load-last-checkpoint")
    if str(_option(argv, "--exp-id", default="0")) != "0" or any(a in argv for a in loads):
        return ""
    name = str(EnvironmentName(env_id))
    runs = Path(str(_option(argv, "-f", "--folder"))) / str(_option(argv, "--algo"))
    ids = sorted(
        int(run.name.rsplit("_", 1)[1])
        for run in runs.glob(f"{name}_[0-9]*")
        if run.name.rsplit("_", 1)[1].isdigit() and (run / f"{name}.zip").is_file()
    )
    if not ids:
        return ""
    return (
        "; the latest run holds no final model (refused, stopped before it ended, or an "
        "-optimize study's, which keeps none?). Runs that hold one: --exp-id "
        f"{', '.join(map(str, ids))}"
    )


def _enjoy(argv: list[str]) -> int:
    from rl_zoo3.enjoy import enjoy

    env_id = str(_option(argv, "--env", default="CartPole-v1"))
    exp_id = str(_option(argv, "--exp-id", default="0"))
    if not exp_id.isdigit():
        print(
            f"error: --exp-id {exp_id!r}: give a run's number (the N of ENV_N in the log "
            "folder), or 0 for the latest run",
            file=sys.stderr,
        )
        return 2
    if _option(argv, "--algo") != "swirl_dqn":
        from huggingface_sb3 import EnvironmentName

        # another algorithm trained on a SWIRL task here: its run holds the task.json
        try:
            _, log_path = _model_path(argv, env_id)
            saved = Path(log_path) / str(EnvironmentName(env_id)) / "task.json"
        except (AssertionError, ValueError):  # not here: rl_zoo3 looks for it (the hub...)
            saved = None
        if saved is None or not saved.is_file():
            _run(enjoy, "enjoy", argv)
            return 0
        task = TaskModel.from_json(saved)
    else:
        if _option(argv, "-f", "--folder") is None:
            argv = [*argv, "-f", "logs"]  # rl_zoo3 would look on the hub: no swirl_dqn there
        try:
            model_path, _ = _model_path(argv, env_id)
            task = _saved_task(model_path)
        except (AssertionError, ValueError) as exc:  # no such run or model
            hint = _runs_with_a_model(argv, env_id) if str(exc).startswith("No model") else ""
            print(f"error: {exc}{hint}", file=sys.stderr)
            return 2
    print(
        f"sb3-swirl: the model's task, {task.n_segments} segment{'s' * (task.n_segments != 1)}",
        flush=True,
    )
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "task.json"
        task.to_json(path)
        os.environ[TASK_FILE_ENV] = os.fspath(path)
        try:
            _run(enjoy, "enjoy", argv)
        finally:
            del os.environ[TASK_FILE_ENV]
    return 0


def _run(function: Any, name: str, argv: list[str]) -> None:
    saved = sys.argv
    sys.argv = [f"sb3-swirl zoo {name}", *argv]
    try:
        function()
    finally:
        sys.argv = saved


@contextlib.contextmanager
def _fit_warnings_on_one_line() -> Iterator[None]:
    """While a script runs, the fit's and the demo checks' warnings print as one line each
    (``sb3-swirl: warning: ...``), not with the file and line that raised them; others as
    Python shows them. Only their format changes: code that records warnings still gets them."""
    from sb3_swirl.segmentation import SegmentationWarning

    formatted = warnings.formatwarning

    def one_line(message: Any, category: type, *args: Any, **kwargs: Any) -> str:
        if issubclass(category, SegmentationWarning | DemoWarning):
            return f"sb3-swirl: warning: {message}\n"
        return formatted(message, category, *args, **kwargs)

    warnings.formatwarning = one_line
    try:
        yield
    finally:
        warnings.formatwarning = formatted


def main(argv: list[str] | None = None) -> int:
    """``sb3-swirl zoo SCRIPT [rl_zoo3's arguments]``: SCRIPT is ``train``, ``enjoy``,
    ``plot_train``, ``all_plots`` or ``plot_from_file``."""
    with _fit_warnings_on_one_line():
        return _main(list(sys.argv[1:] if argv is None else argv))


def _main(argv: list[str]) -> int:
    scripts = ("train", "enjoy", "plot_train", "all_plots", "plot_from_file")
    if not argv or argv[0] not in scripts:
        print(f"usage: sb3-swirl zoo {{{','.join(scripts)}}} [rl_zoo3 arguments, see -h]")
        if argv[:1] in (["-h"], ["--help"]):
            print(
                "\nrl_zoo3's scripts, with swirl_dqn among the algorithms and the shipped\n"
                "zoo_configs/ as the default -conf for swirl_dqn and the sb3_swirl/ envs:\n"
                "  train           train (-optimize tunes: DQN's search space and SWIRL's)\n"
                "  enjoy           run a trained model, with the task saved in it\n"
                "  plot_train      training curves of a run's monitor files\n"
                "  all_plots       evaluation curves of several algorithms and envs\n"
                "  plot_from_file  plot what all_plots saved\n"
                "`sb3-swirl zoo SCRIPT -h` gives rl_zoo3's arguments of SCRIPT"
            )
            return 0
        what = f"unknown script {argv[0]!r}" if argv else "no script given"
        hint = " (to tune: train -optimize)" if argv[:1] in (["tune"], ["optimize"]) else ""
        print(f"error: {what}{hint}; choose one of {', '.join(scripts)}", file=sys.stderr)
        return 2
    import sb3_swirl  # noqa: F401  (registers the sb3_swirl/ envs)

    register()
    script, rest = argv[0], argv[1:]
    if script in _READ:
        try:
            rest = _spelled_out(rest, script)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    if script == "train":
        return _train(rest)
    if script == "enjoy":
        return _enjoy(rest)
    from rl_zoo3 import plots

    _run(getattr(plots, script), script, rest)
    return 0


if __name__ == "__main__":
    # `python -m sb3_swirl.zoo`: run the imported module's main, so that the configs'
    # `sb3_swirl.zoo.SwirlTaskWrapper` and the registered sampler share one module state
    from sb3_swirl.zoo import main as _main

    sys.exit(_main())
