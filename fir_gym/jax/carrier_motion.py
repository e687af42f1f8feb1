"""CarrierMotion-v0 as a gymnax environment: paper 001's deck motion, with its KF in the state.

The JAX twin of :class:`fir_gym.envs.carrier_motion.CarrierMotionEnv` (the numpy reference)
seen through :func:`fir_gym.wrappers.factory.wrap_observation` — one of its observation
kinds (:data:`KINDS`; ``"measurement-stack"`` and the generic filters ``"ukf"``, ``"fir"``
and ``"ufir"`` as on every plant, :class:`~fir_gym.jax._plant.FilteredPlant`):

* ``"true"``: the true state ``[x1, x2]`` (deck displacement and rate;
  :class:`~fir_gym.wrappers.baselines.TrueStateObservation`);
* ``"measurement"``: the raw measurement ``[(1 + Δc) x1 + v]`` (the plant's own observation);
* ``"kf"``: the Kalman filter's estimate ``x̂`` of ``[x1, x2]``
  (:class:`~fir_gym.wrappers.EstimatorObservation` with
  :class:`~fir_gym.estimators.kalman.KalmanFilter` on the nominal model); the filter's mean,
  covariance and divergence watch live in :class:`CarrierMotionState`. As there,
  ``observation`` may instead be ``"estimate+covariance"`` (a dict: ``estimate`` and
  ``covariance``, the upper triangle of ``P`` row by row, ``[P11, P12, P22]``) or
  ``"estimate+measurement"`` (``estimate`` and ``measurement``).

**Plant** (paper 001, §V): the continuous model ``ẋ = [[0, 1], [a21, a22 + Δ22]] x + g w``,
``E[w wᵀ] = q δ(t)``, ``z = [1 + Δc, 0] x + v``, ``E[v vᵀ] = V δ(t)``, sampled exactly at
``T = sample_period``: ``x[k+1] = A_d x[k] + w_d``, ``A_d = e^{A T}``, ``w_d ~ N(0, Q_d)``
(Van Loan), ``y[k] = C x[k] + v_d``, ``v_d ~ N(0, V / T)``. The sampling is done host-side
by :func:`carrier_motion_params` with the numpy plant's own functions
(:func:`fir_gym.envs.carrier_motion.carrier_discrete`, :func:`fir_gym.envs._base.psd_sqrt`,
scipy's Lyapunov solver), so the parameters are the numpy plant's bit for bit and the JAX
step is the linear map. The action (a compensator offset ``c = action · c_max``, held over
the interval) does not move the deck. Reward, as
:meth:`~fir_gym.envs.carrier_motion.CarrierMotionEnv._reward`: ``−min(((x1[k+1] − c) /
σ1)², cost_cap)``, ``σ1 = √P∞[0, 0]`` of the true stationary covariance (1 for a calm sea,
``q = 0``), ``cost_cap = 100``, a NaN cost counted as the cap
(:func:`fir_gym.envs._base.saturated_cost`). The plant's domain is every finite state: it
never terminates except by a simulation failure — a new state that is not finite or beyond
``±state_limit`` (1e150), or a measurement or reward that is not finite — after which the
plant stays at its last valid state, the observation repeats, the reward is the terminal
penalty ``−cost_cap (1 + steps left to max_steps_in_episode)`` and the episode terminates
(``info["simulation_failure"]``: 0 none, 1 nonfinite_state, 2 state_overflow, 3
nonfinite_observation, 4 nonfinite_reward — :data:`SIMULATION_FAILURES`). Truncation at
``max_steps_in_episode`` (gymnax's ``is_truncated``, the registered ``TimeLimit``). Actions
are clipped to ``[-1, 1]`` (``info["action_clipped"]``); a NaN action, which the numpy plant
refuses with a ``ValueError``, cannot raise under ``jit``: its reward is NaN (not counted
as the cap), a simulation failure (``nonfinite_reward``).

**Start**: ``initial_state + N(0, initial_state_cov)``, the covariance by default the true
system's stationary ``P∞`` (continuous Lyapunov equation), as paper 001 assumes.

**KF** (:mod:`fir_gym.estimators.kalman`): the model is the plant's ``model``, built from
the nominal parameters (Δ22 = Δc = 0 unless ``nominal`` says otherwise; every other
parameter the truth's): ``A_d``, ``Q_d``, ``C``, ``R_d = V / T`` of the nominal system, no
input (``B = 0``). Prior: the plant's initial-state mean and covariance (the *true*
stationary covariance by default), floored: ``P0 + 1e-9 diag(max(1, x0²))``
(:func:`fir_gym.wrappers.estimator_observation.prior_of`). ``reset`` consumes ``y[0]``
(update only); each step predicts (``x⁻ = A_d x̂``, ``P⁻ = A_d P A_dᵀ + Q_d``) and makes the
Joseph-form update — :func:`fir_gym.jax.kalman.kf_predict`, :func:`~fir_gym.jax.kalman.
kf_update` (the Joseph product formed from factors, as the numpy filter forms it) and the
divergence watch :func:`~fir_gym.jax.kalman.watch` with the numpy estimator's defaults. The
numpy filter freezes ``P``, ``K`` and ``S⁻¹`` once the Riccati recursion reaches round-off
(its steady-state shortcut); this one runs the full recursion: the same numbers to
round-off.

**Noise contract.** Every random number comes from the ``key`` of ``reset_env`` /
``step_env`` (gymnax's ``step`` splits its key into the step's and the auto-reset's):
:func:`carrier_motion_reset_noise` and :func:`carrier_motion_noise` each make one draw ``z =
jax.random.normal(key, (3,))`` — ``z[:2]`` for the state, ``z[2:]`` for the measurement —
that the plant's square roots turn into the physical increments, as the numpy plant draws
them (same order, same shapes): at a reset ``initial = z[:2] @ S0ᵀ`` with ``S0 =
psd_sqrt(initial_state_cov)`` (drawn even when the covariance is 0, as there), then
``measurement = z[2:] · √R_d``; at a step ``process = z[:2] @ S_Qᵀ`` with ``S_Q =
psd_sqrt(Q_d)`` of the true system (``V Λ^½`` from ``eigh``; drawn even for ``q = 0``, as
:meth:`~fir_gym.envs.carrier_motion.CarrierMotionEnv._transition` does), then
``measurement = z[2:] · √R_d`` (the numpy plant draws no measurement noise on a failed step;
here it is drawn and unused). The pure functions :meth:`CarrierMotion.reset_with_noise` and
:meth:`CarrierMotion.step_with_noise` take those increments
(:class:`CarrierMotionResetNoise`, :class:`CarrierMotionNoise`) instead of a key, so a caller
can drive the JAX env with any noise sequence — the parity tests drive the numpy env and
this one with the same numbers.

**Parity** (tests/jax/test_carrier_motion_parity.py, episodes of the numpy env on the same
noise, every kind): the default plant (stationary random start), a mismatch (Δ22 = 0.006,
Δc = 0.1 on the truth, the nominal model unchanged), a model given by ``nominal=`` (q, V,
a21), T = 0.2 s with c_max = 0.5 (1000 steps each), a start near ``state_limit`` that
overflows (``state_overflow`` on step 11) and a sensor gain of 1e300 whose measurement
overflows (``nonfinite_observation`` on step 15, the KF's NIS infinite and its watch
raised). Measured max elementwise relative errors: states 1.8e-12, measurements 3.6e-13,
rewards 8.9e-12, KF mean 1.0e-10 and covariance 1.7e-10 (components passing near 0 or
cancelling), the NIS to 5.5e-16 (1 + nis); terminated, truncated, the failure codes and the
divergence flag exactly. The start near 1e150 too, whose prior floor ``1e-9 x0²`` makes
``P0 ≈ 1e290`` against ``R_d = 10`` (a plain Joseph product would lose ``P⁺`` to
cancellation, round-off ``ε ‖P‖ ≈ 1e274``; both filters form it from factors): its mean and
covariance to 8.2e-15; its innovations are the round-off of two numbers near 1e149, so its
NIS is compared within that round-off's NIS, ``(4 ε |x|)² / R_d``.

Everything is a pure function of its arguments: ``jit``-able, ``vmap``-able over keys,
states and parameters (:class:`CarrierMotionParams` is a pytree; a batch of physical
parameters is a stack of :func:`carrier_motion_params` results, the sampling being
host-side).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnax.environments.environment as gymnax_env
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from ._plant import SIMULATION_FAILURES as SIMULATION_FAILURES  # (the numpy plants' codes)
from ._plant import (
    STATE_LIMIT,
    FilteredPlant,
    PlantState,
    Reading,
    filter_prior,
    watch_state,
)
from ._x64 import require_x64
from .filter_model import FilterModel
from .kalman import WatchLimits, kf_predict, kf_update, watch_limits

#: paper 001's sea (Sidar & Doolin): the stiffness and damping terms and the noise input
PAPER_A21 = -0.36
PAPER_A22 = -0.06
PAPER_NOISE_INPUT = (0.6, -0.036)
#: the numpy plant's worst per-step cost (``CarrierMotionEnv.cost_cap``)
COST_CAP = 100.0
#: the observation kinds (the estimator kind last)
KINDS = ("true", "measurement", "measurement-stack", "kf", "ukf", "fir", "ufir")
#: the parameters ``nominal=`` may change (the numpy plant's ``params``)
MODEL_PARAMETERS = ("sample_period", "q", "v", "delta22", "delta_c", "a21", "a22",
                    "noise_input")


@struct.dataclass(kw_only=True)
class CarrierMotionParams(gymnax_env.EnvParams):
    """The sampled true system, the reward's constants, the start, the filter's nominal model
    and its divergence watch (a pytree: any field can be vmapped).

    Build one with :func:`carrier_motion_params` (the numpy env's keywords; it samples the
    continuous model and validates). ``A_d``, ``process_sqrt`` (``psd_sqrt(Q_d)``), ``C``
    and ``measurement_std`` (``√(V/T)``) are the truth's, ``sigma1`` the reward's normaliser,
    ``nominal_*`` the KF's model (``Q_d`` as ``G Q Gᵀ``, ``R`` as a 1x1 matrix). ``a21``,
    ``a22``, ``delta22``, ``sample_period``, ``q`` and ``noise_input`` are the truth's
    continuous parameters, from which :meth:`CarrierMotion.true_fields` samples ``A_d``
    and ``process_sqrt`` again when the ``mismatch`` condition draws ``a21`` and ``a22``
    around the model's ``nominal_a21``, ``nominal_a22``.
    """

    A_d: Any
    process_sqrt: Any
    C: Any
    measurement_std: Any
    c_max: Any
    sigma1: Any
    cost_cap: Any = COST_CAP
    initial_state: Any
    initial_state_cov: Any
    initial_sqrt: Any
    state_limit: Any = STATE_LIMIT
    nominal_A_d: Any
    nominal_Q_d: Any
    nominal_C: Any
    nominal_R: Any
    watch: WatchLimits = struct.field(default_factory=WatchLimits)
    a21: Any = PAPER_A21
    a22: Any = PAPER_A22
    delta22: Any = 0.0
    sample_period: Any = 0.1
    q: Any = 0.035
    noise_input: Any = struct.field(default_factory=lambda: jnp.asarray(PAPER_NOISE_INPUT))
    nominal_a21: Any = PAPER_A21
    nominal_a22: Any = PAPER_A22


@struct.dataclass
class CarrierMotionState(PlantState):
    """The plant, its last observation and the KF (mean, covariance, watch)."""


@struct.dataclass
class CarrierMotionResetNoise:
    """The physical noise of a reset: ``initial`` (2,) added to ``initial_state``,
    ``measurement`` (1,) added to ``C x``."""

    initial: Any
    measurement: Any


@struct.dataclass
class CarrierMotionNoise:
    """The physical noise of a step: ``process`` (2,) added to ``A_d x`` (``w_d``),
    ``measurement`` (1,) added to ``C x[k+1]`` (``v_d``)."""

    process: Any
    measurement: Any


def carrier_motion_params(
    *, sample_period: float = 0.1, q: float = 0.035, v: float = 1.0, delta22: float = 0.0,
    delta_c: float = 0.0, a21: float = PAPER_A21, a22: float = PAPER_A22,
    noise_input: Any = PAPER_NOISE_INPUT, c_max: float = 1.0,
    nominal: Mapping[str, Any] | None = None, initial_state: Any = (0.0, 0.0),
    initial_state_cov: Any = "stationary", max_episode_steps: int | None = None,
    max_covariance_trace: float = 1e12, nis_tail: float = 1e-9, nis_patience: int = 10,
) -> CarrierMotionParams:
    """:class:`CarrierMotionParams` from :class:`~fir_gym.envs.carrier_motion.CarrierMotionEnv`'s
    keywords (and the KF's watch options). Host-side: validates as the numpy constructor does
    (a ``ValueError`` naming the argument), samples the true and the nominal continuous
    models with :func:`~fir_gym.envs.carrier_motion.carrier_discrete`, solves the true
    stationary covariance (the start's default covariance and the reward's ``σ1``) and takes
    the plant's square roots (:func:`~fir_gym.envs._base.psd_sqrt`). ``nominal`` changes any
    of :data:`MODEL_PARAMETERS` for the filter's model (Δ22 = Δc = 0 by default).
    ``randomize`` and ``burst`` are conditions of :func:`fir_gym.jax.make`, not params
    (:class:`~fir_gym.jax.randomized.Randomized`, the env's ``burst``); ``render_mode`` is not
    supported (a ``TypeError``)."""
    require_x64()
    import scipy.linalg

    from fir_gym.envs._base import psd_sqrt
    from fir_gym.envs.carrier_motion import carrier_continuous, carrier_discrete
    from fir_gym.estimators._validation import as_covariance, as_vector, positive

    def non_negative(name: str, value: Any) -> float:
        val = _real(name, value)
        if not np.isfinite(val) or val < 0:
            raise ValueError(f"{name} must be a non-negative finite number; got {value!r}")
        return val

    def model_params(prefix: str, p: Mapping[str, Any]) -> dict[str, Any]:
        g = np.asarray(p["noise_input"], dtype=np.float64)
        if g.shape != (2,) or not np.all(np.isfinite(g)):
            raise ValueError(f"{prefix}noise_input must be 2 finite numbers; "
                             f"got {p['noise_input']!r}")
        checked = {"sample_period": positive(f"{prefix}sample_period", p["sample_period"]),
                   "q": non_negative(f"{prefix}q", p["q"]), "v": positive(f"{prefix}v", p["v"]),
                   "noise_input": tuple(g)}
        for name in ("delta22", "delta_c", "a21", "a22"):
            checked[name] = _real(f"{prefix}{name}", p[name])
            if not np.isfinite(checked[name]):
                raise ValueError(f"{prefix}{name} must be finite; got {p[name]!r}")
        return checked

    truth = model_params("", {"sample_period": sample_period, "q": q, "v": v,
                              "delta22": delta22, "delta_c": delta_c, "a21": a21, "a22": a22,
                              "noise_input": noise_input})
    A, G, _ = carrier_continuous(truth)
    if np.max(np.linalg.eigvals(A).real) >= 0:
        raise ValueError("a21, a22 + delta22 must give a stable carrier model (the stationary "
                         f"distribution must exist); eigenvalues {np.linalg.eigvals(A)}")
    stationary_cov = scipy.linalg.solve_continuous_lyapunov(A, -truth["q"] * G @ G.T)
    c_max_ = positive("c_max", c_max)
    if isinstance(initial_state_cov, str):
        if initial_state_cov != "stationary":
            raise ValueError("initial_state_cov must be 'stationary', None or a 2x2 "
                             f"covariance; got {initial_state_cov!r}")
        initial_state_cov = stationary_cov
    steps = 1000 if max_episode_steps is None else positive("max_episode_steps",
                                                            max_episode_steps, integer=True)
    if nominal is not None and not isinstance(nominal, Mapping):
        raise ValueError("nominal must be a mapping of parameter names to values; got "
                         f"{type(nominal).__name__}")
    unknown = sorted(set(nominal or {}) - set(MODEL_PARAMETERS))
    if unknown:
        raise ValueError(f"nominal has unknown parameter(s) {unknown}; known parameters are "
                         f"{sorted(MODEL_PARAMETERS)}")
    believed = model_params("nominal ", {**truth, "delta22": 0.0, "delta_c": 0.0,
                                         **(nominal or {})})
    x0 = as_vector("initial_state", initial_state, 2)
    P0 = (np.zeros((2, 2)) if initial_state_cov is None
          else as_covariance("initial_state_cov", initial_state_cov, 2))
    A_d, Q_d, C, R_d = carrier_discrete(truth)
    measurement_sqrt = psd_sqrt(as_covariance("measurement_cov", R_d, 1))
    nominal_A_d, nominal_Q_d, nominal_C, nominal_R = carrier_discrete(believed)
    limits = watch_limits(1, max_covariance_trace=positive("max_covariance_trace",
                                                           max_covariance_trace),
                          nis_tail=_probability("nis_tail", nis_tail),
                          nis_patience=positive("nis_patience", nis_patience, integer=True))
    return CarrierMotionParams(
        max_steps_in_episode=int(steps), A_d=jnp.asarray(A_d),
        process_sqrt=jnp.asarray(psd_sqrt(Q_d)), C=jnp.asarray(C),
        measurement_std=float(np.diag(measurement_sqrt)[0]), c_max=c_max_,
        # a calm sea (q = 0) has no stationary spread: the reward divides by 1
        sigma1=float(np.sqrt(stationary_cov[0, 0])) or 1.0,
        initial_state=jnp.asarray(x0), initial_state_cov=jnp.asarray(P0),
        initial_sqrt=jnp.asarray(psd_sqrt(P0)), nominal_A_d=jnp.asarray(nominal_A_d),
        nominal_Q_d=jnp.asarray(nominal_Q_d),     # the model's G Q Gᵀ: G = I, exactly Q_d
        nominal_C=jnp.asarray(nominal_C), nominal_R=jnp.asarray([[float(nominal_R)]]),
        watch=limits, a21=truth["a21"], a22=truth["a22"], delta22=truth["delta22"],
        sample_period=truth["sample_period"], q=truth["q"],
        noise_input=jnp.asarray(truth["noise_input"]), nominal_a21=believed["a21"],
        nominal_a22=believed["a22"])


def _real(name: str, value: Any) -> float:
    """``value`` as a float, or a ``ValueError`` naming ``name``."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number; got {value!r}") from None


def _probability(name: str, value: Any) -> float:
    val = _real(name, value)
    if not 0.0 < val < 1.0:
        raise ValueError(f"{name} must be strictly between 0 and 1; got {value!r}")
    return val


# ---------------------------------------------------------------------------- pure functions
def carrier_motion_reset_noise(key: jax.Array, params: CarrierMotionParams
                               ) -> CarrierMotionResetNoise:
    """The noise of a reset from one draw ``z = jax.random.normal(key, (3,))``:
    ``initial = z[:2] @ psd_sqrt(initial_state_cov)ᵀ``, ``measurement = z[2:] √R_d``."""
    z = jax.random.normal(key, (3,), dtype=jnp.float64)
    return CarrierMotionResetNoise(z[:2] @ jnp.asarray(params.initial_sqrt).T,
                                   z[2:] * params.measurement_std)


def carrier_motion_noise(key: jax.Array, params: CarrierMotionParams) -> CarrierMotionNoise:
    """The noise of a step from one draw ``z = jax.random.normal(key, (3,))``:
    ``process = z[:2] @ psd_sqrt(Q_d)ᵀ`` (of the true system), ``measurement = z[2:] √R_d``."""
    z = jax.random.normal(key, (3,), dtype=jnp.float64)
    return CarrierMotionNoise(z[:2] @ jnp.asarray(params.process_sqrt).T,
                              z[2:] * params.measurement_std)


# ---------------------------------------------------------------------------- the environment
def sampled_truth(params: CarrierMotionParams) -> tuple[jax.Array, jax.Array]:
    """``(A_d, Q_d)`` of the true continuous model in ``params`` —
    :func:`fir_gym.envs.carrier_motion.carrier_discrete` traced: ``A = [[0, 1], [a21, a22 +
    Δ22]]``, ``A_d = e^{A T}``, and ``Q_d = ∫₀ᵀ e^{As} g q gᵀ e^{Aᵀs} ds`` from one exponential
    of Van Loan's block ``[[−A, g q gᵀ], [0, Aᵀ]] T`` (:func:`fir_gym.estimators.discretize.
    integrated_noise`, whose scaling of a ``W`` above 1 this mirrors), with
    :func:`~fir_gym.jax.small_linalg.expm`."""
    from .small_linalg import expm

    A = jnp.array([[0.0, 1.0], [params.a21, params.a22 + params.delta22]], dtype=jnp.float64)
    g = jnp.reshape(jnp.asarray(params.noise_input, dtype=jnp.float64), (2, 1))
    W = params.q * (g @ g.T)
    scale = jnp.maximum(1.0, jnp.max(jnp.abs(W)))
    T = params.sample_period
    block = jnp.block([[-A, W / scale], [jnp.zeros((2, 2)), A.T]])
    V = expm(block * T)
    Q_d = V[2:, 2:].T @ V[:2, 2:]
    return expm(A * T), scale * 0.5 * (Q_d + Q_d.T)


class CarrierMotion(FilteredPlant):
    """``fir_gym/CarrierMotion-v0`` as a gymnax environment observing ``kind`` (see the module
    docstring): ``"true"``, ``"measurement"`` or ``"kf"`` (the default, observing
    ``observation``: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``).

    ``reset_env(key, params)`` and ``step_env(key, state, action, params)`` draw their noise
    from ``key`` (:func:`carrier_motion_reset_noise`, :func:`carrier_motion_noise`) and call
    the pure :meth:`reset_with_noise` / :meth:`step_with_noise`. gymnax's ``step`` adds the
    auto-reset and ``is_truncated`` (``time >= max_steps_in_episode``). ``info`` has
    ``state`` (the true state), ``action`` (applied, float64), ``action_clipped``,
    ``compensator_offset`` (``action · c_max``, the numpy plant's extra),
    ``simulation_failure`` (a code, 0 for none) and, for ``"kf"``, ``estimate``,
    ``estimation_error``, ``estimator_diverged`` and ``nis``.
    """

    kinds = KINDS
    randomizable = ("a21", "a22")
    estimator = "kf"
    default_horizon = 50
    n_x, n_y = 2, 1

    @property
    def default_params(self) -> CarrierMotionParams:
        return carrier_motion_params()

    @property
    def name(self) -> str:
        return "fir_gym/CarrierMotion-v0"

    def filter_model(self, params: CarrierMotionParams) -> FilterModel:
        """The KF's model (the numpy plant's ``model``): ``x ← A_d x`` (the action does not
        enter it), the nominal ``C``, ``Q_d`` and ``R``."""
        def f(x: jax.Array, u: jax.Array) -> jax.Array:
            return params.nominal_A_d @ x

        def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
            return params.nominal_A_d @ x, params.nominal_A_d

        return FilterModel(f, f_and_F, params.nominal_C, params.nominal_Q_d, params.nominal_R)

    def draw_centres(self, params: CarrierMotionParams) -> dict[str, jax.Array]:
        return {"a21": jnp.asarray(params.nominal_a21, dtype=jnp.float64),
                "a22": jnp.asarray(params.nominal_a22, dtype=jnp.float64)}

    def true_fields(self, params: CarrierMotionParams, values: dict[str, Any]
                    ) -> dict[str, Any]:
        """``a21``/``a22`` from ``values`` and the truth sampled again with them (the numpy
        plant's ``_apply_params``): ``A_d = e^{A T}`` and ``Q_d`` by Van Loan's method
        (:func:`sampled_truth`), its square root by :func:`~fir_gym.jax._plant.psd_sqrt`."""
        from ._plant import psd_sqrt

        A_d, Q_d = sampled_truth(params.replace(**values))
        return {**values, "A_d": A_d, "process_sqrt": psd_sqrt(Q_d)}

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """The true measurement noise's square root (the outliers' scale)."""
        return jnp.reshape(jnp.asarray(params.measurement_std, dtype=jnp.float64), (1, 1))

    # ------------------------------------------------------------------ reset
    def reset_env(self, key: jax.Array, params: CarrierMotionParams
                  ) -> tuple[Any, CarrierMotionState]:
        return self.reset_with_noise(carrier_motion_reset_noise(key, params), params,
                                     self.sensor_reading(key, 0, params))

    def reset_with_noise(self, noise: CarrierMotionResetNoise, params: CarrierMotionParams,
                         missing: Reading | jax.Array | bool = False
                         ) -> tuple[Any, CarrierMotionState]:
        """The reset with the given noise (:meth:`fir_gym.envs._base.PlantEnv.reset`): ``x =
        initial_state + noise.initial``, ``y = C x + noise.measurement`` (held where
        ``missing``, with dropout); the KF (for ``"kf"``) consumes ``y`` from its prior (an
        update only)."""
        require_x64()
        x = jnp.asarray(params.initial_state, dtype=jnp.float64) + noise.initial
        y = self.deliver(missing, jnp.asarray(params.C) @ x + noise.measurement,
                         self.first_hold(params))
        x0, P0 = filter_prior(params)
        state = CarrierMotionState.start(x, y, x0, P0)
        if self.runs_own_filter:
            updated = watch_state(state, *kf_update(x0, P0, y, params.nominal_C,
                                                    params.nominal_R), params.watch)
            state = self.own_update(missing, state, updated, x0, P0, params)
        state = self.finish_reset(state, params, missing)
        return self.get_obs(state, params), state

    # ------------------------------------------------------------------ step
    def step_env(self, key: jax.Array, state: CarrierMotionState, action: Any,
                 params: CarrierMotionParams
                 ) -> tuple[Any, CarrierMotionState, jax.Array, jax.Array, dict[str, Any]]:
        obs, state, reward, terminated, info = self.step_with_noise(
            state, action, carrier_motion_noise(key, params), params,
            self.sensor_reading(key, state.time + 1, params, state.sensor_stuck))
        # gymnax's rule: transitions are detached unless gradients were asked for
        obs, state = self._apply_transition_gradient_policy(obs, state)
        return obs, state, reward, terminated, info

    def step_with_noise(self, state: CarrierMotionState, action: Any, noise: CarrierMotionNoise,
                        params: CarrierMotionParams, missing: Reading | jax.Array | bool = False
                        ) -> tuple[Any, CarrierMotionState, jax.Array, jax.Array, dict[str, Any]]:
        """One env step with the given noise: ``(obs, state, reward, terminated, info)``;
        with dropout, a ``missing`` reading holds the last delivered one.

        :meth:`fir_gym.envs._base.PlantEnv.step` of
        :class:`~fir_gym.envs.carrier_motion.CarrierMotionEnv` (``x[k+1] = A_d x[k] + w_d``,
        its ``_reward``, the simulation-failure rules) and, for ``"kf"``, the KF step of
        :class:`~fir_gym.wrappers.EstimatorObservation`; its only Python branches are on the
        (static) kind.
        """
        require_x64()
        u_in = jnp.reshape(jnp.asarray(action, dtype=jnp.float64), (1,))
        u = jnp.clip(u_in, -1.0, 1.0)
        x = state.x
        burst = self.burst_delta(state.time)
        x_next = self.stretch(x, x @ jnp.asarray(params.A_d).T + noise.process, burst)
        offset = u[0] * params.c_max                       # c_k, held over the interval
        time = state.time + 1
        left = jnp.maximum(params.max_steps_in_episode - time, 0)
        penalty = -params.cost_cap * (1.0 + left)

        finite_state = jnp.all(jnp.isfinite(x_next))
        overflow = jnp.any(jnp.abs(x_next) > params.state_limit)
        d = (x_next[0] - offset) / params.sigma1
        cost = d * d
        reward = -jnp.where(cost < params.cost_cap, cost, params.cost_cap)
        reward = jnp.where(jnp.isfinite(u[0]), reward, jnp.nan)   # a NaN action: a failure
        y_next = jnp.asarray(params.C) @ x_next + noise.measurement
        failure = jnp.select(
            [~finite_state, overflow, ~jnp.isfinite(reward), ~jnp.all(jnp.isfinite(y_next))],
            [1, 2, 4, 3], 0)
        # every finite state is in the domain: only a failed step terminates
        terminated = failure > 0
        x_kept = jnp.where(terminated, x, x_next)
        y = self.deliver(missing, jnp.where(terminated, state.y, y_next), state.y)
        reward = jnp.where(terminated, penalty, reward)
        new = state.replace(time=time, x=x_kept, y=y, terminated=terminated)
        info: dict[str, Any] = {"state": x_kept, "action": u, "action_clipped": jnp.any(u != u_in),
                                "compensator_offset": offset, "simulation_failure": failure}
        if self.runs_own_filter:
            xp, Pp = kf_predict(state.filter_x, state.filter_P, params.nominal_A_d,
                                params.nominal_Q_d)
            updated = watch_state(new, *kf_update(xp, Pp, y, params.nominal_C,
                                                  params.nominal_R), params.watch)
            new = self.own_update(missing, new, updated, xp, Pp, params)
        obs, new, info = self.finish_step(state, new, u, params, info, missing)
        return obs, new, reward, terminated, info
