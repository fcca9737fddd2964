"""Swing-up supervisor for :class:`~sb3_swirl.envs.acrobot.NoisyAcrobotEnv`."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_swirl.envs.acrobot import NoisyAcrobotEnv
from sb3_swirl.supervisors._shared import controlled_env
from swirl_wrappers._validation import check_int


def _max_power_action(env: NoisyAcrobotEnv, w1: float, w2: float) -> int:
    """The action whose torque puts the most power ``tau . omega`` into the arm."""
    if env.actuation == "second":
        return 2 if w2 >= 0.0 else 0
    if abs(w1) >= abs(w2):
        return 0 if w1 >= 0.0 else 1
    return 2 if w2 >= 0.0 else 3


class AcrobotSupervisor:
    """Energy-pumping swing-up controller with a short look-ahead on the noise-free model.

    The paper's supervisor was model-predictive control with re-planning (Appendix B). This
    one re-plans every step: for each action it simulates the env's own
    dynamics without noise for ``horizon`` steps, the first step with that action and the
    rest with the action that puts the most power into the arm (``argmax tau . omega``,
    energy pumping à la Spong with discrete torques). It takes the action whose rollout
    raises the tip above the line soonest or, when none does within the horizon, the one
    that ends with the most mechanical energy. Re-planning absorbs the torque noise.

    Parameters
    ----------
    env : NoisyAcrobotEnv
        The environment to control (wrappers are looked through with ``env.unwrapped``);
        its link lengths and torque define the model.
    seed : int, optional
        Accepted for the common supervisor interface; this controller is deterministic.
    horizon : int, default 10
        Look-ahead in steps.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/NoisyAcrobot-v0")
    >>> sup = AcrobotSupervisor(env.unwrapped)
    >>> obs, info = env.reset(seed=0)
    >>> sup.reset(obs)
    >>> while True:
    ...     obs, reward, terminated, truncated, info = env.step(sup.act(obs))
    ...     if terminated or truncated:
    ...         break
    >>> info["is_success"]
    True
    """

    def __init__(self, env: gym.Env, seed: int | None = None, horizon: int = 10) -> None:
        self.env = controlled_env(env, NoisyAcrobotEnv, "AcrobotSupervisor")
        self.seed = seed
        self.horizon = check_int("horizon", horizon, low=1)

    def reset(self, obs: np.ndarray) -> None:
        """Start a new episode from ``obs`` (the controller keeps no state between steps)."""
        self._check_obs(obs)

    def act(self, obs: np.ndarray) -> int:
        """The action to take in ``obs = (theta1, theta2, omega1, omega2)``."""
        state = self._check_obs(obs)
        actions = range(self.env.action_space.n)
        scores = [self._rollout_score(state, action) for action in actions]
        return int(np.argmax(scores))

    def _check_obs(self, obs: np.ndarray) -> tuple[float, float, float, float]:
        arr = np.asarray(obs, dtype=np.float64)
        if arr.shape != (4,) or not np.all(np.isfinite(arr)):
            raise ValueError(
                f"obs must be 4 finite numbers (theta1, theta2, omega1, omega2), got {obs!r}"
            )
        t1, t2, w1, w2 = arr.tolist()
        return t1, t2, w1, w2

    def _rollout_score(self, state: tuple[float, float, float, float], action: int) -> float:
        env = self.env
        for k in range(self.horizon):
            state = env.simulate(state, action)
            if env.tip_height(state) > env.SUCCESS_HEIGHT:
                # Any success outranks any energy; sooner is better.
                return 1e6 - k
            action = _max_power_action(env, state[2], state[3])
        return env.energy(state)
