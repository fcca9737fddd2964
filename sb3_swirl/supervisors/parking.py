"""The parallel-parking demonstrator: a manoeuvre planner with model-predictive re-planning.

The paper's supervisor ran RRT* on the deterministic car model and re-planned under the noisy
dynamics (Appendix A). Ours plans over a small family of human-like manoeuvres instead of a
random tree, which is fast and always gives the same kind of demonstration — the structure
that SWIRL should recover (paper Fig. 13: positioning, then orienting before reversing):

1. *forward*: speed up to cruise speed, drive straight along the driving lane and stop beside
   the front obstacle at ``x_stop``;
2. *reverse in*: reverse while steering right, so that the rear swings into the slot;
3. *reverse out*: reverse while steering left until the car is straight again;
4. *final*: straighten and stop at the slot centre.

Each phase is a simple feedback law; the family is parameterised by the stopping point
``x_stop`` and the lateral target that decides when to counter-steer. A plan is the noise-free
rollout (:meth:`ParallelParkingEnv.simulate`) of one member from the current state; the
supervisor keeps the fastest member whose rollout parks the car with clearance, follows it,
and re-plans from the actual state whenever the noisy car leaves the predicted path.

The laws are written to give clean data for behavioural cloning: the same state always gets
the same action; no action is one that does nothing (steering a stopped car, which a cloned
policy would repeat forever); speed comes before steering; and a deadband on the heading
keeps the wheel from chattering left-right (the only left-after-right is the counter-steer).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from sb3_swirl.envs.parking import (
    ACCELERATE,
    DECELERATE,
    NOOP,
    STEER_LEFT,
    STEER_RIGHT,
    ParallelParkingEnv,
    State,
)
from swirl_wrappers._validation import check_real

_FORWARD, _REVERSE_IN, _REVERSE_OUT, _FINAL = range(4)
# Heading errors a driver leaves alone: the car parks within 15 degrees anyway, and small
# corrections at walking pace (a few degrees per step) would only add ambiguous labels.
_STRAIGHT_ENOUGH = math.radians(5.0)
_Params = tuple[float, float]  # (x_stop, lateral target of the reverse S-curve)


class ParkingSupervisor:
    """Demonstrator for :class:`~sb3_swirl.envs.parking.ParallelParkingEnv`.

    It reads the car's full state from the environment (it is the demonstrator, so it also
    works on the partial-observation variant) and plans with the environment's own noise-free
    dynamics (so it also works on the perturbed variant).

    Parameters
    ----------
    env : ParallelParkingEnv
        The unwrapped environment being stepped (``env.unwrapped``).
    seed : int, optional
        Unused: the supervisor is deterministic given the states it sees. Accepted so that
        every supervisor has the same constructor.
    clearance : float, default 0.15
        Metres of clearance a plan must keep from obstacles and curb; plans without it are
        used only when no plan has it.
    cruise_speed : float, default 0.3
        Forward speed (m/s) of the positioning phase.
    reverse_speed : float, default 0.2
        Speed (m/s) while reversing into the slot.
    x_stops : sequence of float, optional
        Candidate stopping points of the forward phase (default 2.5 to 6.0 m every 0.25 m).
    lateral_targets : sequence of float, optional
        Candidate lateral targets of the reverse S-curve (default -0.3 to 0.3 m).
    centre_weight : float, default 20.0
        How many steps a plan may spend to park one metre nearer the slot centre.
    deadband : float, default 0.7
        Heading errors up to this fraction of one steering step's turn (and up to 5 degrees)
        get no steering. Above 0.5 a steering step cannot overshoot into the opposite
        correction, so the wheel does not chatter left-right; in [0.5, 1).

    Attributes
    ----------
    n_replans : int
        Plans made in the current episode (1 when no noise ever moved the car off the plan).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/ParallelParking-v0")
    >>> sup = ParkingSupervisor(env.unwrapped)
    >>> obs, info = env.reset(seed=0)
    >>> sup.reset(obs)
    >>> done = False
    >>> while not done:
    ...     obs, reward, terminated, truncated, info = env.step(sup.act(obs))
    ...     done = terminated or truncated
    >>> info["is_success"]
    True
    """

    def __init__(
        self,
        env: ParallelParkingEnv,
        seed: int | None = None,
        *,
        clearance: float = 0.15,
        cruise_speed: float = 0.3,
        reverse_speed: float = 0.2,
        x_stops: Sequence[float] | None = None,
        lateral_targets: Sequence[float] | None = None,
        centre_weight: float = 20.0,
        deadband: float = 0.7,
    ) -> None:
        env = getattr(env, "unwrapped", env)
        if not isinstance(env, ParallelParkingEnv):
            raise ValueError(
                f"ParkingSupervisor needs a ParallelParkingEnv, got {type(env).__name__}"
            )
        self.env = env
        self.seed = seed
        self.clearance = check_real("clearance", clearance, low=0.0)
        self.centre_weight = check_real("centre_weight", centre_weight)
        self.deadband = check_real("deadband", deadband, low=0.5, high=1.0, high_open=True)
        self._cruise = self._units(cruise_speed, "cruise_speed")
        self._reverse = self._units(reverse_speed, "reverse_speed")
        x_stops = np.arange(2.5, 6.01, 0.25) if x_stops is None else x_stops
        lateral_targets = (
            (-0.3, -0.15, 0.0, 0.15, 0.3) if lateral_targets is None else lateral_targets
        )
        self.x_stops = tuple(float(x) for x in x_stops)
        self.lateral_targets = tuple(float(y) for y in lateral_targets)
        if not self.x_stops or not self.lateral_targets:
            raise ValueError("x_stops and lateral_targets must not be empty")
        half = 0.5 * env.wheelbase
        beta = math.atan(0.5 * math.tan(env.max_steering))
        self._radius = half / math.sin(beta)  # turning radius of the car's centre
        self._beta = beta
        self._step_m = env.speed_unit * env.dt  # metres per step per speed unit
        self._plan: list[tuple[int, State, int]] = []
        self._expected: State | None = None
        self._params: _Params | None = None
        self._phase = _FORWARD
        self._t = 0
        self.n_replans = 0
        spec = env.spec
        # Plans must park within the episode's time limit (the registered ids: 200 steps).
        self._max_steps = spec.max_episode_steps if spec and spec.max_episode_steps else 200

    def _units(self, speed: float, name: str) -> int:
        units = round(speed / self.env.speed_unit)
        if units < 2 or units * self.env.speed_unit > self.env.max_speed + 1e-9:
            raise ValueError(
                f"{name} must be between {2 * self.env.speed_unit} and {self.env.max_speed} m/s, "
                f"got {speed}"
            )
        return units

    # ------------------------------------------------------------------ public API
    def reset(self, obs: Any = None) -> None:
        """Start a new episode (call after ``env.reset``)."""
        self._check_obs(obs)
        self._plan = []
        self._params = None
        self._phase = _FORWARD
        self._t = 0
        self.n_replans = 0

    def act(self, obs: Any = None) -> int:
        """The next action for the current state of the environment."""
        self._check_obs(obs)
        state = self.env.raw_state
        # Noise-free steps keep the car exactly on the plan; any deviation triggers a re-plan.
        if not self._plan or state != self._expected:
            self._replan(state)
        action, self._expected, self._phase = self._plan.pop(0)
        self._t += 1
        return action

    @property
    def phase(self) -> int:
        """Phase of the last action: 0 forward, 1 reverse in, 2 reverse out, 3 final."""
        return self._phase

    # ------------------------------------------------------------------ planning
    def _check_obs(self, obs: Any) -> None:
        if obs is None:
            return
        obs = np.asarray(obs, dtype=np.float64).ravel()
        # (x, y, theta, v), or (x, y, theta) and perhaps the last displacement (partial)
        n = 4 if obs.shape[0] == 4 else 3
        if obs.shape[0] not in (3, 4, 6) or not np.allclose(obs[:n], self.env.state[:n], atol=1e-3):
            raise ValueError(
                "obs does not match the state of the environment given to ParkingSupervisor; "
                "pass the env that is being stepped"
            )

    def _replan(self, state: State) -> None:
        self.n_replans += 1
        horizon = max(1, self._max_steps - self._t)
        # Starting the manoeuvre over (pull forward again) is always a candidate, so a car
        # that noise pushed off every continuation of its current phase still gets parked.
        candidates = [(_FORWARD, (x, y)) for x in self.x_stops for y in self.lateral_targets]
        if self._phase != _FORWARD and self._params is not None:
            x_stop = self._params[0]
            candidates += [(self._phase, (x_stop, y)) for y in self.lateral_targets]
        best: tuple[tuple[float, ...], list[tuple[int, State, int]], _Params] | None = None
        cx, cy = self.env.slot_center
        for phase, params in candidates:
            plan, outcome = self._rollout(state, phase, params, horizon)
            end = plan[-1][1]
            # Parked with clearance beats parked beats not parked; then fewer steps and a
            # car nearer the slot centre (a metre is worth ``centre_weight`` steps); then the
            # parameters being followed (no needless switching).
            cost = len(plan) + self.centre_weight * math.hypot(end[0] - cx, end[1] - cy)
            key = (outcome, cost, params != self._params)
            if best is None or key < best[0]:
                best = (key, plan, params)
        assert best is not None
        self._plan, self._params = best[1], best[2]

    def _rollout(
        self, state: State, phase: int, params: _Params, horizon: int
    ) -> tuple[list[tuple[int, State, int]], int]:
        """Noise-free rollout of the manoeuvre; outcome 0 parked with clearance, 1 parked, 2 not."""
        env = self.env
        plan: list[tuple[int, State, int]] = []
        clear = True
        for _ in range(horizon):
            action, phase = self._policy(state, phase, params)
            state = env.simulate(state, action)
            plan.append((action, state, phase))
            if env.collides(state) or not env.in_world(state):
                return plan, 2
            if clear and self.clearance > 0 and env.collides(state, self.clearance):
                clear = False
            if env.is_parked(state):
                return plan, 0 if clear else 1
        return plan, 2

    # ------------------------------------------------------------------ the manoeuvre
    def _stop_distance(self, units: int) -> float:
        """Distance covered while braking from ``units`` (> 0) to a stop."""
        total = 0
        while units > 1:
            units -= 2
            total += max(units, 0)
        return total * self._step_m

    def _turn_per_step(self, units: int) -> float:
        return abs(units) * self._step_m / self._radius

    def _speed_towards(self, units: int, target: int) -> int | None:
        """The speed action that brings ``units`` to ``target`` (within one unit), if any."""
        if units < target - 1:
            return ACCELERATE
        if units > target + 1:
            return DECELERATE
        return None

    def _policy(self, state: State, phase: int, params: _Params) -> tuple[int, int]:
        env = self.env
        x, y, theta, units = state
        x_stop, lateral = params
        if phase == _FORWARD:
            remaining = x_stop - x
            if units <= 1 and remaining <= 0.3:
                phase = _REVERSE_IN
            else:
                if (
                    units > 1
                    and remaining - self._stop_distance(units) < 0.5 * units * self._step_m
                ):
                    return DECELERATE, phase
                # Speed first, as a driver pulling out does: steering at walking pace (or at a
                # standstill, where it does nothing) would make the start states ambiguous.
                nxt = units + 2
                if (
                    nxt <= self._cruise
                    and nxt * self._step_m + self._stop_distance(nxt) <= remaining
                ):
                    return ACCELERATE, phase
                # Hold the heading, no lane keeping: one steering step at cruise speed turns
                # the car by 8 degrees or more, so chasing the lane centre makes it weave (and
                # the BC success drop), and the plan picks a reverse that suits the offset.
                steer = self._straighten(theta, units)
                return (NOOP if steer is None else steer), phase
        if phase == _REVERSE_IN:
            speed = self._speed_towards(units, -self._reverse)
            if speed is not None:
                return speed, phase
            # Counter-steer as soon as doing so ends the S-curve closest to the lateral target.
            now = abs(self._lateral_after_countersteer(y, theta) - lateral)
            after = env.simulate(state, STEER_RIGHT)
            later = abs(self._lateral_after_countersteer(after[1], after[2]) - lateral)
            if (theta <= 0.0 or later < now) and theta < 1.2:
                return STEER_RIGHT, phase
            phase = _REVERSE_OUT
        if phase == _REVERSE_OUT:
            speed = self._speed_towards(units, -self._reverse)
            if speed is not None:
                return speed, phase
            if theta > self.deadband * self._turn_per_step(units):
                return STEER_LEFT, phase
            phase = _FINAL
        return self._final(state), phase

    def _lateral_after_countersteer(self, y: float, theta: float) -> float:
        # The centre's y once a reversing car steering left has turned from ``theta`` back to
        # 0: an arc of the turning circle (the centre moves at angle beta to the heading).
        beta = self._beta
        return y - self._radius * (math.cos(beta) - math.cos(theta + beta))

    def _straighten(self, theta: float, units: int) -> int | None:
        """The steering action that turns the heading towards 0, unless within the deadband."""
        tolerance = max(self.deadband * self._turn_per_step(units), _STRAIGHT_ENOUGH)
        if abs(units) <= 1 or abs(theta) <= tolerance:
            return None
        return STEER_LEFT if (theta < 0) == (units > 0) else STEER_RIGHT

    def _final(self, state: State) -> int:
        """Straighten and stop at the slot centre (forwards or backwards as needed)."""
        x, _, theta, units = state
        gap = self.env.slot_center[0] - x
        direction = 1 if gap >= 0 else -1
        along = units * direction  # speed towards the slot centre, in units
        distance = abs(gap)
        toward = ACCELERATE if direction > 0 else DECELERATE
        away = DECELERATE if direction > 0 else ACCELERATE
        if along < -1:
            return toward
        if along > 1 and distance - self._stop_distance(along) < 0.5 * along * self._step_m:
            return away
        steer = self._straighten(theta, units)
        if steer is not None:
            return steer
        nxt = along + 2
        if nxt <= self._reverse and nxt * self._step_m + self._stop_distance(nxt) <= distance:
            return toward
        if along > 1:
            return NOOP
        return toward if distance > 0.3 else NOOP
