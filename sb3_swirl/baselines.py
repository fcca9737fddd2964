"""Comparison methods of the paper: pure demonstration (behavioural cloning), with or without
SWIRL's segments.

A :class:`BCPolicy` predicts like a Stable-Baselines3 model (``predict(obs, deterministic)``),
so one evaluation loop scores it beside SwirlDQN and DQN. Fit it on the raw observations for
the paper's *behavioural cloning*, or on SWIRL-lifted observations (:func:`lifted_demos`) and
run it inside a :class:`~swirl_wrappers.SwirlWrapper` for its *segmented demonstrations*
(a clone per segment, no refinement).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sb3_swirl.demos import Demonstration
from swirl_wrappers import Lifter, TaskModel
from swirl_wrappers._validation import check_option


class BCPolicy:
    """Behavioural cloning: a scikit-learn classifier of the demo actions (standardised inputs).

    Parameters
    ----------
    classifier : {"mlp", "svm"}, default "mlp"
        A multi-layer perceptron (:class:`sklearn.neural_network.MLPClassifier`, ReLU units,
        Adam) or a support vector machine with an RBF kernel (:class:`sklearn.svm.SVC`, the
        paper's SVM baseline).
    hidden_layer_sizes : tuple of int, default (64, 64)
        The perceptron's hidden layers.
    max_iter : int, default 2000
    random_state : int, optional
        Seeds the network's initialisation and batches.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0], [0.1], [0.9], [1.0]])
    >>> policy = BCPolicy(random_state=0).fit(x, np.array([0, 0, 1, 1]))
    >>> int(policy.predict(np.array([0.95]))[0])
    1
    """

    def __init__(
        self,
        classifier: str = "mlp",
        hidden_layer_sizes: tuple[int, ...] = (64, 64),
        max_iter: int = 2000,
        random_state: int | None = None,
    ) -> None:
        self.classifier = check_option("classifier", classifier, ("mlp", "svm"))
        self.hidden_layer_sizes = hidden_layer_sizes
        self.max_iter = max_iter
        self.random_state = random_state

    def fit(self, observations: np.ndarray, actions: np.ndarray) -> BCPolicy:
        """Fit on observations (n, d) and their discrete actions (n,); returns ``self``."""
        from sklearn.neural_network import MLPClassifier
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler
        from sklearn.svm import SVC

        observations = np.asarray(observations, dtype=np.float64)
        actions = np.asarray(actions)
        if observations.ndim != 2 or actions.shape != (len(observations),):
            raise ValueError(
                "observations must have shape (n, d) and actions shape (n,), got "
                f"{observations.shape} and {actions.shape}"
            )
        if self.classifier == "svm":
            classifier = SVC(kernel="rbf", random_state=self.random_state)
        else:
            classifier = MLPClassifier(
                self.hidden_layer_sizes, max_iter=self.max_iter, random_state=self.random_state
            )
        self.model_ = make_pipeline(StandardScaler(), classifier).fit(observations, actions)
        return self

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[Any, None]:
        """The cloned action for one observation (d,) or a batch (n, d), as SB3's ``predict``
        returns it (the second item, SB3's recurrent state, is always None)."""
        x = np.asarray(observation, dtype=np.float64)
        action = self.model_.predict(x.reshape(-1, x.shape[-1]))
        return (action if x.ndim == 2 else action[0]), None


def lifted_demos(
    demos: Sequence[Demonstration], task: TaskModel, observation_space: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The demos' (observation, action) pairs as an agent in a SwirlWrapper sees them: each
    observation with the one-hot of its segment appended (segments as the wrapper tracks them).

    ``observation_space`` is the env's own (unlifted) space. Returns observations (n, d + k)
    and actions (n,).
    """
    lifter = Lifter(observation_space, task)
    observations, actions = [], []
    for demo in demos:
        states = demo.observations[:-1]
        index = task.segment_indices(demo.observations)[:-1]
        observations.append(lifter.lift(states, index))
        actions.append(demo.actions)
    return np.concatenate(observations), np.concatenate(actions)
