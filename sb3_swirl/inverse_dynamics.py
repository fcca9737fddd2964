"""Inverse dynamics ``p(a | s, s')``: action labels for state-only demonstrations (BCO)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from sklearn.exceptions import NotFittedError
from torch import nn
from torch.nn import functional as F

from swirl_wrappers._validation import check_int, check_real, check_widths

__all__ = ["InverseDynamics"]


class InverseDynamics:
    """An MLP classifier of the discrete action that moved a state ``s`` to ``s'``.

    Inputs are ``(s, s' - s)``, standardised with the statistics of the training transitions.

    Parameters
    ----------
    net_arch : sequence of int
        Hidden layer widths.
    epochs : int
        Passes over the training transitions.
    lr : float
        Adam learning rate.
    batch_size : int
    seed : int, optional
        Seeds the initial weights and the minibatch order.

    Attributes
    ----------
    model_ : torch.nn.Sequential
        The fitted network (logits over the actions).
    accuracy_ : float
        Fraction of the training transitions whose action the fitted model predicts.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> s = rng.normal(size=(600, 2)); a = rng.integers(2, size=600)
    >>> s_next = s + np.where(a[:, None] == 1, 0.1, -0.1)
    >>> model = InverseDynamics(epochs=20, seed=0).fit(s, s_next, a, n_actions=2)
    >>> bool((model.predict(s, s_next) == a).mean() > 0.95)
    True
    """

    def __init__(
        self,
        net_arch: Sequence[int] = (64, 64),
        epochs: int = 50,
        lr: float = 1e-3,
        batch_size: int = 256,
        seed: int | None = None,
    ) -> None:
        self.net_arch = check_widths("net_arch", net_arch)
        self.epochs = check_int("epochs", epochs, low=1)
        self.lr = check_real("lr", lr, low=0.0, low_open=True)
        self.batch_size = check_int("batch_size", batch_size, low=1)
        self.seed = None if seed is None else check_int("seed", seed, low=0, high=2**32 - 1)

    @classmethod
    def from_kwargs(cls, kwargs: dict[str, Any] | None, seed: int | None = None) -> InverseDynamics:
        """Build from a dict of the constructor's settings, naming unknown keys."""
        kwargs = dict(kwargs or {})
        allowed = ("net_arch", "epochs", "lr", "batch_size")
        unknown = sorted(set(kwargs) - set(allowed))
        if unknown:
            raise ValueError(f"unknown inverse dynamics settings {unknown}; use {list(allowed)}")
        return cls(**kwargs, seed=seed)

    @staticmethod
    def _transitions(states: Any, next_states: Any, dim: int | None = None) -> np.ndarray:
        """``(s, s' - s)`` of each transition, after checking shapes and values."""
        s = np.asarray(states, dtype=np.float64)
        s_next = np.asarray(next_states, dtype=np.float64)
        if s.ndim != 2 or s.shape != s_next.shape or not len(s):
            raise ValueError(
                "states and next_states must be arrays of one shape (n_transitions, state_dim), "
                f"n >= 1; got {s.shape} and {s_next.shape}"
            )
        if dim is not None and s.shape[1] != dim:
            raise ValueError(f"states have {s.shape[1]} dims; the model was fitted on {dim}")
        bad = np.flatnonzero(~np.isfinite(np.concatenate([s, s_next], axis=1)).all(axis=1))
        if bad.size:
            raise ValueError(f"transition {bad[0]} holds NaN or inf")
        return np.concatenate([s, s_next - s], axis=1)

    def _inputs(self, states: np.ndarray, next_states: np.ndarray) -> th.Tensor:
        z = self._transitions(states, next_states, self._mean.size // 2)
        return th.as_tensor((z - self._mean) / self._std, dtype=th.float32)

    def fit(
        self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray, n_actions: int
    ) -> InverseDynamics:
        """Train on transitions ``states[i] -> next_states[i]`` taken with ``actions[i]``.

        Parameters
        ----------
        states, next_states : arrays of shape (n, state_dim)
        actions : int array of shape (n,)
            Discrete actions in ``0 .. n_actions - 1`` (the labels of a ``Discrete`` space).
        n_actions : int

        Raises
        ------
        ValueError
            Naming the problem: shapes that do not match, NaN or inf, actions that are not
            integers in ``0 .. n_actions - 1`` (a continuous action has no class to learn).
        """
        n_actions = check_int("n_actions", n_actions, low=1)
        z = self._transitions(states, next_states)
        labels = np.asarray(actions)
        if labels.shape != (len(z),):
            raise ValueError(
                f"actions must have shape ({len(z)},): one discrete action per transition, got "
                f"{labels.shape} (InverseDynamics labels Discrete actions only)"
            )
        wrong = np.flatnonzero((labels != np.round(labels)) | (labels < 0) | (labels >= n_actions))
        if wrong.size:
            raise ValueError(
                f"action {labels[wrong[0]]!r} of transition {wrong[0]} is not an integer in "
                f"0 .. {n_actions - 1} (InverseDynamics labels Discrete actions only)"
            )
        self._mean, self._std = z.mean(axis=0), z.std(axis=0) + 1e-8
        gen = th.Generator().manual_seed(
            int(np.random.SeedSequence(self.seed).generate_state(1)[0])
        )
        with th.random.fork_rng(devices=[]):
            th.manual_seed(int(th.randint(2**31 - 1, (1,), generator=gen)))
            sizes = [z.shape[1], *self.net_arch, n_actions]
            layers: list[nn.Module] = []
            for i in range(len(sizes) - 1):
                layers += [nn.Linear(sizes[i], sizes[i + 1]), nn.ReLU()]
            self.model_ = nn.Sequential(*layers[:-1])
        optimizer = th.optim.Adam(self.model_.parameters(), lr=self.lr)
        x = self._inputs(states, next_states)
        y = th.as_tensor(labels.astype(np.int64))
        for _ in range(self.epochs):
            for batch in th.randperm(len(x), generator=gen).split(self.batch_size):
                loss = F.cross_entropy(self.model_(x[batch]), y[batch])
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
        with th.no_grad():
            self.accuracy_ = float((self.model_(x).argmax(dim=1) == y).float().mean())
        return self

    def predict(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """The most likely action of each transition ``states[i] -> next_states[i]``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        if not hasattr(self, "model_"):
            raise NotFittedError("InverseDynamics is not fitted yet: call fit first")
        with th.no_grad():
            return self.model_(self._inputs(states, next_states)).argmax(dim=1).numpy()
