"""The paper's comparison methods (§8.2), with one interface and one result format.

:func:`run_method` fits a method on demos, trains it for a budget of env steps and evaluates
its true success, returning the record of :func:`sb3_swirl.experiments.train_and_evaluate`,
so SwirlDQN and every baseline share one table and one plot (:data:`METHODS` lists them:
SWIRL with model-free or MaxEnt rewards, DQN, RBF DQN, behavioural cloning with SVMs, a
perceptron or imitation's ``bc.BC``, Q-init, global IRL and GAIL).

A :class:`BCPolicy` predicts like a Stable-Baselines3 model (``predict(obs, deterministic)``),
so one evaluation loop scores it beside SwirlDQN and DQN. Fit it on the raw observations for
the paper's *behavioural cloning*, or on SWIRL-lifted observations (:func:`lifted_demos`) and
run it inside a :class:`~swirl_wrappers.SwirlWrapper` for its *segmented demonstrations*
(a clone per segment, no refinement).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from sklearn.exceptions import NotFittedError

from sb3_swirl.demos import Demonstration, as_demonstrations
from swirl_wrappers import Lifter, TaskModel, observation_state
from swirl_wrappers._validation import check_int, check_option, check_widths


class BCPolicy:
    """Behavioural cloning: a scikit-learn classifier of the demo actions (standardised inputs).

    Parameters
    ----------
    classifier : {"mlp", "svm", "linear_svm"}, default "mlp"
        A multi-layer perceptron (:class:`sklearn.neural_network.MLPClassifier`, ReLU units,
        Adam), a support vector machine with an RBF kernel (:class:`sklearn.svm.SVC`, the
        paper's acrobot baseline) or a linear one as the paper's parking baseline (Appendix
        A.2: hinge loss, L2 regularisation ``alpha = 5e-3``; :class:`sklearn.linear_model.
        SGDClassifier`).
    hidden_layer_sizes : tuple of int, default (64, 64)
        The perceptron's hidden layers.
    max_iter : int, default 2000
    random_state : int, optional
        Seeds the network's initialisation and batches.
    state_key : str or sequence of str, optional
        For ``Dict`` observations: the key, or the keys joined in order, whose values the
        policy reads (what the demos record; :func:`sb3_swirl.collect_demos`).

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0], [0.1], [0.9], [1.0]])
    >>> policy = BCPolicy(random_state=0).fit(x, np.array([0, 0, 1, 1]))
    >>> int(policy.predict(np.array([0.95]))[0])
    1
    """

    def __init__(
        self,
        classifier: str = "mlp",
        hidden_layer_sizes: tuple[int, ...] = (64, 64),
        max_iter: int = 2000,
        random_state: int | None = None,
        state_key: str | Sequence[str] | None = None,
    ) -> None:
        self.classifier = check_option("classifier", classifier, ("mlp", "svm", "linear_svm"))
        self.state_key = state_key
        self.hidden_layer_sizes = tuple(check_widths("hidden_layer_sizes", hidden_layer_sizes))
        self.max_iter = check_int("max_iter", max_iter, low=1)
        self.random_state = (
            None
            if random_state is None
            else check_int("random_state", random_state, low=0, high=2**32 - 1)
        )

    def fit(self, observations: np.ndarray, actions: np.ndarray) -> BCPolicy:
        """Fit on observations (n, d) and their discrete actions (n,); returns ``self``."""
        from sklearn.linear_model import SGDClassifier
        from sklearn.neural_network import MLPClassifier
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import SVC

        try:
            observations = np.asarray(observations, dtype=np.float64)
            actions = np.asarray(actions)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"BCPolicy.fit takes arrays of observations and actions ({exc})"
            ) from None
        if observations.ndim != 2 or actions.shape != (len(observations),):
            raise ValueError(
                "observations must have shape (n, d) and actions shape (n,), got "
                f"{observations.shape} and {actions.shape}"
            )
        if not len(observations):
            raise ValueError("BCPolicy.fit got no observations: the demos hold no steps")
        bad = np.flatnonzero(~np.isfinite(observations).all(axis=1))
        if bad.size:
            raise ValueError(f"observations contain NaN or inf (first at row {int(bad[0])})")
        if actions.dtype.kind not in "biuf" or np.any(actions != np.round(actions)):
            raise ValueError(
                "actions must be the integers of a Discrete action space (BC here classifies "
                f"them), got {actions.dtype} values such as {actions.flat[0]!r}"
            )
        if len(np.unique(actions)) < 2:
            raise ValueError(
                f"the demos take one action only ({actions.flat[0]!r}): a classifier needs two"
            )
        if self.classifier == "svm":
            classifier = SVC(kernel="rbf", random_state=self.random_state)
        elif self.classifier == "linear_svm":
            classifier = SGDClassifier(
                loss="hinge", penalty="l2", alpha=5e-3, random_state=self.random_state
            )
        else:
            classifier = MLPClassifier(
                self.hidden_layer_sizes, max_iter=self.max_iter, random_state=self.random_state
            )
        self.model_ = make_pipeline(StandardScaler(), classifier).fit(observations, actions)
        return self

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[Any, None]:
        """The cloned action for one observation (d,) or a batch (n, d), as SB3's ``predict``
        returns it (the second item, SB3's recurrent state, is always None). ``Dict``
        observations are read with ``state_key``."""
        if not hasattr(self, "model_"):
            raise NotFittedError("This BCPolicy instance is not fitted yet: call fit first")
        if isinstance(observation, dict):
            keys = self.state_key or "observation"
            missing = [
                k for k in ([keys] if isinstance(keys, str) else keys) if k not in observation
            ]
            if missing:
                raise ValueError(
                    f"the Dict observation has no {missing} (keys: {sorted(observation)}): "
                    "give BCPolicy the state_key its demos were recorded with"
                )
            observation = observation_state(observation, keys)
        x = np.asarray(observation, dtype=np.float64)
        width = self.model_.n_features_in_  # sklearn's record of the width fitted on
        if x.ndim not in (1, 2) or x.shape[-1] != width:
            raise ValueError(
                f"observation must have shape ({width},) or (n, {width}) as the observations "
                f"fitted on, got {x.shape}"
            )
        bad = np.flatnonzero(~np.isfinite(x.reshape(-1, width)).all(axis=1))
        if bad.size:
            raise ValueError(f"observation contains NaN or inf (first at row {int(bad[0])})")
        action = self.model_.predict(x.reshape(-1, x.shape[-1]))
        return (action if x.ndim == 2 else action[0]), None


def lifted_demos(
    demos: Sequence[Demonstration], task: TaskModel, observation_space: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The demos' (observation, action) pairs as an agent in a SwirlWrapper sees them: each
    observation with the one-hot of its segment appended (segments as the wrapper tracks them).

    ``observation_space`` is the env's own (unlifted) space. Returns observations (n, d + k)
    and actions (n,).
    """
    lifter = Lifter(observation_space, task)
    observations, actions = [], []
    for demo in demos:
        states = demo.observations[:-1]
        index = task.segment_indices(demo.observations)[:-1]
        observations.append(lifter.lift(states, index))
        actions.append(demo.actions)
    return np.concatenate(observations), np.concatenate(actions)


# ---------------------------------------------------------------------- one interface
#: The comparison methods of :func:`run_method` (paper §8.2; GAIL as a modern reference).
METHODS: dict[str, str] = {
    "swirl": "SwirlDQN on the SWIRL task (model-free local rewards)",
    "swirl_maxent": "SwirlDQN on a SWIRL task with MaxEnt-IRL rewards, estimated dynamics",
    "swirl_maxent_model": "the same with the env's known model (noise_free_step)",
    "dqn": "pure exploration: DQN on the true reward",
    "dqn_rbf": "DQN with the paper's RBF Q-function (RBFFeaturesExtractor)",
    "dqn_her": "DQN with hindsight experience replay (SB3's HerReplayBuffer; goal envs)",
    "swirl_her": "SwirlDQN with hindsight experience replay (goal envs; 1-step returns)",
    "bc_linear_svm": "pure demonstration: linear SVM (hinge loss, L2 alpha 5e-3)",
    "bc_rbf_svm": "pure demonstration: RBF-kernel SVM",
    "bc_mlp": "pure demonstration: a (64, 64) perceptron (scikit-learn)",
    "bc_imitation": "pure demonstration: imitation's bc.BC (neural, optional extra)",
    "qinit": "warm start: SwirlDQN's BC start on the true reward, no segments (§8.2.3)",
    "global_irl": "one MaxEnt-IRL reward for the whole task, then DQN (§8.2.4)",
    "global_irl_model": "the same with the env's known model",
    "gail": "GAIL (imitation, PPO generator; optional extra)",
}
#: The methods of :data:`METHODS` that relabel goals (HER): they need a goal env.
GOAL_ENV_METHODS: tuple[str, ...] = ("dqn_her", "swirl_her")


def _needs_actions(method: str, demos: Sequence[Demonstration]) -> None:
    for i, demo in enumerate(demos):
        if demo.actions is None:
            raise ValueError(
                f"demo {i} has no actions: method {method!r} learns from demonstrated actions "
                "(label state-only demos of discrete actions with sb3_swirl.InverseDynamics "
                "first)"
            )


def evaluate_true_success(policy: Any, env: Any, n_episodes: int, seed: int) -> tuple[float, float]:
    """Greedy episodes of ``policy`` (anything with SB3's ``predict``) in ``env``, the first
    reset with ``seed``: the success rate (``info["is_success"]`` at the end) and the mean true
    return (``info["task_reward"]`` under a SWIRL wrapper, else the reward)."""
    successes, returns = [], []
    obs, _ = env.reset(seed=seed)
    for episode in range(n_episodes):
        if episode:
            obs, _ = env.reset()
        total, done, info = 0.0, False, {}
        while not done:
            action, _ = policy.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(int(action))
            total += float(info.get("task_reward", reward))
            done = terminated or truncated
        successes.append(bool(info.get("is_success", False)))
        returns.append(total)
    return float(np.mean(successes)), float(np.mean(returns))


def _global_task(demos: Sequence[Demonstration], task: TaskModel, learner: Any) -> TaskModel:
    """A one-segment task: the last region of ``task`` (the goal) and one reward learned by
    ``learner`` on the whole demonstrations (no segments)."""
    from swirl_wrappers import QuadraticReward

    goal = task.regions[-1]
    p = goal.mean.size
    stub = TaskModel(
        [goal],
        [QuadraticReward(goal.mean, np.eye(p))],
        dims=task.dims,
        features=task.features,
        angles=task.angles,
    )
    rewards = learner.fit(demos, stub).rewards_
    return TaskModel(
        [goal],
        rewards,
        dims=task.dims,
        features=task.features,
        angles=task.angles,
        metadata={"fitted_by": "sb3_swirl.baselines (global IRL)"},
    )


def run_method(
    method: str,
    preset: Any,
    demos: Sequence[Demonstration],
    *,
    seed: int,
    total_timesteps: int,
    progress: bool = False,
    env_kwargs: dict[str, Any] | None = None,
    fit_kwargs: dict[str, Any] | None = None,
    max_episodes: int | None = None,
) -> dict[str, Any]:
    """Fit ``method`` on ``demos``, train it for ``total_timesteps`` env steps (RL methods) and
    evaluate its true success, in the result format of
    :func:`sb3_swirl.experiments.train_and_evaluate` (``curve`` of evaluations with
    ``timesteps``, ``episodes``, ``success_rate``, ``task_return``; ``final_success``,
    ``best_success``, ``rollouts_to_target``, ``wall_time_s``), so one table and one plot hold
    every method. Behavioural cloning uses no env steps: its curve is one point at 0.

    Parameters
    ----------
    method : str
        A key of :data:`METHODS`.
    preset : sb3_swirl.experiments.Preset
        The task, its fit settings, evaluation schedule and success target.
    demos : sequence of Demonstration
        With actions (every method but ``swirl`` clones or imitates them).
    seed : int
    total_timesteps : int
    progress : bool, default False
    env_kwargs : dict, optional
        ``gym.make`` arguments of the env learned on and evaluated on (the demos may come from
        another: transfer, §9.6).
    fit_kwargs : dict, optional
        :func:`~sb3_swirl.fit_task` settings over the preset's (e.g. ``{"indicator":
        "velocity"}``).
    max_episodes : int, optional
        Stop the DQN-based methods after this many training episodes (the paper's budgets are in
        rollouts), or at ``total_timesteps``, whichever comes first.

    Returns
    -------
    dict
        The result, in :func:`sb3_swirl.experiments.train_and_evaluate`'s format (above).
    """
    import time

    from sb3_swirl.experiments import (
        _swirl_spec,
        _swirl_wrapper_kwargs,
        load_hyperparams,
        rollouts_to_success,
        train_and_evaluate,
    )
    from sb3_swirl.fitting import fit_task

    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {sorted(METHODS)}")
    check_int("total_timesteps", total_timesteps, low=1)  # BC's too: one budget for all
    seed = check_int("seed", seed, low=0, high=2**32 - 10_001)  # the eval env's is seed + 10000
    if method not in ("dqn", "dqn_rbf", "dqn_her"):  # these learn from the env alone
        demos = as_demonstrations(demos)
    if method != "swirl":
        _needs_actions(method, demos)
    env_kwargs = dict(env_kwargs or {})
    budget = {
        "total_timesteps": total_timesteps,
        "seed": seed,
        "progress": progress,
        "env_kwargs": env_kwargs,
        "max_episodes": max_episodes,
    }
    fit = {"random_state": seed, **preset.fit_kwargs, **(fit_kwargs or {})}

    def known_model() -> Any:
        env = gym.make(preset.env_id, **env_kwargs).unwrapped
        if not hasattr(env, "noise_free_step"):
            raise ValueError(f"method {method!r} needs a known model; {preset.env_id} has none")
        return env.noise_free_step

    if method in ("swirl", "swirl_maxent", "swirl_maxent_model"):
        reward = {"swirl": {}, "swirl_maxent": {"reward": "maxent"}}.get(method)
        if reward is None:
            reward = {"reward": "maxent", "dynamics": known_model()}
        task = fit_task(demos, **fit, **reward)
        result = train_and_evaluate("swirl_dqn", preset, task=task, demos=demos, **budget)
        return result | {"method": method, "n_segments": task.n_segments}
    if method == "dqn_her":
        hyperparams = _her_hyperparams(load_hyperparams("dqn", preset.env_id), preset)
        result = train_and_evaluate("dqn", preset, hyperparams=hyperparams, **budget)
        return result | {"method": method}
    if method == "swirl_her":
        hyperparams = _her_hyperparams(load_hyperparams("swirl_dqn", preset.env_id), preset)
        demos = _without_goal_offset(demos, preset)
        task = fit_task(demos, **fit)
        result = train_and_evaluate(
            "swirl_dqn", preset, task=task, demos=demos, hyperparams=hyperparams, **budget
        )
        return result | {"method": method, "n_segments": task.n_segments}
    if method in ("dqn", "dqn_rbf"):
        hyperparams = load_hyperparams("dqn", preset.env_id)
        if method == "dqn_rbf":
            from sb3_swirl.features import RBFFeaturesExtractor

            hyperparams["policy_kwargs"] = {
                "features_extractor_class": RBFFeaturesExtractor,
                "net_arch": [],
            }
        result = train_and_evaluate("dqn", preset, hyperparams=hyperparams, **budget)
        return result | {"method": method}
    if method in ("qinit", "global_irl", "global_irl_model"):
        from sb3_swirl.rewards import MaxEntIRLRewardLearner, QuadraticRewardLearner

        task = fit_task(demos, **fit)
        swirl = load_hyperparams("swirl_dqn", preset.env_id)
        spec = _swirl_spec(swirl)
        if method == "qinit":  # the true reward alone, BC start and SwirlDQN's settings
            learner, hyperparams, clone = QuadraticRewardLearner(), swirl, demos
            reward_config = {"mode": "potential", "scale": 0.0, "task_reward_weight": 1.0}
        else:  # the IRL reward, then plain DQN's settings
            dynamics = known_model() if method == "global_irl_model" else None
            learner, clone = MaxEntIRLRewardLearner(dynamics=dynamics), None
            hyperparams = load_hyperparams("dqn", preset.env_id)
            reward_config = spec.get("reward_config", {})
        # the entry's other wrapper settings (a Dict observation's state_key) stay
        wrapper = {**_swirl_wrapper_kwargs(swirl), "reward_config": reward_config}
        hyperparams = {
            **hyperparams,
            "env_wrapper": [{"sb3_swirl.zoo.SwirlTaskWrapper": wrapper}],
        }
        global_task = _global_task(demos, task, learner)
        result = train_and_evaluate(
            "swirl_dqn", preset, task=global_task, demos=clone, hyperparams=hyperparams, **budget
        )
        return result | {"method": method}

    start = time.perf_counter()
    if method.startswith("bc_"):
        env = gym.make(preset.env_id, **{**_entry_env_kwargs(preset), **env_kwargs})
        policy = _fit_bc(method, demos, env, seed, preset.state_key)
        steps = episodes = 0
    else:
        policy, steps, episodes = _train_gail(
            demos, preset.env_id, total_timesteps, seed, env_kwargs
        )
    eval_env = gym.make(preset.env_id, **{**_entry_env_kwargs(preset), **env_kwargs})
    success, task_return = evaluate_true_success(
        policy, eval_env, preset.n_eval_episodes, seed + 10_000
    )
    curve = [
        {
            "timesteps": steps,
            "episodes": episodes,
            "success_rate": success,
            "task_return": task_return,
        }
    ]
    return {
        "algo": method,
        "method": method,
        "hyperparams": {},
        "curve": curve,
        "final_success": success,
        "best_success": success,
        "best_success_episodes": episodes,
        "rollouts_to_target": rollouts_to_success(curve, preset.target_success),
        "wall_time_s": time.perf_counter() - start,
    }


def _require_imitation(method: str) -> None:
    try:
        import imitation  # noqa: F401
    except ImportError:
        raise ImportError(
            f"method {method!r} needs the imitation library, installed without its old pins: "
            "pip install --no-deps imitation==1.0.1 seals==0.2.1 (make install does it)"
        ) from None


def _entry_env_kwargs(preset: Any) -> dict[str, Any]:
    """The ``env_kwargs`` of the task's ``swirl_dqn`` entry: the env the demos fit."""
    from sb3_swirl.experiments import load_hyperparams

    return dict(load_hyperparams("swirl_dqn", preset.env_id).get("env_kwargs") or {})


def _her_hyperparams(hyperparams: dict[str, Any], preset: Any) -> dict[str, Any]:
    """An rl-zoo entry (``dqn`` or ``swirl_dqn``) with SB3's ``HerReplayBuffer`` (4 future
    goals per transition, as in the HER paper). HER relabels ``desired_goal`` alone, so the
    env gets no observation key computed from the goal (the Fetch tasks' ``goal_offset``).
    SwirlDQN's relabelled rewards read each step's info (``copy_info_dict``); HER has 1-step
    returns only. The relabelled goal must reach the network, so it reads every key (an
    entry's :class:`~sb3_swirl.features.KeysExtractor` is dropped)."""
    from stable_baselines3 import HerReplayBuffer

    from sb3_swirl.experiments import _normalize_kwargs, _policy_kwargs, _swirl_spec
    from sb3_swirl.features import KeysExtractor

    if not hyperparams.get("policy", "").startswith("MultiInput"):
        raise ValueError(f"HER needs a goal env with Dict observations; {preset.env_id} is not")
    hyperparams = dict(hyperparams)
    env_kwargs = dict(hyperparams.get("env_kwargs") or {})
    env_kwargs.pop("goal_offset", None)
    normalize = _normalize_kwargs(hyperparams.get("normalize", False))
    if normalize is not None and "norm_obs_keys" in normalize:
        keys = [key for key in normalize["norm_obs_keys"] if key != "goal_offset"]
        hyperparams["normalize"] = normalize | {"norm_obs_keys": keys}
    policy_kwargs = _policy_kwargs(hyperparams.get("policy_kwargs"))
    extractor = (policy_kwargs or {}).get("features_extractor_class")
    if isinstance(extractor, type) and issubclass(extractor, KeysExtractor):
        hyperparams["policy_kwargs"] = {
            k: v for k, v in policy_kwargs.items() if not k.startswith("features_extractor")
        }
    buffer_kwargs: dict[str, Any] = {"n_sampled_goal": 4, "goal_selection_strategy": "future"}
    spec = _swirl_spec(hyperparams)
    if spec:
        state_key = [key for key in spec.get("state_key") or () if key != "goal_offset"]
        wrapper = spec | ({"state_key": state_key} if state_key else {})
        hyperparams["env_wrapper"] = [{"sb3_swirl.zoo.SwirlTaskWrapper": wrapper}]
        hyperparams["n_steps"] = 1
        buffer_kwargs["copy_info_dict"] = True
    return hyperparams | {
        "env_kwargs": env_kwargs,
        "replay_buffer_class": HerReplayBuffer,
        "replay_buffer_kwargs": buffer_kwargs,
    }


def _without_goal_offset(demos: Sequence[Demonstration], preset: Any) -> list[Demonstration]:
    """The demos' states without the Fetch tasks' ``goal_offset`` key (the last one the
    preset's ``state_key`` lists), as an env without that key records them."""
    import dataclasses

    keys = preset.state_key
    if not isinstance(keys, list | tuple) or "goal_offset" not in keys:
        return list(demos)
    if keys[-1] != "goal_offset":
        raise ValueError(f"goal_offset must be the last state key, got {keys}")
    size = gym.make(preset.env_id, goal_offset=True).observation_space["goal_offset"].shape[0]
    kept = demos[0].observations.shape[1] - size if demos else 0
    dims = preset.fit_kwargs.get("dims")
    if dims is None or max(dims) >= kept:
        raise ValueError(
            f"the SWIRL task of {preset.env_id} reads the goal's offset (fit dims {dims}), "
            "which hindsight relabelling would leave stale: swirl_her needs a task on the "
            "observation alone"
        )
    return [
        dataclasses.replace(
            d,
            observations=d.observations[:, :-size],
            state_key=None if d.state_key is None else d.state_key[:-1],
        )
        for d in demos
    ]


def _fit_bc(
    method: str,
    demos: Sequence[Demonstration],
    env: Any,
    seed: int,
    state_key: str | Sequence[str] | None = None,
) -> Any:
    """A behavioural clone of the demos on the raw observations (``env`` gives the spaces;
    ``state_key`` what the demos record of a ``Dict`` observation)."""
    if method == "bc_imitation":
        _require_imitation(method)
        from imitation.algorithms import bc
        from imitation.util import logger

        from sb3_swirl.demos import to_imitation

        trainer = bc.BC(
            observation_space=env.observation_space,
            action_space=env.action_space,
            demonstrations=to_imitation(demos),
            rng=np.random.default_rng(seed),
            batch_size=64,
            custom_logger=logger.configure(format_strs=[]),
        )
        trainer.train(n_epochs=300, progress_bar=False, log_interval=10**9)
        return trainer.policy
    observations = np.concatenate([d.observations[:-1] for d in demos])
    actions = np.concatenate([np.asarray(d.actions) for d in demos])
    classifier = {"bc_linear_svm": "linear_svm", "bc_rbf_svm": "svm", "bc_mlp": "mlp"}[method]
    return BCPolicy(classifier, random_state=seed, state_key=state_key).fit(observations, actions)


def _train_gail(
    demos: Sequence[Demonstration],
    env_id: str,
    total_timesteps: int,
    seed: int,
    env_kwargs: dict[str, Any],
) -> tuple[Any, int, int]:
    """GAIL (imitation) with a PPO generator for ``total_timesteps`` env steps."""
    _require_imitation("gail")
    from imitation.algorithms.adversarial.gail import GAIL
    from imitation.data.wrappers import RolloutInfoWrapper
    from imitation.rewards.reward_nets import BasicRewardNet
    from imitation.util import logger
    from imitation.util.networks import RunningNorm
    from imitation.util.util import make_vec_env
    from stable_baselines3 import PPO

    from sb3_swirl.demos import to_imitation

    n_envs, n_steps = 4, 256
    if total_timesteps < n_envs * n_steps:
        raise ValueError(
            f"gail needs total_timesteps >= {n_envs * n_steps} (one round of its PPO generator: "
            f"{n_steps} steps in each of {n_envs} envs), got {total_timesteps}"
        )
    venv = make_vec_env(
        env_id,
        rng=np.random.default_rng(seed),
        n_envs=n_envs,
        env_make_kwargs=env_kwargs,
        post_wrappers=[lambda env, _: _EpisodeCounter(RolloutInfoWrapper(env))],
    )
    learner = PPO("MlpPolicy", venv, batch_size=64, n_steps=n_steps, seed=seed, verbose=0)
    reward_net = BasicRewardNet(
        venv.observation_space, venv.action_space, normalize_input_layer=RunningNorm
    )
    trainer = GAIL(
        demonstrations=to_imitation(demos),
        demo_batch_size=256,
        gen_replay_buffer_capacity=1024,
        n_disc_updates_per_round=4,
        venv=venv,
        gen_algo=learner,
        reward_net=reward_net,
        allow_variable_horizon=True,
        custom_logger=logger.configure(format_strs=[]),  # no tables on stdout
    )
    trainer.train(total_timesteps)
    episodes = sum(int(e.get_wrapper_attr("episodes")) for e in venv.envs)
    return learner, int(learner.num_timesteps), episodes


class _EpisodeCounter(gym.Wrapper):
    """Counts the episodes that end (the rollouts of an on-policy learner)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.episodes = 0

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.episodes += bool(terminated or truncated)
        return obs, reward, terminated, truncated, info
