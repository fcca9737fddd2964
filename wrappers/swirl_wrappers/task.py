"""The proxy task learned by SWIRL: ordered transition regions and one quadratic reward per segment.

A :class:`TaskModel` is plain data. It holds no learning code, serialises to versioned JSON, and
exposes two pure, vectorised functions:

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
"""

from __future__ import annotations

import functools
import json
import operator
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SCHEMA_VERSION = 1


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
    return arr


def check_angles(angles: Any) -> tuple[tuple[int, ...], ...] | None:
    """Validate ``TaskModel.angles``: ``None`` or non-empty sequences of non-negative ints."""
    if angles is None:
        return None
    try:
        if isinstance(angles, str) or any(isinstance(angle, str) for angle in angles):
            raise TypeError("strings are not index sequences")
        out = tuple(tuple(operator.index(i) for i in angle) for angle in angles)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"TaskModel.angles must be a sequence of sequences of ints, got {angles!r}"
        ) from exc
    if not out or any(not angle or min(angle) < 0 for angle in out):
        raise ValueError(
            "TaskModel.angles must hold at least one angle, each a non-empty sequence of "
            f"non-negative observation indices, got {angles!r}"
        )
    return out


def _angle_features(phi: np.ndarray) -> np.ndarray:
    """``(cos phi_1, sin phi_1, ..., cos phi_m, sin phi_m)`` for angles of shape (..., m)."""
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
    phi = np.stack([x[..., list(angle)].sum(axis=-1) for angle in checked], axis=-1)
    return _angle_features(phi)


@dataclass(frozen=True, eq=False)
class Region:
    """An ellipsoidal transition region in task space, optionally limited to a time window.

    A point ``x`` at time ``t`` is inside when ``(x - mean)^T precision (x - mean) <= threshold``
    and, if ``time_bounds`` is set, ``time_bounds[0] <= t <= time_bounds[1]``.

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
    """

    mean: np.ndarray
    covariance: np.ndarray
    threshold: float
    time_bounds: tuple[float, float] | None = None
    precision: np.ndarray = field(init=False, repr=False)
    whitening: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mean = _as_float_array(self.mean, "Region.mean", 1)
        cov = _as_float_array(self.covariance, "Region.covariance", 2)
        if cov.shape != (mean.size, mean.size):
            raise ValueError(
                f"Region.covariance must have shape {(mean.size, mean.size)}, got {cov.shape}"
            )
        if not np.allclose(cov, cov.T):
            raise ValueError("Region.covariance must be symmetric")
        try:
            whitening = np.linalg.inv(np.linalg.cholesky(cov))
        except np.linalg.LinAlgError as exc:
            raise ValueError("Region.covariance must be positive definite") from exc
        try:
            threshold = float(self.threshold)
        except (TypeError, ValueError):
            threshold = np.nan
        if not (np.isfinite(threshold) and threshold > 0):
            raise ValueError(f"Region.threshold must be a positive number, got {self.threshold!r}")
        bounds = self.time_bounds
        if bounds is not None:
            try:
                lo, hi = (float(b) for b in bounds)
            except (TypeError, ValueError) as exc:
                raise ValueError(
                    f"Region.time_bounds must be a pair of numbers, got {bounds!r}"
                ) from exc
            bounds = (lo, hi)
            if np.isnan(lo) or np.isnan(hi) or not lo <= hi:
                raise ValueError(f"Region.time_bounds must be (lo, hi) with lo <= hi, got {bounds}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "threshold", threshold)
        object.__setattr__(self, "time_bounds", bounds)
        object.__setattr__(self, "whitening", whitening)
        object.__setattr__(self, "precision", whitening.T @ whitening)

    def mahalanobis2(self, x: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distance of ``x`` (shape (p,) or (n, p)) to the centre."""
        diff = np.asarray(x, dtype=np.float64) - self.mean
        return np.einsum("...i,ij,...j->...", diff, self.precision, diff)

    def contains(self, x: np.ndarray, t: np.ndarray | float | None = None) -> np.ndarray:
        """Whether ``x`` (shape (p,) or (n, p)) at time ``t`` lies in the region."""
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
    def from_dict(cls, data: dict[str, Any]) -> Region:
        bounds = data.get("time_bounds")
        return cls(
            mean=data["mean"],
            covariance=data["covariance"],
            threshold=data["threshold"],
            time_bounds=None if bounds is None else tuple(bounds),
        )


@dataclass(frozen=True, eq=False)
class QuadraticReward:
    """A local reward ``R(x) = -(x - target)^T weight (x - target)``.

    Parameters
    ----------
    target : array of shape (p,)
        The centroid ``mu_i`` of the region this segment leads to.
    weight : array of shape (p, p)
        Symmetric positive semi-definite matrix ``Psi_i``.
    """

    target: np.ndarray
    weight: np.ndarray

    def __post_init__(self) -> None:
        target = _as_float_array(self.target, "QuadraticReward.target", 1)
        weight = _as_float_array(self.weight, "QuadraticReward.weight", 2)
        if weight.shape != (target.size, target.size):
            raise ValueError(
                f"QuadraticReward.weight must have shape {(target.size, target.size)}, "
                f"got {weight.shape}"
            )
        if not np.allclose(weight, weight.T):
            raise ValueError("QuadraticReward.weight must be symmetric")
        if np.linalg.eigvalsh(weight).min() < -1e-9 * max(1.0, np.abs(weight).max()):
            raise ValueError("QuadraticReward.weight must be positive semi-definite")
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "weight", weight)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        diff = np.asarray(x, dtype=np.float64) - self.target
        return -np.einsum("...i,ij,...j->...", diff, self.weight, diff)

    def to_dict(self) -> dict[str, Any]:
        return {"target": self.target.tolist(), "weight": self.weight.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> QuadraticReward:
        return cls(target=data["target"], weight=data["weight"])


@dataclass(frozen=True, eq=False)
class RBFFeatures:
    """An explicit RBF feature map ``phi(s) = exp(-gamma ||s - c_j||^2) @ projection``.

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
        if not (np.isfinite(self.gamma) and self.gamma > 0):
            raise ValueError(f"RBFFeatures.gamma must be positive, got {self.gamma}")
        object.__setattr__(self, "landmarks", landmarks)
        object.__setattr__(self, "projection", projection)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "gamma", float(self.gamma))

    @property
    def input_dim(self) -> int:
        return self.landmarks.shape[1]

    @property
    def output_dim(self) -> int:
        return self.projection.shape[1]

    def __call__(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=np.float64)
        sq = np.sum((s[..., None, :] - self.landmarks) ** 2, axis=-1)
        return np.exp(-self.gamma * sq) @ self.projection - self.offset

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "rbf",
            "landmarks": self.landmarks.tolist(),
            "gamma": self.gamma,
            "projection": self.projection.tolist(),
            "offset": self.offset.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RBFFeatures:
        if data.get("type") != "rbf":
            raise ValueError(f"unknown feature map type {data.get('type')!r}")
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
        for i, item in enumerate(regions):
            if not isinstance(item, Region):
                raise ValueError(f"regions[{i}] is a {type(item).__name__}, expected Region")
        for i, item in enumerate(rewards):
            if not isinstance(item, QuadraticReward):
                raise ValueError(
                    f"rewards[{i}] is a {type(item).__name__}, expected QuadraticReward"
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
        try:
            if isinstance(self.dims, str):
                raise TypeError("a string is not a sequence of indices")
            dims = None if self.dims is None else tuple(operator.index(d) for d in self.dims)
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"TaskModel.dims must be a sequence of ints, got {self.dims!r}"
            ) from exc
        angles = check_angles(self.angles)
        if angles is not None and dims is None:
            raise ValueError(
                "TaskModel.dims must be given with angles: it lists the observation entries "
                "passed through besides the angle features (use () for none)"
            )
        if dims is not None and ((not dims and angles is None) or min(dims, default=0) < 0):
            raise ValueError(f"TaskModel.dims must be non-negative indices, got {dims}")
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
        object.__setattr__(self, "angles", angles)
        object.__setattr__(self, "regions", regions)
        object.__setattr__(self, "rewards", rewards)
        object.__setattr__(self, "dims", dims)
        if not isinstance(self.metadata, dict):
            raise ValueError(f"metadata must be a dict, got {type(self.metadata).__name__}")
        try:  # checked now: a task that to_json cannot write would be lost
            json.dumps(self.metadata)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"metadata must be JSON-serialisable: {exc}") from exc
        object.__setattr__(self, "metadata", dict(self.metadata))
        object.__setattr__(self, "_tables", _Tables.build(self))

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
        return self._tables.timed

    @property
    def task_dim(self) -> int:
        """Dimension of task space (where regions and rewards live)."""
        return self.regions[0].mean.size

    # ------------------------------------------------------------------ functions
    def check_state_dim(self, state_dim: int) -> None:
        """Raise ``ValueError`` unless states of ``state_dim`` values fit this task.

        Wrappers call it once at construction so that the per-step functions need no checks.
        """
        if self.dims is not None:
            used = max([*self.dims, *(i for angle in self.angles or () for i in angle)])
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
        """Map observations of shape (..., obs_dim) into task space (..., task_dim)."""
        x = np.asarray(obs, dtype=np.float64)
        self.check_state_dim(x.shape[-1])
        if not self._tables.linear:
            return self._task_input(x)
        return x if self.dims is None else x[..., list(self.dims)]

    def _check_index(self, index: np.ndarray | int) -> np.ndarray:
        index = np.asarray(index)
        if not np.issubdtype(index.dtype, np.integer):
            raise ValueError(f"segment index must be an integer, got dtype {index.dtype}")
        if index.size and (index.min() < 0 or index.max() > self.n_segments):
            raise ValueError(f"segment index must lie in [0, {self.n_segments}], got {index}")
        return index.astype(np.int64, copy=False)

    def _task_input(self, obs: np.ndarray) -> np.ndarray:
        """What the tables' factors multiply: task space, or a leading slice when linear."""
        tb = self._tables
        if tb.lift is None:
            x = obs[..., tb.select]
        else:
            # One product gives (phi_1, phi_1 - pi/2, ..., obs[dims]) and one cosine the angle
            # features (sin phi = cos(phi - pi/2)): a few microseconds per step, several times
            # less than stacking and concatenating.
            x = obs[..., tb.select].dot(tb.lift)
            x -= tb.lift_shift
            np.cos(x[..., : tb.n_trig], out=x[..., : tb.n_trig])
        return x if tb.features is None else tb.features(x)

    def _region_distances(self, obs: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distance over threshold to every index's region: (n, n_indices).

        A state is inside region ``i`` when column ``i`` is at most 1; the last column (index
        ``k``, which has no region) is always above 1.
        """
        x = self._task_input(obs)
        inputs = self.input_buffer(len(x))
        inputs[:, :-1] = x
        z = inputs.dot(self._tables.weights)  # the product of reward_and_next_batch
        z *= z
        return z.reshape(len(x), self.n_indices, 2, -1)[:, :, 1, :].sum(axis=-1)

    def reward_and_next(self, obs: np.ndarray, t: float | None, index: int) -> tuple[float, int]:
        """Reward and segmentation step for one state, as Python scalars (the wrappers' hot path).

        Returns ``(R_index(obs), M(obs, t, index))`` computed from one small matrix product. The
        caller guarantees ``obs`` is a 1-D array that passed :meth:`check_state_dim` and
        ``0 <= index <= k``; use :meth:`reward` and :meth:`next_segment` for checked calls.

        Examples
        --------
        >>> import numpy as np
        >>> from swirl_wrappers import QuadraticReward, Region, TaskModel
        >>> task = TaskModel(
        ...     regions=[Region(mean=[1.0], covariance=[[0.01]], threshold=1.0)],
        ...     rewards=[QuadraticReward(target=[1.0], weight=[[4.0]])],
        ... )
        >>> task.reward_and_next(np.array([0.0]), t=0, index=0)
        (-4.0, 0)
        >>> reward, index = task.reward_and_next(np.array([1.05]), t=1, index=0)
        >>> round(reward, 6), index
        (-0.01, 1)
        """
        tb = self._tables
        x = obs[tb.select] if tb.linear else self._task_input(obs)
        # ndarray.dot: the @ operator costs about a microsecond more on arrays this small.
        z = tb.factor_list[index].dot(x)
        z -= tb.offset_list[index]
        z *= z
        reward, dist2 = tb.halves.dot(z).tolist()
        if dist2 <= 1.0 and (t is None or tb.t_lo[index] <= t <= tb.t_hi[index]):
            return reward, index + 1
        return reward, index

    def reward_and_next_batch(
        self,
        obs: np.ndarray,
        t: np.ndarray | float | None,
        index: np.ndarray,
        buffer: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised :meth:`reward_and_next` for ``n`` states of shape (n, obs_dim).

        ``index`` has shape (n,) and ``t`` is ``None``, a scalar or shape (n,). Returns float64
        rewards (n,) and int64 next indices (n,). Unchecked, like :meth:`reward_and_next`.
        ``buffer``, from :meth:`input_buffer`, is reused for the inputs of the product instead
        of a new array (the vector wrappers call this on every step).
        """
        tb = self._tables
        n, m = len(index), self.n_indices
        # One product projects onto every index's factors, offsets included (the inputs end
        # in a column of ones); then each row keeps its own index: row index * m + index of the
        # (n * m, 2p) reshape. `take` costs a fraction of 2-D fancy indexing.
        inputs = self.input_buffer(n) if buffer is None else buffer[:n]
        inputs[:, :-1] = self._task_input(obs)
        z = inputs.dot(tb.weights).reshape(n * m, -1)
        z = z.take(index + _row_starts(n, m), axis=0)
        z *= z
        # (2, n): contiguous rows, which compare and return several times faster than columns.
        q = tb.halves.dot(z.T)
        inside = q[1] <= _ones(n)  # an array: a scalar operand costs a conversion per call
        if tb.timed and t is not None:
            inside &= (t >= tb.t_lo_array[index]) & (t <= tb.t_hi_array[index])
        return q[0], index + inside

    def input_buffer(self, n: int) -> np.ndarray:
        """A buffer for ``n`` rows of :meth:`reward_and_next_batch`'s inputs (ones at the end)."""
        return np.ones((n, self._tables.weights.shape[0]))

    def next_segment(
        self, obs: np.ndarray, t: np.ndarray | float | None, index: np.ndarray | int
    ) -> np.ndarray:
        """The Markov segmentation function ``M(s_t, i_t)``.

        Parameters
        ----------
        obs : array of shape (obs_dim,) or (n, obs_dim)
        t : time step(s), used only by regions with ``time_bounds``
        index : current segment index(es) in ``0 .. k``

        Returns
        -------
        ndarray of int
            ``index + 1`` where the state lies in region ``index``; ``index`` elsewhere.
        """
        return self._evaluate(obs, t, index)[1]

    def reward(self, obs: np.ndarray, index: np.ndarray | int) -> np.ndarray:
        """The local reward ``R_i(s)`` of segment ``index`` (segment ``k - 1``'s at index ``k``)."""
        return self._evaluate(obs, None, index)[0]

    def _evaluate(
        self, obs: np.ndarray, t: np.ndarray | float | None, index: np.ndarray | int
    ) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(obs, dtype=np.float64)
        if x.ndim not in (1, 2):
            raise ValueError(f"obs must have shape (obs_dim,) or (n, obs_dim), got {x.shape}")
        self.check_state_dim(x.shape[-1])
        index = self._check_index(index)
        batch = x[None] if x.ndim == 1 else x
        idx = np.broadcast_to(index, batch.shape[:1])
        if t is not None:
            t = np.broadcast_to(np.asarray(t, dtype=np.float64), idx.shape)
        rewards, nxt = self.reward_and_next_batch(batch, t, idx)
        if x.ndim == 1:
            return rewards[0], nxt[0]
        return rewards, nxt

    def segment_indices(self, observations: np.ndarray) -> np.ndarray:
        """Run the segmentation function along one trajectory of shape (T+1, obs_dim).

        ``out[t]`` is the index after observing ``s_t``: the index advances at the first step
        whose state lies in the next region, exactly as the wrapper advances it online.
        """
        x = np.asarray(observations, dtype=np.float64)
        if x.ndim != 2:
            raise ValueError(f"observations must have shape (T+1, obs_dim), got {x.shape}")
        self.check_state_dim(x.shape[-1])
        tb = self._tables
        dist2 = self._region_distances(x).tolist()
        out = np.zeros(len(x), dtype=np.int64)
        i = 0
        for t, row in enumerate(dist2):
            if row[i] <= 1.0 and tb.t_lo[i] <= t <= tb.t_hi[i]:
                i += 1
            out[t] = i
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
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TaskModel:
        if not isinstance(data, dict):
            raise ValueError(f"a task model must be a JSON object, got {type(data).__name__}")
        if data.get("kind") != "swirl_task":
            raise ValueError(
                f"not a SWIRL task model: expected 'kind': 'swirl_task', got {data.get('kind')!r}"
            )
        version = data.get("schema_version")
        if version != SCHEMA_VERSION:
            raise ValueError(
                f"unsupported task model schema version {version!r}; this swirl_wrappers "
                f"reads version {SCHEMA_VERSION}"
            )
        try:
            features = data.get("features")
            return cls(
                regions=[Region.from_dict(r) for r in data["regions"]],
                rewards=[QuadraticReward.from_dict(r) for r in data["rewards"]],
                dims=data.get("dims"),
                features=None if features is None else RBFFeatures.from_dict(features),
                metadata=data.get("metadata") or {},
                angles=data.get("angles"),
            )
        except KeyError as exc:
            raise ValueError(f"malformed task model: missing field {exc.args[0]!r}") from exc
        except (TypeError, IndexError, AttributeError) as exc:
            raise ValueError(f"malformed task model: {exc}") from exc

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """Serialise to a JSON string; also write it to ``path`` if given."""
        text = json.dumps(self.to_dict(), indent=1)
        if path is not None:
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(text)
        return text

    @classmethod
    def from_json(cls, source: str | os.PathLike) -> TaskModel:
        """Load from a JSON string or from a path to a JSON file.

        A path-like, or a string naming an existing file, is read as a file; any other string
        that starts like JSON is parsed as JSON text.
        """
        text = str(source)
        file = None  # the file read, named in every error
        if (
            isinstance(source, os.PathLike)
            or os.path.isfile(text)
            or not text.lstrip().startswith(("{", "["))
        ):
            file = os.fspath(source) if isinstance(source, os.PathLike) else text
            try:
                with open(file, encoding="utf-8") as fh:
                    text = fh.read()
            except (OSError, UnicodeDecodeError) as exc:  # a binary file is not UTF-8
                raise ValueError(f"cannot read task model file {file}: {exc}") from exc
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            what = "task model" if file is None else f"task model file {file}"
            raise ValueError(f"{what} is not valid JSON (corrupted or truncated?): {exc}") from exc
        try:
            return cls.from_dict(data)
        except ValueError as exc:
            if file is None:
                raise
            raise ValueError(f"{file}: {exc}") from exc


@functools.lru_cache(maxsize=16)
def _row_starts(n: int, m: int) -> np.ndarray:
    """``0, m, 2m, ...`` (n values), read-only: cached, as a vector env asks for one n."""
    starts = np.arange(0, n * m, m)
    starts.flags.writeable = False
    return starts


@functools.lru_cache(maxsize=16)
def _ones(n: int) -> np.ndarray:
    """``n`` ones, read-only: cached like :func:`_row_starts`."""
    ones = np.ones(n)
    ones.flags.writeable = False
    return ones


@dataclass(frozen=True)
class _Tables:
    """Every segment's reward and region folded into one affine map, evaluated per step.

    For index ``i``, the first ``p`` entries of ``factors[i] @ x - offsets[i]`` are
    ``F_i (x - mu_i)`` with ``F_i^T F_i = Psi_i`` and the last ``p`` are
    ``L_i^{-1} (x - m_i) / sqrt(threshold_i)`` with ``L_i L_i^T`` region ``i``'s covariance: one
    small product, a square and two signed block sums (``halves``) give the reward ``R_i(x)``
    and a distance that is at most 1 exactly inside region ``i``. The final index has no
    region; a constant offset keeps its distance at 4. ``weights`` stacks every index's
    ``factors[i].T`` over the row ``-offsets``, so ``[x, 1] @ weights`` evaluates all indices in
    one product (batches); ``factor_list`` / ``offset_list`` serve one state at one index.
    Wrappers call this every step, so it is built once.
    """

    select: np.ndarray | slice
    features: RBFFeatures | None
    linear: bool
    lift: np.ndarray | None
    lift_shift: np.ndarray | None
    n_trig: int
    weights: np.ndarray
    halves: np.ndarray
    factor_list: list[np.ndarray]
    offset_list: list[np.ndarray]
    t_lo: list[float]
    t_hi: list[float]
    t_lo_array: np.ndarray
    t_hi_array: np.ndarray
    timed: bool

    @classmethod
    def build(cls, task: TaskModel) -> _Tables:
        k, p = task.n_segments, task.task_dim
        linear = task.features is None and task.angles is None
        lift = lift_shift = None
        n_trig = 0
        if linear:
            # Without a feature map the dims selection is linear: fold it into the factors
            # and read only a leading slice of the observation (a view, no copy).
            n_in = p if task.dims is None else max(task.dims) + 1
            embed = np.zeros((p, n_in))
            embed[np.arange(p), np.arange(p) if task.dims is None else list(task.dims)] = 1.0
            select: np.ndarray | slice = slice(0, n_in)
        elif task.angles is not None:
            dims = list(task.dims or ())
            n_trig = 2 * len(task.angles)
            # obs[:n_in] @ lift = (phi_1, phi_1, ..., phi_m, phi_m, obs[dims]).
            lift = np.zeros((max([*dims, *np.concatenate(task.angles)]) + 1, n_trig + len(dims)))
            for j, angle in enumerate(task.angles):
                for i in angle:
                    lift[i, 2 * j : 2 * j + 2] += 1.0
            lift[dims, n_trig + np.arange(len(dims))] = 1.0
            lift_shift = np.zeros(lift.shape[1])
            lift_shift[1:n_trig:2] = np.pi / 2
            embed = np.eye(p)
            select = slice(0, len(lift))
        else:
            embed = np.eye(p)
            select = slice(None) if task.dims is None else np.array(task.dims, dtype=np.intp)
        factors = np.zeros((k + 1, 2 * p, embed.shape[1]))
        offsets = np.zeros((k + 1, 2 * p))
        for i in range(k + 1):
            reward = task.rewards[min(i, k - 1)]
            eigval, eigvec = np.linalg.eigh(reward.weight)
            blocks = [(np.sqrt(np.clip(eigval, 0.0, None))[:, None] * eigvec.T, reward.target)]
            if i < k:
                region = task.regions[i]
                blocks.append((region.whitening / np.sqrt(region.threshold), region.mean))
            for b, (factor, centre) in enumerate(blocks):
                factors[i, b * p : (b + 1) * p] = factor @ embed
                offsets[i, b * p : (b + 1) * p] = factor @ centre
        offsets[k, p] = -2.0
        halves = np.kron(np.diag([-1.0, 1.0]), np.ones(p))  # R_i(x), distance
        factors_t = np.ascontiguousarray(factors.reshape(-1, factors.shape[-1]).T)
        bounds = [r.time_bounds or (-np.inf, np.inf) for r in task.regions]
        t_lo = [b[0] for b in bounds] + [-np.inf]
        t_hi = [b[1] for b in bounds] + [np.inf]
        return cls(
            select=select,
            features=task.features,
            linear=linear,
            lift=lift,
            lift_shift=lift_shift,
            n_trig=n_trig,
            # [x, 1] @ weights = factors @ x - offsets, for every index at once
            weights=np.vstack([factors_t, -offsets.reshape(1, -1)]),
            halves=halves,
            factor_list=[np.ascontiguousarray(f) for f in factors],
            offset_list=list(offsets),
            t_lo=t_lo,
            t_hi=t_hi,
            t_lo_array=np.array(t_lo),
            t_hi_array=np.array(t_hi),
            timed=any(r.time_bounds is not None for r in task.regions),
        )
