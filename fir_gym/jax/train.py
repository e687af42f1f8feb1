"""PPO on a :mod:`fir_gym.jax` environment: every seed of one (plant, kind) in one program.

The JAX twin of ``fir-gym train`` (:func:`fir_gym.training.train`) for the plants and kinds
:data:`SUPPORTED` lists: rejax's PPO (``rejax.PPO``, which takes a gymnax environment
instance) with the shipped recipe of ``fir_gym/training/hyperparams/ppo.yml``
(:func:`recipe` reads it through :meth:`fir_gym.training.RunConfig.settings`, so
``steps``, ``n_envs`` and ``algo_kwargs`` override it as they do for stable-baselines3),
trained for all seeds at once: ``jax.jit(jax.vmap(one_seed))(initial_states)``
(:func:`over_seeds`; a single seed unbatched), one compiled
program (each seed's initial state made beforehand: :func:`initial_states`).
JAX's persistent compilation cache (:func:`enable_compilation_cache`; the folder
``$FIR_GYM_JAX_CACHE``, else ``$XDG_CACHE_HOME/fir-gym/jax``, else ``~/.cache/fir-gym/jax``)
keeps it on disk, so a second run of the same (plant, kind, recipe, seeds count) loads it
instead of compiling.

**The algorithm** is :class:`fir_gym.jax.ppo.SB3LikePPO` (rejax's PPO made stable-baselines3's
where that changes learning; its module says how, and what still differs: :data:`UNMATCHED`).

**The recurrent kind** trains :class:`fir_gym.jax.recurrent_ppo.RecurrentPPO` (this class
with sb3-contrib's LSTM policy) on the ``measurement`` env with the recipe of
``ppo_lstm.yml`` (:func:`recipe` with ``kind="recurrent"``: ``Recipe.lstm_hidden_size``);
the deterministic policy of every kind is :meth:`SB3LikePPO.policy_action`, with the state
it carries from step to step (:meth:`SB3LikePPO.policy_carry`: none, or the LSTMs').

**The networks compute in float32** (``Recipe.network_dtype``), as PyTorch's modules do in
stable-baselines3 and sb3-contrib: their parameters, activations, gradients and Adam's
moments; the plant, its filter, the normalisation statistics, the rewards, the values, the
returns and the advantages stay float64. ``network_dtype="float64"`` (:func:`recipe`,
:func:`train`) computes the networks in float64 too (what the tests compare with torch's
double-precision modules); a run folder saved before the field existed was trained that way
(its kernels stored in float32, widened exactly when it is read) and is read as such.

**Returns** are what :func:`fir_gym.training.evaluate` reports: the undiscounted sum of the
plant's raw reward over whole episodes, the policy deterministic (the Gaussian's mean,
clipped to the action box), observations through the run's final normalisation
statistics. The evaluation episodes are the same for every seed and checkpoint (keys from
``eval_seed``, 10 000 as ``fir-gym evaluate``'s default seed).
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from fir_gym._extras import require

require("jax", "gymnax", "rejax")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from .ppo import ADAM_EPS as ADAM_EPS  # noqa: E402  (the algorithm, re-exported)
from .ppo import NETWORK_DTYPES as NETWORK_DTYPES  # noqa: E402
from .ppo import UNMATCHED as UNMATCHED  # noqa: E402
from .ppo import Critic as Critic  # noqa: E402
from .ppo import Gymnax0 as Gymnax0  # noqa: E402
from .ppo import Policy as Policy  # noqa: E402
from .ppo import SB3LikePPO as SB3LikePPO  # noqa: E402
from .ppo import actor_loss as actor_loss  # noqa: E402
from .registry import PLANTS, make  # noqa: E402  (after fir_gym.jax: x64 on)

#: the env ids and kinds the JAX backend trains
#: (every plant's env kinds, and ``recurrent``: the ``measurement`` env with an LSTM policy,
#: :mod:`fir_gym.jax.recurrent_ppo`)
SUPPORTED: dict[str, tuple[str, ...]] = {env_id: (*p.kinds, "recurrent")
                                         for env_id, p in PLANTS.items()}
#: the algorithm settings the translation understands (stable-baselines3's PPO names)
KNOWN_ALGO_KWARGS = ("n_steps", "batch_size", "n_epochs", "learning_rate", "gamma",
                     "gae_lambda", "clip_range", "ent_coef", "vf_coef", "max_grad_norm",
                     "policy_kwargs", "normalize_advantage", "clip_range_vf")
#: stable-baselines3's PPO defaults for what the YAML leaves out
SB3_DEFAULTS = {"vf_coef": 0.5, "max_grad_norm": 0.5, "net_arch": (64, 64),
                "activation": "tanh", "log_std_init": 0.0}
#: VecNormalize's defaults
VECNORMALIZE_DEFAULTS = {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0,
                         "clip_reward": 10.0, "gamma": 0.99, "epsilon": 1e-8}
#: sb3-contrib's RecurrentActorCriticPolicy defaults the recurrent policy matches (the LSTM's
#: size may be set; the rest is the arrangement :mod:`fir_gym.jax.recurrent_ppo` builds)
LSTM_DEFAULTS = {"lstm_hidden_size": 256, "n_lstm_layers": 1, "shared_lstm": False,
                 "enable_critic_lstm": True}
CACHE_ENV = "FIR_GYM_JAX_CACHE"
#: a run folder's whole training state (:func:`save`, :func:`continue_training`)
STATE_FILE = "state.msgpack"


def supported_line() -> str:
    """One line naming what the JAX backend trains: each plant and its kinds."""
    return "; ".join(f"{env_id} with kind {', '.join(kinds)}"
                     for env_id, kinds in SUPPORTED.items())


def check_supported(env_id: str, kind: str, observation: str = "estimate") -> None:
    """Refuse, in one line, a plant, kind or observation the JAX backend does not train."""
    if env_id not in SUPPORTED or kind not in SUPPORTED[env_id]:
        raise ValueError(f"the jax backend trains {supported_line()} (PPO); not {env_id} "
                         f"with kind {kind}")
    if observation != "estimate":
        raise ValueError(f"the jax backend trains {supported_line()} (PPO), observing the "
                         "estimate only (rejax's networks take one array); not --observation "
                         f"{observation}")


# ---------------------------------------------------------------------------- the recipe
@dataclass(frozen=True)
class Recipe:
    """The PPO settings in rejax's names, translated from stable-baselines3's."""

    steps: int                    # asked for; trained: iterations * rollout
    num_envs: int
    num_steps: int
    num_minibatches: int
    num_epochs: int
    learning_rate: float
    gamma: float
    gae_lambda: float
    clip_eps: float
    ent_coef: float
    vf_coef: float
    max_grad_norm: float
    hidden_layer_sizes: tuple[int, ...]
    activation: str
    log_std_init: float
    normalize_observations: bool
    normalize_rewards: bool
    clip_obs: float
    clip_reward: float
    #: the LSTM's units of the ``recurrent`` kind's policy (sb3-contrib's
    #: ``lstm_hidden_size``); 0 for the feed-forward policy of every other kind
    lstm_hidden_size: int = 0
    #: the networks' arithmetic, a key of :data:`fir_gym.jax.ppo.NETWORK_DTYPES` (module
    #: docstring)
    network_dtype: str = "float32"

    @property
    def rollout(self) -> int:
        return self.num_envs * self.num_steps

    @property
    def iterations(self) -> int:
        """PPO iterations: as SB3, rollouts until at least ``steps`` (the last one whole)."""
        return max(1, math.ceil(self.steps / self.rollout))


def recipe(env_id: str = "fir_gym/Orbit-v0", *, steps: int | None = None,
           n_envs: int | None = None, algo_kwargs: dict[str, Any] | None = None,
           hyperparams: str | None = None, kind: str = "true",
           network_dtype: str = "float32") -> Recipe:
    """The shipped (or ``hyperparams``) PPO recipe of ``env_id`` in rejax's terms.

    Read through :meth:`fir_gym.training.RunConfig.settings`, so the overrides and the
    clamps (a rollout no longer than the budget) are the SB3 backend's; ``kind``
    ``"recurrent"`` reads RecurrentPPO's recipe (``ppo_lstm.yml``), every other kind PPO's.
    Refuses settings it cannot translate: an algorithm keyword it does not know, different
    actor and critic layers, value clipping, advantages not normalised, a minibatch size that
    does not divide the rollout; for ``recurrent`` an LSTM other than sb3-contrib's default
    arrangement (one layer, the critic's own), and a ``batch_size`` that is not a multiple of
    ``n_steps`` (:mod:`fir_gym.jax.recurrent_ppo`'s minibatches: rows of whole envs'
    sequences, masked to sb3-contrib's slices); a ``network_dtype`` not
    in :data:`fir_gym.jax.ppo.NETWORK_DTYPES`.
    """
    from fir_gym.training.run import RunConfig

    if network_dtype not in NETWORK_DTYPES:
        raise ValueError(f"network_dtype must be one of {list(NETWORK_DTYPES)}; got "
                         f"{network_dtype!r}")

    recurrent = kind == "recurrent"
    settings = RunConfig(env_id, "recurrent" if recurrent else "true", algo="ppo",
                         steps=steps, n_envs=n_envs, algo_kwargs=dict(algo_kwargs or {}),
                         hyperparams=hyperparams).settings()
    algo = dict(settings["algo_kwargs"])
    unknown = sorted(set(algo) - set(KNOWN_ALGO_KWARGS))
    if unknown:
        raise ValueError(f"the jax backend does not translate PPO setting(s) {unknown}; it "
                         f"knows {list(KNOWN_ALGO_KWARGS)}")
    if algo.get("clip_range_vf") is not None or not algo.get("normalize_advantage", True):
        raise ValueError("the jax backend trains with clip_range_vf=None and normalised "
                         "advantages (stable-baselines3's defaults)")
    policy = dict(algo.get("policy_kwargs") or {})
    known = {"log_std_init", "net_arch", "activation_fn", "ortho_init"}
    if recurrent:
        known |= set(LSTM_DEFAULTS)
    for key in sorted(set(policy) - known):
        raise ValueError(f"the jax backend does not translate policy_kwargs {key!r}")
    if policy.get("ortho_init", True) is not True:
        raise ValueError("the jax backend initialises as SB3's ortho_init=True only")
    for key, value in LSTM_DEFAULTS.items():
        if key != "lstm_hidden_size" and policy.get(key, value) != value:
            raise ValueError(f"the jax backend's recurrent policy has policy_kwargs {key}="
                             f"{value!r} only; got {policy[key]!r}")
    arch = policy.get("net_arch", SB3_DEFAULTS["net_arch"])
    if isinstance(arch, dict):
        if list(arch.get("pi", [])) != list(arch.get("vf", [])):
            raise ValueError("the jax backend's actor and critic have the same hidden layers; "
                             f"got net_arch {arch}")
        arch = arch.get("pi", [])
    activation = policy.get("activation_fn", SB3_DEFAULTS["activation"])
    if not isinstance(activation, str):                  # a torch.nn class (nn.Tanh)
        activation = activation.__name__.lower()
    n_envs_, n_steps = int(settings["n_envs"]), int(algo["n_steps"])
    batch = int(algo["batch_size"])
    if (n_envs_ * n_steps) % batch:
        raise ValueError(f"the jax backend needs batch_size ({batch}) to divide the rollout "
                         f"n_steps x n_envs ({n_steps} x {n_envs_})")
    minibatches = n_envs_ * n_steps // batch
    if recurrent and batch % n_steps:
        raise ValueError(f"the jax backend's recurrent PPO needs batch_size ({batch}) to be a "
                         f"multiple of n_steps ({n_steps}): its minibatches are rows of whole "
                         f"envs' sequences, masked to sb3-contrib's slices")
    norm = settings["normalize"]
    norm = None if norm is None else {**VECNORMALIZE_DEFAULTS, **norm}
    return Recipe(
        steps=int(settings["steps"]), num_envs=n_envs_, num_steps=n_steps,
        num_minibatches=minibatches, num_epochs=int(algo.get("n_epochs", 10)),
        learning_rate=float(algo.get("learning_rate", 3e-4)),
        gamma=float(algo.get("gamma", 0.99)), gae_lambda=float(algo.get("gae_lambda", 0.95)),
        clip_eps=float(algo.get("clip_range", 0.2)), ent_coef=float(algo.get("ent_coef", 0.0)),
        vf_coef=float(algo.get("vf_coef", SB3_DEFAULTS["vf_coef"])),
        max_grad_norm=float(algo.get("max_grad_norm", SB3_DEFAULTS["max_grad_norm"])),
        hidden_layer_sizes=tuple(int(n) for n in arch), activation=str(activation),
        log_std_init=float(policy.get("log_std_init", SB3_DEFAULTS["log_std_init"])),
        normalize_observations=bool(norm and norm["norm_obs"]),
        normalize_rewards=bool(norm and norm["norm_reward"]),
        clip_obs=float(norm["clip_obs"]) if norm else math.inf,
        clip_reward=float(norm["clip_reward"]) if norm else math.inf,
        lstm_hidden_size=int(policy.get("lstm_hidden_size", LSTM_DEFAULTS["lstm_hidden_size"]))
        if recurrent else 0, network_dtype=network_dtype)


def make_env(env_id: str, kind: str, env_kwargs: dict[str, Any] | None = None,
             kind_kwargs: dict[str, Any] | None = None) -> tuple[Any, Any]:
    """``(gymnax env, params)`` of a supported plant and kind (``kind_kwargs``: the kind's
    ``horizon``, :func:`fir_gym.jax.make`); ``recurrent`` observes the ``measurement``."""
    check_supported(env_id, kind)
    observed = "measurement" if kind == "recurrent" else kind
    return make(env_id, observed, kind_kwargs=kind_kwargs, **(env_kwargs or {}))


def make_algorithm(env: Any, params: Any, rec: Recipe) -> SB3LikePPO:
    """The PPO of ``rec`` on ``env`` (rejax's ``create``, then the SB3-like policy):
    :class:`SB3LikePPO`, or :class:`fir_gym.jax.recurrent_ppo.RecurrentPPO` where the recipe
    has an LSTM."""
    algorithm: Any = SB3LikePPO
    extra: dict[str, Any] = {}
    if rec.lstm_hidden_size:
        from .recurrent_ppo import RecurrentPPO

        algorithm, extra = RecurrentPPO, {"lstm_hidden_size": rec.lstm_hidden_size}
    algo = algorithm.create(**extra,
        env=Gymnax0(env), env_params=params, num_envs=rec.num_envs, num_steps=rec.num_steps,
        num_minibatches=rec.num_minibatches, num_epochs=rec.num_epochs,
        learning_rate=rec.learning_rate, gamma=rec.gamma, gae_lambda=rec.gae_lambda,
        clip_eps=rec.clip_eps, ent_coef=rec.ent_coef, vf_coef=rec.vf_coef,
        max_grad_norm=rec.max_grad_norm, normalize_observations=rec.normalize_observations,
        normalize_rewards=rec.normalize_rewards, reward_normalization_discount=rec.gamma,
        clip_obs=rec.clip_obs, clip_reward=rec.clip_reward,
        network_dtype=rec.network_dtype, total_timesteps=rec.iterations * rec.rollout,
        skip_initial_evaluation=True,
        agent_kwargs={"activation": rec.activation,
                      "hidden_layer_sizes": rec.hidden_layer_sizes})
    space = env.action_space(params)
    dtype = NETWORK_DTYPES[rec.network_dtype]
    actor = Policy(int(np.prod(space.shape)), (space.low, space.high),
                   rec.hidden_layer_sizes, algo.actor.activation, log_std_init=rec.log_std_init,
                   dtype=dtype)
    critic = Critic(rec.hidden_layer_sizes, algo.actor.activation, dtype=dtype)
    return algo.replace(actor=actor, critic=critic)


# ---------------------------------------------------------------------------- evaluation
def evaluate_policy(algo: SB3LikePPO, ts: Any, keys: Any) -> Any:
    """Undiscounted raw returns of the deterministic policy, one episode per key (each a
    full episode: ``max_steps_in_episode`` steps, masked after its end)."""
    env, params = algo.env, algo.env_params

    def episode(key: Any) -> Any:
        reset_key, key = jax.random.split(key)
        obs, state = env.reset(reset_key, params)

        def step(carry: Any, step_key: Any) -> Any:
            obs, state, memory, total, done, start = carry
            seen = obs
            if algo.normalize_observations:
                seen = algo.normalize_obs(ts.obs_rms_state, obs)
            memory, action = algo.policy_action(ts.actor_ts.params, memory, seen[None],
                                                jnp.asarray([start]))
            obs, state, reward, finished, _ = env.step(step_key, state, action[0], params)
            total = total + jnp.where(done, 0.0, jnp.squeeze(reward))
            return (obs, state, memory, total, done | finished, False), None

        steps = jax.random.split(key, params.max_steps_in_episode)
        first = (obs, state, algo.policy_carry(1), jnp.zeros(()), False, True)
        (_, _, _, total, _, _), _ = jax.lax.scan(step, first, steps)
        return total

    return jax.vmap(episode)(keys)


def _segments(iterations: int, checkpoints: int) -> tuple[int, int, int]:
    """``(k, per, tail)``: ``k`` checkpoints every ``per`` iterations, then ``tail`` more."""
    k = max(1, min(checkpoints, iterations))
    per = iterations // k
    return k, per, iterations - k * per


def training_program(algo: SB3LikePPO, rec: Recipe, *, checkpoints: int, curve_episodes: int,
                     episodes: int, eval_seed: int) -> Any:
    """The function of one seed's initial train state (:func:`initial_states`): ``(final
    train state, curve returns (k, curve_episodes), final returns (episodes,))``.

    The ``rec.iterations`` iterations are one loop, and the curve's evaluation after every
    ``per``-th of the first ``k · per`` is a ``lax.cond`` on the (unbatched) iteration count
    inside it (:func:`_segments`), so that the program holds PPO's iteration — its rollout,
    the env step, the update — once: the checkpoints' scan followed by a loop over the
    ``tail`` iterations held it twice, which XLA compiled twice (docs/jax.md,
    "Compilation"). The same iterations and evaluations in the same order: the same bits
    (``tests/jax/test_train.py``)."""
    k, per, _ = _segments(rec.iterations, checkpoints)
    curve_keys = jax.random.split(jax.random.PRNGKey(eval_seed), curve_episodes)
    final_keys = jax.random.split(jax.random.PRNGKey(eval_seed), episodes)

    def one_seed(ts: Any) -> Any:
        returns = jax.eval_shape(lambda ts: evaluate_policy(algo, ts, curve_keys), ts)
        curve = jnp.zeros((k, *returns.shape), returns.dtype)

        def iteration(i: Any, carry: Any) -> Any:
            ts, curve = carry
            ts = algo.train_iteration(ts)
            checkpoint = ((i + 1) % per == 0) & (i < k * per)
            curve = jax.lax.cond(
                checkpoint,
                lambda: curve.at[(i + 1) // per - 1].set(
                    evaluate_policy(algo, ts, curve_keys)),
                lambda: curve)
            return ts, curve

        ts, curve = jax.lax.fori_loop(0, rec.iterations, iteration, (ts, curve))
        return ts, curve, evaluate_policy(algo, ts, final_keys)

    return one_seed


def over_seeds(one_seed: Any) -> Any:
    """``one_seed`` over stacked seeds (a leading axis of every leaf): ``jax.vmap``, except
    that a single seed runs unbatched and gets its axis back — XLA's CPU backend compiles the
    networks' matrix products of a batch of one as batched products, measured 12-15 % slower
    per PPO iteration than the plain ones on the development machine (docs/jax.md). The same
    seed alone and among others agrees to round-off, not to the bit, as before."""
    batched = jax.vmap(one_seed)

    def run(states: Any) -> Any:
        if jax.tree.leaves(states)[0].shape[0] == 1:
            out = one_seed(jax.tree.map(lambda x: x[0], states))
            return jax.tree.map(lambda x: jnp.asarray(x)[None], out)
        return batched(states)

    return run


def initial_states(algo: SB3LikePPO, seeds: list[int]) -> Any:
    """Each seed's initial train state (``algo.init_state(PRNGKey(seed))``), stacked along a
    leading axis — computed one seed at a time, outside the vmapped training program: the
    networks' orthogonal initialisation is a QR factorisation, a LAPACK call, and a batch of
    them inside the program splits across XLA's CPU thread pool and can deadlock it
    (docs/jax.md, "A hang, found and avoided"); one at a time each runs on the calling thread."""
    init = jax.jit(algo.init_state)
    states = [init(jax.random.PRNGKey(s)) for s in seeds]
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *states)


# ---------------------------------------------------------------------------- the cache
def cache_dir() -> Path:
    """``$FIR_GYM_JAX_CACHE``, else ``$XDG_CACHE_HOME/fir-gym/jax``, else
    ``~/.cache/fir-gym/jax``."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fir-gym" / "jax"


def enable_compilation_cache(folder: str | Path | None = None) -> Path:
    """Turn on JAX's persistent compilation cache in ``folder`` (default :func:`cache_dir`)
    for every program (no minimum compile time or size): a process-wide JAX setting."""
    from jax.experimental.compilation_cache import compilation_cache

    path = Path(folder) if folder is not None else cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    if getattr(jax.config, "jax_compilation_cache_dir", None) not in (None, str(path)):
        # JAX opens its cache once, at the first compile: another folder needs a reset
        compilation_cache.reset_cache()
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


# ---------------------------------------------------------------------------- training
@dataclass
class JaxTraining:
    """The result of :func:`train` (or of :func:`load`, reading its run folder): per-seed
    learning curves and final returns, and the trained policies in ``train_state``."""

    env_id: str
    kind: str
    seeds: list[int]
    recipe: Recipe
    checkpoint_steps: list[int]               # env steps trained at each checkpoint
    curves: list[list[float]]                 # [seed][checkpoint]: mean eval return
    final_returns: list[list[float]]          # [seed][episode]
    compile_seconds: float                    # lowering + compiling (or loading from cache)
    train_seconds: float                      # running the compiled program
    cache: str | None
    train_state: Any = field(default=None, repr=False)   # the vmapped rejax state
    kind_kwargs: dict[str, Any] = field(default_factory=dict)   # the kind's options
    env_kwargs: dict[str, Any] = field(default_factory=dict)    # the plant's keywords
    #: the evaluation settings of the call (``checkpoints``, ``curve_episodes``,
    #: ``episodes``, ``eval_seed``): with the fields above, everything :func:`train` was given
    settings: dict[str, Any] = field(default_factory=dict)
    #: whether ``train_state`` is the whole training state (the optimisers, the statistics,
    #: the envs, the keys: :func:`continue_training` can go on from it), not only the policies
    resumable: bool = field(default=False, repr=False)

    @property
    def per_seed(self) -> list[float]:
        return [float(np.mean(r)) for r in self.final_returns]

    @property
    def iqm(self) -> float:
        """The IQM over the seeds' mean returns (:func:`fir_gym.training.stats.iqm`, the SB3
        backend's)."""
        from fir_gym.training.stats import iqm

        return iqm(self.per_seed)

    @property
    def steps_trained(self) -> int:
        return self.recipe.iterations * self.recipe.rollout

    def to_dict(self) -> dict[str, Any]:
        data = {k: v for k, v in asdict(self).items() if k not in ("train_state", "resumable")}
        unmatched = list(UNMATCHED)
        if self.kind == "recurrent":
            from .recurrent_ppo import UNMATCHED as RECURRENT_UNMATCHED

            unmatched += RECURRENT_UNMATCHED
        data.update(per_seed=self.per_seed, iqm=self.iqm, steps_trained=self.steps_trained,
                    unmatched=unmatched, backend="jax")
        return data


def train(env_id: str, kind: str, seeds: list[int] | int, *, steps: int | None = None,
          n_envs: int | None = None, algo_kwargs: dict[str, Any] | None = None,
          env_kwargs: dict[str, Any] | None = None, hyperparams: str | None = None,
          kind_kwargs: dict[str, Any] | None = None, checkpoints: int = 10,
          curve_episodes: int = 8, episodes: int = 20, eval_seed: int = 10_000,
          cache: str | Path | bool | None = True, network_dtype: str = "float32"
          ) -> JaxTraining:
    """Train PPO on ``env_id`` observing ``kind`` for every seed in one compiled program.

    ``seeds``: a list, or a count (``0..n-1``). ``kind_kwargs``: the kind's options
    (``horizon``). ``checkpoints`` evaluations of
    ``curve_episodes`` episodes along training make the curves, ``episodes`` at the end the
    final returns (module docstring). ``cache``: ``True`` for :func:`cache_dir`, a folder,
    or ``False``/``None`` for none (what is already on leaves JAX's setting as it is).
    ``network_dtype``: the networks' arithmetic (module docstring).
    """
    check_supported(env_id, kind)
    seed_list = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("give at least one seed")
    for name, value in (("checkpoints", checkpoints), ("curve_episodes", curve_episodes),
                        ("episodes", episodes)):
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
    folder = None
    if cache:
        folder = str(enable_compilation_cache(None if cache is True else cache))
    rec = recipe(env_id, steps=steps, n_envs=n_envs, algo_kwargs=algo_kwargs,
                 hyperparams=hyperparams, kind=kind, network_dtype=network_dtype)
    env, params = make_env(env_id, kind, env_kwargs, kind_kwargs)
    algo = make_algorithm(env, params, rec)
    start = time.perf_counter()
    initial = initial_states(algo, seed_list)
    settings = {"checkpoints": checkpoints, "curve_episodes": curve_episodes,
                "episodes": episodes, "eval_seed": eval_seed}
    ts, curves, final, compiled_at, done = _run(algo, rec, initial, settings)
    k, per, _ = _segments(rec.iterations, checkpoints)
    return JaxTraining(
        env_id=env_id, kind=kind, seeds=seed_list, recipe=rec,
        checkpoint_steps=[(i + 1) * per * rec.rollout for i in range(k)],
        curves=curves, final_returns=final,
        compile_seconds=compiled_at - start, train_seconds=done - compiled_at, cache=folder,
        train_state=ts, kind_kwargs=dict(kind_kwargs or {}), env_kwargs=dict(env_kwargs or {}),
        settings=settings, resumable=True)


def _run(algo: SB3LikePPO, rec: Recipe, initial: Any, settings: dict[str, Any]
         ) -> tuple[Any, list[list[float]], list[list[float]], float, float]:
    """Compile and run :func:`training_program` (``rec.iterations`` iterations) from the
    stacked states ``initial``: ``(train state, curves [seed][checkpoint], final returns
    [seed][episode], time compiled, time done)``."""
    program = jax.jit(over_seeds(training_program(algo, rec, **settings)))
    compiled = program.lower(initial).compile()
    compiled_at = time.perf_counter()
    ts, curve, final = jax.block_until_ready(compiled(initial))
    return (ts, np.asarray(curve).mean(axis=-1).tolist(), np.asarray(final).tolist(),
            compiled_at, time.perf_counter())


def continue_training(result: JaxTraining, steps: int, *, checkpoints: int = 10,
                      cache: str | Path | bool | None = True) -> JaxTraining:
    """Train ``result``'s run on to ``steps`` in all (SB3's ``model.learn`` once more): the
    iterations the new budget adds, from the whole saved training state (the optimisers'
    moments, the normalisation statistics, the envs mid-episode, the keys), so that the
    continued run is the run that would have been trained straight to ``steps`` — bit for
    bit (``tests/jax/test_train.py``). ``checkpoints`` evaluations along the added part extend
    the curves; the final returns are the new final policies' (the run's evaluation
    settings). ``result``: just trained (:func:`train`) or read from a folder that kept its
    state (:func:`load`, ``state.msgpack``).

    Raises:
        ValueError: ``result`` has no whole training state, or ``steps`` adds no iteration.
    """
    if not result.resumable or result.train_state is None:
        raise ValueError(f"{result.env_id} {result.kind}: the run kept its policies only (no "
                         "state.msgpack), so it can be played, not trained further")
    if isinstance(steps, bool) or not isinstance(steps, int):
        raise ValueError(f"steps must be an integer; got {steps!r}")
    rec = replace(result.recipe, steps=steps)
    more = rec.iterations - result.recipe.iterations
    if more <= 0:
        raise ValueError(f"steps must be more than the {result.steps_trained} steps the run "
                         f"has trained; got {steps}")
    if isinstance(checkpoints, bool) or not isinstance(checkpoints, int) or checkpoints <= 0:
        raise ValueError(f"checkpoints must be a positive integer; got {checkpoints!r}")
    folder = str(enable_compilation_cache(None if cache is True else cache)) if cache else None
    env, params = make_env(result.env_id, result.kind, result.env_kwargs, result.kind_kwargs)
    algo = make_algorithm(env, params, rec)
    part = replace(rec, steps=more * rec.rollout)
    settings = {"curve_episodes": 8, "episodes": 20, "eval_seed": 10_000, **result.settings,
                "checkpoints": checkpoints}
    start = time.perf_counter()
    ts, curves, final, compiled_at, done = _run(algo, part, result.train_state, settings)
    k, per, _ = _segments(part.iterations, checkpoints)
    trained = result.steps_trained
    return JaxTraining(
        env_id=result.env_id, kind=result.kind, seeds=list(result.seeds), recipe=rec,
        checkpoint_steps=[*result.checkpoint_steps,
                          *(trained + (i + 1) * per * rec.rollout for i in range(k))],
        curves=[[*old, *new] for old, new in zip(result.curves, curves, strict=True)],
        final_returns=final,
        compile_seconds=result.compile_seconds + (compiled_at - start),
        train_seconds=result.train_seconds + (done - compiled_at), cache=folder,
        train_state=ts, kind_kwargs=dict(result.kind_kwargs),
        env_kwargs=dict(result.env_kwargs),
        settings={**settings, "checkpoints": len(result.checkpoint_steps) + k},
        resumable=True)


def save(result: JaxTraining, out: str | Path) -> Path:
    """Write a run folder: ``results.json`` (:meth:`JaxTraining.to_dict`: the plant, the kind
    and their keywords, the seeds, the recipe, the returns), ``code_version.txt`` and, per
    seed, ``seed<s>/policy.msgpack`` (the actor's and critic's parameters and the observation
    normalisation statistics, flax-serialised, and under ``run`` the run it belongs to:
    :func:`_identity`) and, for a run that has it, ``state.msgpack``: the whole training
    state of every seed, from which :func:`continue_training` goes on. :func:`load` reads it
    back."""
    from flax import serialization

    from fir_gym.code_version import code_version

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "code_version.txt").write_text(code_version() + "\n")
    (out / "results.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    ts = result.train_state
    if ts is not None:
        for i, seed in enumerate(result.seeds):
            state = {"actor": ts.actor_ts.params, "critic": ts.critic_ts.params,
                     "obs_rms": ts.obs_rms_state}
            one = jax.tree.map(lambda x, i=i: np.asarray(x)[i], state)
            one["run"] = _identity(result.env_id, result.kind, seed, asdict(result.recipe),
                                   result.env_kwargs, result.kind_kwargs)
            (out / f"seed{seed}").mkdir(exist_ok=True)
            (out / f"seed{seed}" / "policy.msgpack").write_bytes(serialization.to_bytes(one))
    state_file = out / STATE_FILE
    if ts is not None and result.resumable:
        state_file.write_bytes(serialization.to_bytes(ts))
    elif state_file.exists():                  # another run's: it must not be continued
        state_file.unlink()
    return out


def finished_run(out: str | Path, env_id: str, kind: str, seeds: list[int], *,
                 steps: int | None = None, n_envs: int | None = None,
                 algo_kwargs: dict[str, Any] | None = None,
                 env_kwargs: dict[str, Any] | None = None, hyperparams: str | None = None,
                 kind_kwargs: dict[str, Any] | None = None, checkpoints: int = 10,
                 curve_episodes: int = 8, episodes: int = 20, eval_seed: int = 10_000,
                 network_dtype: str = "float32") -> JaxTraining | None:
    """The run in ``out`` (:func:`load`) if it is the one :func:`train` with these arguments
    would make, or the same run trained for fewer steps that kept its training state — the
    same plant, kind, seeds, recipe but its budget, keywords and evaluation settings (the
    number of ``checkpoints`` aside: it samples the curve, it does not change the training),
    at the same :func:`~fir_gym.code_version.code_version` — else ``None`` (nothing there, the
    same run at other code, or fewer steps without the state: train it again). ``fir-gym
    train --backend jax --resume`` skips the finished run (``result.recipe.steps == steps``)
    and continues the shorter one (:func:`continue_training`).

    Raises:
        ValueError: ``out`` holds another run (another configuration, one trained for more
            steps, or another backend's): naming what differs, so that nothing is overwritten
            by mistake.
    """
    from fir_gym.code_version import code_version

    folder = Path(out)
    if not (folder / "results.json").is_file():
        if (folder / "run.json").is_file():
            raise ValueError(f"--out {folder} holds a stable-baselines3 run: give another "
                             "folder")
        return None
    saved = json.loads((folder / "results.json").read_text())
    rec = recipe(env_id, steps=steps, n_envs=n_envs, algo_kwargs=algo_kwargs,
                 hyperparams=hyperparams, kind=kind, network_dtype=network_dtype)
    wanted = {"env_id": env_id, "kind": kind, "seeds": [int(s) for s in seeds],
              "recipe": asdict(rec), "env_kwargs": dict(env_kwargs or {}),
              "kind_kwargs": dict(kind_kwargs or {}),
              "settings": {"curve_episodes": curve_episodes, "episodes": episodes,
                           "eval_seed": eval_seed}}
    as_saved = json.loads(json.dumps(wanted))
    mine = dict(saved)
    if "settings" not in saved:                 # written before the settings were recorded
        as_saved.pop("settings")
    else:
        mine["settings"] = {k: v for k, v in saved["settings"].items() if k != "checkpoints"}
    saved_steps = (saved.get("recipe") or {}).get("steps")
    if isinstance(mine.get("recipe"), dict):
        mine["recipe"] = {**saved_recipe(mine["recipe"]), "steps": rec.steps}
    differ = [k for k, v in as_saved.items() if mine.get(k) != v]
    if not differ and isinstance(saved_steps, int) and saved_steps > rec.steps:
        differ = [f"steps ({saved_steps} > {rec.steps})"]
    if differ:
        raise ValueError(f"--out {folder} holds another run (its {', '.join(differ)} differ "
                         "from this one's): give another folder, or leave out --resume to "
                         "train and overwrite it")
    version = folder / "code_version.txt"
    if ("settings" not in saved or not version.is_file()
            or version.read_text().strip() != code_version()):
        return None
    if saved_steps != rec.steps and not (folder / STATE_FILE).is_file():
        return None
    return load(folder)


def saved_recipe(written: dict[str, Any]) -> dict[str, Any]:
    """A ``results.json``'s recipe as :class:`Recipe`'s fields: one written before
    ``network_dtype`` was recorded was trained with float64 networks (module docstring)."""
    return {"network_dtype": "float64", **written}


def _identity(env_id: str, kind: str, seed: int, recipe: dict[str, Any],
              env_kwargs: dict[str, Any], kind_kwargs: dict[str, Any]) -> dict[str, str]:
    """What a saved policy belongs to, as strings (msgpack keeps them): the plant, the kind,
    the seed and, as JSON, the recipe as ``results.json`` holds it (:class:`Recipe`'s fields)
    and the plant's and the kind's keywords — so that :func:`load` tells a policy file of
    another run even where the networks' shapes agree."""
    def text(value: Any) -> str:
        return json.dumps(value, sort_keys=True)

    return {"env_id": env_id, "kind": kind, "seed": str(seed), "recipe": text(recipe),
            "env_kwargs": text(env_kwargs), "kind_kwargs": text(kind_kwargs)}


def _policy_template(algo: SB3LikePPO, seeds: list[int]) -> tuple[Any, dict[str, Any]]:
    """``(stacked initial train states of `seeds`, one seed's saved part)``: the structure,
    shapes and dtypes a ``policy.msgpack`` of this plant, kind and recipe has."""
    initial = initial_states(algo, seeds)
    state = {"actor": initial.actor_ts.params, "critic": initial.critic_ts.params,
             "obs_rms": initial.obs_rms_state}
    return initial, jax.tree.map(lambda x: np.asarray(x)[0], state)


def _read_policy(path: Path, template: dict[str, Any], identity: dict[str, str], run: str
                 ) -> dict[str, Any]:
    """One seed's ``policy.msgpack``: its ``run`` (where saved: files written before it was
    are not checked) equal to ``identity``, then leaf by leaf the same names and shapes as
    ``template`` and dtypes that widen exactly to the template's (:func:`_widened`: a
    folder's float32 kernels into float64 networks) before flax restores it into the
    template's structure, widened (:func:`_widened_tree`)."""
    from flax import serialization, traverse_util

    try:
        raw = serialization.msgpack_restore(path.read_bytes())
    except Exception as err:                 # msgpack's errors have no common base
        raise ValueError(f"{path} is not a flax-serialised policy ({type(err).__name__})"
                         ) from None
    saved_by = raw.pop("run", None) if isinstance(raw, dict) else None
    if isinstance(saved_by, dict):
        differ = [k for k in identity if saved_by.get(k) != identity[k]]
        if differ:
            raise ValueError(f"{path} is not a policy of {run}: it was saved by a run of "
                             f"{saved_by.get('env_id')} {saved_by.get('kind')} seed "
                             f"{saved_by.get('seed')} (differing in {', '.join(differ)})")
    want = traverse_util.flatten_dict(serialization.to_state_dict(template), sep="/")
    have = traverse_util.flatten_dict(raw, sep="/") if isinstance(raw, dict) else {}
    if set(want) != set(have):
        odd = sorted(set(want) ^ set(have))
        raise ValueError(f"{path} is not a policy of {run}: its entries differ in "
                         f"{', '.join(odd[:4])}" + (" ..." if len(odd) > 4 else ""))
    for name, leaf in want.items():
        got = np.asarray(have[name])
        if got.shape != np.shape(leaf) or _widened(got, np.asarray(leaf).dtype) is None:
            raise ValueError(f"{path} is not a policy of {run}: {name} is {got.dtype}"
                             f"{list(got.shape)} where the run's policy has "
                             f"{np.asarray(leaf).dtype}{list(np.shape(leaf))}")
    return _widened_tree(serialization.from_state_dict(template, raw), template)


def _widened(x: np.ndarray, dtype: Any) -> np.ndarray | None:
    """``x`` as ``dtype`` where that loses nothing (the same dtype, or a float widened:
    float32 -> float64), else ``None``."""
    if x.dtype == dtype:
        return x
    if np.issubdtype(x.dtype, np.floating) and np.issubdtype(dtype, np.floating) \
            and np.finfo(x.dtype).bits < np.finfo(dtype).bits:
        return x.astype(dtype)
    return None


def _widened_tree(tree: Any, template: Any) -> Any:
    """``tree`` with every leaf :func:`_widened` to the dtype of ``template``'s leaf in its
    place, or ``None`` where one cannot be."""
    leaves, structure = jax.tree.flatten(tree)
    widened = [_widened(np.asarray(x), np.asarray(t).dtype)
               for x, t in zip(leaves, jax.tree.leaves(template), strict=True)]
    if any(x is None for x in widened):
        return None
    return jax.tree.unflatten(structure, widened)


def load(run_dir: str | Path) -> JaxTraining:
    """Read a run folder of :func:`save` back into a :class:`JaxTraining`.

    The recipe, the plant's and the kind's keywords, the seeds and the returns come from
    ``results.json`` (a folder written before ``env_kwargs`` and ``kind_kwargs`` were
    recorded reads them as ``{}``); the env and the algorithm are rebuilt from them
    (:func:`make_env`, :func:`make_algorithm`), and ``train_state`` is the seeds' initial
    states (:func:`initial_states`) with each seed's saved actor and critic parameters and
    observation statistics in place, stacked along the seed axis as :func:`train` returns
    them — enough to play the policies (:func:`fir_gym.jax.benchmark.play_in_numpy_env`,
    :func:`evaluate_policy`), not to resume training (the optimiser's state and the reward
    statistics are not saved). Raises ``ValueError`` naming the folder and what is missing
    or does not fit: no ``results.json``, a run of another backend, a missing
    ``seed<s>/policy.msgpack``, a policy of another plant, kind or recipe.
    """
    folder = Path(run_dir)
    results = folder / "results.json"
    if not results.is_file():
        what = ("does not exist" if not folder.exists() else "is not a folder"
                if not folder.is_dir() else "has no results.json")
        raise ValueError(f"{folder} is not a run folder of `fir-gym train --backend jax` (it "
                         f"{what})")
    try:
        data = json.loads(results.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{results} is not JSON ({err})") from None
    if not isinstance(data, dict) or data.get("backend") != "jax":
        backend = data.get("backend") if isinstance(data, dict) else None
        raise ValueError(f"{folder} is not a run folder of `fir-gym train --backend jax` (its "
                         f"results.json's backend is {backend!r}, not 'jax')")
    absent = [k for k in ("env_id", "kind", "seeds", "recipe") if k not in data]
    if absent:
        raise ValueError(f"{results} lacks {', '.join(absent)}")
    try:
        written = data["recipe"]
        rec = Recipe(**{**saved_recipe(written),
                        "hidden_layer_sizes": tuple(written["hidden_layer_sizes"])})
    except (TypeError, KeyError) as err:
        raise ValueError(f"{results}'s recipe is not this version's ({err})") from None
    env_id, kind, seeds = str(data["env_id"]), str(data["kind"]), [int(s) for s in data["seeds"]]
    if not seeds:
        raise ValueError(f"{results} lists no seeds")
    env_kwargs = dict(data.get("env_kwargs") or {})
    kind_kwargs = dict(data.get("kind_kwargs") or {})
    files = [folder / f"seed{s}" / "policy.msgpack" for s in seeds]
    missing = [str(f.relative_to(folder)) for f in files if not f.is_file()]
    if missing:
        raise ValueError(f"{folder} lacks {', '.join(missing)} (its results.json lists seeds "
                         f"{seeds})")
    try:
        env, params = make_env(env_id, kind, env_kwargs, kind_kwargs)
    except (ValueError, TypeError) as err:
        raise ValueError(f"{folder}: {err}") from None
    algo = make_algorithm(env, params, rec)
    initial, template = _policy_template(algo, seeds)
    run = f"{results}'s plant, kind and recipe ({env_id} {kind})"
    saved = [_read_policy(f, template, _identity(env_id, kind, s, written, env_kwargs,
                                                 kind_kwargs), run)
             for s, f in zip(seeds, files, strict=True)]
    stacked = jax.tree.map(lambda *leaves: jnp.stack(leaves), *saved)
    state = initial.replace(
        actor_ts=initial.actor_ts.replace(params=stacked["actor"]),
        critic_ts=initial.critic_ts.replace(params=stacked["critic"]),
        obs_rms_state=stacked["obs_rms"])
    whole = _read_state(folder / STATE_FILE, initial, stacked)
    return JaxTraining(
        env_id=env_id, kind=kind, seeds=seeds, recipe=rec,
        checkpoint_steps=list(data.get("checkpoint_steps", [])),
        curves=list(data.get("curves", [])), final_returns=list(data.get("final_returns", [])),
        compile_seconds=float(data.get("compile_seconds", math.nan)),
        train_seconds=float(data.get("train_seconds", math.nan)), cache=data.get("cache"),
        train_state=state if whole is None else whole, kind_kwargs=kind_kwargs,
        env_kwargs=env_kwargs, settings=dict(data.get("settings") or {}),
        resumable=whole is not None)


def _read_state(path: Path, template: Any, policies: dict[str, Any]) -> Any:
    """A folder's ``state.msgpack`` restored into ``template``'s structure (the stacked
    initial states), or ``None`` where there is none; refused in one line where it does not
    fit the template or holds other policies than the seed files (``policies``)."""
    from flax import serialization

    if not path.is_file():
        return None
    try:
        whole = serialization.from_bytes(template, path.read_bytes())
    except Exception as err:                 # msgpack's and flax's errors have no common base
        raise ValueError(f"{path} is not this run's training state ({type(err).__name__}: "
                         f"{str(err)[:120]})") from None
    whole = _widened_tree(whole, template)
    if whole is None:
        raise ValueError(f"{path} is not this run's training state: its dtypes are not the "
                         "run's networks'")
    mine = {"actor": whole.actor_ts.params, "critic": whole.critic_ts.params,
            "obs_rms": whole.obs_rms_state}
    for a, b in zip(jax.tree.leaves(mine), jax.tree.leaves(policies), strict=True):
        if np.shape(a) != np.shape(b) or not np.array_equal(np.asarray(a), np.asarray(b)):
            raise ValueError(f"{path} is not this run's training state: its policies differ "
                             "from the seed folders'")
    return whole
