"""SwirlDQN: DQN on a SWIRL proxy task, started from per-segment behavioural cloning (paper §7)."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Literal, TypeVar

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.type_aliases import GymEnv, Schedule
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper
from stable_baselines3.dqn.policies import DQNPolicy
from torch import nn
from torch.nn import functional as F

from sb3_swirl.demos import Demonstration, as_demonstrations
from sb3_swirl.features import RBFFeaturesExtractor
from sb3_swirl.vec_env import SwirlVecEnv
from swirl_wrappers import SegmentTracker, SwirlWrapper, TaskModel
from swirl_wrappers._checks import is_finite_real, is_integer

SelfSwirlDQN = TypeVar("SelfSwirlDQN", bound="SwirlDQN")

_WRAP_HINT = (
    "wrap it with the SWIRL proxy task first, e.g. `SwirlWrapper(gym.make(env_id), task)` "
    "(from swirl_wrappers) or `make_swirl_env(env_id, task, n_envs=...)` "
    "(from sb3_swirl.dqn)"
)


_REWARD_SETTINGS = ("reward_scale", "region_bonus", "reward_mode", "task_reward_weight", "gamma")


def swirl_settings(env: VecEnv) -> dict[str, Any]:
    """The proxy task and reward settings of the SWIRL wrapper inside a vectorised env.

    Looks for a ``SwirlVecEnv`` in the chain of vec-env wrappers first, then for a
    ``SwirlWrapper`` inside the sub-environments.

    Returns
    -------
    dict
        ``task``, ``reward_scale``, ``region_bonus``, ``terminate_on_completion``,
        ``reward_mode``, ``task_reward_weight`` and ``gamma``.

    Raises
    ------
    ValueError
        If the env carries no task, with a hint on how to wrap it.
    """
    venv: Any = env
    while isinstance(venv, VecEnvWrapper):
        if isinstance(venv, SwirlVecEnv):
            tracker = venv.tracker
            return {
                "task": venv.task,
                "terminate_on_completion": False,
                **{name: getattr(tracker, name) for name in _REWARD_SETTINGS},
            }
        venv = venv.venv
    names = ("task", "terminate_on_completion", *_REWARD_SETTINGS)
    # has_attr first: a get_attr that fails inside a SubprocVecEnv worker kills the worker
    settings = {}
    if venv.has_attr("task"):
        settings = {name: venv.get_attr(name, indices=[0])[0] for name in names}
    if not isinstance(settings.get("task"), TaskModel):
        raise ValueError(f"the environment carries no SWIRL proxy task: {_WRAP_HINT}")
    return settings


def _inverse_dynamics_settings(kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """``inverse_dynamics_kwargs`` over their defaults, checked."""
    settings = {"net_arch": [64, 64], "epochs": 50, "lr": 1e-3, "batch_size": 256}
    unknown = set(kwargs or {}) - set(settings)
    if unknown:
        raise ValueError(f"unknown inverse_dynamics_kwargs {sorted(unknown)}; use {list(settings)}")
    settings.update(kwargs or {})

    arch = settings["net_arch"]
    if not (isinstance(arch, list | tuple) and all(is_integer(width, 1) for width in arch)):
        raise ValueError(f"inverse_dynamics_kwargs net_arch must be a list of widths, got {arch!r}")
    for name in ("epochs", "batch_size"):
        if not is_integer(settings[name], 1):
            raise ValueError(
                f"inverse_dynamics_kwargs {name} must be an integer >= 1, got {settings[name]!r}"
            )
    if not (is_finite_real(settings["lr"]) and settings["lr"] > 0):
        raise ValueError(f"inverse_dynamics_kwargs lr must be > 0, got {settings['lr']!r}")
    return settings


def find_task(env: VecEnv) -> TaskModel:
    """The proxy task carried by ``env`` (see :func:`swirl_settings`)."""
    return swirl_settings(env)["task"]


def make_swirl_env(
    env_id_or_env: str | gym.Env | Callable[[], gym.Env],
    task: TaskModel,
    n_envs: int = 1,
    seed: int | None = None,
    wrapper_kwargs: dict[str, Any] | None = None,
    vec_env_cls: type[DummyVecEnv] | None = None,
    **make_kwargs: Any,
) -> VecEnv:
    """A vectorised env whose sub-envs are ``Monitor(SwirlWrapper(env, task, **wrapper_kwargs))``.

    The monitor sits outside the SWIRL wrapper, so it sees the episode as the agent does
    (including an early end with ``terminate_on_completion``); the env's own reward stays in
    ``info["task_reward"]``.

    Parameters
    ----------
    env_id_or_env : str, gymnasium.Env or callable
        A registered id (made with ``gym.make(env_id, **make_kwargs)``), an env instance
        (``n_envs`` must then be 1) or a factory.
    task : TaskModel
        The proxy task.
    n_envs : int
        Number of sub-environments.
    seed : int, optional
        Seed of the first sub-env; the others get ``seed + i``.
    wrapper_kwargs : dict, optional
        ``reward_scale``, ``region_bonus``, ``terminate_on_completion`` of ``SwirlWrapper``.
    vec_env_cls : type, optional
        ``DummyVecEnv`` (default) or ``SubprocVecEnv``.

    Examples
    --------
    >>> import sb3_swirl.envs  # doctest: +SKIP
    >>> venv = make_swirl_env("sb3_swirl/ParallelParking-v0", task, n_envs=2)  # doctest: +SKIP
    """
    if not is_integer(n_envs, 1):
        raise ValueError(f"n_envs must be an integer >= 1, got {n_envs!r}")
    wrapper_kwargs = dict(wrapper_kwargs or {})
    if isinstance(env_id_or_env, gym.Env):
        if n_envs != 1:
            raise ValueError(
                f"an env instance can back only one sub-env, got n_envs={n_envs}; "
                "pass an env id or a factory instead"
            )
        instance = env_id_or_env

        def base() -> gym.Env:
            return instance

    elif isinstance(env_id_or_env, str):
        env_id = env_id_or_env

        def base() -> gym.Env:
            return gym.make(env_id, **make_kwargs)

    else:
        base = env_id_or_env

    def factory() -> gym.Env:
        return Monitor(SwirlWrapper(base(), task, **wrapper_kwargs))

    return make_vec_env(factory, n_envs=n_envs, seed=seed, vec_env_cls=vec_env_cls)


def _mlp(sizes: Sequence[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class SwirlDQN(DQN):
    """DQN on a SWIRL proxy task, initialised by per-segment behavioural cloning (paper §7.2).

    The env must carry the proxy task: a ``SwirlWrapper`` in every sub-env or a ``SwirlVecEnv``
    (see :func:`make_swirl_env`). Before the first ``learn`` the demonstrations are lifted into
    the agent's observation space (state ⊕ one-hot of the segment index in force at each step,
    exactly as the wrapper shows it) and the Q-network is trained to pick the demonstrated action
    in every segment (:meth:`pretrain`); Q-learning then explores ε-greedily from that start.

    After BC, the warm-up steps before ``learning_starts`` also follow the cloned policy
    ε-greedily (plain DQN takes uniform actions there). A BC start usually wants a small
    ``exploration_initial_eps``: ε = 1 would discard it.

    Cross-entropy on Q-values as logits drives them to arbitrary scales that the first TD updates
    then wipe out; measured on parking (5 demos), the cloned policy's success fell from 0.3 to 0
    within 500 steps of plain TD learning. Following DQfD (Hester et al., 2018):

    * ``bc_loss="margin"`` (default) is the large-margin loss
      ``max_a [Q(s, a) + l (a != a_E)] - Q(s, a_E)``: zero once the demo action wins by
      ``bc_margin``, so it does not inflate Q; ``"cross_entropy"`` is the paper's softmax.
    * ``demo_loss_coef > 0`` (default 1) keeps that supervised loss on a segment-balanced demo
      batch in every Q-learning update, which kept the BC start alive (and improving) above.
      ``save`` stores the lifted demo pairs with the model, so a loaded model trains on with
      the same loss (SB3 saves the replay buffer only on request: ``save_replay_buffer``).
    * ``bc_td_coef > 0`` adds a 1-step TD loss on the demo transitions during BC (off by
      default: with ``reward_scale=1`` it lowered the BC accuracy from 0.90 to 0.83 on parking).
    * ``prefill_replay=True`` puts the demo transitions in the replay buffer.

    The proxy reward is the wrapper's: with ``SwirlWrapper(..., reward_mode="potential")`` (the
    tuned parking setting) give the wrapper the same ``gamma`` as SwirlDQN (a warning says when
    they differ), so the shaping keeps the true task's optimal policies.

    Parameters
    ----------
    policy, env, learning_rate, ..., device :
        As in :class:`stable_baselines3.DQN`.
    demonstrations : sequence of Demonstration, optional
        Demos of the task (states; actions optional). ``None`` gives plain DQN on the proxy task.
    task : TaskModel, optional
        Only checked: it must equal the task carried by ``env``.
    bc_loss : {"margin", "cross_entropy"}
        Supervised loss on the demo actions.
    bc_margin : float
        Margin ``l`` of the large-margin loss.
    bc_td_coef : float
        Weight of the TD loss on demo transitions during BC (0 disables it).
    bc_epochs : int
        Passes over the demo pairs.
    bc_lr : float
        Adam learning rate of the BC stage.
    bc_batch_size : int
        Minibatch size; minibatches are drawn so every segment weighs the same.
    demo_loss_coef : float
        Weight of the supervised loss on demo pairs added to every Q-learning update
        (0: plain DQN updates after the BC start).
    prefill_replay : bool
        Add the demo transitions (proxy reward, done at each demo's end) to the replay buffer.
    infer_actions : {"inverse_dynamics", "none"}
        For demos without actions: label them with an inverse-dynamics model trained on the
        agent's own first ``inverse_dynamics_steps`` random-action steps (which also go into the
        replay buffer), or leave them out of BC.
    inverse_dynamics_steps : int
        Env steps collected to train the inverse-dynamics model.
    inverse_dynamics_kwargs : dict, optional
        ``net_arch`` (default ``[64, 64]``), ``epochs`` (50), ``lr`` (1e-3), ``batch_size`` (256).
    """

    policy_aliases: ClassVar = DQN.policy_aliases

    def __init__(
        self,
        policy: str | type[DQNPolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule = 1e-4,
        buffer_size: int = 1_000_000,
        learning_starts: int = 100,
        batch_size: int = 32,
        tau: float = 1.0,
        gamma: float = 0.99,
        train_freq: int | tuple[int, str] = 4,
        gradient_steps: int = 1,
        replay_buffer_class: Any = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        optimize_memory_usage: bool = False,
        n_steps: int = 1,
        target_update_interval: int = 10000,
        exploration_fraction: float = 0.1,
        exploration_initial_eps: float = 1.0,
        exploration_final_eps: float = 0.05,
        max_grad_norm: float = 10,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        demonstrations: Sequence[Demonstration] | None = None,
        task: TaskModel | None = None,
        bc_loss: Literal["margin", "cross_entropy"] = "margin",
        bc_margin: float = 0.8,
        bc_td_coef: float = 0.0,
        bc_epochs: int = 300,
        bc_lr: float = 1e-3,
        bc_batch_size: int = 64,
        prefill_replay: bool = False,
        infer_actions: Literal["inverse_dynamics", "none"] = "inverse_dynamics",
        inverse_dynamics_steps: int = 2000,
        inverse_dynamics_kwargs: dict[str, Any] | None = None,
        demo_loss_coef: float = 1.0,
        _init_setup_model: bool = True,
    ) -> None:
        if bc_loss not in ("margin", "cross_entropy"):
            raise ValueError(f"bc_loss must be 'margin' or 'cross_entropy', got {bc_loss!r}")
        if infer_actions not in ("inverse_dynamics", "none"):
            raise ValueError(
                f"infer_actions must be 'inverse_dynamics' or 'none', got {infer_actions!r}"
            )
        for name, value in (
            ("bc_epochs", bc_epochs),
            ("bc_batch_size", bc_batch_size),
            ("inverse_dynamics_steps", inverse_dynamics_steps),
        ):
            minimum = 0 if name == "bc_epochs" else 1
            if not is_integer(value, minimum):
                raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
        for name, value, positive in (
            ("bc_lr", bc_lr, True),
            ("bc_margin", bc_margin, False),
            ("bc_td_coef", bc_td_coef, False),
            ("demo_loss_coef", demo_loss_coef, False),
        ):
            if not (is_finite_real(value) and (value > 0 if positive else value >= 0)):
                bound = "> 0" if positive else ">= 0"
                raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
        _inverse_dynamics_settings(inverse_dynamics_kwargs)  # fail now, not after the steps
        if task is not None and not isinstance(task, TaskModel):
            raise ValueError(f"task must be a swirl_wrappers.TaskModel, got {type(task).__name__}")
        n_step = max(int(n_steps), int(dict(replay_buffer_kwargs or {}).get("n_steps", 1)))
        if prefill_replay and (n_step > 1 or optimize_memory_usage):
            raise ValueError(
                "prefill_replay needs a plain 1-step replay buffer: the demo transitions do not "
                "follow the buffer's env columns, which n-step returns and "
                "optimize_memory_usage read across rows (set prefill_replay=False)"
            )
        super().__init__(
            policy,
            env,  # type: ignore[arg-type]
            learning_rate=learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            tau=tau,
            gamma=gamma,
            train_freq=train_freq,
            gradient_steps=gradient_steps,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=optimize_memory_usage,
            n_steps=n_steps,
            target_update_interval=target_update_interval,
            exploration_fraction=exploration_fraction,
            exploration_initial_eps=exploration_initial_eps,
            exploration_final_eps=exploration_final_eps,
            max_grad_norm=max_grad_norm,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
        )
        self.demonstrations = None if demonstrations is None else as_demonstrations(demonstrations)
        self.bc_loss = bc_loss
        self.bc_margin = bc_margin
        self.bc_td_coef = bc_td_coef
        self.bc_epochs = int(bc_epochs)
        self.bc_lr = bc_lr
        self.bc_batch_size = int(bc_batch_size)
        self.prefill_replay = prefill_replay
        self.infer_actions = infer_actions
        self.inverse_dynamics_steps = int(inverse_dynamics_steps)
        self.inverse_dynamics_kwargs = dict(inverse_dynamics_kwargs or {})
        self.demo_loss_coef = demo_loss_coef
        self._bc_done = False
        self.bc_n_pairs_ = 0
        # The lifted demo pairs of the supervised loss: saved with the model, so that training
        # goes on with the same loss after `load` (the tensors are rebuilt from them).
        self._demo_data: dict[str, np.ndarray] | None = None
        self._demo: dict[str, th.Tensor] | None = None
        self.task: TaskModel | None = None
        self.task_json: str | None = None
        if self.env is not None:
            settings = swirl_settings(self.env)  # type: ignore[arg-type]
            if settings["reward_mode"] == "potential" and settings["gamma"] != self.gamma:
                warnings.warn(
                    f"the SWIRL wrapper shapes with gamma={settings['gamma']} but SwirlDQN "
                    f"discounts with gamma={self.gamma}: the potential shaping is "
                    "policy-invariant only when they are equal",
                    stacklevel=2,
                )
            self.task = settings["task"]
            self.task_json = self.task.to_json()
            if task is not None and task.to_json() != self.task_json:
                raise ValueError(
                    "task differs from the task carried by the environment's SWIRL wrapper"
                )
        elif _init_setup_model:
            raise ValueError(f"SwirlDQN needs an environment: {_WRAP_HINT}")
        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        if self.task_json is not None and (
            self.task is None or self.task.to_json() != self.task_json
        ):
            if self.task is not None:  # `load` with an env, as set_env refuses it
                raise ValueError(
                    "the environment's proxy task differs from the one this model was trained "
                    "with; load without env=, then wrap the env with model.task"
                )
            self.task = TaskModel.from_json(self.task_json)
        extractor = self.policy_kwargs.get("features_extractor_class")
        if isinstance(extractor, type) and issubclass(extractor, RBFFeaturesExtractor):
            fe_kwargs = dict(self.policy_kwargs.get("features_extractor_kwargs") or {})
            if "n_indices" not in fe_kwargs and self.task is not None:
                fe_kwargs["n_indices"] = self.task.n_indices
                self.policy_kwargs = {**self.policy_kwargs, "features_extractor_kwargs": fe_kwargs}
        super()._setup_model()
        if self._demo_data is not None and self._demo is None:  # after `load`
            self._demo = self._demo_tensors(self._demo_data)
            self._demo_gen = self._rng(3)

    def set_env(self, env: Any, force_reset: bool = True) -> None:
        """:meth:`stable_baselines3.DQN.set_env`, refusing an env with a different proxy task.

        The demonstrations are lifted and the Q-network was trained with ``model.task``; an
        env that segments or rewards by another task would silently train on a different
        problem.
        """
        super().set_env(env, force_reset)
        if self.task_json is not None and find_task(self.env).to_json() != self.task_json:
            raise ValueError(
                "the new environment's proxy task differs from the one this model was built "
                "with (model.task); wrap the env with model.task, or start a new model"
            )

    def _setup_learn(self, *args: Any, **kwargs: Any) -> tuple[int, Any]:
        result = super()._setup_learn(*args, **kwargs)
        if not self._bc_done and self.demonstrations:
            self.pretrain()
        return result

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        # After BC the warm-up steps follow the cloned policy ε-greedily: uniform actions
        # before ``learning_starts`` would throw the demonstrations' head start away.
        if self.bc_n_pairs_ > 0:
            learning_starts = 0
        return super()._sample_action(learning_starts, action_noise, n_envs)

    # ------------------------------------------------------------------ demonstrations
    def _lift_demos(self) -> list[dict[str, np.ndarray]]:
        """Demo transitions exactly as the wrapper would present them, one dict per demo.

        The states are replayed through the wrappers' own :class:`SegmentTracker`, so the
        segment index in each lifted observation and each proxy reward (scale, region bonus,
        index before the step) are those the agent sees online. The last transition of a demo
        is terminal (demos end when the task is done); with ``terminate_on_completion`` a demo
        ends on the step that reaches the last region, as the wrapper's episode would. Demos
        without rewards are taken to end in success: task reward 1 on their last transition
        (it matters only with the wrapper's ``task_reward_weight``).
        """
        settings = swirl_settings(self.env)  # type: ignore[arg-type]
        task = self.task
        assert task is not None
        obs_space = self.observation_space
        if not isinstance(obs_space, spaces.Box) or len(obs_space.shape) != 1:
            raise ValueError(f"SwirlDQN needs a flat Box observation space, got {obs_space}")
        state_dim = obs_space.shape[0] - task.n_indices
        state_space = spaces.Box(obs_space.low[:state_dim], obs_space.high[:state_dim])
        n_actions = int(self.action_space.n)  # type: ignore[attr-defined]
        lifted = []
        for n, demo in enumerate(self.demonstrations or []):
            states = np.asarray(demo.observations, dtype=np.float64)
            if states.shape[1] != state_dim:
                raise ValueError(
                    f"demonstration {n}: observations have {states.shape[1]} dims, the "
                    f"environment's (unlifted) observations have {state_dim} (demos must be "
                    "states of the env under the SWIRL wrapper; frame stacking is not supported)"
                )
            tracker = SegmentTracker(
                task,
                1,
                state_space,
                **{name: settings[name] for name in _REWARD_SETTINGS},
            )
            # The last transition is terminal: the demo's end or, with
            # terminate_on_completion, the step that reaches the last region.
            end = len(demo)
            if settings["terminate_on_completion"]:
                complete = np.flatnonzero(task.segment_indices(states)[1:] == task.n_segments)
                end = int(complete[0]) + 1 if len(complete) else end
            task_rewards = np.zeros(end)
            if demo.rewards is not None:
                task_rewards[:] = np.asarray(demo.rewards, dtype=np.float64)[:end]
            elif end == len(demo):
                task_rewards[-1] = 1.0
            tracker.reset(states[:1])
            obs, index, reward = [tracker.lift(states[:1])[0]], [tracker.index[0]], []
            for t, state in enumerate(states[1 : end + 1]):
                step_reward = tracker.step(
                    state[None],
                    task_rewards=task_rewards[t : t + 1],
                    terminated=np.array([t == end - 1]),
                )
                reward.append(step_reward[0])
                obs.append(tracker.lift(state[None])[0])
                index.append(tracker.index[0])
            x = np.asarray(obs, dtype=obs_space.dtype)
            done = np.zeros(len(reward), dtype=bool)
            done[-1] = True
            actions = None
            if demo.actions is not None:
                actions = np.asarray(demo.actions).reshape(len(demo), -1)
                if actions.shape[1] != 1 or not np.all(actions == np.round(actions)):
                    raise ValueError(
                        f"demonstration {n}: actions must be integers of shape ({len(demo)},) "
                        f"for a Discrete action space, got shape {np.shape(demo.actions)}"
                    )
                actions = actions[: len(reward), 0].astype(np.int64)
                if actions.min() < 0 or actions.max() >= n_actions:
                    raise ValueError(
                        f"demonstration {n}: actions must lie in [0, {n_actions}), "
                        f"got values in [{actions.min()}, {actions.max()}]"
                    )
            lifted.append(
                {
                    "obs": x[:-1],
                    "next_obs": x[1:],
                    "segment": np.asarray(index[:-1]),
                    "reward": np.asarray(reward),
                    "done": done,
                    "actions": actions,
                    "state": states[: len(x)],
                }
            )
        return lifted

    def _rng(self, offset: int) -> th.Generator:
        gen = th.Generator()
        gen.manual_seed(int(np.random.SeedSequence(self.seed).generate_state(1)[0]) + offset)
        return gen

    def infer_demo_actions(self, states: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Label state-only demos with an inverse-dynamics model ``p(a | s, s')``.

        The model is an MLP trained on ``inverse_dynamics_steps`` steps of uniformly random
        actions in the training env (those transitions also go into the replay buffer, so the
        interaction is not wasted). The fitted model is kept as ``inverse_dynamics_``; the
        episodes it used are counted in ``inverse_dynamics_episodes_``.

        Parameters
        ----------
        states : sequence of arrays of shape (T+1, d)
            The raw state sequences of the demos.

        Returns
        -------
        list of int arrays of shape (T,)
        """
        kw = _inverse_dynamics_settings(self.inverse_dynamics_kwargs)
        assert self.task is not None
        state_dim = self.observation_space.shape[0] - self.task.n_indices  # type: ignore[index]
        n_actions = int(self.action_space.n)  # type: ignore[attr-defined]
        vec_norm = self._vec_normalize_env
        raw = vec_norm.unnormalize_obs if vec_norm is not None else (lambda o: o)
        if self._last_obs is None:
            self._last_obs = self.env.reset()  # type: ignore[union-attr, assignment]
            if vec_norm is not None:
                self._last_original_obs = vec_norm.get_original_obs()
        rng = np.random.default_rng(np.random.SeedSequence(self.seed).spawn(2)[1])
        n_envs = self.n_envs
        s, s_next, acts = [], [], []
        self.inverse_dynamics_episodes_ = 0
        for _ in range(-(-self.inverse_dynamics_steps // n_envs)):
            actions = rng.integers(n_actions, size=n_envs)
            before = raw(np.asarray(self._last_obs))[:, :state_dim]
            new_obs, rewards, dones, infos = self.env.step(actions)  # type: ignore[union-attr]
            after = raw(np.asarray(new_obs)).copy()
            for i in np.flatnonzero(dones):
                after[i] = raw(infos[i]["terminal_observation"])
            s.append(before)
            s_next.append(after[:, :state_dim])
            acts.append(actions)
            self.inverse_dynamics_episodes_ += int(np.sum(dones))
            self._store_transition(self.replay_buffer, actions, new_obs, rewards, dones, infos)  # type: ignore[arg-type]
        x0, x1 = np.concatenate(s), np.concatenate(s_next)
        inputs = np.concatenate([x0, x1 - x0], axis=1)
        mean, std = inputs.mean(axis=0), inputs.std(axis=0) + 1e-8

        def features(a: np.ndarray, b: np.ndarray) -> th.Tensor:
            z = (np.concatenate([a, b - a], axis=1) - mean) / std
            return th.as_tensor(z, dtype=th.float32)

        gen = self._rng(1)
        with th.random.fork_rng(devices=[]):
            th.manual_seed(int(th.randint(2**31 - 1, (1,), generator=gen)))
            model = _mlp([2 * state_dim, *kw["net_arch"], n_actions])
        optimizer = th.optim.Adam(model.parameters(), lr=kw["lr"])
        x, y = features(x0, x1), th.as_tensor(np.concatenate(acts), dtype=th.int64)
        for _ in range(int(kw["epochs"])):
            for batch in th.randperm(len(x), generator=gen).split(int(kw["batch_size"])):
                loss = F.cross_entropy(model(x[batch]), y[batch])
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
        self.inverse_dynamics_ = model
        with th.no_grad():
            labels = [model(features(d[:-1], d[1:])).argmax(dim=1).numpy() for d in states]
            train_acc = float((model(x).argmax(dim=1) == y).float().mean())
        self._record("bc/inverse_dynamics_accuracy", train_acc)
        self._record("bc/inverse_dynamics_episodes", self.inverse_dynamics_episodes_)
        return labels

    def _record(self, key: str, value: float) -> None:
        if hasattr(self, "_logger"):
            self.logger.record(key, value)

    def pretrain(self) -> dict[str, float]:
        """Per-segment behavioural cloning of the demonstrations into the Q-network.

        Runs once (``learn`` calls it; the saved flag ``_bc_done`` stops a repeat after
        ``load``), and can be called by hand. Labels state-only demos first (see
        ``infer_actions``), trains ``q_net`` on the demo pairs of every segment with equal
        weight per segment, copies it to ``q_net_target`` and, with ``prefill_replay``, adds
        the demo transitions to the replay buffer. Logs ``bc/loss`` and ``bc/accuracy``.

        Returns
        -------
        dict
            ``loss`` (last epoch), ``accuracy`` (greedy action == demo action on the demo
            states), ``n_pairs``.
        """
        lifted = self._lift_demos()
        missing = [n for n, d in enumerate(lifted) if d["actions"] is None]
        if missing and self.infer_actions == "inverse_dynamics":
            labels = self.infer_demo_actions([lifted[n]["state"] for n in missing])
            for n, label in zip(missing, labels, strict=True):
                lifted[n]["actions"] = label
        lifted = [d for d in lifted if d["actions"] is not None]
        self._bc_done = True
        if not lifted:
            warnings.warn(
                "no demonstration has actions and infer_actions='none': skipping BC",
                stacklevel=2,
            )
            return {"loss": float("nan"), "accuracy": float("nan"), "n_pairs": 0}
        data = {k: np.concatenate([d[k] for d in lifted]) for k in lifted[0] if k != "state"}
        vec_norm = self._vec_normalize_env
        if vec_norm is not None and vec_norm.training and vec_norm.norm_obs:
            # else BC fits inputs normalised by the statistics of a reset or two, which the
            # first rollouts then move far away
            vec_norm.obs_rms.update(data["obs"])
        self._demo_data = data
        self._demo = self._demo_tensors(data)
        self._demo_gen = self._rng(3)
        info = self._behaviour_clone(self._demo)
        if self.prefill_replay:
            self._prefill(data)
        return info

    def _demo_tensors(self, data: dict[str, np.ndarray]) -> dict[str, th.Tensor]:
        def tensor(a: np.ndarray, dtype: th.dtype | None = None) -> th.Tensor:
            return th.as_tensor(a, dtype=dtype, device=self.device)

        # every segment weighs the same, so short segments are not drowned out by long ones
        counts = np.bincount(data["segment"])
        return {
            "obs": tensor(data["obs"]),
            "next_obs": tensor(data["next_obs"]),
            "actions": tensor(data["actions"]),
            "reward": tensor(data["reward"], th.float32),
            "not_done": tensor(~data["done"], th.float32),
            "weights": th.as_tensor(1.0 / counts[data["segment"]], dtype=th.float64),
        }

    def _demo_obs(self, key: str, rows: th.Tensor | None = None) -> th.Tensor:
        """Demo observations (``"obs"`` or ``"next_obs"``) as the Q-network sees them now.

        The demo tensors hold raw observations; under ``VecNormalize`` they are normalised with
        its current statistics at every use, as SB3's replay buffer does with its samples.
        """
        assert self._demo is not None
        obs = self._demo[key] if rows is None else self._demo[key][rows]
        if self._vec_normalize_env is None:
            return obs
        normalized = self._vec_normalize_env.normalize_obs(obs.cpu().numpy())
        return th.as_tensor(normalized, device=self.device)

    def _supervised_loss(self, q: th.Tensor, actions: th.Tensor) -> th.Tensor:
        if self.bc_loss == "cross_entropy":
            return F.cross_entropy(q, actions)
        margin = th.full_like(q, self.bc_margin).scatter(1, actions[:, None], 0.0)
        return ((q + margin).max(dim=1).values - q.gather(1, actions[:, None])[:, 0]).mean()

    def _behaviour_clone(self, demo: dict[str, th.Tensor]) -> dict[str, float]:
        obs, actions = self._demo_obs("obs"), demo["actions"]
        n = len(actions)
        batch_size = min(self.bc_batch_size, n)  # no batch larger than the demo pairs
        n_batches = -(-n // batch_size)
        gen = self._rng(2)
        optimizer = th.optim.Adam(self.q_net.parameters(), lr=self.bc_lr)
        self.policy.set_training_mode(True)
        loss_value = float("nan")
        for _ in range(self.bc_epochs):
            self.q_net_target.load_state_dict(self.q_net.state_dict())
            draw = th.multinomial(demo["weights"], n_batches * batch_size, True, generator=gen)
            losses = []
            for batch in draw.to(self.device).split(batch_size):
                q = self.q_net(obs[batch])
                a = actions[batch]
                loss = self._supervised_loss(q, a)
                if self.bc_td_coef > 0:
                    with th.no_grad():
                        next_obs = self._demo_obs("next_obs", batch)
                        next_q = self.q_net_target(next_obs).max(dim=1).values
                        target = demo["reward"][batch] + (
                            demo["not_done"][batch] * self.gamma * next_q
                        )
                    td = F.smooth_l1_loss(q.gather(1, a[:, None])[:, 0], target)
                    loss = loss + self.bc_td_coef * td
                optimizer.zero_grad()
                loss.backward()
                th.nn.utils.clip_grad_norm_(self.q_net.parameters(), self.max_grad_norm)
                optimizer.step()
                losses.append(loss.item())
            loss_value = float(np.mean(losses))
        self.policy.set_training_mode(False)
        self.q_net_target.load_state_dict(self.q_net.state_dict())
        with th.no_grad():
            accuracy = float((self.q_net(obs).argmax(dim=1) == actions).float().mean())
        self._record("bc/loss", loss_value)
        self._record("bc/accuracy", accuracy)
        self._record("bc/n_pairs", n)
        self.bc_n_pairs_ = n
        return {"loss": loss_value, "accuracy": accuracy, "n_pairs": n}

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """DQN's TD update, plus DQfD's supervised loss on demo pairs when ``demo_loss_coef``."""
        if not (self.demo_loss_coef > 0 and self._demo is not None):
            return super().train(gradient_steps, batch_size)
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        demo = self._demo
        losses, demo_losses = [], []
        for _ in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            with th.no_grad():
                next_q = self.q_net_target(replay_data.next_observations).max(dim=1).values
                target = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q[:, None]
            current = th.gather(self.q_net(replay_data.observations), 1, replay_data.actions.long())
            loss = F.smooth_l1_loss(current, target)
            rows = th.multinomial(demo["weights"], batch_size, True, generator=self._demo_gen)
            rows = rows.to(self.device)
            demo_q = self.q_net(self._demo_obs("obs", rows))
            demo_loss = self._supervised_loss(demo_q, demo["actions"][rows])
            losses.append(loss.item())
            demo_losses.append(demo_loss.item())
            self.policy.optimizer.zero_grad()
            (loss + self.demo_loss_coef * demo_loss).backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))
        self.logger.record("train/demo_loss", np.mean(demo_losses))

    def _prefill(self, data: dict[str, np.ndarray]) -> None:
        """Add the demo transitions to the replay buffer, ``n_envs`` rows at a time."""
        n, n_envs = len(data["actions"]), self.n_envs
        # the last group is completed by wrapping around to the first transitions
        order = np.arange(-(-n // n_envs) * n_envs) % n
        for rows in order.reshape(-1, n_envs):
            self.replay_buffer.add(  # type: ignore[union-attr]
                data["obs"][rows],
                data["next_obs"][rows],
                data["actions"][rows][:, None],
                data["reward"][rows],
                data["done"][rows],
                [{} for _ in rows],
            )

    def _excluded_save_params(self) -> list[str]:
        # Before BC the demonstrations are saved (a loaded model still starts with BC); after
        # it, the lifted demo pairs (_demo_data) are.
        return [
            *super()._excluded_save_params(),
            *(["demonstrations"] if self._bc_done else []),
            "task",
            "inverse_dynamics_",
            "_demo",
            "_demo_gen",
        ]

    def learn(
        self: SelfSwirlDQN,
        total_timesteps: int,
        callback: Any = None,
        log_interval: int = 4,
        tb_log_name: str = "SwirlDQN",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfSwirlDQN:
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )
