"""VanDerPol-v0 as a gymnax environment: paper 002, §4, with its EKF in the state.

The JAX twin of :class:`fir_gym.envs.van_der_pol.VanDerPolEnv` (the numpy reference) seen
through :func:`fir_gym.wrappers.factory.wrap_observation` — one of three observation kinds:

* ``"true"``: the true state ``[x1, x2]``
  (:class:`~fir_gym.wrappers.baselines.TrueStateObservation`);
* ``"measurement"``: the raw measurement ``[x̄1 + v̄]``, the interval average of ``x1`` plus
  noise (the plant's own observation);
* ``"ekf"``: the extended Kalman filter's estimate ``x̂`` of ``[x1, x2]``
  (:class:`~fir_gym.wrappers.EstimatorObservation` with
  :class:`~fir_gym.estimators.extended.ExtendedKalmanFilter` on the env's ``model``); the
  filter's mean, covariance and divergence watch live in :class:`VanDerPolState`. As there,
  ``observation`` may instead be ``"estimate+covariance"`` (a dict: ``estimate`` and
  ``covariance``, the upper triangle of ``P`` row by row, ``[P11, P12, P22]``) or
  ``"estimate+measurement"`` (``estimate`` and ``measurement``).

**Plant** (paper 002, §4, with a force ``u = action · u_max`` on the x2 equation, held over
the interval): ``dx = a(x, u) dt + [1, 1]ᵀ dW``, ``a = [x2, −x1 + ε (1 − x1²) x2 + u]``,
``E[dW²] = Q dt``, integrated by ``substeps`` (100) stochastic Heun steps of ``τ = h /
substeps`` per env step of ``h`` (0.1): ``x̃ = x + a(x) τ + [1, 1]ᵀ ΔW``, ``x⁺ = x + (a(x)
+ a(x̃)) τ / 2 + [1, 1]ᵀ ΔW``, ``ΔW = √(Q τ) z`` (:func:`heun_plant_interval`, a
:func:`jax.lax.fori_loop` that mirrors :meth:`fir_gym.envs.van_der_pol.VanDerPolDynamics.
integrate` operation for operation). Measurement (integrate-and-dump): the trapezoid mean of
``x1`` over the interval's Heun grid plus ``v̄ ~ N(0, R/h)``; the one ``reset`` returns is
``x1(0) + v̄``. Reward ``−min((x1² + x2²)/4 + 0.01 action², cost_cap)``, ``cost_cap =
state_bound²/2 + 0.01``; termination when ``|x1|`` or ``|x2|`` exceeds ``state_bound`` (or
is not finite), paid ``−cost_cap (1 + steps left to max_steps_in_episode)``; a step whose new
state is not finite or beyond ``±state_limit`` (or whose reward or measurement is not
finite) is a simulation failure: the plant stays at its last valid state, the observation
repeats, the reward is the terminal penalty and the episode terminates (``info
["simulation_failure"]``: 0 none, 1 nonfinite_state, 2 state_overflow, 3
nonfinite_observation, 4 nonfinite_reward — :data:`SIMULATION_FAILURES`). Truncation at
``max_steps_in_episode`` (gymnax's ``is_truncated``, the registered ``TimeLimit``).
Actions are clipped to ``[-1, 1]`` (``info["action_clipped"]``); a NaN action, which the
numpy plant refuses with a ``ValueError``, cannot raise under ``jit``: it makes the new
state NaN, a simulation failure.

**EKF** (:mod:`fir_gym.estimators.extended` on
:meth:`~fir_gym.envs.van_der_pol.VanDerPolEnv._build_model` of the nominal parameters): ``f``
the noise-free Heun map over one interval with the model's ``ε, u_max, h, substeps``, ``F``
its exact Jacobian, the product of the Heun step Jacobians ``I + τ/2 (J(x) + J(x̃)(I + τ
J(x)))`` (:func:`heun_model_interval`, the same loop), ``h(x) = x1`` at the interval's end
(``H = [1, 0]``), ``R_model = R/h`` and the model's process noise ``Q_d`` —
:func:`fir_gym.envs.van_der_pol.process_noise_covariance`, Van Loan's integral averaged over
the limit cycle, computed host-side by :func:`van_der_pol_params` (``model_Q``). Prior: the
plant's initial-state mean, covariance ``initial_state_cov + 1e-9 diag(max(1, x0²))``
(:func:`fir_gym.wrappers.estimator_observation.prior_of`). ``reset`` consumes ``y[0]``
(update only); each step predicts with the applied action (:func:`fir_gym.jax.kalman.
ekf_predict`), then makes the Joseph-form update with the innovation ``y − x̂⁻₁``
(:func:`fir_gym.jax.kalman.kf_update_innovation`), then the divergence watch
(:func:`fir_gym.jax.kalman.watch`, the numpy defaults).

**Noise contract.** Every random number comes from the ``key`` of ``reset_env`` /
``step_env`` (gymnax's ``step`` splits its key into the step's and the auto-reset's), in
the numpy plant's draw order and shapes:

* :func:`van_der_pol_reset_noise`: ``z = jax.random.normal(key, (3,))``, ``z[:2]`` for the
  initial state (the numpy plant's ``standard_normal((2,))``, turned into ``sqrt(
  initial_state_cov) z[:2]`` with ``V Λ^½`` from ``eigh``, as
  :func:`fir_gym.envs._base.psd_sqrt`), ``z[2:]`` for the measurement (``√(R/h) z[2:]``);
* :func:`van_der_pol_noise`: ``z = jax.random.normal(key, (substeps + 1,))``, ``z[:substeps]``
  the standard normals of the Wiener increments — one per Heun substep, the numpy plant's
  ``standard_normal((substeps,))``, drawn even when ``Q = 0`` — turned into ``ΔW = √(Q τ)
  z[:substeps]``, then ``z[substeps:]`` for the measurement (``√(R/h) z[substeps:]``).

The pure functions :meth:`VanDerPol.reset_with_noise` and :meth:`VanDerPol.step_with_noise`
take those physical increments (:class:`VanDerPolResetNoise`, :class:`VanDerPolNoise`)
instead of a key, so a caller can drive the JAX env with any noise sequence — the parity
tests drive the numpy env and this one with the same numbers. (A step whose simulation
fails draws no measurement noise in the numpy plant; here the draw is made and unused.)

**Parity** (``tests/jax/test_van_der_pol_parity.py``): over 300-step episodes of the three
kinds — the paper's plant, a random start with other true parameters, a model mismatch
(``nominal`` ε, u_max, Q), a coarser model (50 substeps), a state leaving the domain —
states, observations, rewards, the EKF's mean and covariance agree with the numpy env to
5.2e-12 relative, ``terminated``, ``truncated`` and the divergence flag exactly. Not to the
bit: XLA's CPU backend always contracts ``a * b + c`` into fused multiply-adds, so the Heun
loop differs from the numpy one (and its numba twin) by round-off from the first substep;
the Van der Pol origin being unstable, that round-off grows in open loop (like ``e^{ε t/2}``),
which is why the parity episodes run under a feedback both envs evaluate.

Conditions (through :func:`fir_gym.jax.make`, not the params): ``burst=`` stretches the whole
path of a step about its start, its end and the interval average alike, as the numpy plant
does (:class:`~fir_gym.jax._plant.FilteredPlant`), and ``randomize=``
(:class:`fir_gym.jax.randomized.Randomized`). Not mirrored: ``render``.

Everything is a pure function of its arguments: ``jit``-able, ``vmap``-able over keys,
states and parameters (:class:`VanDerPolParams` is a pytree; ``substeps`` and
``nominal_substeps`` are static). ``model_Q`` and ``model_R`` are computed from the nominal
parameters by :func:`van_der_pol_params`: replacing ``nominal_epsilon`` in a params pytree
does not update them (build one params per value and stack them instead).
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

#: the observation kinds
KINDS = ("true", "measurement", "measurement-stack", "ekf", "ukf", "efir")
#: the Heun loops are unrolled by this factor (:func:`jax.lax.fori_loop`'s ``unroll``; the
#: value :mod:`fir_gym.jax.orbit` measured for its Euler loops)
UNROLL = 10
#: the numpy env's parameters that ``nominal=`` may change (its ``params``)
NOMINAL_KEYS = ("Q", "R", "epsilon", "h", "substeps", "u_max")
#: the Heun accuracy limit the numpy constructor checks: ``|ε| state_bound² τ <= 0.5``
HEUN_LIMIT = 0.5


@struct.dataclass
class VanDerPolParams(gymnax_env.EnvParams):
    """The physical, noise and filter parameters (a pytree: any float field can be vmapped).

    The first group is the truth (:class:`fir_gym.envs.van_der_pol.VanDerPolEnv`'s
    keywords: ``Q`` the spectral density of ``dW``, ``R`` the intensity of the continuous
    measurement noise, so the measurement's variance is ``R/h``), the ``nominal_*`` and
    ``model_*`` fields what the EKF's model believes (from its ``nominal=`` dict: the Heun
    map's ``ε, u_max, h`` and ``nominal_substeps``, ``model_Q`` the integrated process noise
    ``Q_d``, ``model_R = R/h``), the last group the filter's divergence watch
    (:class:`fir_gym.estimators.base.Estimator`'s defaults). Build one with
    :func:`van_der_pol_params`, which also validates and computes ``model_Q``.
    """

    max_steps_in_episode: int = 100
    epsilon: Any = 1.0
    Q: Any = 5.0                        # spectral density of the Wiener process
    R: Any = 5.0                        # intensity of the continuous measurement noise
    h: Any = 0.1                        # the env step (block-pulse interval)
    u_max: Any = 20.0
    state_bound: Any = 20.0
    initial_state: Any = struct.field(default_factory=lambda: jnp.array([1.0, 1.0]))
    initial_state_cov: Any = struct.field(default_factory=lambda: jnp.zeros((2, 2)))
    state_limit: Any = STATE_LIMIT
    nominal_epsilon: Any = 1.0
    nominal_h: Any = 0.1
    nominal_u_max: Any = 20.0
    #: process_noise_covariance of the default plant (van_der_pol_params computes it)
    model_Q: Any = struct.field(default_factory=lambda: jnp.array(
        [[0.548, 0.472], [0.472, 0.425]]))
    model_R: Any = 50.0
    max_covariance_trace: Any = 1e12
    #: ``scipy.stats.chi2.isf(nis_tail, 1)`` for the default ``nis_tail = 1e-9``
    nis_threshold: Any = 37.324893051362324
    nis_patience: Any = 10
    substeps: int = struct.field(pytree_node=False, default=100)
    nominal_substeps: int = struct.field(pytree_node=False, default=100)
    #: square root(s) of the noise covariance(s) (:func:`~fir_gym.jax._plant.sqrt_of`: the
    #: builder computes them; ``None`` computes them in the trace)
    initial_sqrt: Any = None


@struct.dataclass
class VanDerPolState(PlantState):
    """The plant, its last observation and the EKF (mean, covariance, watch)."""


@struct.dataclass
class VanDerPolResetNoise:
    """The physical noise of a reset: ``initial`` (2,) added to ``initial_state``,
    ``measurement`` (1,) added to ``x1(0)``."""

    initial: Any
    measurement: Any


@struct.dataclass
class VanDerPolNoise:
    """The physical noise of a step: ``process`` (substeps,) the Wiener increments ``ΔW``
    of the Heun substeps, in order (each enters both states: ``[1, 1]ᵀ ΔW``),
    ``measurement`` (1,) added to the interval average of ``x1`` (``v̄``)."""

    process: Any
    measurement: Any


def _positive(name: str, value: Any) -> float:
    """``value`` as a positive finite float, else a ValueError naming ``name``."""
    try:
        val = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number; got {value!r}") from None
    if not (math.isfinite(val) and val > 0):
        raise ValueError(f"{name} must be a positive finite number; got {value!r}")
    return val


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        raise ValueError(f"{name} must be a positive integer; got {value!r}")
    return int(value)


def _finite(name: str, value: Any) -> float:
    try:
        val = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number; got {value!r}") from None
    if not math.isfinite(val):
        raise ValueError(f"{name} must be a finite number; got {value!r}")
    return val


def _nonnegative(name: str, value: Any) -> float:
    val = _finite(name, value)
    if val < 0:
        raise ValueError(f"{name} must be a non-negative spectral density; got {value!r}")
    return val


def _checked(prefix: str, values: Mapping[str, Any]) -> dict[str, Any]:
    """The plant parameters ``Q, R, epsilon, h, substeps, u_max`` validated as the numpy
    constructor validates them (names in messages prefixed, e.g. ``nominal epsilon``)."""
    return {"epsilon": _finite(prefix + "epsilon", values["epsilon"]),
            "Q": _nonnegative(prefix + "Q", values["Q"]),
            "R": _positive(prefix + "R", values["R"]),
            "h": _positive(prefix + "h", values["h"]),
            "substeps": _positive_int(prefix + "substeps", values["substeps"]),
            "u_max": _positive(prefix + "u_max", values["u_max"])}


def van_der_pol_params(*, epsilon: float = 1.0, Q: float = 5.0, R: float = 5.0, h: float = 0.1,
                       substeps: int = 100, u_max: float = 20.0, state_bound: float = 20.0,
                       nominal: Mapping[str, Any] | None = None,
                       initial_state: Any = (1.0, 1.0), initial_state_cov: Any = None,
                       max_episode_steps: int = 100, max_covariance_trace: float = 1e12,
                       nis_tail: float = 1e-9, nis_patience: int = 10) -> VanDerPolParams:
    """:class:`VanDerPolParams` from :class:`fir_gym.envs.van_der_pol.VanDerPolEnv`'s keywords
    (and the EKF's watch options); ``nominal`` as there (keys ``epsilon, Q, R, h, substeps,
    u_max``; none by default: the model believes the truth). Host-side: validates (a
    ValueError names the argument), checks the numpy constructor's Heun limit ``max(|ε|,
    |ε_nominal|) state_bound² h / substeps <= 0.5``, and computes the model's process noise
    :func:`fir_gym.envs.van_der_pol.process_noise_covariance` (Van Loan's integral over the
    limit cycle, with scipy) and ``R/h`` as the numpy model holds them."""
    require_x64()
    from scipy.stats import chi2

    from fir_gym.envs.van_der_pol import process_noise_covariance
    from fir_gym.estimators._validation import as_covariance

    truth = _checked("", {"epsilon": epsilon, "Q": Q, "R": R, "h": h, "substeps": substeps,
                          "u_max": u_max})
    if nominal is not None and not isinstance(nominal, Mapping):
        raise ValueError(f"nominal must be a mapping of parameter names to values; got "
                         f"{type(nominal).__name__}")
    unknown = sorted(set(nominal or {}) - set(NOMINAL_KEYS))
    if unknown:
        raise ValueError(f"nominal has unknown parameter(s) {unknown}; known parameters are "
                         f"{sorted(NOMINAL_KEYS)}")
    believed = _checked("nominal ", {**truth, **(nominal or {})})
    bound = _positive("state_bound", state_bound)
    tau = truth["h"] / truth["substeps"]
    eps_max = max(abs(truth["epsilon"]), abs(believed["epsilon"]))
    if eps_max * bound ** 2 * tau > HEUN_LIMIT:
        raise ValueError(f"state_bound={state_bound} is too large for substeps={substeps}: the "
                         f"Heun step needs |epsilon| * state_bound² * h / substeps <= 0.5 (got "
                         f"{eps_max * bound ** 2 * tau:.3g}); raise substeps")
    max_steps = _positive_int("max_episode_steps", max_episode_steps)
    if not (isinstance(nis_tail, (int, float)) and 0.0 < float(nis_tail) < 1.0):
        raise ValueError(f"nis_tail must be a probability strictly between 0 and 1; got "
                         f"{nis_tail!r}")
    patience = _positive_int("nis_patience", nis_patience)
    trace_limit = _positive("max_covariance_trace", max_covariance_trace)

    try:
        x0 = np.asarray(initial_state, dtype=np.float64).reshape(2)
    except (TypeError, ValueError):
        raise ValueError(f"initial_state must be 2 real numbers [x1, x2]; got "
                         f"{initial_state!r}") from None
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"initial_state must be finite; got {x0}")

    def cov(name: str, value: Any) -> np.ndarray:
        try:
            return as_covariance(name, value, 2)
        except (TypeError, ValueError) as error:
            raise ValueError(str(error) if name in str(error) else f"{name}: {error}") from None

    P0 = np.zeros((2, 2)) if initial_state_cov is None else cov("initial_state_cov",
                                                                 initial_state_cov)
    # the numpy model's Q and R (StateSpaceModel: as_covariance, then G Q Gᵀ with G = I)
    G = np.eye(2)
    model_Q = G @ as_covariance("Q", process_noise_covariance(believed)) @ G.T
    model_R = float(as_covariance("R", believed["R"] / believed["h"])[0, 0])
    return VanDerPolParams(
        max_steps_in_episode=max_steps,
        epsilon=truth["epsilon"], Q=truth["Q"], R=truth["R"], h=truth["h"],
        u_max=truth["u_max"], state_bound=bound, initial_state=jnp.asarray(x0),
        initial_state_cov=jnp.asarray(P0),
        nominal_epsilon=believed["epsilon"], nominal_h=believed["h"],
        nominal_u_max=believed["u_max"], model_Q=jnp.asarray(model_Q), model_R=model_R,
        max_covariance_trace=trace_limit, nis_threshold=float(chi2.isf(nis_tail, 1)),
        nis_patience=patience, substeps=truth["substeps"],
        nominal_substeps=believed["substeps"], initial_sqrt=numpy_sqrt(P0))


# ---------------------------------------------------------------------------- pure functions
def _drift2(x1: jax.Array, x2: jax.Array, eps: jax.Array, force: jax.Array) -> jax.Array:
    """The second drift component ``−x1 + ε (1 − x1²) x2 + u`` (the numpy order)."""
    return -x1 + eps * (1.0 - x1 * x1) * x2 + force


def _heun_substep(x1: jax.Array, x2: jax.Array, dw: Any, eps: jax.Array, force: jax.Array,
                  tau: jax.Array) -> tuple[jax.Array, ...]:
    """One stochastic Heun step: ``(x1⁺, x2⁺, x̃1, x̃2)``, the operations of
    :meth:`~fir_gym.envs.van_der_pol.VanDerPolDynamics.integrate` in its order."""
    a1 = _drift2(x1, x2, eps, force)                  # drift at x
    y1 = x1 + x2 * tau + dw                           # Euler predictor x̃
    y2 = x2 + a1 * tau + dw
    b1 = _drift2(y1, y2, eps, force)                  # drift at x̃
    return x1 + 0.5 * (x2 + y2) * tau + dw, x2 + 0.5 * (a1 + b1) * tau + dw, y1, y2


def _heun_jacobian_substep(x1: jax.Array, x2: jax.Array, y1: jax.Array, y2: jax.Array,
                           eps: jax.Array, tau: jax.Array, Phi: tuple[jax.Array, ...]
                           ) -> tuple[jax.Array, ...]:
    """``Φ ← (I + τ/2 (J(x) + J(x̃)(I + τ J(x)))) Φ``, ``J = [[0, 1], [c, d]]``, ``c = −1 −
    2 ε x1 x2``, ``d = ε (1 − x1²)`` (the numpy loop's ``s``, ``m`` and ``p`` in its order)."""
    p11, p12, p21, p22 = Phi
    half = 0.5 * tau
    c0, d0 = -1.0 - 2.0 * eps * x1 * x2, eps * (1.0 - x1 * x1)
    c1, d1 = -1.0 - 2.0 * eps * y1 * y2, eps * (1.0 - y1 * y1)
    m11, m12 = 1.0, tau                               # I + τ J0
    m21, m22 = tau * c0, 1.0 + tau * d0
    s11 = 1.0 + half * m21                            # row 1 of J1 is [0, 1]
    s12 = half * (1.0 + m22)
    s21 = half * (c0 + c1 * m11 + d1 * m21)
    s22 = 1.0 + half * (d0 + c1 * m12 + d1 * m22)
    return (s11 * p11 + s12 * p21, s11 * p12 + s12 * p22,
            s21 * p11 + s22 * p21, s21 * p12 + s22 * p22)


def _unroll(substeps: int) -> int:
    return min(UNROLL, max(substeps, 1))


def heun_plant_interval(x: jax.Array, force: jax.Array, dW: jax.Array, epsilon: jax.Array,
                        tau: jax.Array, substeps: int) -> tuple[jax.Array, jax.Array]:
    """The plant's interval: ``substeps`` stochastic Heun steps of ``τ`` from ``x = [x1, x2]``
    under the force ``u_max · action`` with the Wiener increments ``dW`` (substeps,); returns
    ``(x_end, x̄1)`` with ``x̄1 = (x1(0)/2 + Σ x1(j) − x1(end)/2) / substeps``, the trapezoid
    mean of ``x1`` on the Heun grid (the integrate-and-dump measurement's signal).
    :meth:`fir_gym.envs.van_der_pol.VanDerPolDynamics.integrate` with ``dW``."""
    def body(i: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        x1, x2, x1_sum = carry
        x1, x2, _, _ = _heun_substep(x1, x2, dW[i], epsilon, force, tau)
        return x1, x2, x1_sum + x1

    x1, x2, x1_sum = jax.lax.fori_loop(0, substeps, body, (x[0], x[1], 0.5 * x[0]),
                                       unroll=_unroll(substeps))
    return jnp.stack([x1, x2]), (x1_sum - 0.5 * x1) / substeps


def heun_model_interval(x: jax.Array, force: jax.Array, epsilon: jax.Array, tau: jax.Array,
                        substeps: int) -> tuple[jax.Array, jax.Array]:
    """The model's interval map and its Jacobian: ``substeps`` noise-free Heun steps from
    ``x`` and the product of the Heun step Jacobians along the path — ``(f(x, u), F)``,
    :meth:`fir_gym.envs.van_der_pol.VanDerPolDynamics.f_and_F`."""
    def body(_: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        x1, x2, *Phi = carry
        n1, n2, y1, y2 = _heun_substep(x1, x2, 0.0, epsilon, force, tau)
        return (n1, n2, *_heun_jacobian_substep(x1, x2, y1, y2, epsilon, tau, tuple(Phi)))

    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    x1, x2, p11, p12, p21, p22 = jax.lax.fori_loop(0, substeps, body,
                                                   (x[0], x[1], one, zero, zero, one),
                                                   unroll=_unroll(substeps))
    return jnp.stack([x1, x2]), jnp.array([[p11, p12], [p21, p22]])


def heun_plant_and_model_intervals(x: jax.Array, force: jax.Array, dW: jax.Array,
                                   epsilon: jax.Array, tau: jax.Array, xf: jax.Array,
                                   force_f: jax.Array, epsilon_f: jax.Array, tau_f: jax.Array,
                                   substeps: int
                                   ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """:func:`heun_plant_interval` of the plant and :func:`heun_model_interval` of the
    filter's model (from its estimate ``xf``, with its ``force_f, epsilon_f, tau_f``) in one
    loop, when both take ``substeps`` Heun steps: the same numbers as the two loops, half the
    iterations. Returns ``(x_end, x̄1, f(xf), F)``."""
    def body(i: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        x1, x2, x1_sum, f1, f2, *Phi = carry
        x1, x2, _, _ = _heun_substep(x1, x2, dW[i], epsilon, force, tau)
        n1, n2, y1, y2 = _heun_substep(f1, f2, 0.0, epsilon_f, force_f, tau_f)
        return (x1, x2, x1_sum + x1, n1, n2,
                *_heun_jacobian_substep(f1, f2, y1, y2, epsilon_f, tau_f, tuple(Phi)))

    one, zero = jnp.ones_like(xf[0]), jnp.zeros_like(xf[0])
    x1, x2, x1_sum, f1, f2, p11, p12, p21, p22 = jax.lax.fori_loop(
        0, substeps, body, (x[0], x[1], 0.5 * x[0], xf[0], xf[1], one, zero, zero, one),
        unroll=_unroll(substeps))
    return (jnp.stack([x1, x2]), (x1_sum - 0.5 * x1) / substeps, jnp.stack([f1, f2]),
            jnp.array([[p11, p12], [p21, p22]]))


def _measurement_sqrt(params: VanDerPolParams) -> jax.Array:
    """``√(R/h)``: the standard deviation of the interval-averaged measurement noise."""
    return jnp.sqrt(params.R / params.h)


def van_der_pol_reset_noise(key: jax.Array, params: VanDerPolParams) -> VanDerPolResetNoise:
    """The noise of a reset from one draw ``z = jax.random.normal(key, (3,))``:
    ``initial = sqrt(initial_state_cov) z[:2]``, ``measurement = √(R/h) z[2:]``."""
    z = jax.random.normal(key, (3,), dtype=jnp.float64)
    return VanDerPolResetNoise(sqrt_of(params.initial_sqrt, params.initial_state_cov) @ z[:2],
                               _measurement_sqrt(params) * z[2:])


def van_der_pol_noise(key: jax.Array, params: VanDerPolParams) -> VanDerPolNoise:
    """The noise of a step from one draw ``z = jax.random.normal(key, (substeps + 1,))``:
    ``process = √(Q τ) z[:substeps]`` (the Wiener increments, one per Heun substep, ``τ = h /
    substeps``), ``measurement = √(R/h) z[substeps:]``."""
    n = params.substeps
    z = jax.random.normal(key, (n + 1,), dtype=jnp.float64)
    return VanDerPolNoise(jnp.sqrt(params.Q * (params.h / n)) * z[:n],
                          _measurement_sqrt(params) * z[n:])


def ekf_correct(x: jax.Array, P: jax.Array, y: jax.Array, params: VanDerPolParams
                ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The EKF's Joseph-form update of the prior ``(x, P)`` with ``y`` (1,): ``h(x) = x1``,
    ``H = [1, 0]``, ``R = model_R`` (:func:`fir_gym.jax.kalman.kf_update_innovation`):
    ``(x⁺, P⁺, nis)``."""
    H = jnp.array([[1.0, 0.0]])
    return kf_update_innovation(x, P, y - x[:1], H, jnp.reshape(params.model_R, (1, 1)))


# ---------------------------------------------------------------------------- the environment
class VanDerPol(FilteredPlant):
    """``fir_gym/VanDerPol-v0`` as a gymnax environment observing ``kind`` (see the module
    docstring): ``"true"``, ``"measurement"`` or ``"ekf"`` (the default, observing
    ``observation``: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``).

    ``reset_env(key, params)`` and ``step_env(key, state, action, params)`` draw their noise
    from ``key`` (:func:`van_der_pol_reset_noise`, :func:`van_der_pol_noise`) and call the
    pure :meth:`reset_with_noise` / :meth:`step_with_noise`. gymnax's ``step`` adds the
    auto-reset and ``is_truncated`` (``time >= max_steps_in_episode``). ``info`` has
    ``state`` (the true state), ``action`` (applied, float64), ``action_clipped``,
    ``simulation_failure`` (a code, 0 for none), ``x1_average`` (the noise-free interval
    average of ``x1``, the numpy plant's extra; on a failed step whatever the failed
    transition computed) and, for ``"ekf"``, ``estimate``, ``estimation_error``,
    ``estimator_diverged`` and ``nis``.
    """

    kinds = KINDS
    randomizable = ("epsilon", "u_max")
    estimator = "ekf"
    n_x, n_y = 2, 1

    @property
    def default_params(self) -> VanDerPolParams:
        return van_der_pol_params()

    @property
    def name(self) -> str:
        return "fir_gym/VanDerPol-v0"

    def filter_model(self, params: VanDerPolParams) -> FilterModel:
        """The EKF's model (the numpy plant's ``model``): the noise-free Heun interval at the
        nominal ``ε, u_max, h, substeps`` (:func:`heun_model_interval`), ``H = [1, 0]``, the
        integrated process noise ``model_Q`` and ``model_R``."""
        tau_model = params.nominal_h / params.nominal_substeps

        def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
            return heun_model_interval(x, u[0] * params.nominal_u_max, params.nominal_epsilon,
                                       tau_model, params.nominal_substeps)

        return FilterModel(lambda x, u: f_and_F(x, u)[0], f_and_F, jnp.array([[1.0, 0.0]]),
                           jnp.asarray(params.model_Q),
                           jnp.reshape(jnp.asarray(params.model_R, dtype=jnp.float64), (1, 1)))

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """The true measurement noise's square root (the outliers' scale)."""
        return jnp.reshape(_measurement_sqrt(params), (1, 1))

    # ------------------------------------------------------------------ reset
    def reset_env(self, key: jax.Array, params: VanDerPolParams
                  ) -> tuple[Any, VanDerPolState]:
        return self.reset_with_noise(van_der_pol_reset_noise(key, params), params,
                                     self.sensor_reading(key, 0, params))

    def reset_with_noise(self, noise: VanDerPolResetNoise, params: VanDerPolParams,
                         missing: Reading | jax.Array | bool = False) -> tuple[Any, VanDerPolState]:
        """The reset with the given noise: ``x = initial_state + noise.initial``, ``y = x1 +
        noise.measurement`` (the degenerate interval; held where ``missing``, with
        dropout); the EKF (for ``"ekf"``) consumes ``y``
        from its prior (:meth:`fir_gym.envs._base.PlantEnv.reset`,
        :meth:`fir_gym.wrappers.EstimatorObservation.reset`)."""
        require_x64()
        x = jnp.asarray(params.initial_state, dtype=jnp.float64) + noise.initial
        y = self.deliver(missing, x[:1] + noise.measurement, self.first_hold(params))
        x0, P0 = filter_prior(params)
        state = VanDerPolState.start(x, y, x0, P0)
        if self.runs_own_filter:
            updated = watch_state(state, *ekf_correct(x0, P0, y, params),
                                  watch_limits_of(params))
            state = self.own_update(missing, state, updated, x0, P0, params)
        state = self.finish_reset(state, params, missing)
        return self.get_obs(state, params), state

    # ------------------------------------------------------------------ step
    def step_env(self, key: jax.Array, state: VanDerPolState, action: Any,
                 params: VanDerPolParams
                 ) -> tuple[Any, VanDerPolState, jax.Array, jax.Array, dict[str, Any]]:
        obs, state, reward, terminated, info = self.step_with_noise(
            state, action, van_der_pol_noise(key, params), params,
            self.sensor_reading(key, state.time + 1, params, state.sensor_stuck))
        # gymnax's rule: transitions are detached unless gradients were asked for
        obs, state = self._apply_transition_gradient_policy(obs, state)
        return obs, state, reward, terminated, info

    def step_with_noise(self, state: VanDerPolState, action: Any, noise: VanDerPolNoise,
                        params: VanDerPolParams, missing: Reading | jax.Array | bool = False
                        ) -> tuple[Any, VanDerPolState, jax.Array, jax.Array, dict[str, Any]]:
        """One env step with the given noise: ``(obs, state, reward, terminated, info)``;
        with dropout, a ``missing`` reading holds the last delivered one.

        :meth:`fir_gym.envs._base.PlantEnv.step` of
        :class:`~fir_gym.envs.van_der_pol.VanDerPolEnv` (and, for ``"ekf"``, the EKF step of
        :class:`~fir_gym.wrappers.EstimatorObservation`); its only Python branches are on
        static things (the kind, the numbers of substeps), none on data.
        """
        require_x64()
        u_in = jnp.reshape(jnp.asarray(action, dtype=jnp.float64), (1,))
        u = jnp.clip(u_in, -1.0, 1.0)
        x = state.x
        force, force_model = u[0] * params.u_max, u[0] * params.nominal_u_max
        tau = params.h / params.substeps
        tau_model = params.nominal_h / params.nominal_substeps
        fused = self.runs_own_filter and params.substeps == params.nominal_substeps
        if fused:            # the plant's and the model's Heun loops as one (same numbers)
            x_next, x1_average, xp, F = heun_plant_and_model_intervals(
                x, force, noise.process, params.epsilon, tau, state.filter_x, force_model,
                params.nominal_epsilon, tau_model, params.substeps)
        else:
            x_next, x1_average = heun_plant_interval(x, force, noise.process, params.epsilon,
                                                     tau, params.substeps)
        burst = self.burst_delta(state.time)
        if self.burst:       # the whole path stretched about its start: its end and average
            x_next = self.stretch(x, x_next, burst)
            x1_average = self.stretch(x[0], x1_average, burst)
        time = state.time + 1
        left = jnp.maximum(params.max_steps_in_episode - time, 0)
        cost_cap = params.state_bound ** 2 / 2.0 + 0.01
        penalty = -cost_cap * (1.0 + left)

        finite_state = jnp.all(jnp.isfinite(x_next))
        overflow = jnp.any(jnp.abs(x_next) > params.state_limit)
        in_domain = jnp.all(jnp.isfinite(x_next) & (jnp.abs(x_next) <= params.state_bound))
        cost = 0.25 * (x_next[0] * x_next[0] + x_next[1] * x_next[1]) + 0.01 * u[0] * u[0]
        reward = jnp.where(in_domain, -jnp.where(cost < cost_cap, cost, cost_cap), penalty)
        y_next = x1_average[None] + noise.measurement
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
                                "simulation_failure": failure, "x1_average": x1_average}
        if self.runs_own_filter:
            if fused:
                Pp = ekf_predict(state.filter_x, state.filter_P, u, params.model_Q,
                                 lambda *_: (xp, F))[1]
            else:
                xp, Pp = ekf_predict(
                    state.filter_x, state.filter_P, u, params.model_Q,
                    lambda xf, uf: heun_model_interval(xf, uf[0] * params.nominal_u_max,
                                                       params.nominal_epsilon, tau_model,
                                                       params.nominal_substeps))
            updated = watch_state(new, *ekf_correct(xp, Pp, y, params),
                                  watch_limits_of(params))
            new = self.own_update(missing, new, updated, xp, Pp, params)
        obs, new, info = self.finish_step(state, new, u, params, info, missing)
        return obs, new, reward, terminated, info
