"""Reward learning (§6 of the paper, Algorithm 2): one local quadratic reward per segment.

Every reward learner follows the :class:`RewardLearner` protocol: hyperparameters in
``__init__``, ``fit(demos, segmentation)`` learns ``rewards_``, a list of
:class:`swirl_wrappers.QuadraticReward` (one per segment, segment ``i`` leading to region ``i``).
:func:`segment_states` cuts the demonstrations into segments with the same Markov segmentation
function the runtime uses, so any learner (the model-free one here, MaxEnt-IRL ones later) sees
exactly the segments an agent will be rewarded on.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from numbers import Real
from typing import Any, ClassVar

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval, StrOptions

from sb3_swirl.demos import Demonstration, as_demonstrations
from sb3_swirl.segmentation import (
    StrictParamsMixin,
    TransitionStateClustering,
    segment_boundaries,
)
from swirl_wrappers import QuadraticReward, RBFFeatures, Region, TaskModel


def _resolve(
    segmentation: Any, features: RBFFeatures | None
) -> tuple[list[Region], Callable[[np.ndarray], np.ndarray]]:
    """Regions and the state -> task-space map of a fitted segmenter, task model or regions."""
    if isinstance(segmentation, TransitionStateClustering):
        if not hasattr(segmentation, "regions_"):
            raise ValueError("the TransitionStateClustering is not fitted; call fit(demos) first")
        return list(segmentation.regions_), segmentation.transform_states
    if isinstance(segmentation, TaskModel):
        return list(segmentation.regions), segmentation.featurize
    regions = list(segmentation) if isinstance(segmentation, Iterable) else []
    if not regions or not all(isinstance(r, Region) for r in regions):
        raise ValueError(
            "segmentation must be a fitted TransitionStateClustering, a TaskModel or a "
            f"non-empty sequence of Region, got {type(segmentation).__name__}"
        )
    if features is None:
        return regions, lambda s: s
    return regions, features


def segment_states(
    demos: Sequence[Demonstration],
    segmentation: Any,
    features: RBFFeatures | None = None,
) -> tuple[list[list[np.ndarray]], list[Region]]:
    """Cut every demonstration into the segments of a learned segmentation.

    Segment ``i`` of a demonstration holds the states after region ``i - 1`` was reached up to
    and including the first state in region ``i`` (Markov segmentation function, as
    :meth:`swirl_wrappers.TaskModel.segment_indices`). A demonstration that never reaches
    region ``i`` puts all its remaining states in segment ``i`` and none in later segments.

    Parameters
    ----------
    demos : list of Demonstration
    segmentation : fitted TransitionStateClustering, TaskModel or sequence of Region
    features : RBFFeatures, optional
        Feature map of a bare sequence of regions (ignored otherwise).

    Returns
    -------
    segments : list (per segment) of lists (per demonstration) of task-space state arrays
    regions : list of Region
    """
    regions, featurize = _resolve(segmentation, features)
    segments: list[list[np.ndarray]] = [[] for _ in regions]
    for i, demo in enumerate(demos):
        x = featurize(demo.observations)
        if x.shape[-1] != regions[0].mean.size:
            raise ValueError(
                f"demo {i}: states map to {x.shape[-1]} task-space dims but the regions live "
                f"in {regions[0].mean.size}"
            )
        bounds = segment_boundaries(x, regions)
        start = 0
        for j, b in enumerate(bounds):
            end = len(x) if b < 0 else int(b) + 1
            segments[j].append(x[start:end])
            if b < 0:
                break
            start = end
    return segments, regions


class RewardLearner(BaseEstimator, ABC):
    """Protocol of the reward learners: ``fit(demos, segmentation)`` sets ``rewards_``.

    Subclasses (the model-free :class:`QuadraticRewardLearner`; MaxEnt-IRL learners for fully
    observed demonstrations) implement :meth:`fit` and may use :func:`segment_states`.
    """

    rewards_: list[QuadraticReward]

    @abstractmethod
    def fit(
        self, demos: Any, segmentation: Any, features: RBFFeatures | None = None
    ) -> RewardLearner:
        """Learn one :class:`swirl_wrappers.QuadraticReward` per segment into ``rewards_``."""


class QuadraticRewardLearner(StrictParamsMixin, RewardLearner):
    """Model-free local rewards for state-only demonstrations (§6.1, eq. 1).

    For segment ``i`` the reward is ``R_i(x) = -(x - mu_i)^T Psi_i (x - mu_i)`` where ``mu_i``
    is the centre of region ``i`` (the region the segment leads to) and

    * ``metric="mahalanobis"``: ``Psi_i`` is the regularised inverse covariance of the
      segment's task-space states over all demonstrations (eq. 1 writes the uncentred second
      moment; the text means the covariance, which is used here), so deviation along
      directions the demonstrator kept steady costs more;
    * ``metric="euclidean"``: ``Psi_i = I``.

    Parameters
    ----------
    metric : {"mahalanobis", "euclidean"}, default "mahalanobis"
    regularization : float, default 1e-3
        Added to the segment covariance before inversion, relative to the variance of all
        demonstration states along each axis (plus a tiny absolute floor), so segments with
        few states or a constant coordinate still give a finite ``Psi``.
    normalize : bool, default True
        Scale each ``Psi_i`` so the mean reward over the demonstrations' states in segment
        ``i`` is ``-1``. Raw Mahalanobis rewards range over orders of magnitude between
        segments and tasks; normalised, a reward of ``-1`` means "as far from the next region
        as a demonstrator typically was", a sane scale for RL.

    Attributes
    ----------
    rewards_ : list of QuadraticReward
    segment_sizes_ : list of int
        Number of demonstration states used for each segment.

    Examples
    --------
    >>> from sb3_swirl.demos import make_piecewise_linear_demos
    >>> from sb3_swirl.segmentation import TransitionStateClustering
    >>> demos, _ = make_piecewise_linear_demos(n_demos=8, random_state=0)
    >>> tsc = TransitionStateClustering(random_state=0).fit(demos)
    >>> learner = QuadraticRewardLearner().fit(demos, tsc)
    >>> len(learner.rewards_) == len(tsc.regions_)
    True
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "metric": [StrOptions({"mahalanobis", "euclidean"})],
        "regularization": [Interval(Real, 0, np.inf, closed="neither")],
        "normalize": ["boolean"],
    }

    def __init__(
        self, metric: str = "mahalanobis", regularization: float = 1e-3, normalize: bool = True
    ) -> None:
        self.metric = metric
        self.regularization = regularization
        self.normalize = normalize

    def fit(
        self, demos: Any, segmentation: Any, features: RBFFeatures | None = None
    ) -> QuadraticRewardLearner:
        """Learn the local rewards.

        Parameters
        ----------
        demos : anything :func:`sb3_swirl.demos.as_demonstrations` accepts
            The same states the segmentation was fitted on (or full observations when
            ``segmentation`` is a TaskModel with ``dims``).
        segmentation : fitted TransitionStateClustering, TaskModel or sequence of Region
        features : RBFFeatures, optional
            Feature map of a bare sequence of regions.

        Returns
        -------
        self
        """
        self._validate_params()
        demos = as_demonstrations(demos)
        segments, regions = segment_states(demos, segmentation, features)
        pooled = np.concatenate([s for seg in segments for s in seg])
        p = pooled.shape[1]
        floor = self.regularization * np.diag(pooled.var(axis=0)) + 1e-12 * np.eye(p)
        rewards, sizes = [], []
        for seg, region in zip(segments, regions, strict=True):
            # A segment no demonstration entered falls back on the statistics of all states.
            x = np.concatenate(seg) if seg else pooled
            sizes.append(sum(len(s) for s in seg))
            if self.metric == "euclidean":
                weight = np.eye(p)
            else:
                cov = np.cov(x, rowvar=False).reshape(p, p) if len(x) > 1 else np.zeros((p, p))
                weight = np.linalg.inv(cov + floor)
                weight = (weight + weight.T) / 2
            if self.normalize:
                diff = x - region.mean
                mean_cost = float(np.mean(np.einsum("ij,jk,ik->i", diff, weight, diff)))
                if mean_cost > 1e-12:
                    weight = weight / mean_cost
            rewards.append(QuadraticReward(target=region.mean, weight=weight))
        self.rewards_ = rewards
        self.segment_sizes_ = sizes
        return self
