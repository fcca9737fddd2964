"""The proxy task learned by SWIRL: ordered transition regions and one quadratic reward per segment.

A :class:`TaskModel` is plain data. It holds no learning code, serialises to versioned JSON, and
exposes pure, vectorised functions of a state:

* :meth:`TaskModel.next_segment` -- the Markov segmentation function ``i_{t+1} = M(s_t, i_t)``
  of the paper (§5.2): the index advances when the state enters the *next* region in order;
* :meth:`TaskModel.reward` -- the local reward ``R_i(s) = -(x - mu_i)^T Psi_i (x - mu_i)``.

Segment ``i`` (``0 <= i < k``) leads to region ``i``; reaching region ``k - 1`` sets the index to
``k``, which means "every region reached". The lifted observation therefore has ``k + 1`` one-hot
entries (:attr:`TaskModel.n_indices`).

States are mapped into *task space* before regions and rewards are evaluated: first the observation
dimensions in ``dims`` are selected, optionally preceded by ``(cos, sin)`` of ``angles`` (sums of
observation entries, e.g. the absolute link angles of a kinematic chain), then (optionally) an RBF
feature map is applied.

A task also carries the :class:`RewardConfig` the wrappers use by default: how a segment's reward
becomes the agent's reward.

:meth:`TaskModel.evaluate` is the one place where rewards and region membership are computed at
run time (every wrapper, and :meth:`TaskModel.segment_indices` offline). It makes the same BLAS
calls for one state as for each row of a batch, so a state gets bit-for-bit the same reward and
region membership alone (``SwirlWrapper``) as in any vector of sub-environments, and a demo is
segmented offline exactly as the wrappers segment it when it is replayed.
"""

from __future__ import annotations

import json
import math
import numbers
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swirl_wrappers._io import atomic_write
from swirl_wrappers._validation import check_option, check_real

#: Version written by :meth:`TaskModel.to_json`; version 1 files (no reward settings) still load.
SCHEMA_VERSION = 2
REWARD_MODES = ("quadratic", "potential")
# Numbers in a task stay within this bound, so that the product of two of them stays finite.
_LIMIT = 1e100


def _quadratic(factor: np.ndarray, centre: np.ndarray, x: np.ndarray) -> Any:
    """``||factor (x - centre)||^2`` for states ``x`` of shape (p,) or (n, p)."""
    z = (np.asarray(x, dtype=np.float64) - centre) @ factor.T
    return np.einsum("...i,...i->...", z, z)


def _rowwise(matrix: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``matrix @ x`` for one vector ``x`` (p,), or for each row of ``x`` (n, p) with ``matrix``
    of shape (m, p) or one (n, m, p) per row: per row the same BLAS matrix-vector product."""
    if x.ndim == 1:
        return matrix.dot(x)
    return np.matmul(matrix, x[..., None])[..., 0]


def _check_keys(data: Any, name: str, required: tuple[str, ...], optional: tuple[str, ...] = ()):
    """Raise unless ``data`` is a JSON object with the required keys and no others."""
    if not isinstance(data, Mapping):
        raise ValueError(f"{name} must be a JSON object, got {type(data).__name__}")
    missing = [key for key in required if key not in data]
    if missing:
        raise ValueError(f"{name} is missing {', '.join(map(repr, missing))}")
    unknown = sorted(set(data) - set(required) - set(optional))
    if unknown:
        raise ValueError(
            f"{name} has unknown key(s) {', '.join(map(repr, unknown))}; expected "
            f"{', '.join(map(repr, required + optional))}"
        )


def _as_float_array(value: Any, name: str, ndim: int) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    # Not bools or strings: float() would take true or "1.5" (a hand-edited file) silently.
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be real numbers, got {value!r}")
    arr = arr.astype(np.float64, copy=False)
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    if arr.size and np.abs(arr).max() > _LIMIT:
        raise ValueError(
            f"{name} holds {np.abs(arr).max():.3g}, beyond ±{_LIMIT:g}: such values overflow "
            "the quadratic forms; rescale the task"
        )
    return arr


def _as_float(value: Any, name: str, *, positive: bool = False) -> float:
    return check_real(name, value, low=0.0 if positive else -_LIMIT, high=_LIMIT, low_open=positive)


def _as_indices(value: Any, name: str) -> tuple[int, ...]:
    """A sequence of non-negative ints (not bools, not a string)."""
    if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__iter__"):
        raise ValueError(f"{name} must be a sequence of ints, got {value!r}")
    out = []
    for item in value:
        if isinstance(item, bool | np.bool_) or not isinstance(item, numbers.Integral):
            raise ValueError(f"{name} must be a sequence of ints, got {value!r}")
        if item < 0:
            raise ValueError(f"{name} must be non-negative indices, got {value!r}")
        if item >= 2**31:  # numpy's indexing would overflow
            raise ValueError(f"{name} holds the index {item}, beyond any observation's size")
        out.append(int(item))
    return tuple(out)


def check_angles(angles: Any) -> tuple[tuple[int, ...], ...] | None:
    """Validate ``TaskModel.angles``: ``None`` or non-empty sequences of non-negative ints."""
    if angles is None:
        return None
    if isinstance(angles, str | bytes | Mapping) or not hasattr(angles, "__iter__"):
        raise ValueError(
            f"TaskModel.angles must be a sequence of sequences of ints, got {angles!r}"
        )
    try:
        out = tuple(_as_indices(angle, "TaskModel.angles") for angle in angles)
    except ValueError as exc:
        raise ValueError(
            f"TaskModel.angles must be a sequence of sequences of ints (non-negative observation "
            f"indices), got {angles!r}"
        ) from exc
    if not out or not all(out):
        raise ValueError(
            "TaskModel.angles must hold at least one angle, each a non-empty sequence of "
            f"observation indices, got {angles!r}"
        )
    return out


def _angle_features(obs: np.ndarray, angles: tuple[tuple[int, ...], ...]) -> np.ndarray:
    phi = np.stack([obs[..., list(angle)].sum(axis=-1) for angle in angles], axis=-1)
    return np.stack([np.cos(phi), np.sin(phi)], axis=-1).reshape(*phi.shape[:-1], -1)


def angle_features(obs: np.ndarray, angles: Any) -> np.ndarray:
    """The angle features of :attr:`TaskModel.angles` for observations of shape (..., obs_dim).

    Returns ``(cos phi_1, sin phi_1, ..., cos phi_m, sin phi_m)`` with ``phi_j`` the sum of the
    observation entries listed in ``angles[j]``; learning code uses it to build the states a
    task with ``angles`` is fitted on.

    Examples
    --------
    >>> import numpy as np
    >>> angle_features(np.array([np.pi / 2, np.pi / 2, 5.0]), [[0], [0, 1]]).round(6) + 0.0
    array([ 0.,  1., -1.,  0.])
    """
    x = np.asarray(obs, dtype=np.float64)
    checked = check_angles(angles)
    if checked is None:
        raise ValueError("angles must not be None")
    used = max(i for angle in checked for i in angle)
    if x.shape[-1] <= used:
        raise ValueError(f"observation has {x.shape[-1]} dims but angles use index {used}")
    return _angle_features(x, checked)


@dataclass(frozen=True)
class RewardConfig:
    """How the wrappers turn the segment rewards into the agent's reward.

    ``R_i(s')`` is the local reward of the segment ``i`` in force *before* the step, ``r`` the
    environment's own reward and ``entered`` 1 on the step that reaches region ``i``:

    * ``mode="quadratic"`` (the paper's proxy reward):
      ``scale * R_i(s') + region_bonus * entered + task_reward_weight * r``;
    * ``mode="potential"`` (potential-based shaping of the environment's reward, Ng et al. 1999):
      ``task_reward_weight * r + scale * (gamma * Phi(s', i') - Phi(s, i)) + region_bonus *
      entered``, with the progress potential ``Phi(s, i) = i + 1 / (1 - R_i(s))`` (segments done
      plus closeness to the next region) and ``Phi = 0`` after a termination. The shaping
      telescopes over an episode, so with ``region_bonus = 0`` and ``gamma`` equal to the
      agent's discount the optimal policies are the true task's.

    Parameters
    ----------
    mode : {"quadratic", "potential"}
    scale : float
        Weight (>= 0) of the segment reward or of the shaping term.
    region_bonus : float
        Added (>= 0) on the step that reaches the next region.
    task_reward_weight : float, optional
        Weight (>= 0) of the environment's own reward; default 0 for ``"quadratic"`` and 1 for
        ``"potential"`` (where it must be > 0: shaping alone leaves every policy equal).
    gamma : float
        Discount of the shaping term, in [0, 1]; set it to the agent's.

    Examples
    --------
    >>> RewardConfig(mode="potential", task_reward_weight=10.0)
    RewardConfig(mode='potential', scale=1.0, region_bonus=0.0, task_reward_weight=10.0, gamma=0.99)
    >>> RewardConfig.from_dict({"region_bonus": 1}).region_bonus
    1.0
    """

    mode: str = "quadratic"
    scale: float = 1.0
    region_bonus: float = 0.0
    task_reward_weight: float | None = None
    gamma: float = 0.99

    def __post_init__(self) -> None:
        check_option("reward_config mode", self.mode, REWARD_MODES)
        weight = self.task_reward_weight
        if weight is None:
            weight = 1.0 if self.mode == "potential" else 0.0
        settings = {
            "scale": check_real("reward scale", self.scale, low=0.0),
            "region_bonus": check_real("region_bonus", self.region_bonus, low=0.0),
            "task_reward_weight": check_real("task_reward_weight", weight, low=0.0),
            "gamma": check_real("gamma", self.gamma, low=0.0, high=1.0),
        }
        if self.mode == "potential" and settings["task_reward_weight"] == 0.0:
            raise ValueError(
                "mode='potential' shapes the environment's own reward and needs "
                "task_reward_weight > 0 (shaping alone leaves every policy equal)"
            )
        for name, value in settings.items():
            object.__setattr__(self, name, value)

    @property
    def potential(self) -> bool:
        """Whether the reward is potential-based shaping (``mode="potential"``)."""
        return self.mode == "potential"

    def discount_mismatch(self, gamma: float, agent: str) -> str | None:
        """Why the shaping is not policy-invariant for an agent that discounts with ``gamma``
        (``None`` when it is, or when the reward is not potential-based shaping)."""
        if not self.potential or gamma == self.gamma:
            return None
        return (
            f"the SWIRL wrapper shapes with gamma={self.gamma} but {agent} discounts with "
            f"gamma={gamma}: the potential shaping is policy-invariant only when they are equal "
            f"(reward_config={{'gamma': {gamma}}} on the wrapper makes them so)"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "scale": self.scale,
            "region_bonus": self.region_bonus,
            "task_reward_weight": self.task_reward_weight,
            "gamma": self.gamma,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RewardConfig:
        """Build from a mapping of its fields (a JSON object or a YAML entry); unknown keys are
        errors that name them."""
        _check_keys(data, "reward_config", (), tuple(cls().to_dict()))
        return cls(**data)

    def updated(self, value: RewardConfig | Mapping[str, Any] | None) -> RewardConfig:
        """These settings with ``value`` applied, as the wrappers apply theirs to the task's.

        ``None`` keeps them, a RewardConfig replaces them, and a mapping changes only the
        fields it names: ``{"gamma": 0.9}`` keeps the mode and weights. A new ``mode`` without
        a ``task_reward_weight`` takes that mode's default weight.

        Examples
        --------
        >>> shaped = RewardConfig(mode="potential", task_reward_weight=10.0)
        >>> shaped.updated({"gamma": 0.9}).gamma, shaped.updated({"gamma": 0.9}).mode
        (0.9, 'potential')
        >>> shaped.updated({"mode": "quadratic"}).task_reward_weight
        0.0
        """
        if value is None or isinstance(value, RewardConfig):
            return self if value is None else value
        if not isinstance(value, Mapping):
            raise ValueError(
                f"reward_config must be a RewardConfig or a dict of its fields, got {value!r}"
            )
        fields = self.to_dict()
        if value.get("mode", self.mode) != self.mode and "task_reward_weight" not in value:
            del fields["task_reward_weight"]
        return RewardConfig.from_dict({**fields, **value})

    @classmethod
    def coerce(cls, value: RewardConfig | Mapping[str, Any]) -> RewardConfig:
        """``value`` if it is a RewardConfig, else one built from a mapping of its fields."""
        if isinstance(value, RewardConfig):
            return value
        if isinstance(value, Mapping):
            return cls.from_dict(value)
        raise ValueError(
            f"reward_config must be a RewardConfig or a dict of its fields, got {value!r}"
        )


@dataclass(frozen=True, eq=False)
class Region:
    """An ellipsoidal transition region in task space, optionally limited to a time window.

    A point ``x`` at time ``t`` is inside when ``(x - mean)^T covariance^{-1} (x - mean) <=
    threshold`` and, if ``time_bounds`` is set, ``time_bounds[0] <= t <= time_bounds[1]``.

    Parameters
    ----------
    mean : array of shape (p,)
        Centre of the ellipsoid.
    covariance : array of shape (p, p)
        Symmetric positive-definite shape matrix.
    threshold : float
        Squared Mahalanobis radius (a chi-square quantile chosen at fit time).
    time_bounds : tuple of float, optional
        Inclusive window of time steps in which the region counts as reached.

    Attributes
    ----------
    whitening : array of shape (p, p)
        ``L^{-1}`` for the Cholesky factor ``L`` of the covariance: the squared Mahalanobis
        distance is ``||whitening (x - mean)||^2``.
    precision : array of shape (p, p)
        The inverse covariance, ``whitening^T whitening``.
    """

    mean: np.ndarray
    covariance: np.ndarray
    threshold: float
    time_bounds: tuple[float, float] | None = None
    whitening: np.ndarray = field(init=False, repr=False)
    precision: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mean = _as_float_array(self.mean, "Region.mean", 1)
        cov = _as_float_array(self.covariance, "Region.covariance", 2)
        if cov.shape != (mean.size, mean.size):
            raise ValueError(
                f"Region.covariance must have shape {(mean.size, mean.size)} to match "
                f"Region.mean ({mean.size} entries), got {cov.shape}"
            )
        if not np.allclose(cov, cov.T):
            raise ValueError("Region.covariance must be symmetric")
        try:
            whitening = np.linalg.inv(np.linalg.cholesky(cov))
        except np.linalg.LinAlgError as exc:
            raise ValueError("Region.covariance must be positive definite") from exc
        if not np.abs(whitening).max() <= _LIMIT:
            raise ValueError("Region.covariance is numerically singular")
        threshold = _as_float(self.threshold, "Region.threshold", positive=True)
        bounds = self.time_bounds
        if bounds is not None:
            if isinstance(bounds, str | bytes | Mapping) or len(bounds) != 2:
                raise ValueError(f"Region.time_bounds must be a pair of numbers, got {bounds!r}")
            lo, hi = (check_real("Region.time_bounds", b, low=-math.inf) for b in bounds)
            if not lo <= hi:
                raise ValueError(f"Region.time_bounds must be (lo, hi) with lo <= hi, got {bounds}")
            bounds = (lo, hi)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "threshold", threshold)
        object.__setattr__(self, "time_bounds", bounds)
        object.__setattr__(self, "whitening", whitening)
        object.__setattr__(self, "precision", whitening.T @ whitening)

    def mahalanobis2(self, x: np.ndarray) -> Any:
        """Squared Mahalanobis distance of ``x`` (shape (p,) or (n, p)) to the centre."""
        return _quadratic(self.whitening, self.mean, x)

    def contains(self, x: np.ndarray, t: np.ndarray | float | None = None) -> Any:
        """Whether ``x`` (shape (p,) or (n, p)) at time ``t`` lies in the region (``t`` None:
        whatever the time)."""
        inside = self.mahalanobis2(x) <= self.threshold
        if self.time_bounds is not None and t is not None:
            t = np.asarray(t, dtype=np.float64)
            inside = inside & (t >= self.time_bounds[0]) & (t <= self.time_bounds[1])
        return inside

    def to_dict(self) -> dict[str, Any]:
        return {
            "mean": self.mean.tolist(),
            "covariance": self.covariance.tolist(),
            "threshold": self.threshold,
            "time_bounds": None if self.time_bounds is None else list(self.time_bounds),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Region:
        _check_keys(data, "region", ("mean", "covariance", "threshold"), ("time_bounds",))
        return cls(data["mean"], data["covariance"], data["threshold"], data.get("time_bounds"))


@dataclass(frozen=True, eq=False)
class QuadraticReward:
    """A local reward ``R(x) = -(x - target)^T weight (x - target)``.

    Parameters
    ----------
    target : array of shape (p,)
        The centroid ``mu_i`` of the region this segment leads to.
    weight : array of shape (p, p)
        Symmetric positive semi-definite matrix ``Psi_i``.

    Attributes
    ----------
    factor : array of shape (p, p)
        A square root of ``weight`` (``factor^T factor = weight``): ``R(x) = -||factor (x -
        target)||^2``.
    """

    target: np.ndarray
    weight: np.ndarray
    factor: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        target = _as_float_array(self.target, "QuadraticReward.target", 1)
        weight = _as_float_array(self.weight, "QuadraticReward.weight", 2)
        if weight.shape != (target.size, target.size):
            raise ValueError(
                f"QuadraticReward.weight must have shape {(target.size, target.size)} to match "
                f"QuadraticReward.target ({target.size} entries), got {weight.shape}"
            )
        if not np.allclose(weight, weight.T):
            raise ValueError("QuadraticReward.weight must be symmetric")
        eigval, eigvec = np.linalg.eigh(weight)
        if eigval.min() < -1e-9 * max(1.0, np.abs(weight).max()):
            raise ValueError("QuadraticReward.weight must be positive semi-definite")
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "weight", weight)
        object.__setattr__(self, "factor", np.sqrt(eigval.clip(0.0))[:, None] * eigvec.T)

    def __call__(self, x: np.ndarray) -> Any:
        return -_quadratic(self.factor, self.target, x)

    def to_dict(self) -> dict[str, Any]:
        return {"target": self.target.tolist(), "weight": self.weight.tolist()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> QuadraticReward:
        _check_keys(data, "reward", ("target", "weight"))
        return cls(target=data["target"], weight=data["weight"])


@dataclass(frozen=True, eq=False)
class RBFFeatures:
    """An explicit RBF feature map ``phi(s) = exp(-gamma ||s - c_j||^2) @ projection - offset``.

    This is the runtime half of an approximate (Nyström) kernel PCA: the landmarks ``c_j`` and
    the projection are learned at fit time; evaluating the map needs only numpy.

    Parameters
    ----------
    landmarks : array of shape (m, d)
    gamma : float
        ``1 / (2 sigma^2)``.
    projection : array of shape (m, p)
    offset : array of shape (p,), optional
        Subtracted after projection (the feature mean), default zeros.
    """

    landmarks: np.ndarray
    gamma: float
    projection: np.ndarray
    offset: np.ndarray | None = None

    def __post_init__(self) -> None:
        landmarks = _as_float_array(self.landmarks, "RBFFeatures.landmarks", 2)
        projection = _as_float_array(self.projection, "RBFFeatures.projection", 2)
        if projection.shape[0] != landmarks.shape[0]:
            raise ValueError(
                "RBFFeatures.projection must have one row per landmark "
                f"({landmarks.shape[0]}), got {projection.shape[0]}"
            )
        offset = (
            np.zeros(projection.shape[1])
            if self.offset is None
            else _as_float_array(self.offset, "RBFFeatures.offset", 1)
        )
        if offset.shape != (projection.shape[1],):
            raise ValueError(f"RBFFeatures.offset must have shape ({projection.shape[1]},)")
        gamma = _as_float(self.gamma, "RBFFeatures.gamma", positive=True)
        object.__setattr__(self, "landmarks", landmarks)
        object.__setattr__(self, "projection", projection)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "gamma", gamma)
        object.__setattr__(self, "_projection_t", np.ascontiguousarray(projection.T))

    @property
    def input_dim(self) -> int:
        return self.landmarks.shape[1]

    @property
    def output_dim(self) -> int:
        return self.projection.shape[1]

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=np.float64)
        phi = np.exp(-self.gamma * np.sum((s[..., None, :] - self.landmarks) ** 2, axis=-1))
        return _rowwise(self._projection_t, phi) - self.offset

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "rbf",
            "landmarks": self.landmarks.tolist(),
            "gamma": self.gamma,
            "projection": self.projection.tolist(),
            "offset": self.offset.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RBFFeatures:
        if isinstance(data, Mapping) and data.get("type") != "rbf":
            raise ValueError(f"unknown feature map type {data.get('type')!r}")
        _check_keys(data, "features", ("type", "landmarks", "gamma", "projection"), ("offset",))
        return cls(data["landmarks"], data["gamma"], data["projection"], data.get("offset"))


@dataclass(frozen=True, eq=False)
class TaskModel:
    """A SWIRL proxy task: ``k`` ordered regions and one local reward per segment.

    Parameters
    ----------
    regions : sequence of Region
        The transition regions ``rho_1 .. rho_k`` in the order they must be reached.
    rewards : sequence of QuadraticReward
        ``rewards[i]`` is the reward of segment ``i``, which leads to ``regions[i]``.
    dims : sequence of int, optional
        Indices of the (flat) observation that form the state; ``None`` uses all of it.
    features : RBFFeatures, optional
        Feature map applied to the selected state before regions and rewards.
    metadata : dict, optional
        JSON-serialisable free-form information (how the task was fitted).
    angles : sequence of sequences of int, optional
        Angle features for observations holding wrapped angles, where a region straddling
        ``±pi`` would be meaningless: entry ``j`` defines the angle ``phi_j = sum(obs[i] for
        i in angles[j])`` and contributes ``(cos phi_j, sin phi_j)``. The state is then
        ``(cos phi_1, sin phi_1, ..., cos phi_m, sin phi_m, obs[dims])``; ``dims`` must be
        given (it may be empty) and lists only the pass-through entries. Sums turn the relative
        joint angles of a chain into absolute link angles, in which link positions are linear
        (the acrobot's tip height is ``-cos(theta1) - cos(theta1 + theta2)``:
        ``angles=[[0], [0, 1]]``).
    reward_config : RewardConfig or dict, optional
        How the wrappers reward the agent with this task unless they are given other settings
        (default ``RewardConfig()``: the paper's quadratic segment reward).

    Examples
    --------
    >>> import numpy as np
    >>> from swirl_wrappers import QuadraticReward, Region, TaskModel
    >>> task = TaskModel(
    ...     regions=[Region(mean=[1.0, 0.0], covariance=np.eye(2) * 0.01, threshold=9.0)],
    ...     rewards=[QuadraticReward(target=[1.0, 0.0], weight=np.eye(2))],
    ... )
    >>> task.n_segments, task.n_indices
    (1, 2)
    >>> int(task.next_segment(np.array([1.0, 0.05]), t=3, index=0))
    1
    >>> float(task.reward(np.array([0.0, 0.0]), index=0))
    -1.0
    """

    regions: tuple[Region, ...]
    rewards: tuple[QuadraticReward, ...]
    dims: tuple[int, ...] | None = None
    features: RBFFeatures | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    angles: tuple[tuple[int, ...], ...] | None = None
    reward_config: RewardConfig = field(default_factory=RewardConfig)

    def __post_init__(self) -> None:
        regions = tuple(self.regions)
        rewards = tuple(self.rewards)
        if not regions:
            raise ValueError("TaskModel needs at least one region")
        if len(rewards) != len(regions):
            raise ValueError(
                f"TaskModel needs one reward per region: {len(regions)} regions, "
                f"{len(rewards)} rewards"
            )
        for name, items, cls in (
            ("regions", regions, Region),
            ("rewards", rewards, QuadraticReward),
        ):
            for i, item in enumerate(items):
                if not isinstance(item, cls):
                    raise ValueError(
                        f"{name}[{i}] is a {type(item).__name__}, expected {cls.__name__}"
                    )
        if self.features is not None and not isinstance(self.features, RBFFeatures):
            raise ValueError(
                f"features is a {type(self.features).__name__}, expected RBFFeatures or None"
            )
        p = regions[0].mean.size
        for i, (reg, rew) in enumerate(zip(regions, rewards, strict=True)):
            if reg.mean.size != p or rew.target.size != p:
                raise ValueError(
                    f"segment {i}: region/reward dimension differs from task-space dimension {p}"
                )
        dims = None if self.dims is None else _as_indices(self.dims, "TaskModel.dims")
        if dims is not None and len(set(dims)) < len(dims):
            twice = sorted({d for d in dims if dims.count(d) > 1})
            raise ValueError(f"TaskModel.dims lists {twice} more than once: {list(dims)}")
        angles = check_angles(self.angles)
        if angles is not None and dims is None:
            raise ValueError(
                "TaskModel.dims must be given with angles: it lists the observation entries "
                "passed through besides the angle features (use () for none)"
            )
        if dims == () and angles is None:
            raise ValueError("TaskModel.dims must select at least one observation entry")
        state_dim = None if dims is None else len(dims) + 2 * len(angles or ())
        if self.features is not None:
            if state_dim is not None and self.features.input_dim != state_dim:
                raise ValueError(
                    f"features take {self.features.input_dim}-dim states but dims selects "
                    f"{state_dim}"
                )
            if self.features.output_dim != p:
                raise ValueError(
                    f"features produce {self.features.output_dim} dims, regions live in {p}"
                )
        elif state_dim is not None and state_dim != p:
            raise ValueError(
                f"dims and angles give {state_dim} values but regions live in {p} dims"
                if angles
                else f"dims selects {state_dim} values but regions live in {p} dims"
            )
        if not isinstance(self.metadata, dict):
            raise ValueError(f"metadata must be a dict, got {type(self.metadata).__name__}")
        try:  # checked now: a task that to_json cannot write would be lost
            json.dumps(self.metadata, allow_nan=False)  # NaN is no JSON: other readers fail
        except (TypeError, ValueError) as exc:
            raise ValueError(f"metadata must be JSON-serialisable: {exc}") from exc
        for name, value in (
            ("regions", regions),
            ("rewards", rewards),
            ("dims", dims),
            ("angles", angles),
            ("metadata", dict(self.metadata)),
            ("reward_config", RewardConfig.coerce(self.reward_config)),
        ):
            object.__setattr__(self, name, value)
        self._build_tables()

    def _build_tables(self) -> None:
        """Fold every index's reward and region into one affine map, evaluated per step.

        For index ``i``, ``z = factors[i] @ x - offsets[i]`` holds ``F_i (x - mu_i)`` (with
        ``F_i^T F_i = Psi_i``) above ``L_i^{-1} (x - m_i)`` (with ``L_i L_i^T`` region ``i``'s
        covariance), so ``halves @ z**2`` is ``(R_i(x), squared Mahalanobis distance)``. Index
        ``k`` has segment ``k - 1``'s reward and no region: a threshold below any distance.
        """
        p = self.task_dim
        blocks = []
        for i in range(self.n_indices):
            reward = self.rewards[min(i, self.n_segments - 1)]
            region = self.regions[i] if i < self.n_segments else None
            whitening = np.zeros((p, p)) if region is None else region.whitening
            mean = np.zeros(p) if region is None else region.mean
            factor = np.vstack([reward.factor, whitening])
            blocks.append(
                (factor, np.concatenate([reward.factor @ reward.target, whitening @ mean]))
            )
        windows = [r.time_bounds or (-math.inf, math.inf) for r in self.regions]
        windows.append((-math.inf, math.inf))
        thresholds = [r.threshold for r in self.regions] + [-1.0]
        factors = np.stack([factor for factor, _ in blocks])
        offsets = np.stack([offset for _, offset in blocks])
        tables = {
            "_factors": factors,
            "_offsets": offsets,
            "_halves": np.kron(np.diag([-1.0, 1.0]), np.ones(p)),
            "_threshold": np.array(thresholds),
            # The same rows per index, for one state at a time.
            "_per_index": [
                (factors[i], offsets[i], thresholds[i], *windows[i]) for i in range(len(blocks))
            ],
            "_timed": any(r.time_bounds is not None for r in self.regions),
            "_t_lo": np.array([w[0] for w in windows]),
            "_t_hi": np.array([w[1] for w in windows]),
            # A view of the leading entries where dims are 0, 1, ..., p - 1; else an index array.
            "_select": None
            if self.dims is None
            else slice(0, len(self.dims))
            if self.dims == tuple(range(len(self.dims)))
            else np.array(self.dims, dtype=np.intp),
        }
        for name, value in tables.items():
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ shape
    @property
    def n_segments(self) -> int:
        """Number of segments ``k`` (one per region)."""
        return len(self.regions)

    @property
    def n_indices(self) -> int:
        """Number of segment index values, ``k + 1`` (the last means "all regions reached")."""
        return len(self.regions) + 1

    @property
    def timed(self) -> bool:
        """Whether some region has a time window (then ``next_segment`` reads ``t``)."""
        return self._timed

    @property
    def task_dim(self) -> int:
        """Dimension of task space (where regions and rewards live)."""
        return self.regions[0].mean.size

    @property
    def state_entries(self) -> tuple[int, ...] | None:
        """The entries of the state that the task reads (``dims`` and ``angles``, sorted);
        ``None`` when it reads all of them."""
        if self.dims is None:
            return None
        return tuple(sorted({*self.dims, *(i for angle in self.angles or () for i in angle)}))

    # ------------------------------------------------------------------ functions
    def check_state_dim(self, state_dim: int) -> None:
        """Raise ``ValueError`` unless states of ``state_dim`` values fit this task.

        Wrappers call it once at construction so that the per-step functions need no checks.
        """
        if self.state_entries is not None:
            used = max(self.state_entries)
            if state_dim <= used:
                raise ValueError(f"observation has {state_dim} dims but the task uses index {used}")
        elif self.features is not None:
            if state_dim != self.features.input_dim:
                raise ValueError(
                    f"observation has {state_dim} dims but the task's features take "
                    f"{self.features.input_dim}"
                )
        elif state_dim != self.task_dim:
            raise ValueError(
                f"observation has {state_dim} dims but the task expects {self.task_dim}"
            )

    def featurize(self, obs: np.ndarray) -> np.ndarray:
        """Map observations of shape (..., obs_dim) into task space (..., task_dim).

        The wrappers call it on every step with observations that :meth:`check_state_dim`
        accepted; it does not check them again.
        """
        x = np.asarray(obs)
        if self.angles is not None:
            x = np.concatenate([_angle_features(x, self.angles), x[..., list(self.dims)]], axis=-1)
        elif self._select is not None:
            x = x[..., self._select]
        return x if self.features is None else self.features(x)

    def evaluate(self, x: np.ndarray, t: Any, index: Any) -> tuple[Any, Any]:
        """The segment reward and the region test of task-space states: the run-time maths.

        Parameters
        ----------
        x : array of shape (p,) or (n, p)
            Task-space states (:meth:`featurize`).
        t : int, array of shape (n,) or None
            Step(s) of the episode, read by regions with time windows (``None``: any time).
        index : int or int array of shape (n,)
            Segment index of each state, in ``0 .. k``.

        Returns
        -------
        reward : float or array of shape (n,)
            ``R_index(x)`` (segment ``k - 1``'s reward at index ``k``).
        inside : bool or bool array of shape (n,)
            Whether ``x`` at ``t`` lies in region ``index`` (never at index ``k``).

        Unchecked: the wrappers call it on every step with checked inputs; see
        :meth:`reward` and :meth:`next_segment` for checked calls on observations.
        """
        if x.ndim == 1:
            # One state (a wrapper's step): the same products as each row below, answered in
            # Python numbers, which are cheaper in the per-step arithmetic that follows.
            factors, offsets, threshold, lo, hi = self._per_index[index]
            z = factors.dot(x)
            z -= offsets
            z *= z
            reward, distance = self._halves.dot(z).tolist()
            return reward, distance <= threshold and (t is None or lo <= t <= hi)
        z = _rowwise(self._factors[index], x)
        z -= self._offsets[index]
        z *= z
        reward, distance = _rowwise(self._halves, z).T
        inside = distance <= self._threshold[index]
        if self._timed and t is not None:
            inside = inside & (self._t_lo[index] <= t) & (t <= self._t_hi[index])
        return reward, inside

    def _checked(self, obs: Any, index: Any) -> tuple[np.ndarray, Any]:
        x = np.asarray(obs, dtype=np.float64)
        if x.ndim not in (1, 2):
            raise ValueError(f"obs must have shape (obs_dim,) or (n, obs_dim), got {x.shape}")
        self.check_state_dim(x.shape[-1])
        if not np.isfinite(x).all():
            raise ValueError("obs holds NaN or inf")
        index = np.asarray(index)
        if index.dtype.kind not in "iu":
            raise ValueError(f"segment index must be an integer, got dtype {index.dtype}")
        if index.size and (index.min() < 0 or index.max() > self.n_segments):
            raise ValueError(f"segment index must lie in [0, {self.n_segments}], got {index}")
        if x.ndim == 1 and index.ndim:
            raise ValueError("one observation takes one segment index")
        if x.ndim == 2:
            index = np.broadcast_to(index, x.shape[:1])
        return self.featurize(x), index

    def next_segment(self, obs: np.ndarray, t: Any, index: Any) -> Any:
        """The Markov segmentation function ``M(s_t, i_t)``: ``index + 1`` where the state lies
        in region ``index``, ``index`` elsewhere.

        Parameters
        ----------
        obs : array of shape (obs_dim,) or (n, obs_dim)
        t : int, array of shape (n,) or None
            Step(s) of the episode, read by regions with time windows (``None``: any time).
        index : int or array of shape (n,)
            Current segment index(es) in ``0 .. k``.
        """
        x, index = self._checked(obs, index)
        if t is not None:
            t = np.asarray(t)
        return index + self.evaluate(x, t, index)[1]

    def reward(self, obs: np.ndarray, index: Any) -> Any:
        """The local reward ``R_i(s)`` of segment ``index`` (segment ``k - 1``'s at index ``k``)."""
        x, index = self._checked(obs, index)
        return self.evaluate(x, None, index)[0]

    def segment_indices(self, observations: Any) -> np.ndarray:
        """Run the segmentation function along one trajectory of shape (T+1, obs_dim).

        ``observations`` is the array, or a demonstration that holds it as ``.observations``
        (``sb3_swirl.Demonstration``, a Minari episode) or ``.obs`` (an imitation
        ``Trajectory``). ``out[t]`` is the index after observing ``s_t`` (``t = 0``: the start
        state): the index advances at the first step whose state lies in the next region,
        exactly as :meth:`next_segment` and the wrappers advance it online, with the same
        arithmetic.
        """
        held = getattr(observations, "observations", getattr(observations, "obs", observations))
        try:
            x = np.asarray(held, dtype=np.float64)
        except (TypeError, ValueError):  # e.g. a list of demos of different lengths
            x = None
        if x is None or x.ndim != 2:
            got = "" if x is None else f", got shape {x.shape}"
            raise ValueError(
                f"observations must be one trajectory of shape (T+1, obs_dim){got}; for many, "
                "segment each (or use reach_steps)"
            )
        reached = self.reach_steps([x])[0]
        out = np.zeros(len(x), dtype=np.int64)
        for step in reached[reached >= 0]:
            out[step:] += 1
        return out

    def reach_steps(self, trajectories: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The step at which each region is reached, along many trajectories at once.

        Parameters
        ----------
        trajectories : sequence of arrays of shape (T+1, obs_dim)
            Observations at steps ``0 .. T`` (the start state first).

        Returns
        -------
        list of int arrays of shape (n_segments,)
            Per trajectory, ``out[i]`` is the first step after region ``i - 1``'s whose state
            lies in region ``i`` (region 0: from the start state on), ``-1`` once a region is
            never reached: where :meth:`segment_indices` and the wrappers advance the index.
            Each region is tested once on all the trajectories stacked, with the wrappers'
            row-by-row arithmetic.
        """
        xs = [np.asarray(o, dtype=np.float64) for o in trajectories]
        for k, x in enumerate(xs):
            if x.ndim != 2:
                raise ValueError(
                    f"trajectory {k}: observations must have shape (T+1, obs_dim), got {x.shape}"
                )
            try:
                self.check_state_dim(x.shape[-1])
            except ValueError as exc:
                raise ValueError(f"trajectory {k}: {exc}") from None
            bad = np.flatnonzero(~np.isfinite(x).all(axis=1))
            if bad.size:
                raise ValueError(f"trajectory {k}: observations hold NaN or inf at step {bad[0]}")
        if not xs:
            return []
        lengths = [len(x) for x in xs]
        x = self.featurize(np.concatenate(xs))
        steps = np.concatenate([np.arange(n) for n in lengths])
        cuts = np.cumsum(lengths)[:-1]
        inside = [np.split(self.evaluate(x, steps, i)[1], cuts) for i in range(self.n_segments)]
        out = []
        for d in range(len(xs)):
            reached = np.full(self.n_segments, -1, dtype=np.int64)
            t = -1
            for i in range(self.n_segments):
                later = np.flatnonzero(inside[i][d][t + 1 :])
                if not later.size:
                    break
                t += 1 + int(later[0])
                reached[i] = t
            out.append(reached)
        return out

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": SCHEMA_VERSION,
            "kind": "swirl_task",
            "dims": None if self.dims is None else list(self.dims),
            "features": None if self.features is None else self.features.to_dict(),
            "angles": None if self.angles is None else [list(a) for a in self.angles],
            "regions": [r.to_dict() for r in self.regions],
            "rewards": [r.to_dict() for r in self.rewards],
            "reward_config": self.reward_config.to_dict(),
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, data: Any) -> TaskModel:
        """Build a task from :meth:`to_dict`'s output; every malformed field is a ``ValueError``
        that names it."""
        if not isinstance(data, Mapping):
            raise ValueError(f"a task model must be a JSON object, got {type(data).__name__}")
        if data.get("kind") != "swirl_task":
            raise ValueError(
                f"not a SWIRL task model: expected 'kind': 'swirl_task', got {data.get('kind')!r}"
            )
        version = data.get("schema_version")
        if type(version) is not int or version not in (1, SCHEMA_VERSION):
            raise ValueError(
                f"unsupported task model schema version {version!r}; this swirl_wrappers "
                f"reads versions 1 and {SCHEMA_VERSION}"
            )
        optional = ("dims", "features", "angles", "metadata")
        if version >= 2:
            optional += ("reward_config",)
        _check_keys(data, "task model", ("schema_version", "kind", "regions", "rewards"), optional)

        def each(key: str, build: Any) -> list[Any]:
            items = data[key]
            if not isinstance(items, list):
                raise ValueError(f"{key} must be a list, got {type(items).__name__}")
            out = []
            for i, item in enumerate(items):
                try:
                    out.append(build(item))
                except ValueError as exc:
                    raise ValueError(f"{key}[{i}]: {exc}") from exc
            return out

        def one(key: str, build: Any) -> Any:
            value = data.get(key)
            try:
                return None if value is None else build(value)
            except ValueError as exc:
                raise ValueError(f"{key}: {exc}") from exc

        return cls(
            regions=each("regions", Region.from_dict),
            rewards=each("rewards", QuadraticReward.from_dict),
            dims=data.get("dims"),
            features=one("features", RBFFeatures.from_dict),
            metadata={} if data.get("metadata") is None else data["metadata"],
            angles=data.get("angles"),
            reward_config=one("reward_config", RewardConfig.from_dict) or RewardConfig(),
        )

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """Serialise to a JSON string; also write it to ``path`` (atomically) if given."""
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False)
        if path is not None:
            with atomic_write(path) as fh:
                fh.write(text)
        return text

    @classmethod
    def from_json(cls, source: str | bytes | os.PathLike) -> TaskModel:
        """Load from a JSON string (or its UTF-8 bytes) or from a path to a JSON file.

        A path-like, or a string naming an existing file, is read as a file; any other string
        that starts like JSON is parsed as JSON text.
        """
        if isinstance(source, bytes | bytearray):  # JSON text read in binary mode
            try:
                source = bytes(source).decode("utf-8-sig")
            except UnicodeDecodeError:
                raise ValueError(
                    "TaskModel.from_json got bytes that are not UTF-8 text: not the JSON that "
                    "TaskModel.to_json and `sb3-swirl fit` write (a model zip or demos file?)"
                ) from None
        if not isinstance(source, str | os.PathLike):
            raise ValueError(
                "TaskModel.from_json takes JSON text or the path of a JSON file, got "
                f"{type(source).__name__}"
            )
        text = str(source)
        file = None  # the file read, named in every error
        if (
            isinstance(source, os.PathLike)
            or os.path.isfile(text)
            or not text.lstrip("\ufeff \t\r\n").startswith(("{", "["))
        ):
            file = os.fspath(source) if isinstance(source, os.PathLike) else text
            try:  # utf-8-sig: a file an editor saved with a byte-order mark reads too
                with open(file, encoding="utf-8-sig") as fh:
                    text = fh.read()
            except OSError as exc:
                raise ValueError(f"cannot read task model file {file}: {exc}") from exc
            except UnicodeDecodeError:  # a binary file: demos (.npz), a model (.zip), a plot
                raise ValueError(
                    f"cannot read task model file {file}: it is a binary file, not the JSON "
                    "text that TaskModel.to_json and `sb3-swirl fit` write"
                ) from None
        what = "task model" if file is None else f"task model file {file}"
        try:
            data = json.loads(text.lstrip("\ufeff"))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{what} is not valid JSON (corrupted or truncated?): {exc}") from exc
        except RecursionError:
            raise ValueError(f"{what} nests its JSON too deeply to be a task model") from None
        try:
            return cls.from_dict(data)
        except ValueError as exc:
            if file is None:
                raise
            raise ValueError(f"{file}: {exc}") from exc
