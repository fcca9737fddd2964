"""Demonstrations: the typed input of SWIRL.

Everything that learns from demonstrations takes them through :func:`as_demonstrations`, which
accepts the formats users already have (numpy arrays, :class:`Demonstration`, imitation
trajectories, Minari episodes, ``.npz`` files) and validates them once, at the boundary, with a
``ValueError`` that names the demonstration and the problem.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
import zipfile
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_int
from swirl_wrappers.wrappers import _key_tuple, state_space

_NPZ_FORMAT = "sb3_swirl.demos/1"
# Larger observations overflow float64 when squared (covariances, quadratic rewards).
_MAX_MAGNITUDE = 1e150
# How .npz archives (zip, or an empty zip) and .npy arrays start.
_NUMPY_MAGIC = (b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")


@dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstration: a state sequence, optionally with the actions and rewards.

    Parameters
    ----------
    observations : array of shape (T + 1, d)
    actions : array of shape (T,) or (T, action_dim), optional
    rewards : array of shape (T,), optional
    state_key : tuple of str, optional
        For the states of a ``Dict`` observation, the keys whose values each state joins, in
        order (``collect_demos(..., state_key=...)`` records them): a SWIRL wrapper, SwirlDQN
        and the zoo refuse, or warn about, another order. ``None``: not recorded.
    truncated : bool, default False
        The demo was cut short (a time limit, gymnasium's ``truncated``) rather than ending
        where its episode terminates: TD learning on it (SwirlDQN's ``prefill_replay``)
        bootstraps from its last state instead of taking it as terminal. ``collect_demos``
        records it; imitation's ``terminal=False`` and Minari's truncations read as it.
    """

    observations: np.ndarray
    actions: np.ndarray | None = None
    rewards: np.ndarray | None = None
    state_key: tuple[str, ...] | None = None
    truncated: bool = False

    def __len__(self) -> int:
        """Number of transitions ``T``."""
        return len(self.observations) - 1


def _field(item: Any, names: Sequence[str]) -> tuple[bool, Any]:
    """Read the first of ``names`` from an object's attributes or a mapping's keys."""
    for name in names:
        if isinstance(item, Mapping):
            if name in item:
                return True, item[name]
        elif hasattr(item, name):
            return True, getattr(item, name)
    return False, None


def _numeric(value: Any, what: str) -> np.ndarray:
    types = sys.modules.get("imitation.data.types")  # imitation's DictObs, where it is loaded
    if isinstance(value, Mapping) or (types is not None and isinstance(value, types.DictObs)):
        raise ValueError(
            f"{what} are a dict; pass state_key= (the wrapper's, e.g. to fit_task or "
            "as_demonstrations) to join its values in that order, or join them yourself "
            "(swirl_wrappers.observation_state(obs, state_key) does it for one step)"
        )
    if hasattr(value, "detach") and hasattr(value, "cpu"):  # a torch tensor, maybe with grad
        value = value.detach().cpu()
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} cannot be read as one numeric array ({exc})") from exc
    if arr.dtype.kind not in "biuf":
        if arr.dtype == object and arr.size and isinstance(arr.flat[0], Mapping):
            raise ValueError(
                f"{what} are a list of dicts, one per step; pass state_key= (the wrapper's) to "
                "join each step's values in that order"
            )
        raise ValueError(f"{what} have non-numeric dtype {arr.dtype}")
    return arr


def _first_bad_step(arr: np.ndarray) -> int | None:
    if arr.dtype.kind != "f":
        return None
    bad = ~np.isfinite(arr.reshape(len(arr), -1)).all(axis=1)
    return int(np.argmax(bad)) if bad.any() else None


def _joined(obs: Mapping, keys: tuple[str, ...], i: int) -> np.ndarray:
    """The values of a dict of per-key state sequences joined in the order of ``keys``."""
    missing = [key for key in keys if key not in obs]
    if missing:
        raise ValueError(
            f"demo {i}: observations have no key {missing[0]!r} of state_key {list(keys)} "
            f"(their keys: {sorted(map(str, obs))})"
        )
    parts = []
    for key in keys:
        part = _numeric(obs[key], f"demo {i}: observations[{key!r}]")
        part = part[:, None] if part.ndim == 1 else part
        if part.ndim != 2 or (parts and len(part) != len(parts[0])):
            raise ValueError(
                f"demo {i}: observations[{key!r}] must be a (T+1, k) array with as many rows "
                f"as the others, got shape {part.shape}"
            )
        parts.append(part)
    return np.concatenate(parts, axis=1)


def _to_demonstration(item: Any, i: int, state_key: tuple[str, ...] | None = None) -> Demonstration:
    """Convert one item (array, Demonstration, imitation or Minari episode) and check it;
    dict observations are joined in the order of ``state_key`` (then recorded with it)."""
    key, truncated = None, _truncated(item, i)
    if isinstance(item, Demonstration):
        obs, acts, rews, key = item.observations, item.actions, item.rewards, item.state_key
    else:
        if isinstance(item, Mapping) and {"obs", "next_obs", "dones"} <= set(item):
            raise ValueError(  # one of imitation's Transitions: one step, not a trajectory
                f"demo {i} is a single transition (imitation's Transitions, flattened): pass "
                "the trajectories, before flatten_trajectories"
            )
        has_obs, obs = _field(item, ("obs", "observations"))
        if has_obs:
            acts = _field(item, ("acts", "actions"))[1]
            rews = _field(item, ("rews", "rewards"))[1]
            if isinstance(item, Mapping):
                key = item.get("state_key")
        elif isinstance(item, Mapping):
            raise ValueError(
                f"demo {i} is a mapping without 'observations' or 'obs' (its keys: "
                f"{sorted(map(str, item))}); give the states under 'observations'"
            )
        else:
            obs, acts, rews = item, None, None
            if isinstance(item, tuple) and len(item) in (2, 3):  # (obs, acts[, rews])?
                try:
                    np.asarray(item, dtype=np.float64)
                except ValueError:
                    raise ValueError(
                        f"demo {i} is a tuple of {len(item)} arrays of different shapes; "
                        "for observations and actions pass sb3_swirl.Demonstration("
                        "observations, actions)"
                    ) from None

    if type(obs).__name__ == "DictObs" and hasattr(obs, "items"):  # imitation's Dict obs
        obs = dict(obs.items())
    if key is not None:
        key = _key_tuple(key, f"demo {i}: state_key")
        if state_key is not None and key != state_key:  # else fits read other dims silently
            raise ValueError(
                f"demo {i} joins the keys {list(key)}, in that order, but state_key is "
                f"{list(state_key)} (in SwirlDQN and the zoo, the env's): record the demos "
                "with the same state_key"
            )
    join = key if state_key is None else state_key
    steps = isinstance(obs, list | tuple) and bool(obs) and isinstance(obs[0], Mapping)
    if join is not None and steps:  # one dict a step, as env.step returns them
        for t, step in enumerate(obs):
            missing = [k for k in join if k not in step]
            if missing:
                raise ValueError(f"demo {i}: the observation at step {t} has no {missing}")
        obs = {k: [step[k] for step in obs] for k in join}
    if join is not None and isinstance(obs, Mapping):  # per-key arrays: joined in this order
        obs, key = _joined(obs, join, i), join
    obs = _numeric(obs, f"demo {i}: observations")
    if obs.ndim != 2:
        raise ValueError(
            f"demo {i}: observations must be 2-D (T+1, d), got shape {obs.shape}"
            + ("; reshape a 1-D state sequence with x[:, None]" if obs.ndim == 1 else "")
        )
    if len(obs) < 2 or obs.shape[1] < 1:
        raise ValueError(f"demo {i}: needs at least 2 states of dimension >= 1, got {obs.shape}")
    bad = _first_bad_step(obs)
    if bad is not None:
        raise ValueError(f"demo {i}: observations contain NaN or inf (first at step {bad})")
    if obs.dtype.kind == "f":
        big = np.abs(obs).max(axis=1) > _MAX_MAGNITUDE
        if big.any():
            raise ValueError(
                f"demo {i}: observations reach {np.abs(obs).max():.3g} (first above "
                f"{_MAX_MAGNITUDE:g} at step {int(np.argmax(big))}): their squares overflow "
                "float64; rescale them"
            )
    n_steps = len(obs) - 1

    if acts is not None:
        acts = _numeric(acts, f"demo {i}: actions")
        if acts.ndim == 0 or len(acts) != n_steps:
            raise ValueError(
                f"demo {i}: actions must have length T = {n_steps} (one fewer than the "
                f"{n_steps + 1} observations), got shape {acts.shape}"
            )
        bad = _first_bad_step(acts)
        if bad is not None:
            raise ValueError(f"demo {i}: actions contain NaN or inf (first at step {bad})")
        acts = acts.copy()
    if rews is not None:
        rews = _numeric(rews, f"demo {i}: rewards")
        if rews.shape != (n_steps,):
            raise ValueError(
                f"demo {i}: rewards must have shape (T,) = ({n_steps},), got {rews.shape}"
            )
        bad = _first_bad_step(rews)
        if bad is not None:
            raise ValueError(f"demo {i}: rewards contain NaN or inf (first at step {bad})")
        rews = rews.astype(np.float64)
    return Demonstration(np.array(obs, dtype=np.float64), acts, rews, key, truncated)


def _truncated(item: Any, i: int) -> bool:
    """Whether an episode record ends in a truncation: a ``truncated`` field, imitation's
    ``terminal`` (False: cut short) or Minari's ``terminations`` (last step not one)."""
    has, value = _field(item, ("truncated",))
    if not has:
        has, value = _field(item, ("terminal",))
        if has:
            value = value is not None and not value  # imitation: terminal=None is unknown
    if not has:
        has, value = _field(item, ("terminations",))
        if has:
            value = np.asarray(value)
            value = value.size > 0 and not value.reshape(-1)[-1]
    if not has or value is None:
        return False
    flag = np.asarray(value)
    if flag.shape != () or flag.dtype.kind not in "bi" or flag.item() not in (0, 1):
        raise ValueError(f"demo {i}: truncated must be one bool, got {value!r}")
    return bool(flag)


def as_demonstrations(
    data: Any, window: int | None = None, state_key: str | Sequence[str] | None = None
) -> list[Demonstration]:
    """Convert and validate demonstrations.

    Parameters
    ----------
    data : sequence or path
        One of: a sequence of arrays of shape (T+1, d); a sequence of :class:`Demonstration`;
        a sequence of objects with fields ``obs`` (T+1 rows), ``acts`` and optionally ``rews``
        (``imitation.data.types.Trajectory``); a sequence of objects with fields
        ``observations``, ``actions`` and optionally ``rewards`` (Minari ``EpisodeData``) or
        mappings with those keys; a 3-D array (n_demos, T+1, d); or a path to a ``.npz`` file
        written by :func:`save_demos`. Lengths may differ between demonstrations.
    window : int, optional
        The transition-indicator window; each demonstration must then have at least
        ``window + 2`` states (so that two consecutive windows exist).
    state_key : str or sequence of str, optional
        For demos of a ``Dict`` observation given as dicts of per-key arrays (``{"observation":
        (T+1, 25), "desired_goal": (T+1, 3), ...}``, as Minari stores them): the keys to join
        into each state, in the order of the SWIRL wrapper's ``state_key``; recorded as each
        demo's ``state_key``. Without it such demos are refused.

    Returns
    -------
    list of Demonstration
        Observations as float64 arrays; actions keep their dtype; rewards as float64.

    Raises
    ------
    ValueError
        With the demonstration index and the problem: no demonstrations, fewer than two,
        non-numeric or non-finite values (with the first bad step), observations not 2-D,
        actions or rewards whose length is not T, a state dimension or an action shape
        differing between demonstrations, or a demonstration shorter than the window.
    """
    return _as_demonstrations(data, window, state_key, minimum=2)


def _as_demonstrations(data: Any, window: Any, state_key: Any, minimum: int) -> list[Demonstration]:
    """:func:`as_demonstrations`; storing and exporting take a single demo (``minimum=1``)."""
    if isinstance(data, str | os.PathLike):
        data = load_demos(data)
    if isinstance(data, np.ndarray) and data.dtype.kind != "O":
        if data.ndim != 3:
            raise ValueError(
                "a single array of demonstrations must have shape (n_demos, T+1, d), "
                f"got {data.shape}; pass a list of (T+1, d) arrays for ragged lengths"
            )
        data = list(data)
    if isinstance(data, Demonstration | Mapping) or not isinstance(data, Iterable):
        raise ValueError(
            f"expected a sequence of demonstrations or a .npz path, got {type(data).__name__}"
            + ("; a single demonstration? pass a list of them" if isinstance(data, Mapping) else "")
        )
    items = list(data)
    if not items:
        raise ValueError("no demonstrations given")
    if len(items) < minimum:
        raise ValueError(f"SWIRL needs at least 2 demonstrations, got {len(items)}")
    keys = None if state_key is None else _key_tuple(state_key)
    demos = [_to_demonstration(item, i, keys) for i, item in enumerate(items)]
    dim = demos[0].observations.shape[1]
    for i, demo in enumerate(demos):
        if demo.observations.shape[1] != dim:
            raise ValueError(
                f"demo {i} has state dimension {demo.observations.shape[1]} but demo 0 has {dim}"
            )
    keyed = [(i, demo.state_key) for i, demo in enumerate(demos) if demo.state_key is not None]
    for i, keys in keyed[1:]:
        if keys != keyed[0][1]:
            raise ValueError(
                f"demo {i} joins the keys {list(keys)} but demo {keyed[0][0]} "
                f"{list(keyed[0][1])}: record every demo with the same state_key"
            )
    shapes = [(i, demo.actions.shape) for i, demo in enumerate(demos) if demo.actions is not None]
    for i, shape in shapes[1:]:
        if shape[1:] != shapes[0][1][1:]:
            first, first_shape = shapes[0]
            column = {shape[1:], first_shape[1:]} == {(), (1,)}
            raise ValueError(
                f"demo {i} has actions of shape {shape} but demo {first} has {first_shape}: "
                "the actions of every demo must have the same shape after the first (time) axis"
                + ("; for one discrete action a step, pass actions.ravel()" if column else "")
            )
    if window is not None:
        check_window([demo.observations for demo in demos], check_int("window", window, low=1))
    return demos


def check_window(states: Sequence[np.ndarray], window: int) -> None:
    """Raise a ``ValueError`` naming the first demonstration too short for ``window``.

    A window of ``window`` steps needs ``window + 2`` states: two windows, so that a transition
    can show between them.
    """
    need = window + 2
    for i, x in enumerate(states):
        if len(x) < need:
            transposed = (
                f"; it has more dims ({x.shape[1]}) than states: a demo holds one state per "
                "row, shape (T+1, d); is it transposed?"
                if x.ndim == 2 and x.shape[1] > len(x)
                else ""
            )
            raise ValueError(
                f"demo {i} is shorter than the window: it has {len(x)} states, "
                f"window={window} needs at least {need}{transposed}"
            )


class DemoWarning(UserWarning):
    """A demonstration differs strongly from the others (another sampling rate or speed?)."""


# A demo whose typical step or length differs from the other demos' by more than this factor
# is warned about (docs/results.md, "Demos that do not match", has how it was chosen and checked).
_RATE_FACTOR = 3.0
# An entry farther from its dimension's median than this many times the dimension's spread is
# a corrupted value, not data.
_ABSURD_FACTOR = 1e6
_RATE_WHY = (
    "recorded at another sampling rate (or cut short where the others slow down)? By "
    "default (normalize_time=True) the segmentation resamples the demos to a common rate, "
    "which undoes another sampling rate, not a demo cut short"
)
_LENGTH_WHY = "incomplete, or at another rate? An incomplete demo can hide or merge segments"


def check_demos_state_key(
    demos: Sequence[Demonstration], state_key: str | Sequence[str], source: str
) -> None:
    """Raise unless every demo that records its ``state_key`` joined the same keys, in the same
    order, as the wrapper's: two keys of one width swapped would pass every other check.

    Parameters
    ----------
    demos : sequence of Demonstration
    state_key : str or sequence of str
        The wrapper's ``state_key``.
    source : str
        How the messages name a demo (``"demonstration"``: "demonstration 3 joins ...").

    Raises
    ------
    ValueError
        Naming the first demo that joined other keys, and both orders.
    """
    keys = _key_tuple(state_key)
    for i, demo in enumerate(demos):
        if demo.state_key is not None and demo.state_key != keys:
            raise ValueError(
                f"{source} {i} joins the keys {list(demo.state_key)}, in that order, but the "
                f"env's state joins {list(keys)}: record the demos with the same state_key"
            )


def joined_state_note(widths: Mapping[str, int]) -> str:
    """What a demo state of a Dict observation holds, for :func:`check_demos_fit_spaces`.

    Parameters
    ----------
    widths : mapping of str to int
        Each key the state joins, in order, and its width.

    Returns
    -------
    str
        E.g. ``" (observation 25 + achieved_goal 3 + desired_goal 3, joined in this order:
        record the demos with the same state_key)"``.
    """
    parts = " + ".join(f"{key} {width}" for key, width in widths.items())
    return f" ({parts}, joined in this order: record the demos with the same state_key)"


def check_demos_fit_spaces(
    demos: Sequence[Demonstration],
    state_dim: int,
    action_space: spaces.Space | None,
    source: str = "demonstration",
    env_note: str = "the environment's observations",
    hint: str = "",
) -> None:
    """Raise unless every demo has ``state_dim`` observation dims and actions that fit
    ``action_space``: integers in ``start .. start + n - 1`` for ``Discrete``, rows of the
    space's shape for a ``Box`` (values outside its bounds are a :class:`DemoWarning`: the env
    may clip them).

    Messages read ``"{source} {n}: observations have 3 dims, {env_note} have 4{hint}"``.

    Parameters
    ----------
    demos : sequence of Demonstration
    state_dim : int
        The observation dims a demo state must have.
    action_space : gymnasium.spaces.Space or None
        The env's action space; ``None`` or another kind of space leaves actions unchecked.
    source : str
        What a demo is called in messages (``"demonstration"``, ``"demo file x.npz, demo"``).
    env_note : str
        What the demos are compared with in messages (``"the environment's observations"``).
    hint : str
        Appended to the message about observation dims.

    Raises
    ------
    ValueError
        Naming the first demo that does not fit, the field and the problem.
    """
    outside: dict[int, int] = {}  # demo: steps with an action outside a Box
    for n, demo in enumerate(demos):
        if demo.observations.shape[1] != state_dim:
            raise ValueError(
                f"{source} {n}: observations have {demo.observations.shape[1]} dims, {env_note} "
                f"have {state_dim}{hint}"
            )
        if demo.actions is None:
            continue
        if isinstance(action_space, spaces.Discrete):
            _check_discrete_actions(np.asarray(demo.actions), len(demo), action_space, source, n)
        elif isinstance(action_space, spaces.Box):
            actions = np.asarray(demo.actions, dtype=np.float64)
            steps = _box_actions_outside(actions, len(demo), action_space, source, n)
            if steps:
                outside[n] = steps
    if outside:
        shown = ", ".join(f"{n} ({steps} of {len(demos[n])} steps)" for n, steps in outside.items())
        warnings.warn(
            f"{source}s {shown}: actions lie outside the action space {action_space}. The env "
            "may clip them, but a reward learned from the demos' actions (reward='maxent') "
            "reads them as given: record the actions the env applied, in its units",
            DemoWarning,
            stacklevel=2,
        )


def _check_discrete_actions(
    actions: np.ndarray, n_steps: int, space: spaces.Discrete, source: str, n: int
) -> None:
    first, last = int(space.start), int(space.start) + int(space.n) - 1
    if actions.ndim != 1:
        squeeze = " (one action a step: pass actions.ravel())" if actions.size == n_steps else ""
        raise ValueError(
            f"{source} {n}: actions must be integers of shape ({n_steps},) "
            f"for the {space} action space, got shape {actions.shape}{squeeze}"
        )
    fractional = np.flatnonzero(actions != np.round(actions))
    if fractional.size:
        step = int(fractional[0])
        raise ValueError(
            f"{source} {n}: actions must be integers for the {space} action "
            f"space, got {actions[step]!r} at step {step}"
        )
    if actions.size and (actions.min() < first or actions.max() > last):
        raise ValueError(
            f"{source} {n}: actions must lie in the action space {space}, i.e. {first} .. "
            f"{last}; got values in [{actions.min():g}, {actions.max():g}]"
        )


def _box_actions_outside(
    actions: np.ndarray, n_steps: int, space: spaces.Box, source: str, n: int
) -> int:
    """Raise unless ``actions`` has the shape of ``space``'s rows; return the number of steps
    whose action lies outside its bounds (by over 1% of their width)."""
    shape = (n_steps, *space.shape)
    if actions.shape != shape:
        column = (
            " (one value a step: pass actions[:, None])"
            if actions.shape == (n_steps,) and space.shape == (1,)
            else ""
        )
        raise ValueError(
            f"{source} {n}: actions must have shape {shape} for the action space {space}, "
            f"got {actions.shape}{column}"
        )
    low, high = space.low.astype(np.float64), space.high.astype(np.float64)
    width = np.where(np.isfinite(high - low), high - low, 0.0)
    outside = (actions < low - 0.01 * width) | (actions > high + 0.01 * width)
    return int(outside.reshape(n_steps, -1).any(axis=1).sum())


def check_demos_agree(demos: Sequence[Demonstration]) -> list[str]:
    """Check that demonstrations look like samples of one task at one rate.

    * **Absurd values** are an error: an entry farther from its dimension's median than
      ``1e6`` times the dimension's spread (the 99th percentile of ``|x - median|`` over all
      states, or 1 where that is 0). One such value would dominate the scale of its dimension
      and silently change the segmentation.
    * **Another rate** is a warning (:class:`DemoWarning`): a demo whose typical step (the
      median of ``||s_{t+1} - s_t||``, each dimension divided by its spread) differs from the
      median of the other demos' by more than a factor of 3 while its number of steps differs
      by more than 2 the other way, as a demo recorded at another sampling rate does; or whose
      number of steps alone differs by more than 3 (incomplete?). The windowed transition
      indicators compare steps across demos, so such a demo can merge or hide segments.
    * **A demo that never moves** (every state the same) among demos that do is a warning:
      it ends where it starts, inside the goal region, and marks no transition.

    Parameters
    ----------
    demos : sequence of Demonstration

    Returns
    -------
    list of str
        The warnings issued (empty when the demos agree).

    Raises
    ------
    ValueError
        Naming the demo, step and dimension of an absurd value.
    """
    states = [d.observations for d in demos]
    centre, spread = _robust_scale(states)
    for n, x in enumerate(states):
        far = np.abs(x - centre) > _ABSURD_FACTOR * spread
        if far.any():
            step, dim = (int(v) for v in np.argwhere(far)[0])
            raise ValueError(
                f"demo {n}: step {step}, dimension {dim} holds {x[step, dim]:.3g}, "
                f"{abs(x[step, dim] - centre[dim]) / spread[dim]:.1e} times the spread of that "
                f"dimension over all demos ({spread[dim]:.3g} around {centre[dim]:.3g}): a "
                "corrupted value? Fix or drop the demo"
            )
    still = [n for n, x in enumerate(states) if len(x) > 1 and not np.ptp(x, axis=0).any()]
    moving = sum(len(x) > 1 for x in states) - len(still)
    messages = []
    if still and moving:
        messages.append(
            f"demo{'s' if len(still) > 1 else ''} {', '.join(map(str, still))} never "
            f"move{'' if len(still) > 1 else 's'} (every state the same, while {moving} other "
            "demos move): such a demo shows no transition and ends where it starts, inside "
            "the goal region, so it never travels to the regions the fit finds. A recording "
            "that did not run? Drop it"
        )
    found = []
    for n, (step, length) in enumerate(_rate_ratios(states, spread)):
        if _off(step, _RATE_FACTOR) and _off(length, 2.0) and (step > 1) != (length > 1):
            # steps and length off in opposite directions: the time axis is scaled
            found.append((n, "typical step", step, _RATE_WHY))
        elif _off(length, _RATE_FACTOR):
            found.append((n, "number of steps", length, _LENGTH_WHY))
    if len(states) == 2 and len(found) == 2:  # two demos: which one is off cannot be told
        n, what, factor, why = max(found, key=lambda f: f[2])
        messages.append(
            f"demos 0 and 1: the {what} of demo {n} is {factor:.2g} times demo {1 - n}'s: one "
            f"of them {why}"
        )
    else:
        messages += [
            f"demo {n}: its {what} is "
            + (f"{factor:.2g} times" if factor > 1 else f"1/{1 / factor:.2g} of")
            + f" the other demos' (median): {why}"
            for n, what, factor, why in found
        ]
    for message in messages:
        warnings.warn(message, DemoWarning, stacklevel=3)
    return messages


def _off(ratio: float, factor: float) -> bool:
    """Whether ``ratio`` is more than ``factor`` away from 1, either way."""
    return bool(np.isfinite(ratio) and max(ratio, 1 / ratio) > factor)


def _robust_scale(states: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per dimension over all states: the median, and the 99th percentile of the distance to
    it (1 where that is 0), which a few corrupted values do not move."""
    pooled = np.concatenate(states)
    centre = np.median(pooled, axis=0)
    spread = np.percentile(np.abs(pooled - centre), 99, axis=0)
    spread[spread == 0] = 1.0
    return centre, spread


# A demo is at rest at its start (end) while it stays within this fraction of its extent of
# its first (last) state. The rests are left out of its rate when together they hold at least
# _REST_STEPS of its steps (a median of steps is then far off; shorter ones, such as a slow
# approach to a goal, barely move it) and the rest of it _MOTION_STEPS (a single jump in a
# demo that never moves is not its motion).
_REST_FRACTION, _REST_STEPS, _MOTION_STEPS = 0.02, 0.25, 0.05


def _typical_step(x: np.ndarray, scale: np.ndarray) -> tuple[float, int]:
    """A demo's typical step and its number of steps in motion.

    The typical step is the median of ``||s_{t+1} - s_t||``, each dimension divided by
    ``scale``, over the steps between the demo's rest at its start and at its end: the states
    before it leaves (after it settles within) 2% of its extent of its first (last) state,
    where these rests hold a quarter of its steps or more. A demo that waits at its goal until
    a time limit would otherwise read as one recorded at a finer sampling rate.
    """
    z = x / scale
    n_steps = len(z) - 1
    if n_steps < 1:
        return 0.0, 0
    steps = np.linalg.norm(np.diff(z, axis=0), axis=1)
    first, last = (np.linalg.norm(z - z[end], axis=1) for end in (0, -1))
    tol = _REST_FRACTION * max(float(first.max()), float(last.max()))
    moved, unsettled = np.flatnonzero(first > tol), np.flatnonzero(last > tol)
    if moved.size and unsettled.size:
        # steps from the last state at rest at the start to the first state at rest at the end
        start, stop = max(int(moved[0]) - 1, 0), int(unsettled[-1]) + 1
        motion = stop - start
        if n_steps - motion >= _REST_STEPS * n_steps and motion >= _MOTION_STEPS * n_steps:
            return float(np.median(steps[start:stop])), motion
    return float(np.median(steps)), n_steps


def _rate_ratios(states: Sequence[np.ndarray], spread: np.ndarray) -> np.ndarray:
    """Each demo's typical step and number of steps in motion over the median of the other
    demos' (``_typical_step``, with each dimension divided by ``spread``).

    Returns shape (n_demos, 2); NaN where a median is 0.
    """
    values = np.array([_typical_step(x, spread) for x in states], dtype=np.float64)
    others = np.array([np.median(np.delete(values, n, axis=0), axis=0) for n in range(len(values))])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = values / others
    ratios[~np.isfinite(ratios) | (ratios == 0)] = np.nan
    return ratios


def save_demos(
    demos: Any, path: str | os.PathLike, state_key: str | Sequence[str] | None = None
) -> None:
    """Write demonstrations to an uncompressed ``.npz`` file (exact round trip).

    Demonstration ``i`` is stored under ``obs_i`` and, when present, ``acts_i``, ``rews_i``,
    ``keys_i`` (its ``state_key``) and ``trunc_i`` (when ``truncated``), so ragged lengths
    need no padding.

    Parameters
    ----------
    demos : anything :func:`as_demonstrations` accepts
    path : str or path-like
    state_key : str or sequence of str, optional
        For demos with dict observations: the keys whose values are joined into each state,
        in this order (recorded with them), as in :func:`as_demonstrations`.

    Raises
    ------
    TypeError
        If the arguments look swapped (a path first, then the demos).
    """
    if isinstance(demos, str | os.PathLike) and not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"save_demos(demos, path) takes the demos first; got the path {os.fspath(demos)!r} "
            f"first and a {type(path).__name__} second"
        )
    demos = _as_demonstrations(demos, None, state_key, minimum=1)
    arrays: dict[str, np.ndarray] = {
        "format": np.array(_NPZ_FORMAT),
        "n_demos": np.array(len(demos)),
    }
    for i, demo in enumerate(demos):
        arrays[f"obs_{i}"] = demo.observations
        if demo.actions is not None:
            arrays[f"acts_{i}"] = demo.actions
        if demo.rewards is not None:
            arrays[f"rews_{i}"] = demo.rewards
        if demo.state_key is not None:
            arrays[f"keys_{i}"] = np.array(demo.state_key)
        if demo.truncated:
            arrays[f"trunc_{i}"] = np.array(True)
    with atomic_write(path, "wb") as fh:  # a failure leaves the previous file
        np.savez(fh, **arrays)


def load_demos(path: str | os.PathLike) -> list[Demonstration]:
    """Read demonstrations written by :func:`save_demos`, validated as by :func:`as_demonstrations`.

    Parameters
    ----------
    path : str or path-like
        A ``.npz`` file written by :func:`save_demos` (or ``sb3-swirl demos``).

    Returns
    -------
    list of Demonstration
        In the order they were saved, bit for bit as saved.

    Raises
    ------
    ValueError
        If the file cannot be read, is not an sb3-swirl demonstration file of this format
        version, or holds invalid demonstrations (the message names the file and the demo).
    """
    name = os.fspath(path)
    try:
        # np.load takes anything that is neither an archive nor an array for a pickle, and
        # says so: look at the magic bytes first to say what the file is not.
        with open(path, "rb") as fh:
            if not fh.read(6).startswith(_NUMPY_MAGIC):
                raise ValueError("not a NumPy .npz archive (save_demos writes one)")
        loaded = np.load(path, allow_pickle=False)
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as exc:
        hint = ""
        if isinstance(exc, EOFError | zipfile.BadZipFile):
            hint = " (a truncated or damaged file?)"
        elif isinstance(exc, FileNotFoundError) and not os.path.splitext(name)[1]:
            hint = (
                " (a Minari dataset id? In Python pass minari.load_dataset(id) instead of its "
                "id; files on the command line are .npz files that save_demos writes)"
            )
        raise ValueError(f"cannot read demonstrations from {name}: {exc}{hint}") from exc
    if not isinstance(loaded, np.lib.npyio.NpzFile):
        raise ValueError(
            f"{name} holds a single array, not an sb3-swirl demonstration file (an .npz "
            "archive written by save_demos)"
        )
    with loaded as npz:

        def read(key: str) -> np.ndarray:
            try:
                _check_array_size(npz.zip, key)
                return npz[key]
            except (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error) as exc:
                raise ValueError(f"{name}: cannot read {key} (corrupted?): {exc}") from exc

        files = set(npz.files)
        if "n_demos" not in files or "obs_0" not in files:
            raise ValueError(
                f"{name} is not an sb3-swirl demonstration file "
                "(expected keys format, n_demos, obs_0, obs_1, ...; write one with save_demos)"
            )
        version = str(read("format")) if "format" in files else None
        if version != _NPZ_FORMAT:
            raise ValueError(
                f"{name}: unsupported demonstration file format {version!r}; this sb3-swirl "
                f"reads {_NPZ_FORMAT!r}"
            )
        n_demos = read("n_demos")
        if n_demos.shape != () or n_demos.dtype.kind not in "iu" or int(n_demos) < 0:
            raise ValueError(f"{name}: n_demos must be one integer >= 0, got {n_demos!r}")
        n = int(n_demos)
        n_obs = sum(key.startswith("obs_") for key in files)
        if n > n_obs:  # checked before anything proportional to n is built
            raise ValueError(
                f"{name}: n_demos={n} but the file holds {n_obs} demos (obs_0, obs_1, ...): "
                "a damaged or hand-edited file?"
            )
        expected = {"format", "n_demos"} | {
            f"{field}_{i}" for i in range(n) for field in ("obs", "acts", "rews", "keys", "trunc")
        }
        if files - expected:
            raise ValueError(
                f"{name}: unexpected keys {sorted(files - expected)} for n_demos={n} "
                "(a damaged or hand-edited file?)"
            )
        demos = []
        for i in range(n):
            if f"obs_{i}" not in files:
                raise ValueError(f"{name}: demo {i} (key obs_{i}) is missing")
            demos.append(
                {
                    "observations": read(f"obs_{i}"),
                    "actions": read(f"acts_{i}") if f"acts_{i}" in files else None,
                    "rewards": read(f"rews_{i}") if f"rews_{i}" in files else None,
                    "state_key": [str(k) for k in np.atleast_1d(read(f"keys_{i}")).tolist()]
                    if f"keys_{i}" in files
                    else None,
                    "truncated": read(f"trunc_{i}") if f"trunc_{i}" in files else False,
                }
            )
    try:
        return _as_demonstrations(demos, None, None, minimum=1)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from exc


def _check_array_size(archive: zipfile.ZipFile, key: str) -> None:
    """Raise unless the array ``key`` of an .npz archive holds the data its header claims.

    Read before numpy allocates the array: a header claiming a huge shape would otherwise
    end in a ``MemoryError``. The member's own sizes are bounded by the archive's (no member is
    larger than the file, and deflate expands at most about 1032 times).
    """
    info = archive.getinfo(f"{key}.npy")
    archive_size = archive.fp.seek(0, os.SEEK_END) if archive.fp is not None else info.file_size
    if info.compress_size > archive_size or info.file_size > 1100 * info.compress_size:
        raise ValueError(
            f"its sizes in the archive's directory ({info.compress_size} bytes stored, "
            f"{info.file_size} unpacked) are impossible for a {archive_size}-byte file"
        )
    with archive.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
        claimed = math.prod(shape) * dtype.itemsize
        held = info.file_size - fh.tell()
    if claimed > held:
        raise ValueError(
            f"its header claims shape {shape} of {dtype} ({claimed} bytes) but the archive "
            f"holds {held} bytes"
        )


def to_imitation(demos: Any) -> list[Any]:
    """Export demonstrations as ``imitation`` trajectories.

    Each demonstration becomes a ``TrajectoryWithRew`` when it has rewards, else a
    ``Trajectory``; ``terminal`` is ``not demo.truncated``.

    Parameters
    ----------
    demos : anything :func:`as_demonstrations` accepts
        With actions.

    Returns
    -------
    list of imitation.data.types.Trajectory
        One per demonstration (``TrajectoryWithRew`` where it has rewards).

    Raises
    ------
    ValueError
        If a demonstration has no actions (imitation trajectories need them).
    ImportError
        If imitation is not installed.
    """
    from imitation.data.types import Trajectory, TrajectoryWithRew

    out = []
    for i, demo in enumerate(_as_demonstrations(demos, None, None, minimum=1)):
        if demo.actions is None:
            raise ValueError(f"demo {i} has no actions; imitation trajectories need actions")
        terminal = not demo.truncated
        if demo.rewards is None:
            out.append(Trajectory(demo.observations, demo.actions, infos=None, terminal=terminal))
        else:
            out.append(
                TrajectoryWithRew(
                    demo.observations, demo.actions, None, terminal, rews=demo.rewards
                )
            )
    return out


def to_minari(demos: Any, dataset_id: str, env: Any = None, **kwargs: Any) -> Any:
    """Write demonstrations as a local Minari dataset (``minari.create_dataset_from_buffers``).

    Each demonstration becomes one episode that ends on its last step, in a truncation where
    the demo is ``truncated``, else in a termination. Missing rewards are written as zeros.

    Parameters
    ----------
    demos : anything :func:`as_demonstrations` accepts
        Every demonstration needs actions.
    dataset_id : str
        Minari dataset id, e.g. ``"swirl/parking/expert-v0"``.
    env : str, gymnasium.Env or EnvSpec, optional
        The environment the demonstrations come from; without it pass ``observation_space``
        and ``action_space`` in ``kwargs``.
    **kwargs
        Passed on to ``minari.create_dataset_from_buffers`` (e.g. ``author``,
        ``algorithm_name``); ``data_format`` defaults to ``"hdf5"``, which needs no jax.

    Returns
    -------
    minari.MinariDataset
    """
    try:
        import minari  # noqa: F401
    except ImportError as exc:
        raise ImportError('to_minari needs Minari: pip install "sb3-swirl[minari]"') from exc

    demos = _as_demonstrations(demos, None, None, minimum=1)
    for i, demo in enumerate(demos):
        if demo.actions is None:
            raise ValueError(f"demo {i} has no actions; Minari episodes need actions")
    made = gym.make(env) if isinstance(env, str | gym.envs.registration.EnvSpec) else env
    try:  # made once: Minari reads the spec and spaces of the env it is given
        return _write_minari(demos, dataset_id, made, kwargs)
    finally:
        if made is not env:
            made.close()


def _write_minari(demos: list[Demonstration], dataset_id: str, env: Any, kwargs: dict) -> Any:
    """:func:`to_minari` once ``env`` is made (or ``None``)."""
    import minari
    from minari.data_collector import EpisodeBuffer

    obs_space = kwargs.get("observation_space", getattr(env, "observation_space", None))
    act_space = kwargs.get("action_space", getattr(env, "action_space", None))
    if obs_space is None or act_space is None:
        raise ValueError("to_minari needs env=, or observation_space= and action_space=")
    keys = tuple(obs_space.spaces) if isinstance(obs_space, spaces.Dict) else None
    joined = obs_space if keys is None else state_space(obs_space, keys)[0]
    state_dim = int(np.prod(joined.shape))
    if keys is not None:  # Minari stores the env's whole observation, each key in its space
        for i, demo in enumerate(demos):
            if demo.state_key is None or set(demo.state_key) != set(keys):
                raise ValueError(
                    f"demo {i} joins the keys {demo.state_key} but the env's Dict observation "
                    f"has {list(keys)}: Minari stores them all, so record the demos with "
                    f"state_key={list(keys)}"
                )
    check_demos_fit_spaces(demos, state_dim, act_space, "demo", "the env's observations")
    buffers = []
    for i, demo in enumerate(demos):
        n_steps = len(demo)
        rewards = np.zeros(n_steps) if demo.rewards is None else demo.rewards
        ends = np.arange(n_steps) == n_steps - 1
        buffers.append(
            EpisodeBuffer(
                id=i,
                observations=_in_space(demo.observations, obs_space, demo.state_key),
                actions=_in_space(demo.actions, act_space, None),
                rewards=list(rewards),
                terminations=list(ends & (not demo.truncated)),
                truncations=list(ends & demo.truncated),
            )
        )
    kwargs.setdefault("data_format", "hdf5")
    return minari.create_dataset_from_buffers(dataset_id, buffers, env=env, **kwargs)


def _in_space(values: np.ndarray, space: spaces.Space, state_key: tuple[str, ...] | None) -> Any:
    """A demo's rows as ``space`` holds them: its dtype and shape, a ``Dict`` split back into
    its keys (joined in ``state_key``'s order)."""
    if isinstance(space, spaces.Dict):
        parts, start = {}, 0
        for key in state_key or ():
            width = int(np.prod(space[key].shape or ()))
            parts[key] = _in_space(values[:, start : start + width], space[key], None)
            start += width
        return {key: parts[key] for key in space.spaces}
    shape = getattr(space, "shape", None) or ()
    return np.asarray(values).reshape(len(values), *shape).astype(space.dtype)


def make_piecewise_linear_demos(
    n_demos: int = 10,
    n_phases: int = 3,
    dim: int = 2,
    phase_length: int | tuple[int, int] = (25, 40),
    noise: float = 0.05,
    speed: float = 1.0,
    random_state: int | np.random.Generator | None = None,
) -> tuple[list[Demonstration], list[np.ndarray]]:
    """Synthetic demonstrations with known switch points (a toy for tests and benchmarks).

    Every demonstration starts at the origin and moves along the same ``n_phases`` straight
    lines (consecutive directions at least 60 degrees apart; line ``i`` is ``1 + i / 2`` times
    ``speed`` times the mean phase length long), so the corners -- the true transition
    states -- are shared. Each demonstration takes its own number of steps per phase (its own
    speed), so lengths are ragged; Gaussian observation noise is added to every state.

    Parameters
    ----------
    n_demos, n_phases, dim : int
    phase_length : int or (low, high)
        Steps per phase, drawn uniformly from ``[low, high]`` per demonstration and phase.
    noise : float
        Standard deviation of the observation noise.
    speed : float
        Distance travelled per step at the mean phase length.
    random_state : int or numpy Generator, optional

    Returns
    -------
    demos : list of Demonstration
    switches : list of int arrays
        For each demonstration, the ``n_phases - 1`` steps at which the direction changes.
    """
    rng = np.random.default_rng(random_state)
    lo, hi = (phase_length, phase_length) if np.isscalar(phase_length) else phase_length
    directions = [rng.normal(size=dim)]
    while len(directions) < n_phases:
        cand = rng.normal(size=dim)
        if dim == 1:
            cand = -np.sign(directions[-1])
        cos = cand @ directions[-1] / (np.linalg.norm(cand) * np.linalg.norm(directions[-1]))
        if dim == 1 or cos < math.cos(math.radians(60)):
            directions.append(cand)
    directions = [d / np.linalg.norm(d) for d in directions]
    demos, switches = [], []
    for _ in range(n_demos):
        lengths = rng.integers(lo, hi + 1, size=n_phases)
        distance = speed * (lo + hi) / 2 * (1 + 0.5 * np.arange(n_phases))
        steps = np.concatenate(
            [
                np.tile(dist / n * d, (n, 1))
                for d, n, dist in zip(directions, lengths, distance, strict=True)
            ]
        )
        path = np.vstack([np.zeros(dim), np.cumsum(steps, axis=0)])
        obs = path + rng.normal(scale=noise, size=path.shape)
        demos.append(Demonstration(obs))
        switches.append(np.cumsum(lengths)[:-1])
    return demos, switches
