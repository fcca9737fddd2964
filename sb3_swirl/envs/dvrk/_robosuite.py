"""The small gymnasium adapter under both dVRK tasks: a robosuite arm driven in 2 mm steps.

robosuite's own ``GymWrapper`` fails gymnasium's ``check_env`` (no metadata, float64
observations in a float32 space, ``reset(seed)`` does not reach robosuite's rng, the horizon
reported as ``terminated``), and robosuite's default end-effector controller does not make a
2 mm command a 2 mm move. This module fixes both once (see ``NOTES-robosuite.md``):

- an ``OSC_POSITION`` arm controller at 10 Hz with ``kp = 300`` whose goal accumulates the
  commanded steps exactly (``goal_update_mode="desired"``, re-anchored after every reset);
- a workspace box that the commanded goal never leaves;
- no robosuite observables (each task reads the few numbers it needs from the simulator);
- the model is compiled once; ``reset`` only resets the simulator state;
- all randomness from gymnasium's ``np_random``; headless unless ``render_mode="rgb_array"``.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
import weakref
from collections import OrderedDict
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np


def _egl_loads() -> bool:
    """Whether this machine has EGL (libEGL), which MUJOCO_GL=egl needs even to import mujoco."""
    try:
        ctypes.CDLL("libEGL.so.1")
    except OSError:
        return False
    return True


# mujoco picks its OpenGL backend once, when it is imported (robosuite imports it): on a
# headless Linux machine only EGL can render offscreen, and it works with a display too. A
# backend the user chose (MUJOCO_GL set before this) is kept, and without libEGL none is set:
# mujoco with MUJOCO_GL=egl fails on import there, for every MuJoCo env, rendering or not.
if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and _egl_loads():
    os.environ["MUJOCO_GL"] = "egl"
#: the backend mujoco starts with (robosuite's import sets MUJOCO_GL to egl after it)
_MUJOCO_GL = os.environ.get("MUJOCO_GL", "unset: glfw")


def _close_renderer(ref: weakref.ref) -> None:
    """Close a renderer that is still open (its env was never closed)."""
    renderer = ref()
    if renderer is not None:
        renderer.close()


#: robosuite robots that stand in for the dVRK's patient-side manipulator. Only the Panda is
#: tuned and tested: with the same settings the UR5e tracked lines 0.8 cm off and the Sawyer
#: never reached the line.
ROBOTS = ("Panda",)

#: Table top height in robosuite's ``TableArena`` with the default offset (m).
TABLE_TOP = 0.8

_ROBOSUITE_TASKS: dict[str, type] = {}


def look_at_camera(name: str, position: np.ndarray, target: np.ndarray) -> Any:
    """An MJCF ``<camera>`` element at ``position`` looking at ``target`` (world frame, m),
    with the world's z axis up in the picture."""
    import xml.etree.ElementTree as ET

    forward = np.asarray(target, dtype=float) - np.asarray(position, dtype=float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return ET.Element(
        "camera",
        name=name,
        pos=" ".join(f"{v:.4f}" for v in position),
        xyaxes=" ".join(f"{v:.4f}" for v in (*right, *up)),
        fovy="45",
    )


def robosuite_task(name: str, build: Any) -> type:
    """The robosuite ``ManipulationEnv`` subclass ``name``, built once by ``build(base)``.

    robosuite registers every ``ManipulationEnv`` subclass by its class name when the class is
    created, and importing robosuite is slow and noisy; so the task classes are created on first
    use, not when ``sb3_swirl.envs`` is imported.
    """
    if name not in _ROBOSUITE_TASKS:
        import logging

        # robosuite warns on import about files and robots these tasks do not use, and logs
        # every controller it loads: keep its warnings about what happens later, not those
        logger = logging.getLogger("robosuite_logs")
        logger.disabled = True
        try:
            from robosuite.environments.manipulation.manipulation_env import ManipulationEnv
        finally:
            logger.disabled = False
        logger.setLevel(logging.WARNING)

        from robosuite.models.arenas import TableArena

        class _Base(ManipulationEnv):
            """A robosuite task without observables: the adapter reads the simulator itself."""

            #: the physics step (s): the same tracking as robosuite's 2 ms at twice the speed
            model_timestep_override = 0.004
            #: where the task's ``dvrk_view`` camera sits and the point it looks at (m)
            view: tuple[tuple[float, float, float], tuple[float, float, float]] = (
                (0.08, -0.3, TABLE_TOP + 0.2),
                (-0.02, 0.0, TABLE_TOP),
            )

            def _table_arena(self) -> Any:
                """The robot at a table whose top is at :data:`TABLE_TOP`, with the camera."""
                robot = self.robots[0].robot_model
                robot.set_base_xpos(robot.base_xpos_offset["table"](0.8))
                arena = TableArena(table_full_size=(0.8, 0.8, 0.05), table_offset=(0, 0, TABLE_TOP))
                arena.set_origin([0, 0, 0])
                arena.worldbody.append(look_at_camera("dvrk_view", *self.view))
                return arena

            def _setup_observables(self) -> OrderedDict:
                return OrderedDict()

            def initialize_time(self, control_freq: float) -> None:
                super().initialize_time(control_freq)
                self.model_timestep = self.model_timestep_override
                self.sim.model.opt.timestep = self.model_timestep_override

            def reward(self, action: Any = None) -> float:
                return 0.0

        _ROBOSUITE_TASKS[name] = build(_Base)
    return _ROBOSUITE_TASKS[name]


class RobosuiteStepEnv(gym.Env):
    """Base of the dVRK tasks: a robosuite arm that moves its tool in exact 2 mm steps.

    Subclasses define ``_task_class()`` (a robosuite task built with :func:`robosuite_task`),
    ``_task_kwargs()``, ``_after_reset()`` (task randomisation, returns the tool's start
    position), ``_observe()`` and ``_evaluate()`` (reward, terminated, info).

    Parameters
    ----------
    robot : str
        A robosuite robot, one of :data:`ROBOTS`.
    workspace_low, workspace_high : array of shape (3,)
        Box (world frame, m) that the commanded tool position never leaves.
    render_mode : {"rgb_array"}, optional
        ``render()`` returns a picture from ``camera``. Needs an offscreen OpenGL (EGL); never
        needed for training.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}
    #: size of one discrete step (m)
    step_size = 0.002
    control_freq = 10
    kp = 300
    #: control steps of settling after the tool is placed at its start (not part of the episode)
    settle_steps = 10
    #: camera for ``render()`` (each task adds it with :func:`look_at_camera`) and picture size
    camera = "dvrk_view"
    render_size = (480, 480)

    def __init__(
        self,
        *,
        robot: str,
        workspace_low: np.ndarray,
        workspace_high: np.ndarray,
        render_mode: str | None = None,
    ) -> None:
        if robot not in ROBOTS:
            raise ValueError(f"unsupported robot {robot!r}; supported: {list(ROBOTS)}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        self.robot_name = robot
        self.render_mode = render_mode
        self.workspace_low = np.asarray(workspace_low, dtype=np.float64)
        self.workspace_high = np.asarray(workspace_high, dtype=np.float64)
        self._renderer = None
        self._ended: int = 0  # 1: the episode terminated, 2: and a step came after
        self._task = self._make_task()
        self._arm = self._task.robots[0]
        self._controller: Any = None
        self._eef_site = self._arm.eef_site_id["right"]
        # The Panda's rotor inertia (armature up to 5 kg m^2 on the shoulder) makes its
        # operational-space controller settle in seconds, a few mm beside its commands; the
        # dVRK's patient-side arm is light and cable-driven. A tenth of it: the tool trails a
        # moving command by about 3 mm and settles on it (measured in NOTES-robosuite terms).
        dofs = self._arm._ref_joint_vel_indexes
        self.sim.model.dof_armature[dofs] *= 0.1
        self._goal = np.zeros(3)
        self._grip = -1.0
        self._settle_home()

    # ------------------------------------------------------------------ robosuite plumbing
    def _make_task(self) -> Any:
        task_class = self._task_class()  # imports robosuite quietly
        from robosuite.controllers import (
            load_composite_controller_config,
            load_part_controller_config,
        )

        config = load_composite_controller_config(robot=self.robot_name)
        part = load_part_controller_config(default_controller="OSC_POSITION")
        part["kp"] = self.kp
        config["body_parts"]["right"].update(part)
        config["body_parts"]["right"]["gripper"] = {"type": "GRIP"}
        return task_class(
            robots=self.robot_name,
            controller_configs=config,
            has_renderer=False,
            has_offscreen_renderer=False,
            use_camera_obs=False,
            control_freq=self.control_freq,
            horizon=10**9,
            ignore_done=True,
            hard_reset=False,
            initialization_noise=None,
            renderer="mujoco",
            **self._task_kwargs(),
        )

    def _task_class(self) -> type:
        raise NotImplementedError

    def _task_kwargs(self) -> dict[str, Any]:
        return {}

    @property
    def sim(self) -> Any:
        """robosuite's ``MjSim`` of the task (``sim.model._model`` is the ``mujoco.MjModel``)."""
        return self._task.sim

    @property
    def tool_position(self) -> np.ndarray:
        """The tool tip (the gripper's grip site) in the world frame (m)."""
        return np.array(self.sim.data.site_xpos[self._eef_site])

    @property
    def commanded_position(self) -> np.ndarray:
        """Where the controller is taking the tool (world frame, m): the sum of the steps."""
        return self._goal.copy()

    def _anchor_goal(self) -> None:
        """Make the goal accumulate commanded steps from where the tool is now.

        ``set_goal_update_mode("desired")`` alone keeps a goal from before the reset, in the
        wrong frame (the arm jumps about 1 m); so the goal is re-anchored first. robosuite builds
        new controllers on every reset, so the controller is looked up again here.
        """
        c = self._controller = self._arm.composite_controller.part_controllers["right"]
        c.update(force=True)
        c.goal_pos = c.world_to_origin_frame(c.ref_pos)
        c.set_goal_update_mode("desired")
        self._goal = self.tool_position

    def _command(self, target: np.ndarray, grip: float | None = None) -> None:
        """One control step towards ``target`` (world frame), clipped to the workspace."""
        target = np.clip(target, self.workspace_low, self.workspace_high)
        if grip is not None:
            self._grip = grip
        # in "desired" mode a zero arm action keeps the goal set here
        self._controller.goal_pos = self._controller.world_to_origin_frame(target)
        action = np.zeros(self._task.action_dim)
        action[-1] = self._grip
        self._task.step(action)
        self._goal = target

    def _settle_home(self) -> None:
        """Move the arm to the task's home tool position once and start every reset there."""
        self._task.reset()
        self._anchor_goal()
        home = self._home_position()
        for _ in range(40):
            self._command(self._goal + np.clip(home - self._goal, -0.02, 0.02))
        for _ in range(10):
            self._command(home)
        self._arm.init_qpos = np.array(self.sim.data.qpos[self._arm._ref_joint_pos_indexes])

    def _home_position(self) -> np.ndarray:
        return 0.5 * (self.workspace_low + self.workspace_high)

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if options:  # else a setting meant for the line or the sheet is ignored silently
            raise ValueError(
                f"{type(self).__name__}.reset takes no options, got {options!r}: give settings "
                "to the constructor, gym.make(env_id, radius=3.0) for example"
            )
        super().reset(seed=seed)
        self._task.rng = np.random.default_rng(int(self.np_random.integers(2**63)))
        self._task.reset()
        self._anchor_goal()
        start = self._after_reset()
        for _ in range(self.settle_steps):
            self._command(start)
        self._ended = 0
        return self._observe(), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self.action_space.contains(action):
            raise ValueError(f"action must be in {self.action_space}, got {action!r}")
        self._apply(int(action))
        obs = self._observe()
        reward, terminated, info = self._evaluate()
        if self._ended:  # as gymnasium's CartPole: say so once, and pay nothing more
            if self._ended == 1:
                gym.logger.warn(
                    "step() called after the episode terminated: call reset(); these steps "
                    "pay 0 reward"
                )
            self._ended, reward = 2, 0.0
        elif terminated:
            self._ended = 1
        return obs, reward, terminated, False, info

    def _apply(self, action: int) -> None:
        raise NotImplementedError

    def _after_reset(self) -> np.ndarray:
        raise NotImplementedError

    def _observe(self) -> np.ndarray:
        raise NotImplementedError

    def _evaluate(self) -> tuple[float, bool, dict[str, Any]]:
        raise NotImplementedError

    def render(self) -> np.ndarray | None:
        """An RGB picture (H, W, 3) from :attr:`camera`; needs ``render_mode="rgb_array"``."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass one to the constructor")
            return None
        import mujoco

        if self._renderer is None:
            height, width = self.render_size
            try:
                self._renderer = mujoco.Renderer(self.sim.model._model, height, width)
            except Exception as exc:  # gladLoadGL, EGL_NOT_INITIALIZED, no GLContext...
                raise RuntimeError(
                    f"render_mode='rgb_array' needs offscreen OpenGL, and MuJoCo's backend "
                    f"(MUJOCO_GL {_MUJOCO_GL}) could not start here: {type(exc).__name__}: {exc}. "
                    "On a headless Linux machine install EGL (libegl1) and set MUJOCO_GL=egl "
                    "before importing mujoco; training never needs rendering"
                ) from exc
            # closed with the env, or at exit before mujoco ends EGL (its own atexit hook,
            # registered earlier, runs later)
            atexit.register(_close_renderer, weakref.ref(self._renderer))
        # robosuite's collision shapes (geom group 0) would hide the meshes
        shown = mujoco.MjvOption()
        shown.geomgroup[0] = 0
        self._renderer.update_scene(self.sim.data._data, camera=self.camera, scene_option=shown)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()
