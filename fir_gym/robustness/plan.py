"""What ``fir-gym benchmark-robustness`` runs: plants, kinds, conditions, strengths, budgets.

**Plants** (:data:`PLANTS`): all five, each with the episode settings of the controller
benchmark (randomised starts where the paper's start is a single point, so that a policy
cannot memorise one trajectory) and its estimators:

* the **LQG grid** — no training — runs the LQR of the plant's nominal model
  (:class:`~fir_gym.controllers.LQGController`) on the true state and on *every*
  applicable estimator of the registry that estimates the current state (all but the
  FIR smoother), each plain and with an innovation gate (``gate=`` :data:`GATE`), under
  every condition at each of its three strengths, :data:`LQG_EPISODES` episodes each;
* the **learned grid** trains PPO (RecurrentPPO for ``recurrent``) on ``true``,
  ``measurement``, ``measurement-stack``, ``recurrent`` and the plant's learned
  estimator kinds (``ekf``/``kf``, ``ukf``, ``efir``/``fir``, and ``ufir`` where the
  model is linear), :data:`SEEDS` seeds each, in :data:`REGIMES`: on the nominal plant, and
  with a condition on during training (domain randomisation: ``mismatch`` and
  ``dropout`` at their middle strength). Every trained controller is evaluated under every
  condition and strength on :data:`EPISODES` shared episodes (the estimator kinds plain
  and gated: the gate changes the estimate, not the policy).

**Budget.** :data:`PLANTS` gives each plant's training steps; the whole learned grid is
sized for about three hours on two cores with ``--backend joblib`` (docs/robustness.md#budget
gives the arithmetic); ``--quick`` runs two plants' smallest grid with tiny budgets to
check the pipeline (its numbers mean nothing).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from fir_gym.conditions import CONDITIONS, get_condition

#: the innovation gate's probability in the benchmark (a reading whose NIS is above the
#: 99.9 % χ² quantile is treated as missing)
GATE = 0.999
#: closed-loop episodes per (plant, estimator, gate, condition, strength) of the LQG grid
LQG_EPISODES = 100
#: learned controllers: seeds per (plant, kind, regime) and evaluation episodes (five seeds,
#: as the controller benchmark: the whole learned grid then takes about three hours on two
#: cores, docs/robustness.md#budget)
SEEDS = 5
EPISODES = 20
#: the evaluation episodes' first seed (sub-env ``i`` plays seed ``EVAL_SEED + i``)
EVAL_SEED = 10_000
#: the training regimes: ``nominal``, and domain randomisation with a condition at its
#: middle strength
REGIMES: dict[str, tuple[str, float] | None] = {
    "nominal": None,
    "dr-mismatch": ("mismatch", CONDITIONS["mismatch"].strengths[1]),
    "dr-dropout": ("dropout", CONDITIONS["dropout"].strengths[1]),
}
#: the learned kinds without an estimator
PLAIN_KINDS = ("true", "measurement", "measurement-stack", "recurrent")
#: the estimators that do not estimate the current state (never in the grids)
NOT_CURRENT = ("fir-smoother",)


@dataclass(frozen=True)
class PlantPlan:
    """One plant's part of the benchmark."""

    env_id: str
    env_kwargs: dict[str, Any]
    steps: int
    learned_estimators: tuple[str, ...]
    estimator_kwargs: dict[str, dict[str, Any]] = field(default_factory=dict)


#: the windowed filters' window on every plant: 50 measurements, the best of 10, 20 and 50 for
#: the LQG's nominal return on every plant (docs/robustness.md#estimator-settings; paper
#: 000's window of 10 leaves the Orbit velocity at RMSE 0.34 and the oscillator's damping
#: state at 94)
WINDOW: dict[str, dict[str, Any]] = {name: {"horizon": 50}
                                     for name in ("efir", "fir", "ufir", "rfir")}

PLANTS: dict[str, PlantPlan] = {p.env_id: p for p in (
    PlantPlan("fir_gym/Orbit-v0",
              # randomised starts, 3-time-unit episodes (the controller benchmark's)
              {"max_episode_steps": 300, "initial_state_cov": [[0.0025, 0.0], [0.0, 0.04]]},
              200_000, ("ekf", "ukf", "efir"), WINDOW),
    PlantPlan("fir_gym/UncertainOscillator-v0",
              # the clean plant (the paper's own δ window is the burst condition's job), in
              # eq (29)'s "rate" reading, the one the burst generalises (the printed one
              # multiplies the state by 1 + δ per step: 1.15⁵⁰ ≈ 1e3, no controller
              # survives it), randomised starts
              {"delta_schedule": (), "uncertainty": "rate",
               "initial_state_cov": [[0.01, 0, 0], [0, 0.04, 0], [0, 0, 0.0025]]},
              150_000, ("ekf", "ukf", "efir"), WINDOW),
    PlantPlan("fir_gym/CarrierMotion-v0",
              # 30 s episodes (about three periods of the motion) from the stationary
              # distribution
              {"max_episode_steps": 300},
              150_000, ("kf", "ukf", "fir", "ufir"), WINDOW),
    PlantPlan("fir_gym/VanDerPol-v0", {}, 150_000, ("ekf", "ukf", "efir"), WINDOW),
    PlantPlan("fir_gym/PendulumSlider-v0",
              # 100 Hz control (10 MuJoCo steps of 1 ms per env step), 5 s episodes
              {"frame_skip": 10, "max_episode_steps": 500},
              150_000, ("ekf", "ukf", "efir"), WINDOW),
)}

@dataclass(frozen=True)
class QuickPlan:
    """``--quick``: two plants, each condition's middle strength, two estimators in the LQG
    grid, tiny budgets (the numbers mean nothing; the pipeline is checked)."""

    plants: tuple[str, ...] = ("fir_gym/Orbit-v0", "fir_gym/CarrierMotion-v0")
    steps: int = 2048
    seeds: int = 1
    episodes: int = 4
    lqg_episodes: int = 8
    lqg_estimators: int = 2
    regimes: tuple[str, ...] = ("nominal", "dr-dropout")
    kinds: tuple[str, ...] = ("true", "measurement-stack")


QUICK = QuickPlan()


def registered_id(env_id: str) -> str:
    """The Gymnasium id of ``env_id``, importing its module first when it is written
    ``module:id`` (Gymnasium's own convention for ``gym.make``: the module registers the
    plant when imported); ValueError naming what is missing."""
    import importlib

    import gymnasium as gym

    module, _, bare = env_id.rpartition(":")
    if module:
        try:
            importlib.import_module(module)
        except ImportError as err:
            raise ValueError(f"plant {env_id!r}: cannot import module {module!r} ({err})") \
                from None
    if bare not in gym.registry:
        raise ValueError(f"unknown benchmark plant {env_id!r}: not a registered id (the "
                         f"benchmark's plants are {', '.join(PLANTS)}; a plant of your own: "
                         "module:id, where importing module registers id)")
    return bare


def short_name(env_id: str) -> str:
    """A plant's name in folders and tables (``module:ns/Name-v0`` → ``Name-v0``)."""
    return env_id.rpartition(":")[2].split("/")[-1]


#: the training steps of a plant the benchmark was not tuned for (those of most paper plants)
DEFAULT_STEPS = 150_000
#: the learned grid's estimators on such a plant: the first applicable of each group
DEFAULT_LEARNED = (("kf", "ekf"), ("ukf",), ("fir", "efir"))


@functools.cache
def plant_plan(env_id: str) -> PlantPlan:
    """The plan of a plant: its entry of :data:`PLANTS`, else (a plant of the user's own,
    ``fir_gym.register_plant``) its registered options, :data:`DEFAULT_STEPS`, the windowed
    filters' :data:`WINDOW`, and the first applicable estimator of each group of
    :data:`DEFAULT_LEARNED` for the learned grid. ValueError for an id that is not a
    fir-gym plant."""
    if env_id in PLANTS:
        return PLANTS[env_id]
    import warnings

    import gymnasium as gym

    from fir_gym.envs._base import PlantEnv

    registered_id(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id)
    try:
        if not isinstance(env.unwrapped, PlantEnv):
            raise ValueError(f"plant {env_id!r} is not a fir-gym plant (a PlantEnv: "
                             "fir_gym.register_plant builds one from a model)")
        applicable = _applicable(env.unwrapped, {})
    finally:
        env.close()
    learned = tuple(next(name for name in group if name in applicable)
                    for group in DEFAULT_LEARNED if any(name in applicable for name in group))
    return PlantPlan(env_id, {}, DEFAULT_STEPS, learned, WINDOW)


def episode_steps(env_id: str) -> int:
    """The benchmark's episode length on a plant (its ``max_episode_steps`` option, else the
    registered time limit)."""
    import gymnasium as gym

    steps = PLANTS[env_id].env_kwargs.get("max_episode_steps") if env_id in PLANTS else None
    if steps is None:
        steps = gym.spec(registered_id(env_id)).max_episode_steps
    if steps is None:
        raise ValueError(f"{env_id} has no episode length (max_episode_steps)")
    return int(steps)


def settings(conditions: Sequence[str], *, quick: bool = False
             ) -> list[tuple[str, float]]:
    """Every ``(condition, strength)`` evaluated: ``nominal`` once, each other condition at
    each of its strengths (``--quick``: the middle one)."""
    out: list[tuple[str, float]] = []
    for name in conditions:
        condition = get_condition(name)
        if name == "nominal":
            out.append(("nominal", 0.0))
            continue
        strengths = condition.strengths
        if quick:
            strengths = (strengths[len(strengths) // 2],)
        out += [(name, float(s)) for s in strengths]
    return out


def applicable_estimators(env_id: str) -> list[str]:
    """Every registered estimator that builds on the plant's model and estimates its
    current state (the LQG grid's)."""
    import warnings

    import gymnasium as gym

    plan = PLANTS.get(env_id)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id, **plan.env_kwargs if plan else {})
    try:
        return _applicable(env.unwrapped, plan.estimator_kwargs if plan else {})
    finally:
        env.close()


def _applicable(plant: Any, options: dict[str, dict[str, Any]]) -> list[str]:
    """The estimators of the registry (those estimating the current state) that build on
    ``plant`` with their ``options``."""
    from fir_gym.estimators import estimator_class, estimator_names
    from fir_gym.wrappers.estimator_observation import build_estimator

    names = []
    for name in estimator_names():
        if name in NOT_CURRENT:
            continue
        try:
            build_estimator(estimator_class(name), lambda attr: getattr(plant, attr, None),
                            dict(options.get(name, {})))
        except (TypeError, ValueError):
            continue
        names.append(name)
    return names


def check_selection(plants: Sequence[str] | None, conditions: Sequence[str] | None
                    ) -> tuple[list[str], list[str]]:
    """The plants and conditions asked for, checked (ValueError naming a bad one)."""
    chosen = list(plants) if plants else list(PLANTS)
    for env_id in chosen:
        plant_plan(env_id)                  # a plant of the user's own is checked here
    names = list(conditions) if conditions else list(CONDITIONS)
    for name in names:
        get_condition(name)
    if "nominal" not in names:
        names.insert(0, "nominal")           # every comparison needs its nominal reference
    return chosen, names
