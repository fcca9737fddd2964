"""SwirlDQN: DQN on a SWIRL proxy task, started from per-segment behavioural cloning (paper §7)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pickle
import warnings
import zipfile
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN, HerReplayBuffer
from stable_baselines3.common.type_aliases import GymEnv, Schedule
from stable_baselines3.common.vec_env import VecEnv, VecFrameStack, unwrap_vec_wrapper
from stable_baselines3.dqn.policies import DQNPolicy
from torch.nn import functional as F

from sb3_swirl.buffers import DictNStepReplayBuffer
from sb3_swirl.demos import (
    Demonstration,
    DemoWarning,
    _as_demonstrations,
    check_demos_fit_spaces,
    check_demos_state_key,
    joined_state_note,
)
from sb3_swirl.features import RBFFeaturesExtractor
from sb3_swirl.inverse_dynamics import InverseDynamics
from sb3_swirl.vec_env import get_swirl_attr, same_task, swirl_task
from swirl_wrappers import Lifter, RewardConfig, SegmentTracker, TaskModel
from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_bool, check_int, check_option, check_real
from swirl_wrappers.wrappers import (
    GOAL_KEY,
    SEGMENT_KEY,
    SEGMENT_REWARD_KEY,
    TASK_REWARD_KEY,
    _key_tuple,
    far_outside_bounds,
    relabelling_refused,
    state_space,
)

__all__ = ["SwirlDQN"]


def check_state_key_covers(space: spaces.Dict, state_key: str | Sequence[str]) -> None:
    """Raise unless the task state joins every key of a Dict observation (the segment's aside):
    SwirlDQN clones demo states into a Q-network that sees the whole observation.

    Parameters
    ----------
    space : gymnasium.spaces.Dict
        The (lifted or unlifted) observation space.
    state_key : str or sequence of str
        The wrapper's ``state_key``.

    Raises
    ------
    ValueError
        Naming the keys ``state_key`` leaves out.
    """
    keys = list(_key_tuple(state_key))
    missing = [key for key in space.spaces if key != SEGMENT_KEY and key not in keys]
    if missing:
        raise ValueError(
            f"SwirlDQN clones the demos into the Q-network, which sees the whole Dict "
            f"observation, but the task state (state_key={keys}) leaves out {missing}: wrap "
            "with state_key listing every key and let the task read a part of it with "
            "fit_task(dims=...)"
        )


def check_discrete_actions(space: spaces.Space, *, from_zero: bool = True) -> None:
    """Raise unless ``space`` is ``Discrete`` (from 0, with ``from_zero``): SwirlDQN is a DQN.

    Parameters
    ----------
    space : gymnasium.spaces.Space
        The env's action space.
    from_zero : bool
        Also refuse ``Discrete(n, start=k)`` with ``k != 0`` (off where a wrapper applied
        later may shift the actions).

    Raises
    ------
    ValueError
        Naming the space and the algorithms that take it.
    """
    if not isinstance(space, spaces.Discrete):
        raise ValueError(
            f"SwirlDQN needs discrete actions (it is a DQN), and the env has {space}: train "
            "another SB3 algorithm (SAC, TD3, PPO) on the same SWIRL wrapper, without the BC "
            "start"
        )
    if from_zero and int(space.start) != 0:
        raise ValueError(
            f"SwirlDQN needs actions 0 .. n-1 (SB3's DQN picks Q-value indices), and the env "
            f"has {space}: shift them, e.g. a gymnasium.ActionWrapper whose action(a) returns "
            f"a + {int(space.start)}, with its action_space Discrete({space.n}), and record the "
            "demos' actions in that range"
        )


def _carries_task(env: Any) -> bool:
    """Whether ``env`` (a gymnasium env or a VecEnv) is lifted by a SWIRL wrapper."""
    if isinstance(env, VecEnv):
        return swirl_task(env) is not None
    try:
        return isinstance(env.get_wrapper_attr("task"), TaskModel)
    except AttributeError:  # a Fetch env's own `task` is a name, not a TaskModel
        return False


def _atomic_save(path: Any, suffix: str, write: Any) -> None:
    """``write(file)`` to ``path`` (``.suffix`` added when it has none, as SB3 does, and its
    folders made) through :func:`~swirl_wrappers._io.atomic_write`; a file object as it is."""
    if not isinstance(path, str | os.PathLike):
        write(path)
        return
    target = Path(path)
    if target.suffix == "":
        target = Path(f"{target}.{suffix}")
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(target, "wb") as fh:
        write(fh)


def _check_train_freq(train_freq: Any) -> None:
    """``train_freq`` as SB3 takes it, an int >= 1 or ``(n, "step" | "episode")``: SB3's own
    assertion comes only inside ``learn``, after the behavioural cloning."""
    if isinstance(train_freq, tuple) and len(train_freq) == 2:
        check_int("train_freq[0]", train_freq[0], low=1)
        unit = getattr(train_freq[1], "value", train_freq[1])  # SB3's TrainFrequencyUnit too
        check_option("train_freq[1]", unit, ("step", "episode"))
    elif not isinstance(train_freq, tuple):
        check_int("train_freq", train_freq, low=1)
    else:
        raise ValueError(
            f"train_freq must be an int or (n, 'step' | 'episode'), got {train_freq!r}"
        )


def _check_model_zip(path: Path, name: str) -> None:
    """Refuse, naming the file, what SB3's ``load`` would fail on deep inside: a file that is
    not a saved model (the demos' ``.npz``, a task JSON) or a model of another algorithm."""
    if not path.is_file() and path.suffix != ".zip":
        path = path.with_name(path.name + ".zip")  # SB3's load adds the suffix too
    if not path.is_file():
        return  # SB3 says the file is not found
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{name} is not a model saved by SwirlDQN.save (not a zip file)")
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        data = json.loads(archive.read("data")) if "data" in names else None
    if data is None:
        demos = any(n.endswith(".npy") for n in names)
        raise ValueError(
            f"{name} is not a model saved by SwirlDQN.save"
            + (
                ": it holds arrays, as a demos file does (load those with load_demos)"
                if demos
                else ""
            )
        )
    if data.get("task_json") is None:
        policy = data.get("policy_class")
        module = policy.get("__module__", "") if isinstance(policy, dict) else ""
        raise ValueError(
            f"{name} holds no SWIRL task: not a SwirlDQN model"
            + (f" (its policy comes from {module})" if module else "")
            + "; load it with its own algorithm (a plain DQN's with stable_baselines3.DQN.load)"
        )


class SwirlDQN(DQN):
    """DQN on a SWIRL proxy task, initialised by per-segment behavioural cloning (paper §7.2).

    The env carries the proxy task: ``SwirlWrapper`` in every sub-env or a ``SwirlVecEnv`` (see
    :func:`sb3_swirl.make_swirl_env`); SwirlDQN reads it with ``env.get_attr("task")``. Before
    the first ``learn``, :meth:`pretrain` replays the demonstrations through the wrappers' own
    :class:`~swirl_wrappers.SegmentTracker` (so each lifted observation and proxy reward is the
    one the agent sees online) and trains the Q-network to pick the demonstrated action with
    every segment weighted equally; Q-learning then explores ε-greedily from that start. After
    BC, the warm-up steps before ``learning_starts`` also follow the cloned policy ε-greedily
    (plain DQN takes uniform actions there), and a BC start usually wants a small
    ``exploration_initial_eps``.

    The supervised loss follows DQfD (Hester et al., 2018) rather than a plain softmax: with
    ``bc_loss="margin"`` (default) it is the large-margin loss ``max_a [Q(s, a) + l (a != a_E)]
    - Q(s, a_E)``, zero once the demo action wins by ``bc_margin`` (so it does not inflate Q,
    which the first TD updates would undo); ``"cross_entropy"`` is the paper's softmax over
    Q-values. ``demo_loss_coef > 0`` keeps that loss on a segment-balanced demo batch in every
    Q-learning update. ``save`` stores the lifted demo pairs with the model, so a loaded model
    trains on with the same loss.

    On ``Dict`` observations (``"MultiInputPolicy"``) a demo state is the wrapper's
    ``state_key`` values joined, which must cover every key (the Q-network sees them all), and
    ``n_steps > 1`` uses :class:`~sb3_swirl.buffers.DictNStepReplayBuffer` (SB3 has n-step
    returns for Box observations only).

    Parameters
    ----------
    policy, env, learning_rate, ..., device :
        As in :class:`stable_baselines3.DQN`.
    demonstrations : sequence of Demonstration, optional
        Demos of the task (states; actions optional), in any format
        :func:`sb3_swirl.as_demonstrations` reads. ``None``: those the env carries as its
        ``demonstrations`` attribute (:class:`sb3_swirl.zoo.SwirlTaskWrapper`, which rl_zoo3
        configs use), else none, which gives plain DQN on the proxy task.
    task : TaskModel, optional
        Checked against the env's task: they must be the same.
    bc_loss : {"margin", "cross_entropy"}
    bc_margin : float
        Margin ``l`` of the large-margin loss.
    bc_epochs : int
        Passes over the demo pairs in :meth:`pretrain`.
    bc_lr : float
        Adam learning rate of the BC stage.
    bc_batch_size : int
        Minibatch size, drawn so that every segment weighs the same.
    demo_loss_coef : float
        Weight of the supervised demo loss in every Q-learning update (0: plain DQN updates).
    double_q : bool
        Double DQN's TD target (van Hasselt et al., 2016): the online network picks the next
        action, the target network scores it, which curbs the over-estimation of the max.
    prefill_replay : bool
        Add the demo transitions (proxy reward, done at each demo's end) to the replay buffer,
        in order, so that SB3's n-step returns (``n_steps > 1``) read them as DQfD does. With
        ``HerReplayBuffer`` (``copy_info_dict=True``) each demo is an episode whose goals are
        relabelled as the agent's own are.
    pretrain_td_steps : int
        DQfD's pre-training (Hester et al., 2018): after BC, this many updates of the TD loss
        (plus the demo loss) on the prefilled demo transitions alone, the target network copied
        every ``target_update_interval`` of them, so that online learning starts from Q-values
        at the scale of the demos' returns rather than near 0. Where the reward is a cost paid
        at every step, Q-values near 0 are optimistic: the actions the agent tries can fall
        below the ones it has not tried, and the greedy policy drift off the clone (the
        README's Table 1: tensioning). Needs ``prefill_replay``.
    infer_actions : {"inverse_dynamics", "none"}
        For demos without actions: label them with an :class:`InverseDynamics` model trained on
        ``inverse_dynamics_steps`` random-action steps in the env (which also go into the
        replay buffer, and count as the agent's own: in ``num_timesteps``, so within
        ``learn``'s budget, and in the episodes ``TaskEvalCallback`` reports), or leave them
        out of BC.
    inverse_dynamics_steps : int
    inverse_dynamics_kwargs : dict, optional
        ``net_arch``, ``epochs``, ``lr``, ``batch_size`` of :class:`InverseDynamics`.

    Attributes
    ----------
    task : TaskModel
        The proxy task the model learns, with its ``reward_config``: an env wrapped with it
        (``SwirlWrapper(env, model.task)``) segments and rewards as in training.
    reward_config : RewardConfig
        The env's reward settings (the proxy reward of the replayed demos).
    inverse_dynamics_ : InverseDynamics
        After :meth:`infer_demo_actions`; saved with the model, so a loaded one labels more
        state-only demos as the trained one did.
    inverse_dynamics_episodes_ : int
        Episodes that ended during :meth:`infer_demo_actions`'s steps (0 before).
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
        bc_epochs: int = 300,
        bc_lr: float = 1e-3,
        bc_batch_size: int = 64,
        demo_loss_coef: float = 1.0,
        double_q: bool = False,
        prefill_replay: bool = False,
        pretrain_td_steps: int = 0,
        infer_actions: Literal["inverse_dynamics", "none"] = "inverse_dynamics",
        inverse_dynamics_steps: int = 2000,
        inverse_dynamics_kwargs: dict[str, Any] | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        # DQN's own settings, which SB3 checks late (inside learn) or not at all
        if not callable(learning_rate):
            check_real("learning_rate", learning_rate, low=0.0, low_open=True)
        for name, value, low in (
            ("buffer_size", buffer_size, 1),
            ("learning_starts", learning_starts, 0),
            ("batch_size", batch_size, 1),
            ("target_update_interval", target_update_interval, 1),
            ("gradient_steps", gradient_steps, -1),  # -1: as many as the env steps
            ("n_steps", n_steps, 1),
            ("stats_window_size", stats_window_size, 1),
            ("verbose", int(verbose) if isinstance(verbose, bool) else verbose, 0),  # as SB3
        ):
            check_int(name, value, low=low)
        _check_train_freq(train_freq)
        if tensorboard_log is not None and not isinstance(tensorboard_log, str | os.PathLike):
            raise ValueError(
                f"tensorboard_log must be a folder path or None, got {tensorboard_log!r}"
            )
        for name, value in (
            ("gamma", gamma),
            ("tau", tau),
            ("exploration_fraction", exploration_fraction),
            ("exploration_initial_eps", exploration_initial_eps),
            ("exploration_final_eps", exploration_final_eps),
        ):
            check_real(name, value, low=0.0, high=1.0)
        if max_grad_norm != math.inf:  # inf: no clipping, as in DQN
            check_real("max_grad_norm", max_grad_norm, low=0.0, low_open=True)
        if seed is not None:
            check_int("seed", seed, low=0, high=2**32 - 1)
        self.bc_loss = check_option("bc_loss", bc_loss, ("margin", "cross_entropy"))
        self.bc_margin = check_real("bc_margin", bc_margin, low=0.0)
        self.bc_epochs = check_int("bc_epochs", bc_epochs, low=0)
        self.bc_lr = check_real("bc_lr", bc_lr, low=0.0, low_open=True)
        self.bc_batch_size = check_int("bc_batch_size", bc_batch_size, low=1)
        self.demo_loss_coef = check_real("demo_loss_coef", demo_loss_coef, low=0.0)
        self.double_q = check_bool("double_q", double_q)
        self.prefill_replay = check_bool("prefill_replay", prefill_replay)
        self.pretrain_td_steps = check_int("pretrain_td_steps", pretrain_td_steps, low=0)
        if self.pretrain_td_steps and not self.prefill_replay:
            raise ValueError(
                "pretrain_td_steps trains on the demo transitions in the replay buffer: "
                "set prefill_replay=True as well"
            )
        self.infer_actions = check_option(
            "infer_actions", infer_actions, ("inverse_dynamics", "none")
        )
        self.inverse_dynamics_steps = check_int(
            "inverse_dynamics_steps", inverse_dynamics_steps, low=1
        )
        InverseDynamics.from_kwargs(inverse_dynamics_kwargs)  # bad settings fail now
        self.inverse_dynamics_kwargs = dict(inverse_dynamics_kwargs or {})
        if hasattr(env, "action_space"):  # an id: SB3 makes the env and checks
            check_discrete_actions(env.action_space)
        if prefill_replay and optimize_memory_usage:
            raise ValueError(
                "prefill_replay needs a replay buffer without optimize_memory_usage: the "
                "demo transitions do not follow one another as that buffer's rows must "
                "(set prefill_replay=False)"
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
        if demonstrations is None and self.env is not None and self.env.has_attr("demonstrations"):
            demonstrations = self.env.get_attr("demonstrations", indices=[0])[0]
        self.demonstrations: list[Demonstration] | None = None
        self._bc_done = False
        self.inverse_dynamics_episodes_ = 0
        self._labelled_at: int | None = None  # num_timesteps after infer_demo_actions
        self.bc_n_pairs_ = 0
        # The lifted demo pairs of the supervised loss: saved with the model, so that training
        # goes on with the same loss after `load` (the tensors are rebuilt from them).
        self._demo_data: dict[str, np.ndarray] | None = None
        self._demo: dict[str, th.Tensor] | None = None
        self.task: TaskModel | None = None
        self.task_json: str | None = None
        if self.env is not None:
            self._take_task(task)
            if demonstrations is not None:  # dict demos: joined in the wrapper's key order
                dict_obs = isinstance(self.observation_space, spaces.Dict)
                keys = self._state_keys() if dict_obs else None
                # one demo is enough here: the task is fitted already
                self.demonstrations = _as_demonstrations(demonstrations, None, keys, minimum=1)
            self._check_demonstrations()
            self._check_relabelling()
            if not self.demonstrations and (self.prefill_replay or self.pretrain_td_steps):
                warnings.warn(
                    "prefill_replay / pretrain_td_steps without demonstrations: there is "
                    "nothing to prefill the replay buffer with or to pre-train on (nor to "
                    "clone); give demonstrations=, or an env whose SWIRL wrapper holds them",
                    stacklevel=2,
                )
        elif _init_setup_model:
            raise ValueError(
                "SwirlDQN needs an environment that carries the SWIRL task: e.g. "
                "`SwirlWrapper(gym.make(env_id), task)` or `make_swirl_env(env_id, task)`"
            )
        elif demonstrations is not None:
            self.demonstrations = _as_demonstrations(demonstrations, None, None, minimum=1)
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ the task
    def _take_task(self, task: TaskModel | None) -> None:
        """Read the task and reward settings from the env (``get_attr``); check ``task``."""
        assert self.env is not None
        if task is not None and not isinstance(task, TaskModel):
            raise ValueError(f"task must be a swirl_wrappers.TaskModel, got {type(task).__name__}")
        self.reward_config = get_swirl_attr(self.env, "reward_config")
        # model.task rewards as the model was trained: wrapping an env with it goes on alike
        self.task = dataclasses.replace(
            get_swirl_attr(self.env, "task"), reward_config=self.reward_config
        )
        self.terminate_on_completion = get_swirl_attr(self.env, "terminate_on_completion")
        self.task_json = self.task.to_json()
        if task is not None and not same_task(task, self.task):
            raise ValueError("task differs from the task carried by the environment")

    def _trained_on_another(self, task: TaskModel) -> bool:
        """Whether ``task`` has other regions or rewards than the one the model was trained
        with (``task_json``; reward settings aside, which a model adopts)."""
        return self.task_json is not None and not same_task(
            task, TaskModel.from_json(self.task_json)
        )

    def _check_settings(self, saved: RewardConfig, ended: bool, stacklevel: int) -> None:
        """Warn when the env's reward settings or ``terminate_on_completion`` (now the model's)
        differ from ``saved`` and ``ended``, those the model was trained with, and when its
        shaping discounts otherwise."""
        if ended != self.terminate_on_completion:
            warnings.warn(
                f"the environment's SWIRL wrapper has terminate_on_completion="
                f"{self.terminate_on_completion}, but this model was trained with {ended}: its "
                "episodes now "
                + ("end on reaching" if self.terminate_on_completion else "go on past")
                + " the last region, and the demonstrations are replayed so; wrap the env as "
                "the training env was to go on alike",
                stacklevel=stacklevel,
            )
        if saved != self.reward_config:
            already = (
                "the Q-values and the demo transitions replayed so far were learnt with the old"
                if self._bc_done
                else "the demonstrations will be rewarded the same way; the Q-values learnt "
                "so far were not"
            )
            warnings.warn(
                f"the environment's SWIRL wrapper rewards with {self.reward_config}, but this "
                f"model was trained with {saved}; it goes on with the environment's ({already})",
                stacklevel=stacklevel,
            )
        mismatch = self.reward_config.discount_mismatch(self.gamma, "SwirlDQN")
        if mismatch:
            warnings.warn(mismatch, stacklevel=stacklevel)

    def _check_relabelling(self) -> None:
        """Refuse ``HerReplayBuffer`` now, not at the first update, where the task reads the
        goal (``SwirlWrapper.compute_reward`` would refuse every relabelled goal)."""
        her = isinstance(self.replay_buffer_class, type) and issubclass(
            self.replay_buffer_class, HerReplayBuffer
        )
        assert self.env is not None
        # has_attr first: a get_attr that fails inside a SubprocVecEnv worker kills the worker
        if her and self.env.has_attr("reads_goal"):
            reads = self.env.get_attr("reads_goal", indices=[0])[0]
            if reads:
                raise ValueError(relabelling_refused(reads))

    def _check_demonstrations(self) -> None:
        """Refuse demos that do not fit the env's spaces now, not inside ``learn``."""
        if not self.demonstrations:
            return
        if unwrap_vec_wrapper(self.env, VecFrameStack) is not None:
            raise ValueError(
                "SwirlDQN cannot clone demonstrations into a frame-stacked env (VecFrameStack): "
                "a demo holds one state a step. Train without VecFrameStack, or without "
                "demonstrations"
            )
        space = self.observation_space
        dict_obs = isinstance(space, spaces.Dict)
        if dict_obs:
            check_demos_state_key(self.demonstrations, self._state_keys(), "demonstration")
        check_demos_fit_spaces(
            self.demonstrations,
            self._demo_space().shape[0],
            self.action_space,
            "demonstration",
            "the environment's (unlifted) observations",
            joined_state_note({key: space[key].shape[0] for key in self._state_keys()})
            if dict_obs
            else " (demos must be states of the env under the SWIRL wrapper)",
        )
        states = [d.observations for d in self.demonstrations]  # 2 states or more each
        far = far_outside_bounds(
            np.min([x.min(axis=0) for x in states], axis=0),
            np.max([x.max(axis=0) for x in states], axis=0),
            self._demo_space(),
        )
        if far:
            warnings.warn(
                f"the demonstrations' states lie far outside the env's observation bounds "
                f"({far}): recorded in other units, or on another env? BC would clone their "
                "actions at states the agent never sees",
                DemoWarning,
                stacklevel=3,  # the SwirlDQN(...) call
            )
        unlabelled = [i for i, d in enumerate(self.demonstrations) if d.actions is None]
        if unlabelled and self.infer_actions == "inverse_dynamics" and dict_obs:
            raise ValueError(
                f"demonstrations {unlabelled} have no actions, and inferring them needs a flat "
                "Box observation: on Dict observations give demos with actions (or "
                "infer_actions='none' to clone only those that have them)"
            )

    def _demo_space(self) -> spaces.Box:
        """The space of a demo state: the unlifted observation (Box), or on Dict observations
        the values of every key joined in the wrapper's ``state_key`` order, which must name
        them all (a demo is cloned into the Q-network, which sees the whole observation)."""
        space, task = self.observation_space, self.task
        assert task is not None
        if isinstance(space, spaces.Box) and len(space.shape) == 1:
            state_dim = space.shape[0] - task.n_indices
            return spaces.Box(space.low[:state_dim], space.high[:state_dim], dtype=space.dtype)
        if not isinstance(space, spaces.Dict):
            raise ValueError(f"SwirlDQN needs a flat Box or a Dict observation, got {space}")
        keys = self._state_keys()
        check_state_key_covers(space, keys)
        return state_space(space, keys)[0]

    def _state_keys(self) -> tuple[str, ...]:
        assert self.env is not None
        return _key_tuple(get_swirl_attr(self.env, "state_key"))

    def _as_observations(self, states: np.ndarray) -> Any:
        """Demo states as (unlifted) observations: Dict observations split by key."""
        space = self.observation_space
        if not isinstance(space, spaces.Dict):
            return states
        out, start = {}, 0
        for key in self._state_keys():
            size = space[key].shape[0]
            out[key] = states[:, start : start + size].astype(space[key].dtype)
            start += size
        return out

    def _setup_model(self) -> None:
        if self.task is None and self.task_json is not None:  # `load` without an env
            self.task = TaskModel.from_json(self.task_json)
            if isinstance(self.reward_config, RewardConfig):  # the rewards it was trained with
                self.task = dataclasses.replace(self.task, reward_config=self.reward_config)
        elif self.task is not None and self._trained_on_another(self.task):  # `load` with one
            raise ValueError(
                "the environment's proxy task differs from the one this model was trained "
                "with; load without env=, then wrap the env with model.task"
            )
        if self.env is not None:  # built, or loaded with an env: the env's settings count
            trained_with, ended = self.reward_config, self.terminate_on_completion
            self._take_task(None)
            # called from __init__ or load, which the user called
            self._check_settings(trained_with, ended, stacklevel=4)
        extractor = self.policy_kwargs.get("features_extractor_class")
        if isinstance(extractor, type) and issubclass(extractor, RBFFeaturesExtractor):
            fe_kwargs = dict(self.policy_kwargs.get("features_extractor_kwargs") or {})
            if "n_indices" not in fe_kwargs and self.task is not None:
                fe_kwargs["n_indices"] = self.task.n_indices
                self.policy_kwargs = {**self.policy_kwargs, "features_extractor_kwargs": fe_kwargs}
        dict_n_step = (
            self.replay_buffer_class is None
            and isinstance(self.observation_space, spaces.Dict)
            and self.n_steps > 1
        )
        if dict_n_step:  # SB3 has n-step returns for Box observations only
            self.replay_buffer_class = DictNStepReplayBuffer
            self.replay_buffer_kwargs = {
                **self.replay_buffer_kwargs,
                "n_steps": self.n_steps,
                "gamma": self.gamma,
            }
        with warnings.catch_warnings():
            # SB3 says n_steps is ignored when the buffer's kwargs carry it (this buffer's, or
            # SB3's own n-step buffer saved with a model and loaded back)
            if self.n_steps > 1 and self.replay_buffer_kwargs.get("n_steps") == self.n_steps:
                warnings.filterwarnings("ignore", message="`n_steps=", category=UserWarning)
            super()._setup_model()
        if self._demo_data is not None and self._demo is None:  # after `load`
            self._demo = self._demo_tensors(self._demo_data)

    def set_env(self, env: Any, force_reset: bool = True) -> None:
        """:meth:`stable_baselines3.DQN.set_env`, refusing an env with a different proxy task.

        The demonstrations are lifted and the Q-network was trained with ``model.task``; an
        env that segments or rewards by another task would silently train on a different
        problem.
        """
        env = self._wrap_env(env, self.verbose)  # a VecEnv, as SB3's set_env makes it
        if self._trained_on_another(get_swirl_attr(env, "task")):  # before taking the env
            raise ValueError(
                "the new environment's proxy task differs from the one this model was built "
                "with (model.task); wrap the env with model.task, or start a new model"
            )
        super().set_env(env, force_reset)
        trained_with, ended = self.reward_config, self.terminate_on_completion
        self._take_task(None)  # and its reward settings, which replay the demos
        self._check_settings(trained_with, ended, stacklevel=3)

    # ------------------------------------------------------------------ hooks
    def _setup_learn(self, *args: Any, **kwargs: Any) -> tuple[int, Any]:
        # pretrain() called by hand labelled state-only demos with env steps: the first learn
        # counts them as it counts its own labelling steps, rather than resetting them away
        by_hand = self._labelled_at is not None and self._labelled_at == self.num_timesteps > 0
        kept = (self.num_timesteps, self._episode_num, self.ep_info_buffer, self.ep_success_buffer)
        result = super()._setup_learn(*args, **kwargs)
        if by_hand and self.num_timesteps == 0:  # reset_num_timesteps=True
            self.num_timesteps, self._episode_num, self.ep_info_buffer, self.ep_success_buffer = (
                kept
            )
        if not self._bc_done and self.demonstrations:
            before = self.num_timesteps
            self.pretrain()
            labelling = self.num_timesteps - before
            if labelling and self.num_timesteps >= result[0]:
                warnings.warn(
                    f"labelling the state-only demos took {labelling} env steps "
                    f"(inverse_dynamics_steps={self.inverse_dynamics_steps}), which count "
                    f"toward learn's budget: this learn ends at {self.num_timesteps} steps, "
                    "past its total_timesteps and without Q-learning. Give learn more steps, "
                    "or fewer inverse_dynamics_steps",
                    stacklevel=3,
                )
        return result

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        # After BC the warm-up steps follow the cloned policy ε-greedily: uniform actions
        # before ``learning_starts`` would throw the demonstrations' head start away.
        if self.bc_n_pairs_ > 0:
            learning_starts = 0
        return super()._sample_action(learning_starts, action_noise, n_envs)

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """DQN's TD update (Double DQN's target with ``double_q``), plus DQfD's supervised loss
        on demo pairs when ``demo_loss_coef``."""
        with_demo = self.demo_loss_coef > 0 and self._demo is not None
        if not (with_demo or self.double_q):
            return super().train(gradient_steps, batch_size)
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        demo = self._demo
        losses, demo_losses = [], []
        for _ in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            target = self._td_target(replay_data.next_observations)
            target = replay_data.rewards + (1 - replay_data.dones) * discounts * target[:, None]
            current = th.gather(self.q_net(replay_data.observations), 1, replay_data.actions.long())
            loss = F.smooth_l1_loss(current, target)
            losses.append(loss.item())
            if with_demo:
                assert demo is not None
                rows = th.multinomial(demo["weights"], batch_size, True, generator=self._demo_gen)
                rows = rows.to(self.device)
                demo_loss = self._supervised_loss(
                    self.q_net(self._demo_obs(rows)), demo["actions"][rows]
                )
                demo_losses.append(demo_loss.item())
                loss = loss + self.demo_loss_coef * demo_loss
            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))
        if demo_losses:
            self.logger.record("train/demo_loss", np.mean(demo_losses))

    @th.no_grad()
    def _td_target(self, next_observations: th.Tensor) -> th.Tensor:
        """The value of the next states: ``max_a Q_target(s', a)``, or with ``double_q``
        ``Q_target(s', argmax_a Q(s', a))``."""
        next_q = self.q_net_target(next_observations)
        if not self.double_q:
            return next_q.max(dim=1).values
        best = self.q_net(next_observations).argmax(dim=1, keepdim=True)
        return next_q.gather(1, best)[:, 0]

    # ------------------------------------------------------------------ demonstrations
    def _demo_transitions(self) -> list[dict[str, Any]]:
        """Each demo's transitions as the agent sees them, replayed through the wrappers'
        :class:`SegmentTracker`: lifted observations, proxy rewards and segments.

        The last transition of a demo is terminal (demos end when the task is done) unless the
        demo is ``truncated``; with ``terminate_on_completion`` a demo ends on the step that
        reaches the last region, as the wrapper's episode would. Demos without rewards are
        taken to end in success, task reward 1 on their last transition, unless they are
        ``truncated`` (a time limit ended them: every step pays 0).
        """
        task = self.task
        assert task is not None
        unlifted = self.observation_space
        if isinstance(unlifted, spaces.Dict):
            unlifted = spaces.Dict({k: v for k, v in unlifted.items() if k != SEGMENT_KEY})
            lifter = Lifter(unlifted, task, self._state_keys())
        else:
            lifter = Lifter(self._demo_space(), task)
        out = []
        for demo in self.demonstrations or []:
            states, n = demo.observations, len(demo)
            task_rewards = np.zeros(n) if demo.rewards is None else demo.rewards
            if demo.rewards is None and not demo.truncated:
                task_rewards[-1] = 1.0
            tracker = SegmentTracker(task, self.reward_config, None, self.terminate_on_completion)
            tracker.reset(states[0])
            index, rewards, terminated = [tracker.index], [], False
            for t in range(n):
                ends = t == n - 1 and not demo.truncated
                reward, terminated = tracker.step(states[t + 1], task_rewards[t], ends)
                index.append(tracker.index)
                rewards.append(float(reward))
                if terminated:
                    break
            obs = _cast(
                lifter.lift(self._as_observations(states[: len(index)]), np.array(index)),
                self.observation_space,
            )
            out.append(
                {
                    "obs": _take(obs, slice(None, -1)),
                    "next_obs": _take(obs, slice(1, None)),
                    "segment": np.array(index[:-1]),
                    "reward": np.array(rewards),
                    "task_reward": np.asarray(task_rewards[: len(rewards)], dtype=np.float64),
                    # the last transition ends the demo: in a termination, or a truncation
                    "done": (np.arange(len(rewards)) == len(rewards) - 1) & bool(terminated),
                    "end": np.arange(len(rewards)) == len(rewards) - 1,
                    "actions": None if demo.actions is None else demo.actions[: len(rewards)],
                    "states": states[: len(index)],
                }
            )
        return out

    def infer_demo_actions(self, states: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Label state-only demos with an :class:`InverseDynamics` model ``p(a | s, s')``.

        The model is trained on ``inverse_dynamics_steps`` steps of uniformly random actions in
        the training env; those transitions also go into the replay buffer, so the interaction
        is not wasted, and count in ``num_timesteps`` and SB3's episode statistics (the
        episodes that ended, ``inverse_dynamics_episodes_``, in ``TaskEvalCallback``'s), also
        where ``pretrain`` was called by hand before the first ``learn``. The
        fitted model is kept as ``inverse_dynamics_``.

        Parameters
        ----------
        states : sequence of arrays of shape (T+1, d)
            The raw state sequences of the demos.

        Returns
        -------
        list of int arrays of shape (T,)
        """
        assert self.task is not None and self.env is not None
        if isinstance(self.observation_space, spaces.Dict):
            raise ValueError(
                "inferring demo actions needs a flat Box observation; on Dict observations "
                "give demos with actions"
            )
        state_dim = self.observation_space.shape[0] - self.task.n_indices  # type: ignore[index]
        n_actions = int(self.action_space.n)  # type: ignore[attr-defined]
        vec_norm = self._vec_normalize_env
        raw = vec_norm.unnormalize_obs if vec_norm is not None else (lambda o: o)
        if self._last_obs is None:
            self._last_obs = self.env.reset()  # type: ignore[assignment]
            if vec_norm is not None:
                self._last_original_obs = vec_norm.get_original_obs()
        seeds = np.random.SeedSequence(self.seed).generate_state(2)
        rng = np.random.default_rng(seeds[0])
        s, s_next, acts = [], [], []
        for _ in range(-(-self.inverse_dynamics_steps // self.n_envs)):
            actions = rng.integers(n_actions, size=self.n_envs)
            before = raw(np.asarray(self._last_obs))[:, :state_dim]
            new_obs, rewards, dones, infos = self.env.step(actions)
            after = raw(np.asarray(new_obs)).copy()
            for i in np.flatnonzero(dones):
                after[i] = raw(infos[i]["terminal_observation"])
            s.append(before)
            s_next.append(after[:, :state_dim])
            acts.append(actions)
            self._store_transition(self.replay_buffer, actions, new_obs, rewards, dones, infos)  # type: ignore[arg-type]
            self.num_timesteps += self.n_envs  # the agent's own steps, as learn counts them
            if self.ep_info_buffer is None:  # pretrain() by hand, before learn
                self.ep_info_buffer = deque(maxlen=self._stats_window_size)
                self.ep_success_buffer = deque(maxlen=self._stats_window_size)
            self._update_info_buffer(infos, dones)
            self._episode_num += int(np.sum(dones))
            self.inverse_dynamics_episodes_ += int(np.sum(dones))
        self._labelled_at = self.num_timesteps
        model = InverseDynamics.from_kwargs(self.inverse_dynamics_kwargs, seed=int(seeds[1]))
        model.fit(np.concatenate(s), np.concatenate(s_next), np.concatenate(acts), n_actions)
        self.inverse_dynamics_ = model
        self._record("bc/inverse_dynamics_accuracy", model.accuracy_)
        return [model.predict(d[:-1], d[1:]) for d in states]

    def pretrain(self) -> dict[str, float]:
        """Per-segment behavioural cloning of the demonstrations into the Q-network.

        Runs once (``learn`` calls it; the saved flag ``_bc_done`` stops a repeat after
        ``load``) and can be called by hand. Labels state-only demos first (see
        ``infer_actions``), trains ``q_net`` on the demo pairs of every segment with equal
        weight per segment, copies it to ``q_net_target`` and, with ``prefill_replay``, adds
        the demo transitions to the replay buffer, then runs ``pretrain_td_steps`` TD updates
        on them. Logs ``bc/loss``, ``bc/accuracy`` and ``bc/n_pairs`` (and, after labelling,
        ``bc/inverse_dynamics_accuracy``: on the labelling steps themselves, not held out);
        ``train`` logs ``train/demo_loss``, the supervised loss. They are written at the first
        log dump of ``learn``.

        Returns
        -------
        dict
            ``loss`` (last epoch), ``accuracy`` (greedy action == demo action on the demo
            states), ``n_pairs``.
        """
        demos = self._demo_transitions()
        missing = [d for d in demos if d["actions"] is None]
        if missing and self.infer_actions == "inverse_dynamics":
            labels = self.infer_demo_actions([d["states"] for d in missing])
            for demo, label in zip(missing, labels, strict=True):
                demo["actions"] = label[: len(demo["reward"])]
        elif missing and len(missing) < len(demos):
            unlabelled = [n for n, d in enumerate(demos) if d["actions"] is None]
            warnings.warn(
                f"demos {unlabelled} have no actions and infer_actions='none': BC leaves them "
                f"out and clones the other {len(demos) - len(missing)} (infer_actions="
                "'inverse_dynamics' labels them)",
                stacklevel=2,
            )
        demos = [d for d in demos if d["actions"] is not None]
        self._bc_done = True
        if not demos:
            warnings.warn(
                "no demonstration has actions and infer_actions='none': skipping BC",
                stacklevel=2,
            )
            return {"loss": float("nan"), "accuracy": float("nan"), "n_pairs": 0}
        data = {k: _concatenate([d[k] for d in demos]) for k in demos[0] if k != "states"}
        data["actions"] = data["actions"].astype(np.int64)
        vec_norm = self._vec_normalize_env
        if vec_norm is not None and vec_norm.training and vec_norm.norm_obs:
            # else BC fits inputs normalised by the statistics of a reset or two, which the
            # first rollouts then move far away
            if isinstance(data["obs"], dict):
                for key in vec_norm.norm_obs_keys:
                    vec_norm.obs_rms[key].update(data["obs"][key])
            else:
                vec_norm.obs_rms.update(data["obs"])
        self._demo_data = data
        self._demo = self._demo_tensors(data)
        if self.verbose >= 1 and self.bc_epochs:
            print(
                f"SwirlDQN: cloning {len(data['actions'])} demo pairs over {self.bc_epochs} "
                "epochs (behavioural cloning) before the first env step",
                flush=True,
            )
        info = self._behaviour_clone()
        if self.verbose >= 1 and self.bc_epochs:
            print(f"SwirlDQN: BC accuracy {info['accuracy']:.3f} on the demo pairs", flush=True)
        if self.prefill_replay:
            unrewarded = [i for i, d in enumerate(self.demonstrations or []) if d.rewards is None]
            weight = self.reward_config.task_reward_weight
            if unrewarded and weight != 0:  # TD learning reads the env's reward they lack
                warnings.warn(
                    f"demos {unrewarded} hold no rewards: in the replay buffer (prefill_replay) "
                    "their steps pay the env's reward as 0, and 1 on the last step of a demo not "
                    f"truncated (taken to succeed), which task_reward_weight={weight:g} adds to "
                    "the proxy reward. "
                    "Record the env's rewards, Demonstration(observations, actions, rewards) "
                    "(collect_demos does), or set task_reward_weight to 0",
                    DemoWarning,
                    stacklevel=3,
                )
            room = self.replay_buffer.buffer_size * self.n_envs  # type: ignore[union-attr]
            if len(data["actions"]) > room:
                warnings.warn(
                    f"the {len(data['actions'])} demo transitions do not fit the replay buffer "
                    f"(buffer_size={room}): the first are overwritten before any env step, and "
                    "the rest by the agent's own soon after. Raise buffer_size",
                    DemoWarning,
                    stacklevel=3,
                )
            self._prefill(data)
        if self.pretrain_td_steps:
            if self.verbose >= 1:
                print(
                    f"SwirlDQN: {self.pretrain_td_steps} TD updates on the demo transitions "
                    "before the first env step (pretrain_td_steps)",
                    flush=True,
                )
            self._pretrain_td()
        return info

    def _pretrain_td(self) -> None:
        """DQfD's pre-training: Q-learning updates on the prefilled demo transitions alone."""
        if not hasattr(self, "_logger"):  # `pretrain` called by hand, before `learn`
            from stable_baselines3.common.logger import Logger

            self._logger = Logger(folder=None, output_formats=[])
        left = self.pretrain_td_steps
        while left > 0:
            steps = min(left, self.target_update_interval)
            self.train(steps, self.batch_size)
            self.q_net_target.load_state_dict(self.q_net.state_dict())
            left -= steps
        self.policy.set_training_mode(False)

    def _demo_tensors(self, data: dict[str, np.ndarray]) -> dict[str, th.Tensor]:
        # every segment weighs the same, so short segments are not drowned out by long ones
        counts = np.bincount(data["segment"])
        self._demo_gen = self._torch_generator(3)
        return {
            "obs": _map(data["obs"], lambda a: th.as_tensor(a, device=self.device)),
            "actions": th.as_tensor(data["actions"], device=self.device),
            "weights": th.as_tensor(1.0 / counts[data["segment"]], dtype=th.float64),
        }

    def _torch_generator(self, stream: int) -> th.Generator:
        seed = int(np.random.SeedSequence(self.seed).generate_state(1)[0]) + stream
        return th.Generator().manual_seed(seed)

    def _demo_obs(self, rows: th.Tensor | None = None) -> Any:
        """Demo observations as the Q-network sees them now.

        The demo tensors hold raw observations; under ``VecNormalize`` they are normalised with
        its current statistics at every use, as SB3's replay buffer does with its samples.
        """
        assert self._demo is not None
        obs = self._demo["obs"] if rows is None else _take(self._demo["obs"], rows)
        if self._vec_normalize_env is None:
            return obs
        normalized = self._vec_normalize_env.normalize_obs(_map(obs, lambda t: t.cpu().numpy()))
        return _map(normalized, lambda a: th.as_tensor(a, device=self.device))

    def _supervised_loss(self, q: th.Tensor, actions: th.Tensor) -> th.Tensor:
        if self.bc_loss == "cross_entropy":
            return F.cross_entropy(q, actions)
        margin = th.full_like(q, self.bc_margin).scatter(1, actions[:, None], 0.0)
        return ((q + margin).max(dim=1).values - q.gather(1, actions[:, None])[:, 0]).mean()

    def _behaviour_clone(self) -> dict[str, float]:
        assert self._demo is not None
        obs, actions = self._demo_obs(), self._demo["actions"]
        n = len(actions)
        batch_size = min(self.bc_batch_size, n)  # no batch larger than the demo pairs
        n_batches = -(-n // batch_size)
        gen = self._torch_generator(2)
        optimizer = th.optim.Adam(self.q_net.parameters(), lr=self.bc_lr)
        self.policy.set_training_mode(True)
        loss_value = float("nan")
        for _ in range(self.bc_epochs):
            draw = th.multinomial(
                self._demo["weights"], n_batches * batch_size, True, generator=gen
            )
            losses = []
            for batch in draw.to(self.device).split(batch_size):
                loss = self._supervised_loss(self.q_net(_take(obs, batch)), actions[batch])
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

    def _prefill(self, data: dict[str, np.ndarray]) -> None:
        """Add the demo transitions to the replay buffer, ``n_envs`` rows at a time.

        Each env column gets a contiguous run of the transitions (the last column wraps around
        to the first ones), so an n-step buffer reads a demo in order; where a column's run
        cuts a demo short, or a ``truncated`` demo ends, the end is a time-limit truncation, so
        no return is read across it into the next demo, the next column's or the online
        transitions, and ``HerReplayBuffer`` draws no goal from beyond it. The infos hold the
        rewards' parts, as the wrapper's steps do, for ``SwirlWrapper.compute_reward``.
        """
        n, n_envs = len(data["actions"]), self.n_envs
        length = -(-n // n_envs)
        order = (np.arange(length * n_envs) % n).reshape(n_envs, length).T
        goals = data["next_obs"].get("desired_goal") if isinstance(data["obs"], dict) else None
        for t, rows in enumerate(order):
            done = data["done"][rows]
            truncated = ~done & (data["end"][rows] | (t == length - 1))
            infos: list[dict[str, Any]] = [
                {
                    "TimeLimit.truncated": bool(truncated[i]),
                    TASK_REWARD_KEY: float(data["task_reward"][row]),
                    SEGMENT_REWARD_KEY: float(data["reward"][row]),
                    **({} if goals is None else {GOAL_KEY: goals[row]}),
                }
                for i, row in enumerate(rows)
            ]
            self.replay_buffer.add(  # type: ignore[union-attr]
                _take(data["obs"], rows),
                _take(data["next_obs"], rows),
                data["actions"][rows][:, None],
                data["reward"][rows],
                done | truncated,
                infos,
            )

    def _record(self, key: str, value: float) -> None:
        if hasattr(self, "_logger"):
            self.logger.record(key, value)

    def save(
        self,
        path: Any,
        exclude: Sequence[str] | None = None,
        include: Sequence[str] | None = None,
    ) -> None:
        """SB3's ``save``, written atomically: a failure part-way (Ctrl-C, a full disk) leaves
        the file it replaces as it was, and a path that is a folder is an error (SB3 writes
        ``PATH_2`` instead, where a replay buffer saved to the same path would land too). As in
        SB3, ``.zip`` is added to a path without a suffix and missing folders are made."""
        _atomic_save(path, "zip", lambda fh: super(SwirlDQN, self).save(fh, exclude, include))

    def save_replay_buffer(self, path: Any) -> None:
        """SB3's ``save_replay_buffer``, written atomically as :meth:`save` is (``.pkl``)."""
        _atomic_save(path, "pkl", lambda fh: super(SwirlDQN, self).save_replay_buffer(fh))

    def load_replay_buffer(self, path: Any, truncate_last_traj: bool = True) -> None:
        """SB3's ``load_replay_buffer``; a buffer that does not fit this model (another number
        of envs, other spaces: another env's or task's) is refused, naming the file, and the
        model keeps its own (SB3 takes it, and ``learn`` fails deep inside the buffer), as is
        a file that holds no replay buffer."""
        own, name = (
            self.replay_buffer,
            os.fspath(path) if isinstance(path, str | os.PathLike) else path,
        )
        try:
            super().load_replay_buffer(path, truncate_last_traj)
        except (pickle.UnpicklingError, EOFError) as exc:  # SB3: "invalid load key, '{'"
            self.replay_buffer = own
            raise ValueError(
                f"{name}: not a replay buffer written by save_replay_buffer, or cut short ({exc})"
            ) from exc
        except AssertionError as exc:  # SB3's check that it holds a ReplayBuffer
            self.replay_buffer = own
            raise ValueError(f"{name}: {exc}; it holds no replay buffer") from exc
        buffer = self.replay_buffer
        wrong = [
            f"{what} {theirs} (this model: {ours})"
            for what, theirs, ours in (
                ("n_envs", buffer.n_envs, self.n_envs),
                ("observation space", buffer.observation_space, self.observation_space),
                ("action space", buffer.action_space, self.action_space),
            )
            if theirs != ours
        ]
        if wrong:
            self.replay_buffer = own
            raise ValueError(
                f"{name}: the replay buffer does not fit this model: {'; '.join(wrong)}"
            )

    @classmethod
    def load(cls, path: Any, *args: Any, **kwargs: Any) -> SwirlDQN:  # type: ignore[override]
        """SB3's ``load``; a zip that holds no SWIRL task (a plain DQN's) is refused, naming
        the file, rather than giving a SwirlDQN that knows no segments."""
        name = os.fspath(path) if isinstance(path, str | os.PathLike) else path
        env = kwargs.get("env", args[0] if args else None)
        if env is not None and not _carries_task(env):  # SB3 would say its spaces differ
            raise ValueError(
                f"env= carries no SWIRL task: wrap it with the one {name} holds, "
                f"`SwirlWrapper(env, SwirlDQN.load({name!r}).task)`, or load without env="
            )
        if isinstance(path, str | os.PathLike):
            _check_model_zip(Path(path), name)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = super().load(path, *args, **kwargs)
        for warning in caught:  # said where the user called load
            warnings.warn(warning.message, warning.category, stacklevel=2)
        if model.task_json is None:
            raise ValueError(
                f"{name} holds no SWIRL task: not a SwirlDQN model (a plain DQN's loads with "
                "stable_baselines3.DQN.load)"
            )
        return model

    def _excluded_save_params(self) -> list[str]:
        # Before BC the demonstrations are saved (a loaded model still starts with BC); after
        # it, the lifted demo pairs (_demo_data) are. The task is saved as task_json.
        return [
            *super()._excluded_save_params(),
            *(["demonstrations"] if self._bc_done else []),
            "task",
            "_demo",
            "_demo_gen",
        ]

    def predict(
        self,
        observation: Any,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """DQN's ``predict``; an observation of the env without its SWIRL wrapper (no segment)
        is refused with how to wrap it, where SB3 would only say that its shape differs."""
        space, task = self.observation_space, self.task
        if isinstance(space, spaces.Dict) and isinstance(observation, Mapping):
            unlifted = SEGMENT_KEY not in observation
        else:
            shape = np.shape(observation)
            unlifted = (
                isinstance(space, spaces.Box)
                and len(space.shape) == 1
                and task is not None
                and bool(shape)
                and shape[-1] == space.shape[0] - task.n_indices
            )
        if unlifted:
            raise ValueError(
                "the observation has no segment: it comes from the env without its SWIRL "
                "wrapper. Predict (and evaluate) on the env wrapped with the model's task, "
                "SwirlWrapper(env, model.task) or make_swirl_env(env_id, model.task)"
            )
        return super().predict(observation, state, episode_start, deterministic)

    def learn(
        self,
        total_timesteps: int,
        callback: Any = None,
        log_interval: int = 4,
        tb_log_name: str = "SwirlDQN",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SwirlDQN:
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )


# Demo observations are arrays (Box observations) or dicts of arrays (Dict observations).
def _map(obs: Any, fn: Any) -> Any:
    return {key: fn(value) for key, value in obs.items()} if isinstance(obs, dict) else fn(obs)


def _take(obs: Any, rows: Any) -> Any:
    return _map(obs, lambda value: value[rows])


def _concatenate(parts: list[Any]) -> Any:
    if isinstance(parts[0], dict):
        return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}
    return np.concatenate(parts)


def _cast(obs: Any, space: spaces.Space) -> Any:
    if isinstance(obs, dict):
        return {key: value.astype(space[key].dtype) for key, value in obs.items()}
    return obs.astype(space.dtype)
