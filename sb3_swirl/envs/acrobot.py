"""NoisyAcrobot: the paper's acrobot (§9, Appendix B) with torques on both joints and noise."""

from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Real
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.envs.classic_control import utils
from gymnasium.envs.classic_control.acrobot import AcrobotEnv

from sb3_swirl.envs._angles import wrap_angle
from swirl_wrappers._validation import check_option, check_real

#: gravitational acceleration [m/s^2], the value gymnasium's ``AcrobotEnv._dsdt`` uses
GRAVITY = 9.8


class NoisyAcrobotEnv(AcrobotEnv):
    """Two-link pendulum swing-up with a torque on either joint and Gaussian torque noise.

    The arm hangs from a fixed pivot under gravity. Each step applies a torque of fixed
    magnitude to *one* of the two joints, counter-clockwise or clockwise, plus Gaussian
    noise on that torque. The task is to raise the tip above the horizontal line one link
    length above the pivot (``y = 1`` in Fig. 1b of the paper), as in gymnasium's ``Acrobot-v1``:
    ``-cos(theta1) - l2 * cos(theta1 + theta2) > 1``.

    Physics reused from gymnasium's :class:`~gymnasium.envs.classic_control.acrobot.AcrobotEnv`
    ("book" equations of Sutton & Barto): link masses, centre-of-mass positions, moments of
    inertia, integration step ``dt = 0.2`` s, velocity limits (4π and 9π rad/s, clipped after
    each step), the success test and the pygame renderer. Changed: the equations of motion are
    solved with a torque on the first joint too (gymnasium actuates only the second), and the
    fourth-order Runge-Kutta step is unrolled over plain floats (gymnasium's ``rk4`` allocates
    arrays; this is several times faster and integrates the same ODE).

    Torque and noise were chosen so an energy-pumping controller needs a few hundred of the
    1000 steps and random play rarely succeeds (see :attr:`TORQUE` and
    :attr:`TORQUE_NOISE_STD`).

    Planners and tests can use :meth:`simulate` (the transition with explicit noise),
    :meth:`energy`, :meth:`tip_height` and :meth:`set_state`.

    ## Action space
    ``Discrete(4)``: 0 = counter-clockwise (+) torque on joint 1, 1 = clockwise (−) torque on
    joint 1, 2 = counter-clockwise torque on joint 2, 3 = clockwise torque on joint 2.

    ## Observation space
    ``Box(4,)`` float32: ``(theta1, theta2, omega1, omega2)``. ``theta1`` is the angle of link 1
    from straight down, ``theta2`` the angle of link 2 relative to link 1, both wrapped to
    ``[-pi, pi)``; ``omega1`` in ``[-4π, 4π]``, ``omega2`` in ``[-9π, 9π]``.

    ## Rewards and episode end
    Reward 1.0 and ``terminated=True`` on the step the tip rises above the line, 0.0 otherwise;
    ``info["is_success"]`` on every step. The registered ``sb3_swirl/NoisyAcrobot-v0``
    truncates at 1000 steps.

    ## Starting state
    All four state variables uniform in ``[-0.1, 0.1]`` (hanging down), like gymnasium;
    ``reset(options={"low": ..., "high": ...})`` changes the bounds.

    Parameters
    ----------
    render_mode : {"human", "rgb_array"}, optional
    link_length_2 : float, default 1.0
        Length of link 2 [m] (the §9.6 transfer experiment). Link 2 is a uniform rod whose
        mass scales with its length, so its mass is ``link_length_2`` kg, its centre of mass
        at ``link_length_2 / 2`` and its moment of inertia ``link_length_2 ** 3`` (gymnasium's
        1 kg·m² at length 1). The success line stays at ``y = 1``.
    torque : float, default :attr:`TORQUE`
        Magnitude of the applied torque [N·m]; 0 leaves the arm passive (only noise acts).
    torque_noise_std : float, default :attr:`TORQUE_NOISE_STD`
        Standard deviation of the Gaussian noise added to the applied torque [N·m]; 0 makes
        the dynamics deterministic.
    actuation : {"both", "second"}, default "both"
        ``"second"``: the under-actuated acrobot of gymnasium's ``Acrobot-v1``, a torque on
        joint 2 only, ``Discrete(3)``: 0 = clockwise (−), 1 = none, 2 = counter-clockwise (+);
        the noise is added to joint 2's torque on every step. Registered as
        ``sb3_swirl/UnderactuatedAcrobot-v0`` with gymnasium's torque (1 N·m) and noise of 20%
        of it, the ratio of this env's defaults; not tuned to any method.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/NoisyAcrobot-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space.n
    ((4,), 4)
    >>> obs, reward, terminated, truncated, info = env.step(0)
    >>> info["is_success"]
    False
    """

    #: default torque magnitude [N·m]; a quarter of gymnasium's, so that swinging up takes
    #: hundreds of steps of energy pumping and random actions do not reach the line
    #: (the README has the measured numbers)
    TORQUE = 0.25
    #: default standard deviation of the Gaussian torque noise [N·m] (20% of :attr:`TORQUE`)
    TORQUE_NOISE_STD = 0.05
    #: height of the success line above the pivot [m]
    SUCCESS_HEIGHT = 1.0

    actions_num = 4

    def __init__(
        self,
        render_mode: str | None = None,
        link_length_2: float = 1.0,
        torque: float = TORQUE,
        torque_noise_std: float = TORQUE_NOISE_STD,
        actuation: str = "both",
    ) -> None:
        link_length_2 = check_real("link_length_2", link_length_2, low=0.0, low_open=True)
        torque = check_real("torque", torque, low=0.0)
        torque_noise_std = check_real("torque_noise_std", torque_noise_std, low=0.0)
        self.actuation = check_option("actuation", actuation, ("both", "second"))
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.screen = None
        self.clock = None
        self.isopen = True
        self.link_length_2 = float(link_length_2)
        self.torque = float(torque)
        self.torque_noise_std = float(torque_noise_std)
        # Link 2 as a uniform rod; these shadow gymnasium's class constants (the inherited
        # renderer reads LINK_LENGTH_2).
        self.LINK_LENGTH_2 = self.link_length_2
        self.LINK_MASS_2 = self.link_length_2
        self.LINK_COM_POS_2 = self.link_length_2 / 2.0
        self.LINK_MOI_2 = self.LINK_MOI * self.link_length_2**3

        m1, m2 = self.LINK_MASS_1, self.LINK_MASS_2
        l1, lc1, lc2 = self.LINK_LENGTH_1, self.LINK_COM_POS_1, self.LINK_COM_POS_2
        i1, i2 = self.LINK_MOI, self.LINK_MOI_2
        # Constant parts of the mass matrix and of the Coriolis/gravity terms.
        self._h = m2 * l1 * lc2
        self._d11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2) + i1 + i2
        self._d22 = m2 * lc2**2 + i2
        self._g1 = (m1 * lc1 + m2 * l1) * GRAVITY
        self._g2 = m2 * lc2 * GRAVITY

        high = np.array(
            [math.pi, math.pi, self.MAX_VEL_1, self.MAX_VEL_2],
            dtype=np.float32,
        )
        self.observation_space = spaces.Box(low=-high, high=high, dtype=np.float32)
        self.action_space = spaces.Discrete(4 if self.actuation == "both" else 3)
        self.state: np.ndarray | None = None
        self._noise = np.empty(0)
        self._noise_pos = 0

    # ----------------------------------------------------------------- physics
    def _derivs(
        self, t1: float, t2: float, w1: float, w2: float, tau1: float, tau2: float
    ) -> tuple[float, float]:
        """Angular accelerations of both joints (the book equations, torque on both joints)."""
        c2 = math.cos(t2)
        s2 = math.sin(t2)
        h = self._h
        d1 = self._d11 + 2.0 * h * c2
        d2 = self._d22 + h * c2
        phi2 = self._g2 * math.sin(t1 + t2)
        phi1 = -h * s2 * w2 * (w2 + 2.0 * w1) + self._g1 * math.sin(t1) + phi2
        dd2 = (tau2 + d2 / d1 * (phi1 - tau1) - h * w1 * w1 * s2 - phi2) / (
            self._d22 - d2 * d2 / d1
        )
        dd1 = (tau1 - d2 * dd2 - phi1) / d1
        return dd1, dd2

    def _integrate(
        self, t1: float, t2: float, w1: float, w2: float, tau1: float, tau2: float
    ) -> tuple[float, float, float, float]:
        """One RK4 step of length ``dt`` with constant torques (no wrapping or clipping)."""
        dt = self.dt
        h2 = dt / 2.0
        a1, b1 = self._derivs(t1, t2, w1, w2, tau1, tau2)
        a2, b2 = self._derivs(t1 + h2 * w1, t2 + h2 * w2, w1 + h2 * a1, w2 + h2 * b1, tau1, tau2)
        w1b, w2b = w1 + h2 * a2, w2 + h2 * b2
        a3, b3 = self._derivs(
            t1 + h2 * (w1 + h2 * a1), t2 + h2 * (w2 + h2 * b1), w1b, w2b, tau1, tau2
        )
        w1c, w2c = w1 + dt * a3, w2 + dt * b3
        a4, b4 = self._derivs(t1 + dt * w1b, t2 + dt * w2b, w1c, w2c, tau1, tau2)
        s = dt / 6.0
        return (
            t1 + s * (w1 + 2.0 * (w1 + h2 * a1) + 2.0 * w1b + w1c),
            t2 + s * (w2 + 2.0 * (w2 + h2 * b1) + 2.0 * w2b + w2c),
            w1 + s * (a1 + 2.0 * a2 + 2.0 * a3 + a4),
            w2 + s * (b1 + 2.0 * b2 + 2.0 * b3 + b4),
        )

    def simulate(
        self, state: Sequence[float], action: int, torque_noise: float = 0.0
    ) -> tuple[float, float, float, float]:
        """The state one step after ``state`` under ``action``, without touching the env.

        This is the env's own transition (angles wrapped, velocities clipped) with the torque
        noise given explicitly, so planners can use the noise-free model.

        Parameters
        ----------
        state : sequence of 4 floats
            ``(theta1, theta2, omega1, omega2)``.
        action : int
            In ``[0, action_space.n)``; see the class docstring.
        torque_noise : float, default 0.0
            Added to the applied torque [N·m].
        """
        if self.actuation == "second":
            tau1, tau2 = 0.0, (action - 1) * self.torque + torque_noise
        else:
            tau = (self.torque if action % 2 == 0 else -self.torque) + torque_noise
            tau1, tau2 = (tau, 0.0) if action < 2 else (0.0, tau)
        t1, t2, w1, w2 = self._integrate(*state, tau1, tau2)
        mv1, mv2 = self.MAX_VEL_1, self.MAX_VEL_2
        return (
            wrap_angle(t1),
            wrap_angle(t2),
            min(max(w1, -mv1), mv1),
            min(max(w2, -mv2), mv2),
        )

    def noise_free_step(self, observation: Sequence[float], action: int) -> np.ndarray:
        """The observation one step after ``observation`` under ``action``, without noise
        (the known model of ``fit_task(demos, reward="maxent", dynamics=...)``)."""
        return np.array(self.simulate(observation, int(action)), dtype=np.float32)

    def energy(self, state: Sequence[float] | None = None) -> float:
        """Total mechanical energy (kinetic + potential, zero at the pivot height) [J].

        Parameters
        ----------
        state : sequence of 4 floats, optional
            ``(theta1, theta2, omega1, omega2)``; the current state if omitted.
        """
        t1, t2, w1, w2 = self._current() if state is None else state
        c2 = math.cos(t2)
        d11 = self._d11 + 2.0 * self._h * c2
        d12 = self._d22 + self._h * c2
        kinetic = 0.5 * (d11 * w1 * w1 + 2.0 * d12 * w1 * w2 + self._d22 * w2 * w2)
        return kinetic - self._g1 * math.cos(t1) - self._g2 * math.cos(t1 + t2)

    def tip_height(self, state: Sequence[float] | None = None) -> float:
        """Height of the tip of link 2 above the pivot [m]; success is ``> SUCCESS_HEIGHT``.

        Parameters
        ----------
        state : sequence of 4 floats, optional
            ``(theta1, theta2, omega1, omega2)``; the current state if omitted.
        """
        t1, t2, _, _ = self._current() if state is None else state
        return -self.LINK_LENGTH_1 * math.cos(t1) - self.link_length_2 * math.cos(t1 + t2)

    def set_state(
        self, theta1: float, theta2: float, omega1: float = 0.0, omega2: float = 0.0
    ) -> np.ndarray:
        """Put the arm in a given state and return its observation.

        Angles are wrapped and velocities clipped as after a step. Meant for tests and
        planners; the episode's step count (``TimeLimit``) is not touched.
        """
        values = (theta1, theta2, omega1, omega2)
        if not all(isinstance(v, Real) and math.isfinite(v) for v in values):
            raise ValueError(
                f"set_state needs 4 finite numbers (theta1, theta2, omega1, omega2), got {values}"
            )
        mv1, mv2 = self.MAX_VEL_1, self.MAX_VEL_2
        self.state = np.array(
            (
                wrap_angle(float(theta1)),
                wrap_angle(float(theta2)),
                min(max(float(omega1), -mv1), mv1),
                min(max(float(omega2), -mv2), mv2),
            )
        )
        return self._get_ob()

    def _current(self) -> np.ndarray:
        if self.state is None:
            raise RuntimeError("Call reset before using NoisyAcrobotEnv.")
        return self.state

    # --------------------------------------------------------------- gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super(AcrobotEnv, self).reset(seed=seed)
        low, high = utils.maybe_parse_reset_bounds(options, -0.1, 0.1)
        self.set_state(*self.np_random.uniform(low=low, high=high, size=4).tolist())
        self._noise_pos = len(self._noise)  # draw fresh noise from the (re)seeded generator
        if self.render_mode == "human":
            self.render()
        return self._get_ob(), {"is_success": False}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        state = self._current()
        if not self.action_space.contains(action):
            raise ValueError(
                f"action must be an integer in [0, {self.action_space.n}), got {action!r}"
            )
        noise = self.torque_noise_std * self._next_noise() if self.torque_noise_std > 0 else 0.0
        self.state = np.array(self.simulate(state.tolist(), int(action), noise))
        success = self._terminal()
        if self.render_mode == "human":
            self.render()
        return self._get_ob(), 1.0 if success else 0.0, success, False, {"is_success": success}

    def _next_noise(self) -> float:
        # Normals drawn in blocks: a generator call per step would cost as much as the physics.
        if self._noise_pos >= len(self._noise):
            self._noise = self.np_random.standard_normal(256)
            self._noise_pos = 0
        value = self._noise[self._noise_pos]
        self._noise_pos += 1
        return float(value)

    def _get_ob(self) -> np.ndarray:
        return self.state.astype(np.float32)

    def _terminal(self) -> bool:
        return self.tip_height() > self.SUCCESS_HEIGHT

    def __getstate__(self) -> dict[str, Any]:
        # pygame surfaces cannot be pickled; the renderer recreates them on demand.
        state = self.__dict__.copy()
        state["screen"] = None
        state["clock"] = None
        return state
