"""Inverse dynamics ``p(a | s, s')``: action labels for state-only demonstrations (BCO)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from torch import nn
from torch.nn import functional as F

from swirl_wrappers._validation import check_int, check_real

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
        if not isinstance(net_arch, Sequence) or not all(
            isinstance(width, int | np.integer) and width >= 1 for width in net_arch
        ):
            raise ValueError(f"net_arch must be a list of layer widths, got {net_arch!r}")
        self.net_arch = [int(width) for width in net_arch]
        self.epochs = check_int("epochs", epochs, low=1)
        self.lr = check_real("lr", lr, low=0.0, low_open=True)
        self.batch_size = check_int("batch_size", batch_size, low=1)
        self.seed = seed

    @classmethod
    def from_kwargs(cls, kwargs: dict[str, Any] | None, seed: int | None = None) -> InverseDynamics:
        """Build from a dict of the constructor's settings, naming unknown keys."""
        kwargs = dict(kwargs or {})
        allowed = ("net_arch", "epochs", "lr", "batch_size")
        unknown = sorted(set(kwargs) - set(allowed))
        if unknown:
            raise ValueError(f"unknown inverse dynamics settings {unknown}; use {list(allowed)}")
        return cls(**kwargs, seed=seed)

    def _inputs(self, states: np.ndarray, next_states: np.ndarray) -> th.Tensor:
        z = np.concatenate([states, next_states - states], axis=1)
        return th.as_tensor((z - self._mean) / self._std, dtype=th.float32)

    def fit(
        self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray, n_actions: int
    ) -> InverseDynamics:
        """Train on transitions ``states[i] -> next_states[i]`` taken with ``actions[i]``."""
        states, next_states = np.asarray(states), np.asarray(next_states)
        z = np.concatenate([states, next_states - states], axis=1)
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
        y = th.as_tensor(np.asarray(actions), dtype=th.int64)
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
        """The most likely action of each transition ``states[i] -> next_states[i]``."""
        with th.no_grad():
            return self.model_(self._inputs(states, next_states)).argmax(dim=1).numpy()
