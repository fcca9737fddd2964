"""Supervisors: the scripted experts that demonstrate the paper's tasks.

Every supervisor has the same small interface::

    sup = Supervisor(env.unwrapped, seed=None)
    obs, info = env.reset(seed=...)
    sup.reset(obs)
    action = sup.act(obs)  # each step
    sup.phase  # optional: the phase of the plan the last action belongs to (an int)

and :func:`collect_demos` runs the right one for a registered env id.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

import sb3_swirl.envs  # noqa: F401  (registers the sb3_swirl/ env ids)
from sb3_swirl.demos import Demonstration
from sb3_swirl.supervisors.acrobot import AcrobotSupervisor
from sb3_swirl.supervisors.fetch import (
    FetchPickAndPlaceSupervisor,
    FetchPushSupervisor,
    FetchReachSupervisor,
)
from sb3_swirl.supervisors.line_cutting import LineCuttingSupervisor
from sb3_swirl.supervisors.tensioning import TensioningSupervisor
from swirl_wrappers import observation_state, state_space
from swirl_wrappers._validation import check_int
from swirl_wrappers.wrappers import _key_tuple

#: env id -> ``"module:Class"`` of its supervisor, imported on first use
SUPERVISORS: dict[str, str] = {
    "sb3_swirl/ParallelParking-v0": "sb3_swirl.supervisors.parking:ParkingSupervisor",
    "sb3_swirl/ParallelParkingPartial-v0": "sb3_swirl.supervisors.parking:ParkingSupervisor",
    "sb3_swirl/ParallelParkingPartialDisplacement-v0": (
        "sb3_swirl.supervisors.parking:ParkingSupervisor"
    ),
    "sb3_swirl/ParallelParkingPerturbed-v0": "sb3_swirl.supervisors.parking:ParkingSupervisor",
    "sb3_swirl/NoisyAcrobot-v0": "sb3_swirl.supervisors.acrobot:AcrobotSupervisor",
    "sb3_swirl/UnderactuatedAcrobot-v0": "sb3_swirl.supervisors.acrobot:AcrobotSupervisor",
    "sb3_swirl/DVRKLineCutting-v0": "sb3_swirl.supervisors.line_cutting:LineCuttingSupervisor",
    "sb3_swirl/DVRKTensioning-v0": "sb3_swirl.supervisors.tensioning:TensioningSupervisor",
    "sb3_swirl/FetchReachDiscrete-v0": "sb3_swirl.supervisors.fetch:FetchReachSupervisor",
    "sb3_swirl/FetchPushDiscrete-v0": "sb3_swirl.supervisors.fetch:FetchPushSupervisor",
    "sb3_swirl/FetchPickAndPlaceDiscrete-v0": (
        "sb3_swirl.supervisors.fetch:FetchPickAndPlaceSupervisor"
    ),
}


class Supervisor(Protocol):
    """What :func:`collect_demos` needs from a supervisor."""

    def __init__(self, env: gym.Env, seed: int | None = None) -> None: ...

    def reset(self, obs: Any) -> None: ...

    def act(self, obs: Any) -> int: ...


def supervisor_for(env_id: str) -> type[Supervisor]:
    """The supervisor class for a registered env id.

    Raises
    ------
    ValueError
        If no supervisor is registered for ``env_id``; the message lists the supported ids.
    """
    try:
        target = SUPERVISORS[env_id]
    except (KeyError, TypeError):
        raise ValueError(
            f"no supervisor for env id {env_id!r}; supported ids: {sorted(SUPERVISORS)}"
        ) from None
    module_name, class_name = target.split(":")
    return getattr(importlib.import_module(module_name), class_name)


def collect_demos(
    env_id: str,
    n: int,
    seed: int = 0,
    *,
    progress: bool = False,
    max_attempts: int | None = None,
    return_phases: bool = False,
    state_key: str | Sequence[str] | None = None,
    **env_kwargs: Any,
) -> list[Demonstration] | tuple[list[Demonstration], list[np.ndarray]]:
    """Run the env's supervisor for ``n`` successful episodes and return them as demos.

    Episode ``i`` is reset with a seed drawn from ``np.random.SeedSequence(seed).spawn``,
    so the first ``m`` demos do not depend on ``n`` and the same ``seed`` gives the same demos.

    Parameters
    ----------
    env_id : str
        A registered id with a supervisor (see :data:`SUPERVISORS`), e.g.
        ``"sb3_swirl/NoisyAcrobot-v0"``.
    n : int
        Number of demonstrations.
    seed : int, default 0
        Seeds the episodes and the supervisor.
    progress : bool, default False
        Show a rich progress bar.
    max_attempts : int, optional
        Episodes to try at most. By default every episode must succeed (a supervisor is
        expected to be reliable, and silently dropping failures would bias the demos towards
        easy starts); with ``max_attempts > n``, failed episodes are skipped until ``n`` succeed.
    return_phases : bool, default False
        Also return, per demo, the supervisor's phase at every action (an int array of shape
        (T,)): the ground truth of a segmentation, for supervisors that plan in phases (the
        parking supervisor: forward, reverse in, reverse out, final).
    state_key : str or sequence of str, optional
        For envs with ``Dict`` observations (the Fetch tasks), what a demo records: the value
        under this key, or the values under these keys concatenated, as
        :class:`~swirl_wrappers.SwirlWrapper` reads the task state with the same
        ``state_key``. Default ``"observation"``.
    **env_kwargs
        Passed to ``gym.make`` (e.g. ``link_length_2=1.5``).

    Returns
    -------
    list of Demonstration
        ``observations`` (T + 1, d) float64, ``actions`` (T,) int64, ``rewards`` (T,) float64;
        ``truncated`` where the episode ended at the env's time limit (tensioning's do).
        With ``return_phases``, a tuple of that list and the list of phase arrays.

    Raises
    ------
    ValueError
        Unknown ``env_id``, ``n`` / ``max_attempts`` not positive integers with
        ``max_attempts >= n``, ``return_phases`` for a supervisor without phases, an env
        setting the env does not take, or a ``state_key`` not in its observation space.
    RuntimeError
        If fewer than ``n`` episodes succeed within ``max_attempts``; names the failed seeds.

    Examples
    --------
    >>> demos = collect_demos("sb3_swirl/NoisyAcrobot-v0", 2, seed=0)
    >>> demos[0].observations.shape[1], demos[0].actions.dtype
    (4, dtype('int64'))
    """
    supervisor_cls = supervisor_for(env_id)
    n = check_int("n", n, low=1)
    attempts = n if max_attempts is None else check_int("max_attempts", max_attempts, low=n)
    if seed is not None:
        seed = check_int("seed", seed, low=0)
    children = np.random.SeedSequence(seed).spawn(int(attempts))
    if return_phases and not isinstance(getattr(supervisor_cls, "phase", None), property):
        raise ValueError(f"{supervisor_cls.__name__} does not plan in phases (no .phase)")

    try:
        env = gym.make(env_id, **env_kwargs)
    except TypeError as exc:  # a setting the env does not take: named, not a traceback
        raise ValueError(f"{env_id} does not take the settings {env_kwargs}: {exc}") from None
    if isinstance(env.observation_space, gym.spaces.Dict):
        state_key = "observation" if state_key is None else state_key
        try:  # an unknown key is named before any episode runs
            state_space(env.observation_space, state_key)
        except ValueError:
            env.close()
            raise
    elif state_key is not None:
        env.close()
        raise ValueError(f"state_key is for Dict observations; {env_id}'s are not")
    demos: list[Demonstration] = []
    phases: list[np.ndarray] = []
    failed: list[int] = []
    try:
        with _progress_bar(progress, f"{env_id} demos", n) as advance:
            for child in children:
                env_seed, supervisor_seed = (int(x) for x in child.generate_state(2))
                demo, phase = _run_episode(
                    env, supervisor_cls, env_seed, supervisor_seed, state_key
                )
                if demo is None:
                    failed.append(env_seed)
                    if max_attempts is None:
                        break
                    continue
                demos.append(demo)
                phases.append(phase)
                advance()
                if len(demos) == n:
                    break
    finally:
        env.close()
    if len(demos) < n:
        raise RuntimeError(
            f"{supervisor_cls.__name__} failed on {env_id} with env seed(s) {failed} "
            f"({len(demos)} of {n} demos collected in {len(demos) + len(failed)} episodes); "
            + (
                "pass max_attempts > n to skip failed episodes"
                if max_attempts is None
                else f"all {attempts} attempts are spent; raise max_attempts"
            )
        )
    return (demos, phases) if return_phases else demos


def _run_episode(
    env: gym.Env,
    supervisor_cls: type[Supervisor],
    env_seed: int,
    supervisor_seed: int,
    state_key: str | Sequence[str] | None,
) -> tuple[Demonstration | None, np.ndarray]:
    """One supervised episode and its phases (-1 without); ``None`` unless it succeeds."""
    supervisor = supervisor_cls(env.unwrapped, seed=supervisor_seed)
    obs, _ = env.reset(seed=env_seed)
    supervisor.reset(obs)
    observations = [obs]
    actions: list[int] = []
    rewards: list[float] = []
    phases: list[int] = []
    while True:
        action = supervisor.act(obs)
        phases.append(int(getattr(supervisor, "phase", -1)))
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(action)
        rewards.append(float(reward))
        if terminated or truncated:
            break
    if not info.get("is_success", False):
        return None, np.asarray(phases)
    states = [observation_state(obs, state_key) for obs in observations]
    demo = Demonstration(
        observations=np.asarray(states, dtype=np.float64),
        actions=np.asarray(actions, dtype=np.int64),
        rewards=np.asarray(rewards, dtype=np.float64),
        state_key=None if state_key is None else _key_tuple(state_key),
        truncated=bool(truncated and not terminated),  # a time limit: not a terminal state
    )
    return demo, np.asarray(phases, dtype=np.int64)


@contextmanager
def _progress_bar(enabled: bool, description: str, total: int) -> Iterator[Callable[[], None]]:
    """A rich progress bar when ``enabled``, a no-op otherwise; yields its ``advance``."""
    if not enabled:
        yield lambda: None
        return
    from rich.progress import Progress

    with Progress() as bar:
        task = bar.add_task(description, total=total)
        yield lambda: bar.advance(task)


__all__ = [
    "SUPERVISORS",
    "AcrobotSupervisor",
    "FetchPickAndPlaceSupervisor",
    "FetchPushSupervisor",
    "FetchReachSupervisor",
    "LineCuttingSupervisor",
    "Supervisor",
    "TensioningSupervisor",
    "collect_demos",
    "supervisor_for",
]
