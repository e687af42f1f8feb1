"""Orbit-v0 as a gymnax environment: paper 000, simulation 1, with its EKF in the state.

The JAX twin of :class:`fir_gym.envs.orbit.OrbitEnv` (the numpy reference) seen through
:func:`fir_gym.wrappers.factory.wrap_observation` — one of three observation kinds:

* ``"true"``: the true state ``[r, v]`` (:class:`~fir_gym.wrappers.baselines.TrueStateObservation`);
* ``"measurement"``: the raw measurement ``[r + noise]`` (the plant's own observation);
* ``"ekf"``: the extended Kalman filter's estimate ``x̂`` of ``[r, v]``
  (:class:`~fir_gym.wrappers.EstimatorObservation` with
  :class:`~fir_gym.estimators.extended.ExtendedKalmanFilter`); the filter's mean, covariance
  and divergence watch live in :class:`OrbitState`. As there, ``observation`` may instead be
  ``"estimate+covariance"`` (a dict: ``estimate`` and ``covariance``, the upper triangle of
  ``P`` row by row, ``[P11, P12, P22]``) or ``"estimate+measurement"`` (``estimate`` and
  ``measurement``).

**Plant** (paper 000, eq (27), with a radial thrust ``a = action · thrust_max`` held over
the interval): ``r ← r + v Δ``, ``v ← v + (a − μ / r²) Δ``, ``Δ = euler_dt``, repeated
``substeps`` (M = 100) times per env step (:func:`orbit_plant_interval` and, with the
Jacobian product, :func:`orbit_interval`: :func:`jax.lax.fori_loop` loops that mirror
:meth:`fir_gym.envs.orbit.OrbitDynamics.propagate` operation for operation; for ``"ekf"``
with the model's ``substeps`` the plant's, one loop runs both,
:func:`orbit_plant_and_model_intervals`), then ``+ w``, ``w ~ N(0, Q)``
(Q = 0 by default, as in the paper). Measurement, eq (28): ``y = r + v``, ``v ~ N(0, R)``.
Reward ``−min((r' − r_ref)² + 0.01 action², cost_cap)``; termination when ``r' ∉ (r_min,
r_max)``, paid ``−cost_cap (1 + steps left to max_steps_in_episode)``; a step whose new
state is not finite or beyond ``±state_limit`` (or whose reward or measurement is not
finite) is a simulation failure: the plant stays at its last valid state, the observation
repeats, the reward is the terminal penalty and the episode terminates (``info
["simulation_failure"]``: 0 none, 1 nonfinite_state, 2 state_overflow, 3
nonfinite_observation, 4 nonfinite_reward — :data:`SIMULATION_FAILURES`). Truncation at
``max_steps_in_episode`` (gymnax's ``is_truncated``, the registered ``TimeLimit``).
Actions are clipped to ``[-1, 1]`` (``info["action_clipped"]``); a NaN action, which the
numpy plant refuses with a ``ValueError``, cannot raise under ``jit``: it makes the new
state NaN, a simulation failure.

**EKF** (:mod:`fir_gym.estimators.extended`): the model believes the nominal parameters
(``nominal_mu`` = 19.91 by default, the truth being 19.92244165). Prior: the plant's
initial-state mean, covariance ``initial_state_cov + 1e-9 diag(max(1, x0²))``
(:func:`fir_gym.wrappers.estimator_observation.prior_of`). ``reset`` consumes ``y[0]``
(update only); each step predicts with the applied action — ``x⁻ = f(x̂, u)``, ``P⁻ = F P Fᵀ
+ Q`` with ``F`` the product of the Euler Jacobians — then makes the Joseph-form update with
``H = [1, 0]``, its covariance formed from factors as the numpy reference forms it
(:func:`fir_gym.jax.kalman.factored_joseph`, the twin of
:func:`fir_gym.estimators._kalman_linalg.factored_joseph`): positive semidefinite by
construction, where the plain product ``A P Aᵀ + K R Kᵀ`` leaves the cone for a prior far
above ``R``. The divergence watch is the numpy one with its defaults
(:meth:`fir_gym.estimators.base.Estimator._accept`): a non-finite estimate or covariance is
not stored (the last finite one stays), and the sticky ``diverged`` flag is raised by it,
by ``trace P > max_covariance_trace`` or by ``nis_patience`` consecutive NIS above the
``1 − nis_tail`` χ² quantile.

**Noise contract.** Every random number comes from the ``key`` of ``reset_env`` /
``step_env`` (gymnax's ``step`` splits its key into the step's and the auto-reset's):
:func:`orbit_reset_noise` and :func:`orbit_noise` each make one draw ``z =
jax.random.normal(key, (3,))`` — ``z[:2]`` for the state (the initial-state spread, or the
process noise ``w``), ``z[2:]`` for the measurement — that the square roots of the
covariances (``V Λ^½`` from ``eigh``, as :func:`fir_gym.envs._base.psd_sqrt`) turn into the
physical increments. The
pure functions :meth:`Orbit.reset_with_noise` and :meth:`Orbit.step_with_noise` take those
increments (:class:`OrbitResetNoise`, :class:`OrbitNoise`) instead of a key, so a caller
can drive the JAX env with any noise sequence — the parity tests drive the numpy env and
this one with the same numbers.

Everything is a pure function of its arguments: ``jit``-able, ``vmap``-able over keys,
states and parameters (:class:`OrbitParams` is a pytree; ``substeps`` and
``nominal_substeps`` are static).
"""

from __future__ import annotations

import math
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
from .kalman import factored_joseph, symmetrize
from .stacked_loop import stacked_fori_loop

#: the true gravitational parameter and the one the filter's model believes (paper 000)
TRUE_MU = 19.92244165
NOMINAL_MU = 19.91
#: the observation kinds
KINDS = ("true", "measurement", "measurement-stack", "ekf", "ukf", "efir")
#: the Euler loops are unrolled by this factor (:func:`jax.lax.fori_loop`'s ``unroll``):
#: 1.25x the env-steps/s of no unrolling on a CPU at 2048 envs; 25 compiles slowly and runs
#: slower (scripts/jax_stepping_speed.py)
UNROLL = 10


@struct.dataclass
class OrbitParams(gymnax_env.EnvParams):
    """The physical, noise and filter parameters (a pytree: any float field can be vmapped).

    The first group is the truth (:class:`fir_gym.envs.orbit.OrbitEnv`'s keywords), the
    ``nominal_*`` fields what the EKF's model believes (its ``nominal=`` dict), the last
    group the filter's divergence watch (:class:`fir_gym.estimators.base.Estimator`'s
    defaults). Build one with :func:`orbit_params`, which also validates.
    """

    max_steps_in_episode: int = 1000
    mu: Any = TRUE_MU
    thrust_max: Any = 1.0
    euler_dt: Any = 1e-4
    R: Any = 1e-3                       # measurement noise variance (n_y = 1)
    Q: Any = struct.field(default_factory=lambda: jnp.zeros((2, 2)))   # process noise
    r_ref: Any = 8.0
    r_min: Any = 1.0
    r_max: Any = 100.0
    initial_state: Any = struct.field(default_factory=lambda: jnp.array([7.99, 1.99]))
    initial_state_cov: Any = struct.field(default_factory=lambda: jnp.zeros((2, 2)))
    state_limit: Any = STATE_LIMIT
    nominal_mu: Any = NOMINAL_MU
    nominal_thrust_max: Any = 1.0
    nominal_euler_dt: Any = 1e-4
    nominal_R: Any = 1e-3
    nominal_Q: Any = struct.field(default_factory=lambda: jnp.zeros((2, 2)))
    max_covariance_trace: Any = 1e12
    #: ``scipy.stats.chi2.isf(nis_tail, 1)`` for the default ``nis_tail = 1e-9``
    nis_threshold: Any = 37.324893051362324
    nis_patience: Any = 10
    substeps: int = struct.field(pytree_node=False, default=100)
    nominal_substeps: int = struct.field(pytree_node=False, default=100)
    #: square roots of ``initial_state_cov`` and ``Q`` (:func:`~fir_gym.jax._plant.sqrt_of`:
    #: the builder computes them; ``None`` computes them in the trace)
    initial_sqrt: Any = None
    process_sqrt: Any = None


@struct.dataclass
class OrbitState(PlantState):
    """The plant, its last observation and the EKF (mean, covariance, watch)."""


@struct.dataclass
class OrbitResetNoise:
    """The physical noise of a reset: ``initial`` (2,) added to ``initial_state``,
    ``measurement`` (1,) added to ``r``."""

    initial: Any
    measurement: Any


@struct.dataclass
class OrbitNoise:
    """The physical noise of a step: ``process`` (2,) added to the new state (``w``),
    ``measurement`` (1,) added to its ``r`` (``v``)."""

    process: Any
    measurement: Any


def orbit_params(*, mu: float = TRUE_MU, R: float = 1e-3, Q: Any = None, euler_dt: float = 1e-4,
                 substeps: int = 100, thrust_max: float = 1.0, r_ref: float = 8.0,
                 r_min: float = 1.0, r_max: float = 100.0, nominal: dict[str, Any] | None = None,
                 initial_state: Any = (7.99, 1.99), initial_state_cov: Any = None,
                 max_episode_steps: int = 1000, max_covariance_trace: float = 1e12,
                 nis_tail: float = 1e-9, nis_patience: int = 10) -> OrbitParams:
    """:class:`OrbitParams` from :class:`fir_gym.envs.orbit.OrbitEnv`'s keywords (and the
    EKF's watch options); ``nominal`` as there (keys ``mu, R, Q, euler_dt, substeps,
    thrust_max``; ``{"mu": 19.91}`` by default). Host-side: validates and converts."""
    require_x64()
    from scipy.stats import chi2

    truth = {"mu": mu, "R": R, "Q": np.zeros((2, 2)) if Q is None else Q,
             "euler_dt": euler_dt, "substeps": substeps, "thrust_max": thrust_max}
    believed = {**truth, "mu": NOMINAL_MU, **(nominal or {})}
    unknown = sorted(set(believed) - set(truth))
    if unknown:
        raise ValueError(f"nominal has unknown parameter(s) {unknown}; known parameters are "
                         f"{sorted(truth)}")
    for name, value in (("mu", mu), ("euler_dt", euler_dt), ("thrust_max", thrust_max),
                        ("r_ref", r_ref), ("r_min", r_min), ("r_max", r_max)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be positive and finite; got {value!r}")
    if not r_min < r_ref < r_max:
        raise ValueError(f"need r_min < r_ref < r_max; got {r_min}, {r_ref}, {r_max}")

    def cov(name: str, value: Any, n: int) -> jax.Array:
        M = np.asarray(value, dtype=np.float64).reshape(n, n)
        if not (np.allclose(M, M.T) and np.linalg.eigvalsh(M).min() >= -1e-12 * abs(M).max()):
            raise ValueError(f"{name} must be a symmetric positive semidefinite {n}x{n} matrix")
        return jnp.asarray(M)

    x0 = np.asarray(initial_state, dtype=np.float64).reshape(2)
    P0 = cov("initial_state_cov",
             np.zeros((2, 2)) if initial_state_cov is None else initial_state_cov, 2)
    Q_truth = cov("Q", truth["Q"], 2)
    return OrbitParams(
        max_steps_in_episode=int(max_episode_steps),
        mu=float(mu), thrust_max=float(thrust_max), euler_dt=float(euler_dt),
        R=float(cov("R", R, 1)[0, 0]), Q=Q_truth, r_ref=float(r_ref),
        r_min=float(r_min), r_max=float(r_max), initial_state=jnp.asarray(x0),
        initial_state_cov=P0,
        nominal_mu=float(believed["mu"]), nominal_thrust_max=float(believed["thrust_max"]),
        nominal_euler_dt=float(believed["euler_dt"]),
        nominal_R=float(cov("nominal R", believed["R"], 1)[0, 0]),
        nominal_Q=cov("nominal Q", believed["Q"], 2),
        max_covariance_trace=float(max_covariance_trace),
        nis_threshold=float(chi2.isf(nis_tail, 1)), nis_patience=int(nis_patience),
        substeps=int(substeps), nominal_substeps=int(believed["substeps"]),
        initial_sqrt=numpy_sqrt(P0), process_sqrt=numpy_sqrt(Q_truth))


# ---------------------------------------------------------------------------- pure functions
def _substep(r: jax.Array, v: jax.Array, a: jax.Array, mu: jax.Array, d: jax.Array
             ) -> tuple[jax.Array, jax.Array]:
    """One Euler step of eq (27): ``r + v Δ``, ``v + (a − μ/r²) Δ``."""
    return r + v * d, v + (a - mu / (r * r)) * d


def _jacobian_substep(r: jax.Array, mu: jax.Array, d: jax.Array, J: tuple[jax.Array, ...]
                      ) -> tuple[jax.Array, ...]:
    """``J ← (I + Δ [[0, 1], [2μ/r³, 0]]) J`` at the substep's ``r`` (before it moves)."""
    j11, j12, j21, j22 = J
    g = 2.0 * mu / (r * r * r) * d
    return j11 + d * j21, j12 + d * j22, j21 + g * j11, j22 + g * j12


def _unroll(substeps: int) -> int:
    return min(UNROLL, max(substeps, 1))


def orbit_interval(x: jax.Array, a: jax.Array, mu: jax.Array, euler_dt: jax.Array,
                   substeps: int) -> tuple[jax.Array, jax.Array]:
    """One measurement interval of paper 000's eq (27): ``substeps`` Euler steps of
    ``r ← r + v Δ, v ← v + (a − μ/r²) Δ`` from ``x = [r, v]`` under the thrust acceleration
    ``a`` (a scalar, in physical units), and the interval's Jacobian, the product of the
    Euler Jacobians ``I + Δ [[0, 1], [2μ/r³, 0]]`` along the path. The operations of
    :meth:`fir_gym.envs.orbit.OrbitDynamics.propagate`, in its order."""
    def body(_: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        r, v, *J = carry
        return (*_substep(r, v, a, mu, euler_dt), *_jacobian_substep(r, mu, euler_dt, tuple(J)))

    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    r, v, j11, j12, j21, j22 = stacked_fori_loop(0, substeps, body,
                                                 (x[0], x[1], one, zero, zero, one),
                                                 unroll=_unroll(substeps))
    return jnp.stack([r, v]), jnp.array([[j11, j12], [j21, j22]])


def orbit_plant_interval(x: jax.Array, a: jax.Array, mu: jax.Array, euler_dt: jax.Array,
                         substeps: int) -> jax.Array:
    """:func:`orbit_interval` without the Jacobian (the plant's map, ``OrbitDynamics.f``)."""
    def body(_: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        return _substep(*carry, a, mu, euler_dt)

    r, v = stacked_fori_loop(0, substeps, body, (x[0], x[1]), unroll=_unroll(substeps))
    return jnp.stack([r, v])


def orbit_plant_and_model_intervals(x: jax.Array, a: jax.Array, mu: jax.Array,
                                    euler_dt: jax.Array, xf: jax.Array, af: jax.Array,
                                    muf: jax.Array, euler_dtf: jax.Array, substeps: int
                                    ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """:func:`orbit_plant_interval` of the plant and :func:`orbit_interval` of the filter's
    model (from its estimate ``xf``, with its ``af, muf, euler_dtf``) in one loop, when both
    take ``substeps`` Euler steps: the same numbers as the two loops, half the iterations.
    Returns ``(x_next, xf_next, F)``."""
    def body(_: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        r, v, rf, vf, *J = carry
        return (*_substep(r, v, a, mu, euler_dt), *_substep(rf, vf, af, muf, euler_dtf),
                *_jacobian_substep(rf, muf, euler_dtf, tuple(J)))

    one, zero = jnp.ones_like(xf[0]), jnp.zeros_like(xf[0])
    r, v, rf, vf, j11, j12, j21, j22 = stacked_fori_loop(
        0, substeps, body, (x[0], x[1], xf[0], xf[1], one, zero, zero, one),
        unroll=_unroll(substeps))
    return jnp.stack([r, v]), jnp.stack([rf, vf]), jnp.array([[j11, j12], [j21, j22]])


def orbit_reset_noise(key: jax.Array, params: OrbitParams) -> OrbitResetNoise:
    """The noise of a reset from one draw ``z = jax.random.normal(key, (3,))``:
    ``initial = sqrt(initial_state_cov) z[:2]``, ``measurement = sqrt(R) z[2:]``."""
    z = jax.random.normal(key, (3,), dtype=jnp.float64)
    return OrbitResetNoise(sqrt_of(params.initial_sqrt, params.initial_state_cov) @ z[:2],
                           jnp.sqrt(params.R) * z[2:])


def orbit_noise(key: jax.Array, params: OrbitParams) -> OrbitNoise:
    """The noise of a step from one draw ``z = jax.random.normal(key, (3,))``:
    ``process = sqrt(Q) z[:2]`` (zero for the default Q = 0), ``measurement = sqrt(R) z[2:]``
    (one draw, not one per key split: on a CPU the threefry calls cost more than the
    plant)."""
    z = jax.random.normal(key, (3,), dtype=jnp.float64)
    return OrbitNoise(sqrt_of(params.process_sqrt, params.Q) @ z[:2], jnp.sqrt(params.R) * z[2:])


def ekf_update(x: jax.Array, P: jax.Array, y: jax.Array, R: jax.Array
               ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The Joseph-form update of the prior ``(x, P)`` with ``y`` (1,), ``H = [1, 0]``:
    ``(x⁺, P⁺, nis)``; a non-positive ``S`` gives NaN (the watch then keeps the prior)."""
    e = y[0] - x[0]
    S = P[0, 0] + R
    W = jnp.where(S > 0.0, 1.0 / S, jnp.nan)
    K = P[:, 0] * W
    P_new = factored_joseph(P, jnp.array([[1.0, 0.0]]), jnp.reshape(R, (1, 1)), K[:, None])
    return x + K * e, P_new, e * W * e


# ---------------------------------------------------------------------------- the environment
class Orbit(FilteredPlant):
    """``fir_gym/Orbit-v0`` as a gymnax environment observing ``kind`` (see the module
    docstring): ``"true"``, ``"measurement"`` or ``"ekf"`` (the default, observing
    ``observation``: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``).

    ``reset_env(key, params)`` and ``step_env(key, state, action, params)`` draw their noise
    from ``key`` (:func:`orbit_reset_noise`, :func:`orbit_noise`) and call the pure
    :meth:`reset_with_noise` / :meth:`step_with_noise`. gymnax's ``step`` adds the
    auto-reset and ``is_truncated`` (``time >= max_steps_in_episode``). ``info`` has
    ``state`` (the true state), ``action`` (applied, float64), ``action_clipped``,
    ``simulation_failure`` (a code, 0 for none) and, for ``"ekf"``, ``estimate``,
    ``estimation_error``, ``estimator_diverged`` and ``nis``.
    """

    kinds = KINDS
    randomizable = ("mu", "thrust_max")
    estimator = "ekf"
    n_x, n_y = 2, 1

    @property
    def default_params(self) -> OrbitParams:
        return orbit_params()

    @property
    def name(self) -> str:
        return "fir_gym/Orbit-v0"

    def filter_model(self, params: OrbitParams) -> FilterModel:
        """The EKF's model (:class:`fir_gym.envs.orbit.OrbitEnv`'s ``model``): eq (27)'s
        interval at the nominal ``mu, thrust_max, euler_dt, substeps``, ``H = [1, 0]``, the
        nominal ``Q`` and ``R``."""
        def f(x: jax.Array, u: jax.Array) -> jax.Array:
            return orbit_plant_interval(x, u[0] * params.nominal_thrust_max, params.nominal_mu,
                                        params.nominal_euler_dt, params.nominal_substeps)

        def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
            return orbit_interval(x, u[0] * params.nominal_thrust_max, params.nominal_mu,
                                  params.nominal_euler_dt, params.nominal_substeps)

        return FilterModel(f, f_and_F, jnp.array([[1.0, 0.0]]), jnp.asarray(params.nominal_Q),
                           jnp.reshape(jnp.asarray(params.nominal_R, dtype=jnp.float64), (1, 1)))

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """The true measurement noise's square root (the outliers' scale)."""
        return jnp.sqrt(jnp.reshape(jnp.asarray(params.R, dtype=jnp.float64), (1, 1)))

    # ------------------------------------------------------------------ reset
    def reset_env(self, key: jax.Array, params: OrbitParams) -> tuple[Any, OrbitState]:
        return self.reset_with_noise(orbit_reset_noise(key, params), params,
                                     self.sensor_reading(key, 0, params))

    def reset_with_noise(self, noise: OrbitResetNoise, params: OrbitParams,
                         missing: Reading | jax.Array | bool = False) -> tuple[Any, OrbitState]:
        """The reset with the given noise: ``x = initial_state + noise.initial``,
        ``y = r + noise.measurement`` (held where ``missing``, with dropout); the EKF (for
        ``"ekf"``) consumes ``y`` from its prior."""
        require_x64()
        x = jnp.asarray(params.initial_state, dtype=jnp.float64) + noise.initial
        y = self.deliver(missing, x[:1] + noise.measurement, self.first_hold(params))
        x0, P0 = filter_prior(params)
        state = OrbitState.start(x, y, x0, P0)
        if self.runs_own_filter:
            updated = watch_state(state, *ekf_update(x0, P0, y, params.nominal_R),
                                  watch_limits_of(params))
            state = self.own_update(missing, state, updated, x0, P0, params)
        state = self.finish_reset(state, params, missing)
        return self.get_obs(state, params), state

    # ------------------------------------------------------------------ step
    def step_env(self, key: jax.Array, state: OrbitState, action: Any, params: OrbitParams
                 ) -> tuple[Any, OrbitState, jax.Array, jax.Array, dict[str, Any]]:
        obs, state, reward, terminated, info = self.step_with_noise(
            state, action, orbit_noise(key, params), params,
            self.sensor_reading(key, state.time + 1, params, state.sensor_stuck))
        # gymnax's rule: transitions are detached unless gradients were asked for
        obs, state = self._apply_transition_gradient_policy(obs, state)
        return obs, state, reward, terminated, info

    def step_with_noise(self, state: OrbitState, action: Any, noise: OrbitNoise,
                        params: OrbitParams, missing: Reading | jax.Array | bool = False
                        ) -> tuple[Any, OrbitState, jax.Array, jax.Array, dict[str, Any]]:
        """One env step with the given noise: ``(obs, state, reward, terminated, info)``;
        with dropout, a ``missing`` reading holds the last delivered one.

        :meth:`fir_gym.envs._base.PlantEnv.step` of :class:`~fir_gym.envs.orbit.OrbitEnv`
        (and, for ``"ekf"``, the EKF step of
        :class:`~fir_gym.wrappers.EstimatorObservation`); its only Python branches are on
        static things (the kind, the numbers of substeps), none on data.
        """
        require_x64()
        u_in = jnp.reshape(jnp.asarray(action, dtype=jnp.float64), (1,))
        u = jnp.clip(u_in, -1.0, 1.0)
        x = state.x
        a, a_model = u[0] * params.thrust_max, u[0] * params.nominal_thrust_max
        fused = self.runs_own_filter and params.substeps == params.nominal_substeps
        if fused:            # the plant's and the model's Euler loops as one (same numbers)
            x_det, xp, F = orbit_plant_and_model_intervals(
                x, a, params.mu, params.euler_dt, state.filter_x, a_model, params.nominal_mu,
                params.nominal_euler_dt, params.substeps)
        else:
            x_det = orbit_plant_interval(x, a, params.mu, params.euler_dt, params.substeps)
        burst = self.burst_delta(state.time)
        x_next = self.stretch(x, x_det + noise.process, burst)
        time = state.time + 1
        left = jnp.maximum(params.max_steps_in_episode - time, 0)
        cost_cap = (params.r_ref - params.r_min) ** 2 + 0.01
        penalty = -cost_cap * (1.0 + left)

        finite_state = jnp.all(jnp.isfinite(x_next))
        overflow = jnp.any(jnp.abs(x_next) > params.state_limit)
        r = x_next[0]
        in_domain = (params.r_min < r) & (r < params.r_max)
        e = r - params.r_ref
        cost = e * e + 0.01 * u[0] * u[0]
        reward = jnp.where(in_domain, -jnp.where(cost < cost_cap, cost, cost_cap), penalty)
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
                                "simulation_failure": failure}
        if self.runs_own_filter:
            if not fused:
                xp, F = orbit_interval(state.filter_x, a_model, params.nominal_mu,
                                       params.nominal_euler_dt, params.nominal_substeps)
            Pp = symmetrize(F @ state.filter_P @ F.T + params.nominal_Q)
            updated = watch_state(new, *ekf_update(xp, Pp, y, params.nominal_R),
                                  watch_limits_of(params))
            new = self.own_update(missing, new, updated, xp, Pp, params)
        obs, new, info = self.finish_step(state, new, u, params, info, missing)
        return obs, new, reward, terminated, info
