"""Training, evaluating and comparing controllers on true states, measurements or estimates.

* :func:`make_sb3_vec_env` — a stable-baselines3 ``VecEnv`` driven by the plant's native
  batched env and one batched estimator (:mod:`.vec_env`);
* :class:`RunConfig`, :func:`train` — one run, saved in a folder (:mod:`.run`), with the
  per-plant hyperparameters of the shipped RL Zoo YAML (:mod:`.hyperparams`);
* :func:`evaluate` — returns and closed-loop estimation RMSE/ANEES (:mod:`.evaluation`);
* :func:`compare_controllers` — seeds × kinds as jobs on the runner (:mod:`.compare`);
* the kinds and their options (:mod:`.kinds`); IQM and bootstrap intervals
  (:mod:`.stats`); learning curves (:mod:`.curves`); the published benchmark
  (:mod:`.benchmark`).

Needs the ``rl`` extra (stable-baselines3, sb3-contrib, PyYAML; PyTorch first).
"""

from .compare import compare_controllers, make_configs
from .curves import learning_curve, plot_learning_curves
from .evaluation import Evaluation, evaluate, make_eval_env
from .kinds import CLASSICAL, LEARNED_PLAIN, kind_names, kind_options
from .run import ALGORITHMS, RunConfig, train
from .vec_env import SB3VecEnv, make_sb3_vec_env, make_single_env

#: one env of a run's kind (``fir-gym watch`` replays a run on it)
make_env = make_eval_env

__all__ = ["ALGORITHMS", "CLASSICAL", "LEARNED_PLAIN", "Evaluation", "RunConfig", "SB3VecEnv",
           "compare_controllers", "evaluate", "kind_names", "kind_options", "learning_curve",
           "make_configs", "make_env", "make_eval_env", "make_sb3_vec_env", "make_single_env",
           "plot_learning_curves", "train"]
