"""Features extractors: radial basis functions (the paper's Q representation) and a choice of
keys of a Dict observation."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor

from swirl_wrappers._validation import check_real
from swirl_wrappers.wrappers import SEGMENT_KEY


class RBFFeaturesExtractor(BaseFeaturesExtractor):
    """Gaussian RBF features on a grid of centres, one copy per segment index.

    The paper approximates Q with radial basis functions (Appendix A.1: ``k = 5, sigma = 0.1`` for
    parking; B.1: ``k = 25, sigma = 0.25`` for acrobot). Here ``k`` is read as the number of
    centres *per state dimension*: the state part of the observation is scaled to ``[0, 1]^d``
    with ``low``/``high`` and the centres form a ``k^d`` grid on that box. A per-dimension
    sequence gives a coarser grid where the full one is too large (``25^4`` for acrobot).

    With ``normalize=True`` the features are a softmax over ``-||x - c||^2 / (2 sigma^2)``: a
    partition of unity that never vanishes far from every centre (plain Gaussians underflow to 0
    in float32 a few ``sigma`` away, which would leave Q constant there).

    The trailing ``n_indices`` entries of a SWIRL observation (the one-hot segment index) are not
    smoothed: the output is the outer product ``rbf(state) ⊗ one_hot``, flattened, so a linear
    head on top (``net_arch=[]``) is one linear Q-function per segment, as in the paper's
    segmented Q-learning. ``SwirlDQN`` fills ``n_indices`` from its task when it is not given.

    Parameters
    ----------
    observation_space : gymnasium.spaces.Box
        Flat observation space (state, then ``n_indices`` one-hot entries).
    n_centers_per_dim : int or sequence of int
        Grid size ``k`` per state dimension.
    sigma : float
        Bandwidth, in units of the normalised box.
    low, high : array-like, optional
        Box used to normalise the state part; defaults to the space's bounds, which must then be
        finite.
    n_indices : int
        Number of trailing one-hot entries (``task.n_indices``); 0 for a plain observation.
    normalize : bool
        Normalise the RBF activations to sum to one.

    Examples
    --------
    >>> import numpy as np, torch as th
    >>> from gymnasium import spaces
    >>> space = spaces.Box(low=np.array([0, 0, 0, 0, 0]), high=np.array([1, 1, 1, 1, 1]),
    ...                    dtype=np.float32)
    >>> fe = RBFFeaturesExtractor(space, n_centers_per_dim=3, sigma=0.2, n_indices=3)
    >>> fe.features_dim  # 3 * 3 centres times 3 segment indices
    27
    >>> fe(th.tensor([[0.5, 0.5, 0.0, 1.0, 0.0]])).shape
    torch.Size([1, 27])
    """

    def __init__(
        self,
        observation_space: spaces.Box,
        n_centers_per_dim: int | Sequence[int] = 5,
        sigma: float = 0.1,
        low: Sequence[float] | np.ndarray | None = None,
        high: Sequence[float] | np.ndarray | None = None,
        n_indices: int = 0,
        normalize: bool = True,
    ) -> None:
        if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 1:
            raise ValueError(
                f"RBFFeaturesExtractor needs a flat Box observation space, got {observation_space}"
            )
        obs_dim = observation_space.shape[0]
        n_indices = int(n_indices)
        if not 0 <= n_indices < obs_dim:
            raise ValueError(
                f"n_indices={n_indices} must be in [0, {obs_dim}) for {obs_dim}-dim observations"
            )
        state_dim = obs_dim - n_indices
        low = np.asarray(observation_space.low[:state_dim] if low is None else low, np.float64)
        high = np.asarray(observation_space.high[:state_dim] if high is None else high, np.float64)
        if low.shape != (state_dim,) or high.shape != (state_dim,):
            raise ValueError(
                f"low/high must have shape ({state_dim},) (the state part), "
                f"got {low.shape} and {high.shape}"
            )
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high > low)):
            raise ValueError(
                "the state box must be finite with high > low; the observation space has "
                f"low={low}, high={high}: pass low=... and high=... explicitly"
            )
        counts = np.broadcast_to(np.asarray(n_centers_per_dim, dtype=np.int64), (state_dim,))
        if np.any(counts < 1):
            raise ValueError(f"n_centers_per_dim must be >= 1, got {n_centers_per_dim}")
        sigma = check_real("sigma", sigma, low=0.0, low_open=True)
        # One centre in a dimension sits mid-box; k >= 2 centres span it edge to edge.
        axes = [np.linspace(0.0, 1.0, int(k)) if k > 1 else np.array([0.5]) for k in counts]
        centers = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, state_dim)
        n_rbf = len(centers)
        super().__init__(observation_space, features_dim=n_rbf * max(n_indices, 1))
        self.state_dim = state_dim
        self.n_indices = n_indices
        self.sigma = float(sigma)
        self.normalize = normalize
        self.register_buffer("centers", th.as_tensor(centers, dtype=th.float32))
        self.register_buffer("low", th.as_tensor(low, dtype=th.float32))
        self.register_buffer("scale", th.as_tensor(high - low, dtype=th.float32))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        x = (observations[:, : self.state_dim] - self.low) / self.scale
        # explicit squared distances: cdist's gradient is NaN at a distance of exactly 0
        sq = (x.unsqueeze(1) - self.centers).square().sum(dim=2)
        logits = -sq / (2.0 * self.sigma**2)
        rbf = th.softmax(logits, dim=1) if self.normalize else logits.exp()
        if self.n_indices == 0:
            return rbf
        one_hot = observations[:, self.state_dim :]
        return (rbf.unsqueeze(2) * one_hot.unsqueeze(1)).flatten(1)


class KeysExtractor(CombinedExtractor):
    """SB3's :class:`~stable_baselines3.common.torch_layers.CombinedExtractor` over some keys of a
    Dict observation: the network reads only those.

    The other keys stay in the observation, where others need them: a goal env's
    ``achieved_goal`` and ``desired_goal`` for ``compute_reward`` and hindsight relabelling, a
    supervisor's view for demos. On a SWIRL-wrapped env the segment key is always read. The
    features are joined in the Dict's (sorted) key order, as :attr:`keys` lists them.

    A network that reads no goal cannot learn from relabelled goals: give HER runs every key
    (``sb3-swirl reproduce`` drops this extractor for them).

    Parameters
    ----------
    observation_space : gymnasium.spaces.Dict
        The whole observation space.
    keys : str or sequence of str
        The keys the network reads (at least one besides the segment key).
    cnn_output_dim, normalized_image
        As for ``CombinedExtractor`` (image keys).

    Raises
    ------
    TypeError
        If the observation space is not a Dict.
    ValueError
        If ``keys`` is empty or names a key the observation does not have.

    Examples
    --------
    >>> import numpy as np, torch as th
    >>> from gymnasium import spaces
    >>> space = spaces.Dict({"observation": spaces.Box(-1, 1, (3,)),
    ...                      "desired_goal": spaces.Box(-1, 1, (3,))})
    >>> fe = KeysExtractor(space, keys=["observation"])
    >>> fe.features_dim
    3
    >>> fe({"observation": th.ones(1, 3), "desired_goal": th.zeros(1, 3)})
    tensor([[1., 1., 1.]])
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        keys: Sequence[str],
        cnn_output_dim: int = 256,
        normalized_image: bool = False,
    ) -> None:
        if not isinstance(observation_space, spaces.Dict):
            raise TypeError(
                f"KeysExtractor reads keys of a Dict observation, got {observation_space}"
            )
        keys = [keys] if isinstance(keys, str) else list(keys)
        if not keys:
            raise ValueError("KeysExtractor needs at least one key")
        unknown = [key for key in keys if key not in observation_space.spaces]
        if unknown:
            raise ValueError(
                f"KeysExtractor: {unknown} not among the observation's keys "
                f"{list(observation_space.spaces)}"
            )
        if SEGMENT_KEY in observation_space.spaces and SEGMENT_KEY not in keys:
            keys.append(SEGMENT_KEY)
        chosen = spaces.Dict({key: observation_space[key] for key in keys})
        super().__init__(chosen, cnn_output_dim=cnn_output_dim, normalized_image=normalized_image)
        #: the keys read, in the order their features are joined
        self.keys = list(chosen.spaces)
