"""Parallel parking with noisy nonholonomic dynamics (paper §9 and Appendix A).

The scene, in metres, in a global frame whose x axis runs along the street::

    y
    5 ┼─────────────────────────────────────────────── world edge
      │        car ▭▷  (start area, driving lane y ≈ 2)
    0 ┼   ▭▭▭▭▭ rear     [ slot, centre (0, 0) ]     front ▭▭▭▭▭
   -1 ┼─────────────────────────────────────────────── curb
     -10         -4.5   -2.5        0        2.5   4.5          10  x

The two obstacles (parked cars of the same size as ours, 2 m x 1 m) are 5 m apart
(2.5 car lengths) and the slot between them is the goal.
"""

from __future__ import annotations

import math
import operator
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_swirl.envs._angles import wrap_angle
from swirl_wrappers._validation import check_bool, check_real

#: Action indices of :class:`ParallelParkingEnv` (see its docstring for the table).
NOOP, ACCELERATE, DECELERATE, STEER_LEFT, STEER_RIGHT = range(5)

#: A car state ``(x, y, theta, v_units)``: centre (m), heading (rad, in [-pi, pi)) and the
#: speed as an integer number of speed units (see :attr:`ParallelParkingEnv.speed_unit`).
State = tuple[float, float, float, int]


class ParallelParkingEnv(gym.Env):
    """Park a car with noisy bicycle dynamics between two obstacles.

    **Dynamics.** A kinematic bicycle model (reference point at the car's centre, front and
    rear axles ``wheelbase / 2`` away from it) with state ``(x, y, theta, v)``. One step lasts
    ``dt`` seconds and applies one discrete action:

    ======  =============  ======================================================
    action  name           effect during the step
    ======  =============  ======================================================
    0       no-op          wheels straight, speed unchanged
    1       accelerate     speed += 0.1 m/s^2 * dt (towards forward), wheels straight
    2       decelerate     speed -= 0.1 m/s^2 * dt (towards reverse), wheels straight
    3       steer left     front wheels at +``max_steering_deg`` for this step
    4       steer right    front wheels at -``max_steering_deg`` for this step
    ======  =============  ======================================================

    The speed is updated first (and clipped to ``±max_speed``), then the car moves for ``dt``
    seconds at the new speed along the exact arc of the bicycle model. Reverse is a negative
    speed. The steering is not a state variable: it holds for one step only, so
    ``(x, y, theta, v)`` is the full state and the observation is Markov (the paper's
    partial-observation variant, which hides ``v``, is the one that is not). With the defaults
    (``dt = 1 s``, 30 degree wheels, 1.2 m wheelbase) a steering step turns the heading by
    about 5 degrees at 0.2 m/s — our reading of the paper's "change its heading in increments
    of 5°": a literal 5 degree *wheel* angle gives a 14 m turning radius that cannot park in a
    5 m gap, and heading changes that do not depend on the distance driven would let the car
    turn on the spot.

    Speeds are kept exactly on a grid: internally ``v`` is an integer number of
    ``speed_unit = 0.05 m/s^2 * dt``; accelerate and decelerate change it by 2 units, so in the
    nominal task the speed is always a multiple of 0.1 m/s and 0 is exactly reachable.

    **Noise.** On every step, with probability ``noise_probability`` (0.1), the front-wheel
    angle of that step gets ``+steering_noise_deg`` or ``-steering_noise_deg`` (2.5 degrees,
    each sign equally likely), whatever the action; it only moves the car if the car moves.
    All randomness comes from ``self.np_random`` (seeded by ``reset(seed=...)``).

    **Perturbed variant** (§9.6, ``perturbed=True``): each steer-right action also accelerates
    the car forward by 0.05 m/s^2 (one speed unit), so a reversing car slows down while
    turning right.

    **Episode.** The car starts in the driving lane beside the rear obstacle:
    ``x ~ U(-5, -3)``, ``y ~ U(1.8, 2.2)``, ``theta ~ U(-5°, 5°)``, ``v = 0``. Reward is 1.0 on
    success and 0.0 otherwise. An episode terminates on

    - success (``info["is_success"] = True``): the car is stopped (``|v| <= 0.05 m/s``, which
      in the nominal task means ``v == 0``), its heading is within 15 degrees of the street
      direction (``|theta| <= 15°``, forward-facing) and its centre is within 1 m of the slot
      centre;
    - collision (``info["collision"] = True``, reward 0): the car's rectangle overlaps an
      obstacle's rectangle, or a corner of the car is below the curb line ``y = -1``;
    - leaving the world (reward 0): the car's centre leaves ``[-10, 10] x [-1, 5]``.

    The registered ids add a 200-step ``TimeLimit`` (truncation, reward 0).

    Parameters
    ----------
    render_mode : {"rgb_array", "human"}, optional
    partial_observation : bool, default False
        Observe ``(x, y, theta)`` instead of ``(x, y, theta, v)`` (§9.8).
    observe_displacement : bool, default False
        With ``partial_observation``: also observe the last step's displacement
        ``(dx, dy, dtheta)`` (zero after a reset), a one-step memory from which the hidden
        speed can be read back (not in the paper; an ablation of §9.8).
    perturbed : bool, default False
        Turning right also accelerates the car forward by 0.05 m/s^2 (§9.6).
    dt : float, default 1.0
        Seconds per step.
    noise_probability : float, default 0.1
        Probability per step of the steering noise.
    steering_noise_deg : float, default 2.5
        Magnitude of the steering noise (degrees of front-wheel angle).
    max_steering_deg : float, default 30.0
        Front-wheel angle of a steering action.
    max_speed : float, default 1.0
        Speed limit in m/s, forward and reverse.

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/ParallelParking-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape
    (4,)
    >>> obs, reward, terminated, truncated, info = env.step(1)  # accelerate
    >>> round(float(obs[3]), 6), info["is_success"]
    (0.1, False)
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    #: Car and obstacle size (m): the paper's "5 m apart (2.5 car lengths)".
    car_length = 2.0
    car_width = 1.0
    wheelbase = 1.2
    #: Axis-aligned obstacle boxes ``(x_min, x_max, y_min, y_max)``: rear, then front.
    obstacles = ((-4.5, -2.5, -0.5, 0.5), (2.5, 4.5, -0.5, 0.5))
    slot_center = (0.0, 0.0)
    curb_y = -1.0
    lane_y = 2.0
    #: World the car's centre must stay in: ``(x_min, x_max, y_min, y_max)``.
    world = (-10.0, 10.0, -1.0, 5.0)
    #: Success tolerances.
    goal_distance = 1.0
    goal_heading = math.radians(15.0)
    #: Half-widths of the uniform start distribution around ``start_center = (x, y, theta)``.
    start_center = (-4.0, 2.0, 0.0)
    start_spread = (1.0, 0.2, math.radians(5.0))

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        partial_observation: bool = False,
        observe_displacement: bool = False,
        perturbed: bool = False,
        dt: float = 1.0,
        noise_probability: float = 0.1,
        steering_noise_deg: float = 2.5,
        max_steering_deg: float = 30.0,
        max_speed: float = 1.0,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        partial_observation = check_bool("partial_observation", partial_observation)
        observe_displacement = check_bool("observe_displacement", observe_displacement)
        perturbed = check_bool("perturbed", perturbed)
        dt = check_real("dt", dt, low=0.0, low_open=True)
        noise_probability = check_real("noise_probability", noise_probability, low=0.0, high=1.0)
        max_steering_deg = check_real(
            "max_steering_deg", max_steering_deg, low=0.0, high=90.0, low_open=True, high_open=True
        )
        steering_noise_deg = check_real("steering_noise_deg", steering_noise_deg)
        max_speed = check_real("max_speed", max_speed)
        if not max_speed >= 0.05 * dt:
            raise ValueError(
                f"max_speed must be at least one speed unit (0.05 * dt = {0.05 * dt} m/s), "
                f"got {max_speed}"
            )
        if observe_displacement and not partial_observation:
            raise ValueError(
                "observe_displacement needs partial_observation=True (the full observation "
                "already holds the speed)"
            )
        self.render_mode = render_mode
        self.partial_observation = partial_observation
        self.observe_displacement = observe_displacement
        self.perturbed = perturbed
        self.dt = float(dt)
        self.noise_probability = float(noise_probability)
        self.steering_noise = math.radians(steering_noise_deg)
        self.max_steering = math.radians(max_steering_deg)
        self.max_speed = float(max_speed)
        self.speed_unit = 0.05 * self.dt
        self._max_units = math.floor(self.max_speed / self.speed_unit + 1e-9)

        x0, x1, y0, y1 = self.world
        high_v = self._max_units * self.speed_unit
        low = [x0, y0, -math.pi, -high_v]
        high = [x1, y1, math.pi, high_v]
        n = 3 if partial_observation else 4
        low, high = low[:n], high[:n]
        if observe_displacement:  # a step moves the centre by at most |v| * dt (arc >= chord)
            step = high_v * self.dt
            low += [-step, -step, -math.pi]
            high += [step, step, math.pi]
        self.observation_space = spaces.Box(
            np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)
        )
        self.action_space = spaces.Discrete(5)
        self._state: State = (*self.start_center, 0)
        self._previous: State = self._state
        self._screen: Any = None
        self._clock: Any = None

    # ------------------------------------------------------------------ dynamics (pure)
    def simulate(self, state: State, action: int, steering_noise: float = 0.0) -> State:
        """Next state after ``action`` from ``state``; the one home of the dynamics.

        ``step`` calls it with the sampled steering noise; planners call it without noise.

        Parameters
        ----------
        state : tuple (x, y, theta, v_units)
        action : int in [0, 5)
        steering_noise : float, default 0.0
            Added to the front-wheel angle of this step (radians).

        Returns
        -------
        tuple (x, y, theta, v_units)
        """
        x, y, theta, units = state
        delta = steering_noise
        if action == ACCELERATE:
            units += 2
        elif action == DECELERATE:
            units -= 2
        elif action == STEER_LEFT:
            delta += self.max_steering
        elif action == STEER_RIGHT:
            delta -= self.max_steering
            if self.perturbed:
                units += 1
        elif action != NOOP:
            raise ValueError(f"action must be an integer in [0, 5), got {action!r}")
        units = max(-self._max_units, min(self._max_units, units))
        dist = units * self.speed_unit * self.dt
        if dist != 0.0:
            if delta == 0.0:
                x += dist * math.cos(theta)
                y += dist * math.sin(theta)
            else:
                # The centre moves on a circle of radius lr / sin(beta); the heading turns by
                # the arc length over that radius (Kong et al. 2015, exact for constant inputs).
                half = 0.5 * self.wheelbase
                beta = math.atan(0.5 * math.tan(delta))
                radius = half / math.sin(beta)
                start = theta + beta
                theta += dist / radius
                x += radius * (math.sin(theta + beta) - math.sin(start))
                y -= radius * (math.cos(theta + beta) - math.cos(start))
                theta = wrap_angle(theta)
        return (x, y, theta, units)

    def noise_free_step(self, observation: np.ndarray, action: int) -> np.ndarray:
        """The observation one step after ``observation`` under ``action``, without noise.

        The known model that model-based reward learning can take instead of an estimated one
        (``fit_task(demos, reward="maxent", dynamics=env.unwrapped.noise_free_step)``).

        Raises
        ------
        ValueError
            With ``partial_observation``: the hidden velocity makes the step unknowable.
        """
        if self.partial_observation:
            raise ValueError("noise_free_step needs the velocity, which partial_observation hides")
        x, y, theta, v = (float(o) for o in observation)
        state = self.simulate((x, y, theta, round(v / self.speed_unit)), int(action))
        x, y, theta, units = state
        return np.array((x, y, theta, units * self.speed_unit), dtype=np.float32)

    def collides(self, state: State, margin: float = 0.0) -> bool:
        """Whether the car at ``state`` overlaps an obstacle or crosses the curb.

        ``margin`` (m) grows the car's rectangle on every side, for planners that want
        clearance.
        """
        x, y, theta = state[0], state[1], state[2]
        c, s = math.cos(theta), math.sin(theta)
        hl, hw = 0.5 * self.car_length + margin, 0.5 * self.car_width + margin
        ax, ay, bx, by = hl * c, hl * s, hw * s, hw * c
        xs = (x + ax - bx, x + ax + bx, x - ax - bx, x - ax + bx)
        ys = (y + ay + by, y + ay - by, y - ay + by, y - ay - by)
        lo_x, hi_x, lo_y, hi_y = min(xs), max(xs), min(ys), max(ys)
        if lo_y < self.curb_y:
            return True
        for ox0, ox1, oy0, oy1 in self.obstacles:
            # Separating axis test: the obstacle's axes, then the car's own two axes.
            if hi_x <= ox0 or lo_x >= ox1 or hi_y <= oy0 or lo_y >= oy1:
                continue
            us, ns = [], []
            for px, py in ((ox0, oy0), (ox0, oy1), (ox1, oy0), (ox1, oy1)):
                dx, dy = px - x, py - y
                us.append(dx * c + dy * s)
                ns.append(dy * c - dx * s)
            if min(us) >= hl or max(us) <= -hl or min(ns) >= hw or max(ns) <= -hw:
                continue
            return True
        return False

    def is_parked(self, state: State) -> bool:
        """The success test: stopped, heading within 15° and centre within 1 m of the slot."""
        x, y, theta, units = state
        return (
            abs(units) <= 1
            and abs(theta) <= self.goal_heading
            and math.hypot(x - self.slot_center[0], y - self.slot_center[1]) <= self.goal_distance
        )

    def in_world(self, state: State) -> bool:
        """Whether the car's centre is inside :attr:`world`."""
        x0, x1, y0, y1 = self.world
        return x0 <= state[0] <= x1 and y0 <= state[1] <= y1

    # ------------------------------------------------------------------ state access
    @property
    def state(self) -> tuple[float, float, float, float]:
        """The full state ``(x, y, theta, v)`` in metres, radians and m/s."""
        x, y, theta, units = self._state
        return (x, y, theta, units * self.speed_unit)

    @property
    def raw_state(self) -> State:
        """The internal state ``(x, y, theta, v_units)`` that :meth:`simulate` takes."""
        return self._state

    def set_state(self, x: float, y: float, theta: float, v: float = 0.0) -> np.ndarray:
        """Put the car at a given state (for tests and planners) and return its observation.

        Raises
        ------
        ValueError
            If ``v`` is not a multiple of :attr:`speed_unit` within the speed limit.
        """
        if not all(math.isfinite(value) for value in (x, y, theta, v)):
            raise ValueError(f"the state must be finite, got {(x, y, theta, v)}")
        units = round(v / self.speed_unit)
        if abs(units * self.speed_unit - v) > 1e-9 or abs(units) > self._max_units:
            raise ValueError(
                f"v must be a multiple of {self.speed_unit} m/s within ±{self.max_speed}, got {v}"
            )
        theta = float(theta)
        if not -math.pi <= theta < math.pi:
            theta = wrap_angle(theta)
        self._state = self._previous = (float(x), float(y), theta, int(units))
        return self._obs()

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Draw a start state from the start distribution (see the class docstring)."""
        super().reset(seed=seed)
        u = self.np_random.uniform(-1.0, 1.0, size=3)
        (cx, cy, ct), (sx, sy, st) = self.start_center, self.start_spread
        self._state = (cx + sx * float(u[0]), cy + sy * float(u[1]), ct + st * float(u[2]), 0)
        self._previous = self._state
        if self.render_mode == "human":
            self.render()
        return self._obs(), {"is_success": False, "collision": False}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply one action; see the class docstring for dynamics, noise and termination."""
        try:  # operator.index: ints and integer numpy scalars, not floats or strings
            index = operator.index(action)
        except TypeError:
            index = -1
        if not 0 <= index < self.action_space.n:
            raise ValueError(f"invalid action {action!r} for {self.action_space}")
        noise = 0.0
        p = self.noise_probability
        if p > 0.0:
            r = self.np_random.random()
            if r < p:
                noise = self.steering_noise if r < 0.5 * p else -self.steering_noise
        state = self.simulate(self._state, index, noise)
        self._previous, self._state = self._state, state
        collision = self.collides(state)
        success = not collision and self.is_parked(state)
        terminated = collision or success or not self.in_world(state)
        if self.render_mode == "human":
            self.render()
        return (
            self._obs(),
            1.0 if success else 0.0,
            terminated,
            False,
            {"is_success": success, "collision": collision},
        )

    def _obs(self) -> np.ndarray:
        x, y, theta, units = self._state
        x0, x1, y0, y1 = self.world
        # The car may end its last step just outside the world; the observation stays in
        # the observation space.
        x = min(max(x, x0), x1)
        y = min(max(y, y0), y1)
        if self.observe_displacement:
            px, py, ptheta, _ = self._previous
            turn = wrap_angle(theta - ptheta)
            return np.array((x, y, theta, x - px, y - py, turn), dtype=np.float32)
        if self.partial_observation:
            return np.array((x, y, theta), dtype=np.float32)
        return np.array((x, y, theta, units * self.speed_unit), dtype=np.float32)

    # ------------------------------------------------------------------ rendering
    _PIXELS_PER_METRE = 40

    def render(self) -> np.ndarray | None:
        """Draw the scene: street, curb, slot outline, obstacles and the car with its heading."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass one to the constructor")
            return None
        import pygame

        ppm = self._PIXELS_PER_METRE
        x0, x1, y0, y1 = self.world
        size = (int((x1 - x0) * ppm), int((y1 - y0 + 1.0) * ppm))

        def px(x: float, y: float) -> tuple[int, int]:
            return round((x - x0) * ppm), round((y1 - y) * ppm)

        surf = pygame.Surface(size)
        surf.fill((225, 225, 225))
        pygame.draw.rect(surf, (150, 150, 150), (*px(x0, self.curb_y), size[0], ppm))
        pygame.draw.line(surf, (60, 60, 60), px(x0, self.curb_y), px(x1, self.curb_y), 3)
        lane = px(x0, self.lane_y - 0.5 * self.car_width - 0.5)
        for xd in np.arange(x0, x1, 1.0):
            pygame.draw.line(
                surf, (255, 255, 255), (px(xd, 0)[0], lane[1]), (px(xd + 0.5, 0)[0], lane[1]), 2
            )
        sx, sy = self.slot_center
        goal = pygame.Rect(
            0, 0, round(2 * self.goal_distance * ppm), round(2 * self.goal_distance * ppm)
        )
        goal.center = px(sx, sy)
        pygame.draw.ellipse(surf, (120, 200, 120), goal, 2)
        for ox0, ox1, oy0, oy1 in self.obstacles:
            pygame.draw.rect(
                surf, (90, 90, 160), (*px(ox0, oy1), (ox1 - ox0) * ppm, (oy1 - oy0) * ppm)
            )
        x, y, theta, _ = self._state
        c, s = math.cos(theta), math.sin(theta)
        hl, hw = 0.5 * self.car_length, 0.5 * self.car_width
        corners = [
            px(x + a * hl * c - b * hw * s, y + a * hl * s + b * hw * c)
            for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1))
        ]
        pygame.draw.polygon(surf, (200, 60, 50), corners)
        pygame.draw.line(surf, (255, 230, 0), px(x, y), px(x + hl * c, y + hl * s), 3)

        if self.render_mode == "human":
            if self._screen is None:
                pygame.init()
                pygame.display.init()
                self._screen = pygame.display.set_mode(size)
                self._clock = pygame.time.Clock()
            self._screen.blit(surf, (0, 0))
            pygame.event.pump()
            pygame.display.flip()
            self._clock.tick(self.metadata["render_fps"])
            return None
        return np.ascontiguousarray(np.transpose(pygame.surfarray.pixels3d(surf), (1, 0, 2)))

    def close(self) -> None:
        """Close the pygame window, if any."""
        if self._screen is not None:
            import pygame

            pygame.display.quit()
            pygame.quit()
            self._screen = None
            self._clock = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_screen"] = None
        state["_clock"] = None
        return state
