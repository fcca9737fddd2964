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
dimensions in ``dims`` are selected, then (optionally) an RBF feature map is applied.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SCHEMA_VERSION = 1


def _as_float_array(value: Any, name: str, ndim: int) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimension(s), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


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
            precision = np.linalg.inv(np.linalg.cholesky(cov))
        except np.linalg.LinAlgError as exc:
            raise ValueError("Region.covariance must be positive definite") from exc
        precision = precision.T @ precision
        if not (np.isfinite(self.threshold) and self.threshold > 0):
            raise ValueError(f"Region.threshold must be a positive number, got {self.threshold}")
        bounds = self.time_bounds
        if bounds is not None:
            bounds = (float(bounds[0]), float(bounds[1]))
            if not bounds[0] <= bounds[1]:
                raise ValueError(f"Region.time_bounds must be (lo, hi) with lo <= hi, got {bounds}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "threshold", float(self.threshold))
        object.__setattr__(self, "time_bounds", bounds)
        object.__setattr__(self, "precision", precision)

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
                raise ValueError(f"rewards[{i}] is a {type(item).__name__}, expected QuadraticReward")
        p = regions[0].mean.size
        for i, (reg, rew) in enumerate(zip(regions, rewards, strict=True)):
            if reg.mean.size != p or rew.target.size != p:
                raise ValueError(
                    f"segment {i}: region/reward dimension differs from task-space dimension {p}"
                )
        dims = None if self.dims is None else tuple(int(d) for d in self.dims)
        if dims is not None and (not dims or min(dims) < 0):
            raise ValueError(f"TaskModel.dims must be non-negative indices, got {dims}")
        state_dim = len(dims) if dims is not None else None
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
            raise ValueError(f"dims selects {state_dim} values but regions live in {p} dims")
        object.__setattr__(self, "regions", regions)
        object.__setattr__(self, "rewards", rewards)
        object.__setattr__(self, "dims", dims)
        object.__setattr__(self, "metadata", dict(self.metadata))

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
    def task_dim(self) -> int:
        """Dimension of task space (where regions and rewards live)."""
        return self.regions[0].mean.size

    # ------------------------------------------------------------------ functions
    def featurize(self, obs: np.ndarray) -> np.ndarray:
        """Map observations of shape (..., obs_dim) into task space (..., task_dim)."""
        x = np.asarray(obs, dtype=np.float64)
        if self.dims is not None:
            if x.shape[-1] <= max(self.dims):
                raise ValueError(
                    f"observation has {x.shape[-1]} dims but the task uses index {max(self.dims)}"
                )
            x = x[..., list(self.dims)]
        if self.features is not None:
            x = self.features(x)
        elif x.shape[-1] != self.task_dim:
            raise ValueError(
                f"observation has {x.shape[-1]} dims but the task expects {self.task_dim}"
            )
        return x

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
        x = self.featurize(obs)
        index = np.asarray(index, dtype=np.int64)
        out = index.copy()
        batch = x.ndim == 2
        if not batch:
            i = int(index)
            if i < self.n_segments and bool(self.regions[i].contains(x, t)):
                return np.asarray(i + 1, dtype=np.int64)
            return out
        t_arr = None if t is None else np.broadcast_to(np.asarray(t, dtype=np.float64), index.shape)
        for i in np.unique(index):
            if i >= self.n_segments:
                continue
            sel = index == i
            hit = self.regions[i].contains(x[sel], None if t_arr is None else t_arr[sel])
            out[sel] = np.where(hit, i + 1, i)
        return out

    def reward(self, obs: np.ndarray, index: np.ndarray | int) -> np.ndarray:
        """The local reward ``R_i(s)`` of segment ``index`` (the last segment's after completion)."""
        x = self.featurize(obs)
        index = np.minimum(np.asarray(index, dtype=np.int64), self.n_segments - 1)
        if x.ndim == 1:
            return np.asarray(self.rewards[int(index)](x))
        out = np.empty(x.shape[0], dtype=np.float64)
        for i in np.unique(index):
            sel = index == i
            out[sel] = self.rewards[i](x[sel])
        return out

    def segment_indices(self, observations: np.ndarray) -> np.ndarray:
        """Run the segmentation function along one trajectory of shape (T+1, obs_dim).

        ``out[t]`` is the index after observing ``s_t``: the index advances at the first step
        whose state lies in the next region, exactly as the wrapper advances it online.
        """
        observations = np.asarray(observations, dtype=np.float64)
        x = self.featurize(observations)
        out = np.zeros(len(x), dtype=np.int64)
        i = 0
        for t in range(len(x)):
            if i < self.n_segments and bool(self.regions[i].contains(x[t], t)):
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
            "regions": [r.to_dict() for r in self.regions],
            "rewards": [r.to_dict() for r in self.rewards],
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TaskModel:
        if not isinstance(data, dict) or data.get("kind") != "swirl_task":
            raise ValueError("not a SWIRL task model (missing 'kind': 'swirl_task')")
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
            )
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"malformed task model: {exc!r}") from exc

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """Serialise to a JSON string; also write it to ``path`` if given."""
        text = json.dumps(self.to_dict(), indent=1)
        if path is not None:
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(text)
        return text

    @classmethod
    def from_json(cls, source: str | os.PathLike) -> TaskModel:
        """Load from a JSON string or from a path to a JSON file."""
        text = str(source)
        if not text.lstrip().startswith("{"):
            try:
                with open(source, encoding="utf-8") as fh:
                    text = fh.read()
            except OSError as exc:
                raise ValueError(f"cannot read task model file {source!s}: {exc}") from exc
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"task model is not valid JSON (corrupted or truncated?): {exc}") from exc
        return cls.from_dict(data)
