"""n-step returns for ``Dict`` observations, which SB3's ``NStepReplayBuffer`` lacks.

SwirlDQN needs n-step returns to keep what it cloned (docs/results.md, "The cause: 1-step TD
values off the demos' path"); SB3 2.9 refuses them for ``Dict`` observation spaces (the
goal-conditioned Fetch tasks). This buffer stores transitions as SB3's ``DictReplayBuffer``
and samples them as its ``NStepReplayBuffer`` does: the same arithmetic, keyed observations.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize


class DictNStepReplayBuffer(DictReplayBuffer):
    """SB3's ``DictReplayBuffer`` sampling ``n_steps``-step returns.

    A sampled transition's reward is the discounted sum of the rewards up to ``n_steps`` ahead,
    stopping after the first termination or truncation (never across episodes, nor across the
    write position), its next observation the one after the last of them, and its
    ``discounts`` ``gamma ** k`` for the ``k`` steps summed (DQN bootstraps with it).

    Parameters
    ----------
    *args, **kwargs
        Those of ``DictReplayBuffer`` (no ``optimize_memory_usage``).
    n_steps : int, default 3
    gamma : float, default 0.99
    """

    def __init__(self, *args: Any, n_steps: int = 3, gamma: float = 0.99, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.n_steps = n_steps
        self.gamma = gamma

    def _get_samples(
        self, batch_inds: np.ndarray, env: VecNormalize | None = None
    ) -> DictReplayBufferSamples:
        # the global generator, as SB3's buffers (seeded by the algorithm's set_random_seed)
        env_indices = np.random.randint(0, self.n_envs, size=batch_inds.shape)  # noqa: NPY002
        # the transition before the write position does not lead into the next stored one
        last = self.pos - 1
        saved = self.timeouts[last].copy()
        self.timeouts[last] = np.logical_or(saved, np.logical_not(self.dones[last]))
        try:
            indices = (batch_inds[:, None] + np.arange(self.n_steps)) % self.buffer_size
            column = env_indices[:, None]
            rewards = self._normalize_reward(self.rewards[indices, column], env)
            ends = np.logical_or(self.dones[indices, column], self.timeouts[indices, column])
            end = np.where(ends.any(axis=1), ends.argmax(axis=1), self.n_steps - 1)
            mask = np.arange(self.n_steps) <= end[:, None]
            discounts = self.gamma ** np.arange(self.n_steps, dtype=np.float32)
            returns = (rewards * discounts * mask).sum(axis=1, keepdims=True)
            bootstrap = self.gamma ** mask.sum(axis=1, keepdims=True).astype(np.float32)
            final = (batch_inds + end) % self.buffer_size
            dones = self.dones[final, env_indices] * (1.0 - self.timeouts[final, env_indices])
        finally:
            self.timeouts[last] = saved
        obs = self._normalize_obs(
            {key: value[batch_inds, env_indices] for key, value in self.observations.items()},
            env,
        )
        next_obs = self._normalize_obs(
            {key: value[final, env_indices] for key, value in self.next_observations.items()},
            env,
        )
        return DictReplayBufferSamples(
            observations={key: self.to_torch(value) for key, value in obs.items()},
            actions=self.to_torch(self.actions[batch_inds, env_indices]),
            next_observations={key: self.to_torch(value) for key, value in next_obs.items()},
            dones=self.to_torch(dones.reshape(-1, 1).astype(np.float32)),
            rewards=self.to_torch(returns),
            discounts=self.to_torch(bootstrap),
        )
