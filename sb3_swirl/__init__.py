"""sb3-swirl: SWIRL (Sequential Windowed Inverse Reinforcement Learning) for Stable-Baselines3.

Data flows one way: demonstrations -> :class:`TransitionStateClustering` (regions) ->
:class:`QuadraticRewardLearner` (local rewards) -> :class:`~swirl_wrappers.TaskModel` ->
:class:`~swirl_wrappers.SwirlWrapper` -> :class:`SwirlDQN` (or any SB3 algorithm).

Importing the package registers the ``sb3_swirl/`` gymnasium environments.
"""

from sb3_swirl import envs  # noqa: F401  (registers the sb3_swirl/ gymnasium envs)
from sb3_swirl.baselines import BCPolicy, run_method
from sb3_swirl.callbacks import SegmentProgressCallback, TaskEvalCallback
from sb3_swirl.datasets import make_switching_demos
from sb3_swirl.demos import (
    Demonstration,
    DemoWarning,
    as_demonstrations,
    check_demos_agree,
    check_demos_fit_spaces,
    load_demos,
    save_demos,
    to_imitation,
    to_minari,
)
from sb3_swirl.dqn import SwirlDQN
from sb3_swirl.envs import (
    DVRKLineCuttingEnv,
    DVRKTensioningEnv,
    FetchDiscreteEnv,
    NoisyAcrobotEnv,
    ParallelParkingEnv,
)
from sb3_swirl.features import KeysExtractor, RBFFeaturesExtractor
from sb3_swirl.fitting import fit_task
from sb3_swirl.inverse_dynamics import InverseDynamics
from sb3_swirl.plotting import (
    plot_cut_paths,
    plot_rewards,
    plot_segments,
    plot_sheet,
    plot_transitions,
)
from sb3_swirl.rewards import MaxEntIRLRewardLearner, QuadraticRewardLearner, RewardLearner
from sb3_swirl.runner import run_sweep
from sb3_swirl.segmentation import (
    SegmentationWarning,
    TransitionStateClustering,
    dynamics_cv_error,
    phases_indicator,
    ruptures_indicator,
    switch_scores,
)
from sb3_swirl.supervisors import collect_demos
from sb3_swirl.vec_env import SwirlVecEnv, get_swirl_attr, make_swirl_env, trained_task
from swirl_wrappers import RewardConfig, SwirlVectorWrapper, SwirlWrapper, TaskModel

__all__ = [
    "BCPolicy",
    "DVRKLineCuttingEnv",
    "DVRKTensioningEnv",
    "DemoWarning",
    "Demonstration",
    "FetchDiscreteEnv",
    "InverseDynamics",
    "KeysExtractor",
    "MaxEntIRLRewardLearner",
    "NoisyAcrobotEnv",
    "ParallelParkingEnv",
    "QuadraticRewardLearner",
    "RBFFeaturesExtractor",
    "RewardConfig",
    "RewardLearner",
    "SegmentProgressCallback",
    "SegmentationWarning",
    "SwirlDQN",
    "SwirlVecEnv",
    "SwirlVectorWrapper",
    "SwirlWrapper",
    "TaskEvalCallback",
    "TaskModel",
    "TransitionStateClustering",
    "as_demonstrations",
    "check_demos_agree",
    "check_demos_fit_spaces",
    "collect_demos",
    "dynamics_cv_error",
    "fit_task",
    "get_swirl_attr",
    "load_demos",
    "make_swirl_env",
    "make_switching_demos",
    "phases_indicator",
    "plot_cut_paths",
    "plot_rewards",
    "plot_segments",
    "plot_sheet",
    "plot_transitions",
    "run_method",
    "run_sweep",
    "ruptures_indicator",
    "save_demos",
    "switch_scores",
    "to_imitation",
    "to_minari",
    "trained_task",
]
__version__ = "0.1.0"
