"""Deformable sheet tensioning on robosuite (paper §10.1): reach, grasp, lift, pull flat."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from sb3_swirl.envs.dvrk._robosuite import TABLE_TOP, RobosuiteStepEnv, robosuite_task

#: Action indices of :class:`DVRKTensioningEnv`.
PLUS_X, MINUS_X, PLUS_Y, MINUS_Y, PLUS_Z, MINUS_Z, OPEN, CLOSE = range(8)
_DIRECTIONS = np.vstack([np.eye(3)[k] * sign for k in range(3) for sign in (1.0, -1.0)])

#: Vertices per side of the gauze grid (9 x 9), their spacing (m) and the height of the two
#: pinned corners above the table (m).
GRID = 9
SPACING = 0.01
PIN_HEIGHT = 0.05


def _vertex(i: int, j: int) -> int:
    """Index of the gauze vertex in row ``i`` (along x, 0 = the free edge) and column ``j``."""
    return i * GRID + j


#: The free edge (graspable) and the 3 x 3 fiducial markers whose height variance is the
#: disparity.
FREE_EDGE = tuple(_vertex(0, j) for j in range(GRID))
MARKERS = tuple(_vertex(i, j) for i in (2, 4, 6) for j in (2, 4, 6))
_PINNED = (_vertex(GRID - 1, 0), _vertex(GRID - 1, GRID - 1))


def _build_task(base: type) -> type:
    import xml.etree.ElementTree as ET

    import mujoco
    from robosuite.models.tasks import ManipulationTask
    from robosuite.utils.mjcf_utils import new_geom

    class TensioningTask(base):
        """robosuite scene: the arm over a gauze sheet pinned at its two far corners."""

        #: from the front right, above: the pins, the sheet and the hand that pulls it
        view = ((0.12, -0.16, TABLE_TOP + 0.13), (-0.01, 0.0, TABLE_TOP + 0.035))

        def _load_model(self) -> None:
            super()._load_model()
            arena = self._table_arena()
            # a 9 x 9 sheet, flat at the pins' height: it drapes over the table when the
            # simulation starts (the adapter settles it once and keeps that as the reset state)
            arena.worldbody.append(
                ET.fromstring(
                    f'<flexcomp name="gauze" type="grid" count="{GRID} {GRID} 1" '
                    f'spacing="{SPACING} {SPACING} {SPACING}" pos="0 0 {TABLE_TOP + PIN_HEIGHT}" '
                    'radius="0.002" mass="0.1" dim="2" rgba="0.62 0.76 0.92 1">'
                    # high friction, like gauze on the paper's silicone pad: with 1 the part
                    # lying on the table slides and the sheet bunches up under the pins
                    '<contact condim="3" friction="2 0.005 0.0001" solref="0.01 1" '
                    'selfcollide="none"/>'
                    '<edge equality="true" solref="0.004 1"/>'
                    f'<pin id="{" ".join(map(str, _PINNED))}"/>'
                    "</flexcomp>"
                )
            )
            # the two pins, drawn as posts (visual only: no contact, no mass)
            for y in (-1.0, 1.0):
                arena.worldbody.append(
                    new_geom(
                        name=f"pin_post_{int(y > 0)}",
                        type="cylinder",
                        size=(0.0015, PIN_HEIGHT / 2),
                        pos=(
                            SPACING * (GRID - 1) / 2,
                            y * SPACING * (GRID - 1) / 2,
                            TABLE_TOP + PIN_HEIGHT / 2,
                        ),
                        rgba=(0.25, 0.25, 0.25, 1.0),
                        contype=0,
                        conaffinity=0,
                        group=1,
                        density=0,
                    )
                )
            self.model = ManipulationTask(
                mujoco_arena=arena, mujoco_robots=[r.robot_model for r in self.robots]
            )
            # the grasp: one inactive connect constraint per free-edge vertex, switched on when
            # the gripper closes next to it (a physical pinch of a flat sheet does not hold)
            hand = self.robots[0].gripper["right"].root_body
            for k in FREE_EDGE:
                self.model.equality.append(
                    ET.fromstring(
                        f'<connect name="grasp_{k}" body1="{hand}" body2="gauze_{k}" '
                        'anchor="0 0 0" active="false" solref="0.005 1"/>'
                    )
                )

        def _setup_references(self) -> None:
            super()._setup_references()
            model = self.sim.model._model
            # robosuite's Newton solver with elliptic cones runs the cloth at 5-22 steps/s
            model.opt.solver = mujoco.mjtSolver.mjSOL_CG
            model.opt.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
            model.opt.tolerance = 1e-6
            name2id = mujoco.mj_name2id
            self.grasp_ids = np.array(
                [name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"grasp_{k}") for k in FREE_EDGE]
            )
            self.hand_id = name2id(
                model, mujoco.mjtObj.mjOBJ_BODY, self.robots[0].gripper["right"].root_body
            )
            flex = name2id(model, mujoco.mjtObj.mjOBJ_FLEX, "gauze")
            first = model.flex_vertadr[flex]
            last = first + model.flex_vertnum[flex]
            self.vertex_body = np.array(model.flex_vertbodyid[first:last])
            self.vertex_slice = slice(first, last)

    return TensioningTask


class DVRKTensioningEnv(RobosuiteStepEnv):
    """Tension a gauze sheet: reach its free edge, grasp it, lift it and pull it flat (§10.1).

    A robosuite arm (a Panda; its gripper stands in for the dVRK's needle driver) works over
    an 8 x 8 cm gauze sheet (a MuJoCo ``flexcomp`` grid of 9 x 9 vertices, 0.1 kg) whose two
    far corners are pinned 5 cm above the table, so that the sheet hangs from them and its free
    half lies on the table. The free edge can be grasped: closing the gripper within
    ``grasp_radius`` (2.5 cm) of free-edge vertices attaches them to the gripper (constraints,
    as in SurRoL; a physical pinch of a sheet lying flat does not hold in simulation); opening
    it lets go. The tool moves in 2 mm steps at 10 Hz inside a box that keeps the sheet's
    strain in the range where its elastic model is stable.

    ======  =======  ===============================================
    action  name     effect
    ======  =======  ===============================================
    0-5     ±x ±y ±z  the tool moves 2 mm along that axis
    6       open     open the gripper (drops what it holds)
    7       close    close the gripper (grasps the edge if it is near)
    ======  =======  ===============================================

    **Observation** (float32): the tool's position ``(x, y, z)`` in cm (relative to the table
    centre and top), the gripper state (1 closed, 0 open), the wrist load in N (the force
    sensor at the wrist, tared with nothing held) and the *disparity*: the variance of the
    heights of a 3 x 3 grid of markers on the sheet, in cm² — the paper's flatness feature.

    **Reward** minus the disparity at every step, so the return is the paper's "disparity
    value" (flatter for longer is better). No step ends the episode; the registered id
    truncates at 100 steps. ``info["is_success"]`` is true while the sheet is held and its
    disparity is at most ``success_disparity`` (0.05 cm², markers within about ±2 mm of a
    plane at the same height); ``info`` also holds ``disparity_cm2``, ``load_n`` and
    ``grasped`` (the number of edge vertices held).

    **Episode.** The sheet starts at rest in the same drape; the tool starts open at a random
    place 1-3 cm before the free edge, up to 2 cm to either side, 3-5 cm above the table.

    Parameters
    ----------
    robot : str, default "Panda"
        The robosuite arm (only the Panda is supported so far).
    render_mode : {"rgb_array"}, optional

    Examples
    --------
    >>> import gymnasium as gym
    >>> import sb3_swirl.envs
    >>> env = gym.make("sb3_swirl/DVRKTensioning-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space
    ((6,), Discrete(8))
    """

    grasp_radius = 0.025
    success_disparity = 0.05
    #: lowest tool height above the table (m): lower, the open fingers press on the table
    min_height = 0.01

    def __init__(self, robot: str = "Panda", render_mode: str | None = None) -> None:
        pinned_x = (GRID - 1) * SPACING / 2
        super().__init__(
            robot=robot,
            # at most 11.5 cm from the pinned corners (about 25% strain where the sheet is
            # pulled), 1-6.5 cm above the table, within 4 cm of the sheet's centre line
            workspace_low=np.array([pinned_x - 0.115, -0.04, TABLE_TOP + self.min_height]),
            workspace_high=np.array([pinned_x - 0.01, 0.04, TABLE_TOP + 0.065]),
            render_mode=render_mode,
        )
        self.action_space = spaces.Discrete(8)
        self.observation_space = spaces.Box(
            np.array([-15.0, -15.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32),
            np.array([15.0, 15.0, 15.0, 1.0, 100.0, 25.0], dtype=np.float32),
            dtype=np.float32,
        )
        self._closed = False
        self._disparity = self._load = float("nan")

    def _task_class(self) -> type:
        return robosuite_task("SwirlTensioningTask", _build_task)

    def _home_position(self) -> np.ndarray:
        return np.array([-0.03, 0.0, TABLE_TOP + 0.04])

    def _settle_home(self) -> None:
        task, model = self._task, self.sim.model._model
        # the grid is built flat at the pins' height; start it in a drape instead (hanging from
        # the pins in a straight slope to the table, the rest lying flat towards the robot) and
        # let it come to rest while the arm moves home. The free vertices are bodies with slide
        # joints: moving the bodies' model positions moves the configuration a reset returns to.
        free = task.vertex_body > 0  # pinned vertices have no body of their own
        i = np.repeat(np.arange(GRID), GRID)
        along = (GRID - 1 - i) * SPACING  # distance from the pinned edge, along the sheet
        foot = np.array([0.03, PIN_HEIGHT])  # the slope drops 3 cm along x to the table
        slope = np.linalg.norm(foot)
        t = np.minimum(along, slope) / slope
        x = (GRID - 1) / 2 * SPACING - t * foot[0] - np.maximum(along - slope, 0.0)
        z = TABLE_TOP + PIN_HEIGHT - t * foot[1] + 0.003
        model.body_pos[task.vertex_body[free], 0] = x[free]
        model.body_pos[task.vertex_body[free], 2] = z[free]
        super()._settle_home()
        for _ in range(20):  # the sheet comes to rest
            self._command(self._goal)
        # every reset starts from this drape
        model.body_pos[task.vertex_body[free]] = self.vertices[free]
        self._tare = np.array(self._arm.ee_force["right"])

    @property
    def vertices(self) -> np.ndarray:
        """Positions (81, 3) of the sheet's vertices in the world frame (m); vertex
        ``i * 9 + j`` is in row ``i`` from the free edge and column ``j``."""
        return np.array(self.sim.data._data.flexvert_xpos[self._task.vertex_slice])

    @property
    def held_vertices(self) -> np.ndarray:
        """The free-edge vertices (indices into :attr:`vertices`) the gripper holds."""
        active = self.sim.data._data.eq_active[self._task.grasp_ids].astype(bool)
        return np.asarray(FREE_EDGE)[active]

    def _grasp(self) -> None:
        data, model = self.sim.data._data, self.sim.model._model
        hand = self._task.hand_id
        rotation = data.xmat[hand].reshape(3, 3)
        tool, vertices = self.tool_position, self.vertices
        for eq, vertex in zip(self._task.grasp_ids, FREE_EDGE, strict=True):
            position = vertices[vertex]
            if np.linalg.norm(position - tool) <= self.grasp_radius:
                # hold the vertex where it is now, relative to the hand
                model.eq_data[eq, :3] = rotation.T @ (position - data.xpos[hand])
                model.eq_data[eq, 3:6] = 0.0
                data.eq_active[eq] = 1

    def _after_reset(self) -> np.ndarray:
        rng = self.np_random
        self._closed = False
        self._grip = -1.0
        edge_x = self.vertices[FREE_EDGE[GRID // 2], 0]
        return np.array(
            [
                edge_x + rng.uniform(-0.03, -0.01),
                rng.uniform(-0.02, 0.02),
                TABLE_TOP + rng.uniform(0.03, 0.05),
            ]
        )

    def _apply(self, action: int) -> None:
        if action < OPEN:
            self._command(self._goal + self.step_size * _DIRECTIONS[action])
        elif action == OPEN:
            self._closed = False
            self.sim.data._data.eq_active[self._task.grasp_ids] = 0
            self._command(self._goal, grip=-1.0)
        else:
            if not self._closed:
                self._closed = True
                self._grasp()
            self._command(self._goal, grip=1.0)

    def _observe(self) -> np.ndarray:
        heights = self.vertices[list(MARKERS), 2] * 100.0
        self._disparity = float(np.var(heights))  # read again by _evaluate
        self._load = float(np.linalg.norm(self._arm.ee_force["right"] - self._tare))
        tool = (self.tool_position - [0.0, 0.0, TABLE_TOP]) * 100.0
        obs = np.array([*tool, float(self._closed), self._load, self._disparity])
        return np.clip(obs, self.observation_space.low, self.observation_space.high).astype(
            np.float32
        )

    def _evaluate(self) -> tuple[float, bool, dict[str, Any]]:
        grasped = len(self.held_vertices)
        info = {
            "disparity_cm2": self._disparity,
            "load_n": self._load,
            "grasped": grasped,
            "is_success": grasped > 0 and self._disparity <= self.success_disparity,
        }
        return -self._disparity, False, info
