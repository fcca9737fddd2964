"""Surgical line cutting on robosuite (paper §10.2): position at a marked line, then follow it."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from sb3_swirl.envs.dvrk._robosuite import TABLE_TOP, RobosuiteStepEnv, robosuite_task
from swirl_wrappers._validation import check_bool, check_real

#: Action indices of :class:`DVRKLineCuttingEnv`: one 2 mm step of the tool.
PLUS_X, MINUS_X, PLUS_Y, MINUS_Y = range(4)
_DIRECTIONS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def line_points(radius: float | None, length: float, n: int = 200) -> np.ndarray:
    """Points (n + 1, 2) of a line that starts at the origin heading along +x.

    ``radius=None`` gives a straight line; otherwise an arc of that radius (m) that bends
    towards +y, of arc length ``length`` (m).
    """
    s = np.linspace(0.0, length, n + 1)
    if radius is None:
        return np.stack([s, np.zeros_like(s)], axis=1)
    angle = s / radius
    return np.stack([radius * np.sin(angle), radius * (1.0 - np.cos(angle))], axis=1)


def _nearest_on_polyline(point: np.ndarray, points: np.ndarray) -> tuple[float, float, int, float]:
    """Distance from ``point`` to the polyline, the arc length of its nearest point, the index
    of the piece that holds it and where on that piece (0 at its start, 1 at its end)."""
    a, b = points[:-1], points[1:]
    ab = b - a
    seg_len2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", point - a, ab) / seg_len2, 0.0, 1.0)
    nearest = a + t[:, None] * ab
    dist = np.linalg.norm(point - nearest, axis=1)
    i = int(np.argmin(dist))
    seg_len = np.sqrt(seg_len2)
    return float(dist[i]), float(seg_len[:i].sum() + t[i] * seg_len[i]), i, float(t[i])


def distance_to_polyline(point: np.ndarray, points: np.ndarray) -> tuple[float, float]:
    """Distance from ``point`` (2,) to the polyline ``points`` (n, 2) and the arc length of
    its nearest point (both in the units of the inputs)."""
    dist, s, _, _ = _nearest_on_polyline(point, points)
    return dist, s


def signed_offset(point: np.ndarray, points: np.ndarray) -> float:
    """Signed offset of ``point`` (2,) from the polyline ``points`` (n, 2): positive on the
    left of its direction (the +y side of a line heading along +x).

    Beside the line it is the distance with that sign; before the line's start or past its end
    it is the offset across the line's extension there (the straight line through that end, along
    the end's direction), so it is 0 wherever the tool is lined up with the line.
    """
    return _offset(point, points, *_nearest_on_polyline(point, points))


def _offset(
    point: np.ndarray, points: np.ndarray, dist: float, s: float, i: int, t: float
) -> float:
    """:func:`signed_offset` from the nearest point that ``_nearest_on_polyline`` found."""
    a, b = points[i], points[i + 1]
    tangent = (b - a) / np.linalg.norm(b - a)
    across = float(tangent[0] * (point[1] - a[1]) - tangent[1] * (point[0] - a[0]))
    if (i == 0 and t == 0.0) or (i == len(points) - 2 and t == 1.0):
        return across
    return float(np.copysign(dist, across))


def _build_task(base: type) -> type:
    from robosuite.models.tasks import ManipulationTask
    from robosuite.utils.mjcf_utils import new_body, new_geom

    class LineCuttingTask(base):
        """robosuite scene: the arm over a table with a marked line (visual only)."""

        #: from the front left, above the start: the line and the tool at its end
        view = ((-0.05, -0.18, TABLE_TOP + 0.12), (0.005, -0.01, TABLE_TOP))

        def __init__(self, line_shape: np.ndarray, **kwargs: Any) -> None:
            self.line_shape = line_shape
            super().__init__(**kwargs)

        def _load_model(self) -> None:
            super()._load_model()
            arena = self._table_arena()
            line = new_body(name="marked_line", pos=(0.0, 0.0, TABLE_TOP + 0.0005))
            for i, (p, q) in enumerate(zip(self.line_shape[:-1], self.line_shape[1:], strict=True)):
                line.append(
                    new_geom(
                        name=f"line_{i}",
                        type="capsule",
                        size=(0.0015,),
                        fromto=f"{p[0]} {p[1]} 0 {q[0]} {q[1]} 0",
                        rgba=(0.05, 0.05, 0.05, 1.0),
                        contype=0,
                        conaffinity=0,
                        group=1,
                    )
                )
            arena.worldbody.append(line)
            self.model = ManipulationTask(
                mujoco_arena=arena, mujoco_robots=[r.robot_model for r in self.robots]
            )

        def _setup_references(self) -> None:
            super()._setup_references()
            self.line_body_id = self.sim.model.body_name2id("marked_line")

    return LineCuttingTask


class DVRKLineCuttingEnv(RobosuiteStepEnv):
    """Cut along a line marked on gauze: move to its start, then follow it (paper §10.2).

    A robosuite arm (a Panda by default; its closed gripper stands in for the dVRK's scissors)
    holds its tool 1 cm above a table and moves it in the table plane in 2 mm steps at 10 Hz.
    A line is drawn on the table (visual only): straight (the training lines) or an arc of
    radius ``radius`` (the paper's test lines, 4.0 down to 1.5 cm), 5 cm long, starting at
    ``line_start`` and heading along +x.

    ======  =======  =============================
    action  name     effect
    ======  =======  =============================
    0       +x       the tool moves 2 mm along +x
    1       -x       2 mm along -x
    2       +y       2 mm along +y
    3       -y       2 mm along -y
    ======  =======  =============================

    **Observation** ``(x, y, d)`` in centimetres (float32): the tool's position relative to the
    table centre and its offset from the marked line — the paper's *pix* feature, computed
    exactly from the geometry instead of from a camera. By default ``d`` is signed, as an
    offset seen in an image is: the distance to the line, positive on its left (the +y side of
    a line heading along +x); before the line's start (or past its end) it is the offset across
    the line's extension, so it is 0 wherever the tool is lined up with the line (see
    :func:`signed_offset`). ``signed_distance=False`` gives the unsigned distance to the line
    instead, which cannot tell a clone which way to step back to it: demos on straight lines
    then teach nothing that follows an arc (README, Table 2).

    **Episode.** The tool starts at a random place 2–4 cm before the line's start and up to
    2 cm to either side. The cut begins at the first step the tool is within ``on_line``
    (3 mm) of the line; the *position error* is then its distance to the line's start. The
    episode ends when the point of the line nearest the tool comes within a step (2 mm) of the
    line's end. The cut
    succeeds if the position error is at most ``tolerance`` (1 cm) and the tool was never more
    than ``tolerance`` from the line. A cut that fails goes on to the end, as the paper's did
    (its tracking errors reach 2.4 cm), so the tracking error covers the whole cut. Reward 1.0
    on success, 0 otherwise. The registered id truncates at 150 steps. ``info`` holds
    ``line_distance_cm``, ``cutting``, ``is_success`` and, once the cut has begun,
    ``position_error_cm``, ``tracking_error_cm`` (the mean distance to the line so far) and
    ``cut_failed`` (the cut has already failed: it began more than ``tolerance`` from the line's
    start, or the tool has been more than ``tolerance`` off the line).

    Parameters
    ----------
    radius : float, optional
        Radius of the line in cm, 1 to 100; ``None`` (default) for a straight line.
    line_start : (float, float), default (-2.0, -1.0)
        Start of the line (cm, relative to the table centre).
    line_jitter : float, default 0.0
        Each reset moves the line by up to this many cm along y (training lines "at random
        positions"); 0 keeps it fixed.
    signed_distance : bool, default True
        Observe the signed offset from the line (see above) rather than the distance to it.
    robot : str, default "Panda"
        The robosuite arm (only the Panda is supported so far).
    render_mode : {"rgb_array"}, optional

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/DVRKLineCutting-v0", radius=3.0)
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space
    ((3,), Discrete(4))
    """

    line_length = 0.05
    tool_height = 0.01
    on_line = 0.003
    tolerance = 0.01

    def __init__(
        self,
        radius: float | None = None,
        line_start: tuple[float, float] = (-2.0, -1.0),
        line_jitter: float = 0.0,
        signed_distance: bool = True,
        robot: str = "Panda",
        render_mode: str | None = None,
    ) -> None:
        if radius is not None:
            # a 5 cm arc closes on itself below 0.8 cm
            radius = check_real("radius", radius, low=1.0, high=100.0)
        line_jitter = check_real("line_jitter", line_jitter, low=0.0, high=3.0)
        start = np.asarray(line_start, dtype=np.float64)
        if start.shape != (2,) or not np.all(np.abs(start) <= 5.0):
            raise ValueError(
                "line_start must be (x, y) in cm within 5 cm of the table centre, "
                f"got {line_start!r}"
            )
        self.radius = radius
        self.signed_distance = check_bool("signed_distance", signed_distance)
        self.line_start = start / 100.0
        self.line_jitter = line_jitter / 100.0
        self._shape = line_points(None if radius is None else radius / 100.0, self.line_length)
        self._line = self._shape + self.line_start
        # arc length at each point of the line (a shift by the jitter keeps it)
        self._arc = np.concatenate(
            [[0.0], np.cumsum(np.linalg.norm(np.diff(self._shape, axis=0), axis=1))]
        )
        self._nearest = (float("nan"), float("nan"))
        z = TABLE_TOP + self.tool_height
        super().__init__(
            robot=robot,
            workspace_low=np.array([-0.10, -0.10, z]),
            workspace_high=np.array([0.10, 0.10, z]),
            render_mode=render_mode,
        )
        self.action_space = spaces.Discrete(4)
        self.observation_space = spaces.Box(
            np.array([-15.0, -15.0, -40.0 if self.signed_distance else 0.0], dtype=np.float32),
            np.array([15.0, 15.0, 40.0], dtype=np.float32),
            dtype=np.float32,
        )
        self._cutting = False
        self._failed = False
        self._errors: list[float] = []
        self._position_error = float("nan")

    def _task_class(self) -> type:
        return robosuite_task("SwirlLineCuttingTask", _build_task)

    def _task_kwargs(self) -> dict[str, Any]:
        return {"line_shape": self._shape}

    def _home_position(self) -> np.ndarray:
        return np.array([*(self.line_start - [0.03, 0.0]), TABLE_TOP + self.tool_height])

    @property
    def line(self) -> np.ndarray:
        """The current line as points (n, 2) in the world frame (m)."""
        return self._line.copy()

    def line_distance(self, xy: np.ndarray) -> tuple[float, float]:
        """Distance (m) of a world point ``xy`` to the line and the arc length of its nearest
        point (m, 0 at the line's start)."""
        return distance_to_polyline(np.asarray(xy, dtype=np.float64), self._line)

    def point_along(self, s: float) -> np.ndarray:
        """The world point (2,) of the line at arc length ``s`` (m), clipped to its ends."""
        return np.array([np.interp(s, self._arc, self._line[:, k]) for k in range(2)])

    def _after_reset(self) -> np.ndarray:
        rng = self.np_random
        offset = np.array([0.0, rng.uniform(-self.line_jitter, self.line_jitter)])
        self._line = self._shape + self.line_start + offset
        self.sim.model.body_pos[self._task.line_body_id][:2] = self._line[0]
        self._cutting = False
        self._failed = False
        self._errors = []
        self._position_error = float("nan")
        self._grip = 1.0  # the closed gripper is the tool, from the first settling step on
        start = self._line[0] + [rng.uniform(-0.04, -0.02), rng.uniform(-0.02, 0.02)]
        return np.array([*start, TABLE_TOP + self.tool_height])

    def _apply(self, action: int) -> None:
        target = self._goal.copy()
        target[:2] += self.step_size * _DIRECTIONS[action]
        self._command(target)

    def _observe(self) -> np.ndarray:
        xy = self.tool_position[:2]
        nearest = _nearest_on_polyline(np.asarray(xy, dtype=np.float64), self._line)
        self._nearest = nearest[:2]  # distance and arc length, read again by _evaluate
        d = _offset(xy, self._line, *nearest) if self.signed_distance else nearest[0]
        return (np.array([*xy, d]) * 100.0).astype(np.float32)

    def _evaluate(self) -> tuple[float, bool, dict[str, Any]]:
        d, s = self._nearest
        if not self._cutting and d <= self.on_line:
            self._cutting = True
            self._position_error = float(np.linalg.norm(self.tool_position[:2] - self._line[0]))
        info: dict[str, Any] = {
            "line_distance_cm": 100.0 * d,
            "cutting": self._cutting,
            "is_success": False,
        }
        if not self._cutting:
            return 0.0, False, info
        self._errors.append(d)
        info["position_error_cm"] = 100.0 * self._position_error
        info["tracking_error_cm"] = 100.0 * float(np.mean(self._errors))
        self._failed |= self._position_error > self.tolerance or d > self.tolerance
        info["cut_failed"] = self._failed
        done = s >= self.line_length - self.step_size
        info["is_success"] = success = done and not self._failed
        return float(success), done, info
