"""UncertainOscillator-v0 as a gymnax environment: paper 000, simulation 2, with its EKF.

The JAX twin of :class:`fir_gym.envs.uncertain_oscillator.UncertainOscillatorEnv` (the numpy
reference) seen through :func:`fir_gym.wrappers.factory.wrap_observation` — one of three
observation kinds:

* ``"true"``: the true state ``[x1, x2, x3]``
  (:class:`~fir_gym.wrappers.baselines.TrueStateObservation`);
* ``"measurement"``: the raw measurement ``[x1 + v]`` (the plant's own observation);
* ``"ekf"``: the extended Kalman filter's estimate ``x̂`` of ``[x1, x2, x3]``
  (:class:`~fir_gym.wrappers.EstimatorObservation` with
  :class:`~fir_gym.estimators.extended.ExtendedKalmanFilter`, the numpy ``estimator="ekf"``);
  the filter's mean, covariance and divergence watch live in
  :class:`UncertainOscillatorState`. As there, ``observation`` may instead be
  ``"estimate+covariance"`` (a dict: ``estimate`` and ``covariance``, the upper triangle of
  ``P`` row by row, ``[P11, P12, P13, P22, P23, P33]``) or ``"estimate+measurement"``
  (``estimate`` and ``measurement``).

**Plant** (paper 000, eq (29); :class:`fir_gym.envs.uncertain_oscillator.OscillatorDynamics`):
``x[k+1] = D_k x[k] + r(x[k], u) Δ + [0; Δ; 0] w[k]`` with ``r(x, u) = [x2; −c x1 − d x2 x3
+ b + u u_max; 0]`` (c = ``stiffness`` 25, d = ``damping_gain`` 10, b = ``drive`` 12,
``u_max`` 25, Δ = ``dt`` 0.01) and ``D_k = diag(1 + δ_k, 1 + δ_k, 1)`` — the printed
reading, ``uncertainty="state"``; ``"rate"`` is ``x + D_k r(x, u) Δ`` (``uncertainty`` is
static: it chooses the formula). ``δ_k`` is the sum of the ``delta_schedule`` windows
``(k_first, k_last, δ)`` that hold ``k`` (inclusive; ``k`` indexes the transition from
``x[k]``; the paper's ``((350, 400, 0.15),)`` by default): the schedule is data in the
params (:func:`delta_at`), the step reads it at its step index, ``state.time``.
``w ~ N(0, Q)`` (Q = 0.4) enters the velocity only. Measurement, eq (30): ``y = x1 + v``,
``v ~ N(0, R)`` (R = 0.1). Reward ``−min((x1' − setpoint)² + 1e-3 action², 2.25)``;
termination when a ``|x_i'| > state_bound`` (1e4), paid ``−2.25 (1 + steps left to
max_steps_in_episode)``; a step whose new state is not finite or beyond ``±state_limit``
(or whose reward or measurement is not finite) is a simulation failure: the plant stays at
its last valid state, the observation repeats, the reward is the terminal penalty and the
episode terminates (``info["simulation_failure"]``: 0 none, 1 nonfinite_state, 2
state_overflow, 3 nonfinite_observation, 4 nonfinite_reward — :data:`SIMULATION_FAILURES`).
Truncation at ``max_steps_in_episode`` (500; gymnax's ``is_truncated``, the registered
``TimeLimit``). Actions are clipped to ``[-1, 1]`` (``info["action_clipped"]``); a NaN
action, which the numpy plant refuses with a ``ValueError``, cannot raise under ``jit``: it
makes the new state NaN, a simulation failure.

**EKF** (:mod:`fir_gym.estimators.extended`, on the model
:meth:`~fir_gym.envs.uncertain_oscillator.UncertainOscillatorEnv._build_model` builds): the
model is eq (29) with δ = 0 always, in the plant's reading, with the nominal parameters
(``nominal=``: any of ``Q, R, dt, stiffness, damping_gain, drive, u_max``; none differ by
default), ``G = [0; Δ; 0]`` so ``G Q Gᵀ = diag(0, Δ² Q, 0)``, and the analytic Jacobian
``I + Δ ∂r/∂x``, ``∂r/∂x = [[0, 1, 0], [−c, −d x3, −d x2], [0, 0, 0]]``. Prior: the plant's
initial-state mean, covariance ``initial_state_cov + 1e-9 diag(max(1, x0²))``
(:func:`fir_gym.wrappers.estimator_observation.prior_of`). ``reset`` consumes ``y[0]``
(update only); each step predicts with the applied action (:func:`fir_gym.jax.kalman.
ekf_predict`) and makes the Joseph-form update with ``H = [1, 0, 0]``
(:func:`fir_gym.jax.kalman.kf_update_innovation`; the plain Joseph product where the numpy
filter forms it from factors — the same matrix up to round-off); the divergence watch is
:func:`fir_gym.jax.kalman.watch` with the numpy defaults. A failed step feeds the filter the
repeated measurement, as the numpy wrapper does.

**Noise contract.** Every random number comes from the ``key`` of ``reset_env`` /
``step_env`` (gymnax's ``step`` splits its key into the step's and the auto-reset's).
:func:`uncertain_oscillator_reset_noise` makes one draw ``z = jax.random.normal(key, (4,))``:
``z[:3]`` for the initial-state spread (times ``V Λ^½`` of ``initial_state_cov`` from
``eigh``, as :func:`fir_gym.envs._base.psd_sqrt`), ``z[3:]`` for the measurement (times
``√R``). :func:`uncertain_oscillator_noise` makes one draw ``z = jax.random.normal(key,
(2,))``: ``z[0]`` for the process noise, the velocity increment ``Δ √Q z[0]`` (the numpy
plant's ``dt * sqrt(Q) * z``), ``z[1:]`` for the measurement (times ``√R``). The pure
functions :meth:`UncertainOscillator.reset_with_noise` and
:meth:`UncertainOscillator.step_with_noise` take those increments
(:class:`UncertainOscillatorResetNoise`, :class:`UncertainOscillatorNoise`) instead of a key,
so a caller can drive the JAX env with any noise sequence — the parity tests drive the numpy
env and this one with the same numbers.

**Parity** (tests/jax/test_uncertain_oscillator_parity.py): over whole 500-step episodes (or
to the termination) the states, observations, rewards, EKF mean and covariance agree with
the numpy env to 1e-9 relative (measured: 2.3e-12 at most), ``terminated``, ``truncated``
and the divergence flag exactly, the NIS to ``1e-9 (1 + nis)``; the per-case maxima are in
that test's docstring. (After a state of 1e20 and more the EKF's covariance is no longer
positive definite in float64, in either implementation: each then ends in its own
round-off, and the test compares the filter only until its watch flags it.)
Not bit for bit: XLA's CPU backend contracts ``a * b + c`` into fused multiply-adds where
numpy rounds the product first (an ulp per operation, grown to ~1e-12 relative by the
printed reading's ×1.15-per-step window).

**Conditions** (through :func:`fir_gym.jax.make`, not the params): ``burst=`` — its windows
are added to the δ schedule, as the numpy plant adds them (``info["burst"]`` their part,
``info["delta"]`` the whole δ; :class:`~fir_gym.jax._plant.FilteredPlant`) — and
``randomize=`` (true ``stiffness, damping_gain, drive, u_max`` drawn around the nominal ones
at each reset; :class:`fir_gym.jax.randomized.Randomized`).

Everything is a pure function of its arguments: ``jit``-able, ``vmap``-able over keys,
states and parameters (:class:`UncertainOscillatorParams` is a pytree; ``uncertainty`` is
static).
"""

from __future__ import annotations

import math
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
    numpy_sqrt,
    sqrt_of,
    watch_limits_of,
    watch_state,
)
from ._x64 import require_x64
from .filter_model import FilterModel
from .kalman import ekf_predict, kf_update_innovation

#: the two readings of eq (29) (``UNCERTAINTY_READINGS`` of the numpy plant)
UNCERTAINTY_READINGS = ("state", "rate")
#: the paper's δ schedule: δ = 0.15 for 350 <= k <= 400
PAPER_DELTA_SCHEDULE = ((350, 400, 0.15),)
#: the worst per-step cost (``UncertainOscillatorEnv.cost_cap``)
COST_CAP = 2.25
#: the observation kinds
KINDS = ("true", "measurement", "measurement-stack", "ekf", "ukf", "efir")
#: the parameters ``nominal=`` may change (the numpy plant's ``params``)
PARAMETERS = ("Q", "R", "dt", "stiffness", "damping_gain", "drive", "u_max")
#: ``H`` of ``y = x1 + v``
_H = ((1.0, 0.0, 0.0),)


@struct.dataclass
class UncertainOscillatorParams(gymnax_env.EnvParams):
    """The physical, noise, uncertainty and filter parameters (a pytree: any float field
    can be vmapped).

    The first group is the truth (:class:`~fir_gym.envs.uncertain_oscillator.
    UncertainOscillatorEnv`'s keywords; ``Q`` and ``R`` the scalar variances of ``w`` and
    ``v``), then the δ schedule as three arrays of one entry per window (``delta_first``,
    ``delta_last`` inclusive step indices, ``delta_value`` the δ), the ``nominal_*`` fields
    what the EKF's model believes (its ``nominal=`` dict), the last group the filter's
    divergence watch (:class:`fir_gym.estimators.base.Estimator`'s defaults). Build one with
    :func:`uncertain_oscillator_params`, which also validates.
    """

    max_steps_in_episode: int = 500
    Q: Any = 0.4                        # process noise variance (w enters x2 through Δ)
    R: Any = 0.1                        # measurement noise variance (n_y = 1)
    dt: Any = 0.01
    stiffness: Any = 25.0
    damping_gain: Any = 10.0
    drive: Any = 12.0
    u_max: Any = 25.0
    setpoint: Any = 1.0
    state_bound: Any = 1e4
    initial_state: Any = struct.field(default_factory=lambda: jnp.array([0.0, 0.0, 0.5]))
    initial_state_cov: Any = struct.field(default_factory=lambda: jnp.zeros((3, 3)))
    state_limit: Any = STATE_LIMIT
    delta_first: Any = struct.field(default_factory=lambda: jnp.array([350]))
    delta_last: Any = struct.field(default_factory=lambda: jnp.array([400]))
    delta_value: Any = struct.field(default_factory=lambda: jnp.array([0.15]))
    nominal_Q: Any = 0.4
    nominal_R: Any = 0.1
    nominal_dt: Any = 0.01
    nominal_stiffness: Any = 25.0
    nominal_damping_gain: Any = 10.0
    nominal_drive: Any = 12.0
    nominal_u_max: Any = 25.0
    max_covariance_trace: Any = 1e12
    #: ``scipy.stats.chi2.isf(nis_tail, 1)`` for the default ``nis_tail = 1e-9``
    nis_threshold: Any = 37.324893051362324
    nis_patience: Any = 10
    uncertainty: str = struct.field(pytree_node=False, default="state")
    #: square root(s) of the noise covariance(s) (:func:`~fir_gym.jax._plant.sqrt_of`: the
    #: builder computes them; ``None`` computes them in the trace)
    initial_sqrt: Any = None


@struct.dataclass
class UncertainOscillatorState(PlantState):
    """The plant, its last observation and the EKF (mean, covariance, watch)."""


@struct.dataclass
class UncertainOscillatorResetNoise:
    """The physical noise of a reset: ``initial`` (3,) added to ``initial_state``,
    ``measurement`` (1,) added to ``x1``."""

    initial: Any
    measurement: Any


@struct.dataclass
class UncertainOscillatorNoise:
    """The physical noise of a step: ``process`` (a scalar) added to the new velocity
    ``x2`` (``Δ w``, ``w ~ N(0, Q)``), ``measurement`` (1,) added to its ``x1`` (``v``)."""

    process: Any
    measurement: Any


def uncertain_oscillator_params(
        *, uncertainty: str = "state", delta_schedule: Any = PAPER_DELTA_SCHEDULE,
        Q: Any = 0.4, R: Any = 0.1, dt: float = 0.01, stiffness: float = 25.0,
        damping_gain: float = 10.0, drive: float = 12.0, u_max: float = 25.0,
        setpoint: float = 1.0, state_bound: float = 1e4,
        nominal: Mapping[str, Any] | None = None, initial_state: Any = (0.0, 0.0, 0.5),
        initial_state_cov: Any = None, max_episode_steps: int = 500,
        max_covariance_trace: float = 1e12, nis_tail: float = 1e-9, nis_patience: int = 10
) -> UncertainOscillatorParams:
    """:class:`UncertainOscillatorParams` from :class:`~fir_gym.envs.uncertain_oscillator.
    UncertainOscillatorEnv`'s keywords (and the EKF's watch options); ``nominal`` as there
    (keys ``Q, R, dt, stiffness, damping_gain, drive, u_max``; none by default).

    Host-side: validates with the numpy plant's own checks (a bad value raises a
    ``ValueError`` naming the argument; ``damping_gain``, ``drive`` and ``setpoint``, which
    the numpy plant takes as any float, must be finite here) and, for ``nominal``, the
    numpy model's (``Q``, ``R`` positive semidefinite, ``dt`` positive; the others finite),
    and converts."""
    require_x64()
    from scipy.stats import chi2

    from fir_gym.envs._conditions import check_burst
    from fir_gym.estimators._validation import (
        as_covariance,
        as_vector,
        one_of,
        positive,
    )

    one_of("uncertainty", uncertainty, UNCERTAINTY_READINGS)
    windows = check_burst(delta_schedule, "delta_schedule")

    def finite(name: str, value: Any) -> float:
        try:
            val = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a finite number; got {value!r}") from None
        if isinstance(value, bool) or not math.isfinite(val):
            raise ValueError(f"{name} must be a finite number; got {value!r}")
        return val

    def physical(values: Mapping[str, Any], prefix: str = "") -> dict[str, float]:
        """The numpy plant's checks of its ``params``; for ``nominal`` (``prefix``) the
        numpy model's (Q, R positive semidefinite, dt positive) and finite numbers."""
        strict = positive if not prefix else finite
        return {"Q": float(as_covariance(f"{prefix}Q", values["Q"], 1)[0, 0]),
                "R": float(as_covariance(f"{prefix}R", values["R"], 1,
                                         definite=not prefix)[0, 0]),
                "dt": positive(f"{prefix}dt", values["dt"]),
                "stiffness": strict(f"{prefix}stiffness", values["stiffness"]),
                "damping_gain": finite(f"{prefix}damping_gain", values["damping_gain"]),
                "drive": finite(f"{prefix}drive", values["drive"]),
                "u_max": strict(f"{prefix}u_max", values["u_max"])}

    truth = physical({"Q": Q, "R": R, "dt": dt, "stiffness": stiffness,
                      "damping_gain": damping_gain, "drive": drive, "u_max": u_max})
    if nominal is not None and not isinstance(nominal, Mapping):
        raise ValueError(f"nominal must be a mapping of parameter names to values; got "
                         f"{type(nominal).__name__}")
    unknown = sorted(set(nominal or {}) - set(PARAMETERS))
    if unknown:
        raise ValueError(f"nominal has unknown parameter(s) {unknown}; known parameters are "
                         f"{sorted(PARAMETERS)}")
    believed = physical({**truth, **(nominal or {})}, "nominal ")
    x0 = as_vector("initial_state", initial_state, 3)
    P0 = (np.zeros((3, 3)) if initial_state_cov is None
          else as_covariance("initial_state_cov", initial_state_cov, 3))
    steps = positive("max_episode_steps", max_episode_steps, integer=True)
    tail = finite("nis_tail", nis_tail)
    if not 0.0 < tail < 1.0:
        raise ValueError(f"nis_tail must be a probability strictly between 0 and 1; got "
                         f"{nis_tail!r}")
    return UncertainOscillatorParams(
        max_steps_in_episode=steps, **truth, setpoint=finite("setpoint", setpoint),
        state_bound=positive("state_bound", state_bound), initial_state=jnp.asarray(x0),
        initial_state_cov=jnp.asarray(P0),
        delta_first=jnp.asarray([w[0] for w in windows], dtype=jnp.int64),
        delta_last=jnp.asarray([w[1] for w in windows], dtype=jnp.int64),
        delta_value=jnp.asarray([w[2] for w in windows], dtype=jnp.float64),
        **{f"nominal_{name}": value for name, value in believed.items()},
        max_covariance_trace=positive("max_covariance_trace", max_covariance_trace),
        nis_threshold=float(chi2.isf(tail, 1)),
        nis_patience=positive("nis_patience", nis_patience, integer=True),
        uncertainty=uncertainty, initial_sqrt=numpy_sqrt(P0))


# ---------------------------------------------------------------------------- pure functions
def delta_at(k: jax.Array, first: jax.Array, last: jax.Array, value: jax.Array) -> jax.Array:
    """δ_k of the transition from ``x[k]``: the sum of the windows' δ with ``first <= k <=
    last`` (:meth:`~fir_gym.envs.uncertain_oscillator.UncertainOscillatorEnv.delta`, in its
    order: ``0 + δ_1 [k ∈ w_1] + δ_2 [k ∈ w_2] + …``; the number of windows is static)."""
    total = jnp.zeros((), dtype=jnp.float64)
    for i in range(jnp.shape(value)[0]):
        total = total + value[i] * ((first[i] <= k) & (k <= last[i]))
    return total


def oscillator_rate(x: jax.Array, u: jax.Array, c: Any, d: Any, b: Any, u_max: Any
                    ) -> jax.Array:
    """``r(x, u) = [x2; −c x1 − d x2 x3 + b + u u_max; 0]`` of eq (29), ``u`` the
    normalised action (1,) (:meth:`~fir_gym.envs.uncertain_oscillator.OscillatorDynamics.
    rate`, its operations in its order)."""
    x1, x2, x3 = x[0], x[1], x[2]
    acc = -c * x1 - d * x2 * x3 + b + u[0] * u_max
    return jnp.stack([x2, acc, jnp.zeros_like(x1)])


def oscillator_step(x: jax.Array, u: jax.Array, delta: Any, c: Any, d: Any, b: Any,
                    u_max: Any, dt: Any, uncertainty: str) -> jax.Array:
    """One transition of eq (29) without noise: ``D x + r(x, u) Δ`` (``"state"``) or ``x +
    D r(x, u) Δ`` (``"rate"``), ``D = diag(1 + δ, 1 + δ, 1)``
    (:meth:`~fir_gym.envs.uncertain_oscillator.OscillatorDynamics.step`)."""
    scale = 1.0 + delta * jnp.array([1.0, 1.0, 0.0])
    r = oscillator_rate(x, u, c, d, b, u_max)
    if uncertainty == "state":
        return scale * x + r * dt
    return x + scale * r * dt


def oscillator_jacobian(x: jax.Array, c: Any, d: Any, dt: Any, uncertainty: str,
                        delta: Any = 0.0) -> jax.Array:
    """``∂x⁺/∂x`` of :func:`oscillator_step`: ``D + Δ ∂r/∂x`` (``"state"``) or ``I + Δ D
    ∂r/∂x`` (``"rate"``), ``∂r/∂x = [[0, 1, 0], [−c, −d x3, −d x2], [0, 0, 0]]``
    (:meth:`~fir_gym.envs.uncertain_oscillator.OscillatorDynamics.jacobian`)."""
    zero, one = jnp.zeros_like(x[0]), jnp.ones_like(x[0])
    dr = jnp.stack([jnp.stack([zero, one, zero]),
                    jnp.stack([-c * one, -d * x[2], -d * x[1]]),
                    jnp.stack([zero, zero, zero])])
    scale = jnp.stack([1.0 + delta * one, 1.0 + delta * one, one])
    if uncertainty == "state":
        return jnp.diag(scale) + dt * dr
    return jnp.eye(3) + dt * scale[:, None] * dr


def uncertain_oscillator_reset_noise(key: jax.Array, params: UncertainOscillatorParams
                                     ) -> UncertainOscillatorResetNoise:
    """The noise of a reset from one draw ``z = jax.random.normal(key, (4,))``:
    ``initial = sqrt(initial_state_cov) z[:3]``, ``measurement = √R z[3:]``."""
    z = jax.random.normal(key, (4,), dtype=jnp.float64)
    return UncertainOscillatorResetNoise(
        sqrt_of(params.initial_sqrt, params.initial_state_cov) @ z[:3],
        jnp.sqrt(params.R) * z[3:])


def uncertain_oscillator_noise(key: jax.Array, params: UncertainOscillatorParams
                               ) -> UncertainOscillatorNoise:
    """The noise of a step from one draw ``z = jax.random.normal(key, (2,))``: ``process =
    Δ √Q z[0]`` (the velocity increment, as the numpy plant's ``dt * sqrt(Q) * z``),
    ``measurement = √R z[1:]``."""
    z = jax.random.normal(key, (2,), dtype=jnp.float64)
    return UncertainOscillatorNoise(params.dt * jnp.sqrt(params.Q) * z[0],
                                    jnp.sqrt(params.R) * z[1:])


def model_process_cov(params: UncertainOscillatorParams) -> jax.Array:
    """The model's ``G Q Gᵀ`` with ``G = [0; Δ; 0]`` of the nominal Δ and Q (``(G Q) Gᵀ``,
    the numpy model's ``G @ Q @ G.T``)."""
    G = jnp.stack([0.0 * params.nominal_dt, params.nominal_dt, 0.0 * params.nominal_dt])
    return jnp.outer(G * params.nominal_Q, G)


def ekf_update(state: UncertainOscillatorState, x: jax.Array, P: jax.Array, y: jax.Array,
               params: UncertainOscillatorParams) -> UncertainOscillatorState:
    """The Joseph-form update of the prior ``(x, P)`` with ``y`` (``H = [1, 0, 0]``, the
    nominal R), then the divergence watch (:meth:`fir_gym.estimators.base.Estimator.
    _accept`): the state's filter fields afterwards."""
    H = jnp.asarray(_H)
    R = jnp.reshape(jnp.asarray(params.nominal_R, dtype=jnp.float64), (1, 1))
    x_new, P_new, nis = kf_update_innovation(x, P, y - x[:1], H, R)
    return watch_state(state, x_new, P_new, nis, watch_limits_of(params))


# ---------------------------------------------------------------------------- the environment
class UncertainOscillator(FilteredPlant):
    """``fir_gym/UncertainOscillator-v0`` as a gymnax environment observing ``kind`` (see the
    module docstring): ``"true"``, ``"measurement"`` or ``"ekf"`` (the default, observing
    ``observation``: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``).

    ``reset_env(key, params)`` and ``step_env(key, state, action, params)`` draw their noise
    from ``key`` (:func:`uncertain_oscillator_reset_noise`, :func:`uncertain_oscillator_noise`)
    and call the pure :meth:`reset_with_noise` / :meth:`step_with_noise`. gymnax's ``step``
    adds the auto-reset and ``is_truncated`` (``time >= max_steps_in_episode``). ``info`` has
    ``state`` (the true state), ``action`` (applied, float64), ``action_clipped``,
    ``simulation_failure`` (a code, 0 for none), ``delta`` (the δ of the step's transition)
    and, for ``"ekf"``, ``estimate``, ``estimation_error``, ``estimator_diverged`` and
    ``nis``.
    """

    kinds = KINDS
    randomizable = ("stiffness", "damping_gain", "drive", "u_max")
    estimator = "ekf"
    n_x, n_y = 3, 1

    @property
    def default_params(self) -> UncertainOscillatorParams:
        return uncertain_oscillator_params()

    @property
    def name(self) -> str:
        return "fir_gym/UncertainOscillator-v0"

    def filter_model(self, params: UncertainOscillatorParams) -> FilterModel:
        """The EKF's model (the numpy plant's ``model``): the nominal oscillator with δ = 0,
        ``H = [1, 0, 0]``, ``G Q Gᵀ`` (:func:`model_process_cov`) and the nominal ``R``."""
        def f(x: jax.Array, u: jax.Array) -> jax.Array:
            return oscillator_step(x, u, 0.0, params.nominal_stiffness,
                                   params.nominal_damping_gain, params.nominal_drive,
                                   params.nominal_u_max, params.nominal_dt, params.uncertainty)

        def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
            return f(x, u), oscillator_jacobian(x, params.nominal_stiffness,
                                                params.nominal_damping_gain, params.nominal_dt,
                                                params.uncertainty)

        return FilterModel(f, f_and_F, jnp.asarray(_H), model_process_cov(params),
                           jnp.reshape(jnp.asarray(params.nominal_R, dtype=jnp.float64), (1, 1)))

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """The true measurement noise's square root (the outliers' scale)."""
        return jnp.sqrt(jnp.reshape(jnp.asarray(params.R, dtype=jnp.float64), (1, 1)))

    # ------------------------------------------------------------------ reset
    def reset_env(self, key: jax.Array, params: UncertainOscillatorParams
                  ) -> tuple[Any, UncertainOscillatorState]:
        return self.reset_with_noise(uncertain_oscillator_reset_noise(key, params), params,
                                     self.sensor_reading(key, 0, params))

    def reset_with_noise(self, noise: UncertainOscillatorResetNoise,
                         params: UncertainOscillatorParams,
                         missing: Reading | jax.Array | bool = False
                         ) -> tuple[Any, UncertainOscillatorState]:
        """The reset with the given noise: ``x = initial_state + noise.initial``, ``y = x1 +
        noise.measurement`` (held where ``missing``, with dropout); the EKF (for ``"ekf"``)
        consumes ``y`` from its prior
        (:meth:`fir_gym.envs._base.PlantEnv.reset`, then
        :meth:`fir_gym.wrappers.EstimatorObservation.reset`)."""
        require_x64()
        x = jnp.asarray(params.initial_state, dtype=jnp.float64) + noise.initial
        y = self.deliver(missing, x[:1] + noise.measurement, self.first_hold(params))
        x0, P0 = filter_prior(params)
        state = UncertainOscillatorState.start(x, y, x0, P0)
        if self.runs_own_filter:
            state = self.own_update(missing, state, ekf_update(state, x0, P0, y, params), x0,
                                    P0, params)
        state = self.finish_reset(state, params, missing)
        return self.get_obs(state, params), state

    # ------------------------------------------------------------------ step
    def step_env(self, key: jax.Array, state: UncertainOscillatorState, action: Any,
                 params: UncertainOscillatorParams
                 ) -> tuple[Any, UncertainOscillatorState, jax.Array, jax.Array, dict[str, Any]]:
        obs, state, reward, terminated, info = self.step_with_noise(
            state, action, uncertain_oscillator_noise(key, params), params,
            self.sensor_reading(key, state.time + 1, params, state.sensor_stuck))
        # gymnax's rule: transitions are detached unless gradients were asked for
        obs, state = self._apply_transition_gradient_policy(obs, state)
        return obs, state, reward, terminated, info

    def step_with_noise(self, state: UncertainOscillatorState, action: Any,
                        noise: UncertainOscillatorNoise, params: UncertainOscillatorParams,
                        missing: Reading | jax.Array | bool = False
                        ) -> tuple[Any, UncertainOscillatorState, jax.Array, jax.Array,
                                   dict[str, Any]]:
        """One env step with the given noise: ``(obs, state, reward, terminated, info)``;
        with dropout, a ``missing`` reading holds the last delivered one.

        :meth:`fir_gym.envs._base.PlantEnv.step` of :class:`~fir_gym.envs.
        uncertain_oscillator.UncertainOscillatorEnv` (its ``_transition`` with δ_k of
        ``state.time``, ``_reward``, ``_in_domain``) and, for ``"ekf"``, the EKF step of
        :class:`~fir_gym.wrappers.EstimatorObservation`; its only Python branches are on
        static things (the kind, the reading, the number of δ windows), none on data.
        """
        require_x64()
        u_in = jnp.reshape(jnp.asarray(action, dtype=jnp.float64), (1,))
        u = jnp.clip(u_in, -1.0, 1.0)
        x = state.x
        burst = self.burst_delta(state.time)          # added to the δ schedule (numpy's rule)
        delta = delta_at(state.time, params.delta_first, params.delta_last, params.delta_value)
        if self.burst:
            delta = delta + burst
        x_next = oscillator_step(x, u, delta, params.stiffness, params.damping_gain,
                                 params.drive, params.u_max, params.dt, params.uncertainty)
        x_next = x_next.at[1].add(noise.process)
        time = state.time + 1
        left = jnp.maximum(params.max_steps_in_episode - time, 0)
        penalty = -COST_CAP * (1.0 + left)

        finite_state = jnp.all(jnp.isfinite(x_next))
        overflow = jnp.any(jnp.abs(x_next) > params.state_limit)
        in_domain = jnp.all(jnp.isfinite(x_next) & (jnp.abs(x_next) <= params.state_bound))
        e = x_next[0] - params.setpoint
        cost = e * e + 1e-3 * u[0] * u[0]
        reward = jnp.where(in_domain, -jnp.where(cost < COST_CAP, cost, COST_CAP), penalty)
        y_next = x_next[:1] + noise.measurement
        failure = jnp.select(
            [~finite_state, overflow, ~jnp.isfinite(reward), ~jnp.all(jnp.isfinite(y_next))],
            [1, 2, 4, 3], 0)
        failed = failure > 0
        x_kept = jnp.where(failed, x, x_next)
        y = self.deliver(missing, jnp.where(failed, state.y, y_next), state.y)
        reward = jnp.where(failed, penalty, reward)
        terminated = failed | ~in_domain
        new = state.replace(time=time, x=x_kept, y=y, terminated=terminated)
        info: dict[str, Any] = {"state": x_kept, "action": u, "action_clipped": jnp.any(u != u_in),
                                "simulation_failure": failure, "delta": delta}
        if self.runs_own_filter:
            model = self.filter_model(params)
            xp, Pp = ekf_predict(state.filter_x, state.filter_P, u, model.Q, model.f_and_F)
            new = self.own_update(missing, new, ekf_update(new, xp, Pp, y, params), xp, Pp,
                                  params)
        obs, new, info = self.finish_step(state, new, u, params, info, missing)
        return obs, new, reward, terminated, info
