"""The Kalman filter's steps and the divergence watch as pure JAX functions, for one system.

The JAX twins of the numpy references the environments of :mod:`fir_gym.jax` put inside
their step (``vmap`` them for a batch):

* :func:`kf_predict` — :func:`fir_gym.estimators.kalman.kf_predict`: ``x⁻ = F x + B u``,
  ``P⁻ = F P Fᵀ + Q``, symmetrised. The EKF calls it with ``F`` the Jacobian and ``x⁻ =
  f(x, u)`` computed by the plant's model (:func:`ekf_predict`).
* :func:`kf_update` — :func:`fir_gym.estimators.kalman.kf_update`: the Joseph-form update
  ``x⁺ = x + K e``, ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ``, ``K = P Hᵀ S⁻¹``, ``S = H P
  Hᵀ + R``, ``e = y − H x``, and the normalised innovation squared ``eᵀ S⁻¹ e``, in the
  numpy reference's arithmetic (:func:`fir_gym.estimators.kalman.gain_kernel`): ``S⁻¹`` by
  :func:`fir_gym.jax.small_linalg.spd_inverse` (unrolled, no LAPACK call, see there why),
  NaN where ``S`` is not positive definite, and with it ``x⁺``, ``P⁺`` and the NIS (the
  numpy filter's rule: the watch then keeps the last finite estimate and raises
  ``diverged``); ``P⁺`` by :func:`factored_joseph`, the Joseph product formed from factors,
  positive semidefinite by construction.
* :func:`watch` — :meth:`fir_gym.estimators.base.Estimator._accept` with its defaults: a
  non-finite estimate or covariance is not stored (the last finite one stays), a NIS above
  the ``1 − nis_tail`` χ² quantile (or NaN, for a usable measurement) extends a run, and the
  sticky ``diverged`` flag is raised by a non-finite result, by ``trace P >
  max_covariance_trace`` or by ``nis_patience`` consecutive high NIS.

Every function is pure and shape-static: ``jit``- and ``vmap``-able.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from . import small_linalg


@struct.dataclass
class Belief:
    """An estimator's record inside an environment's state: the mean ``x`` (n,), the
    covariance ``P`` (n, n), this step's ``nis``, the run of high NIS ``nis_run`` and the
    sticky ``diverged`` flag."""

    x: Any
    P: Any
    nis: Any
    nis_run: Any
    diverged: Any


@struct.dataclass
class WatchLimits:
    """The divergence watch's limits (:class:`fir_gym.estimators.base.Estimator`'s
    ``max_covariance_trace``, the χ² quantile of ``nis_tail`` for the measurement's
    dimension, ``nis_patience``)."""

    max_covariance_trace: Any = 1e12
    nis_threshold: Any = 37.324893051362324       # scipy.stats.chi2.isf(1e-9, 1)
    nis_patience: Any = 10


def watch_limits(n_y: int, *, max_covariance_trace: float = 1e12, nis_tail: float = 1e-9,
                 nis_patience: int = 10) -> WatchLimits:
    """:class:`WatchLimits` for a measurement of ``n_y`` channels (host-side: the χ²
    quantile ``scipy.stats.chi2.isf(nis_tail, n_y)``, as the numpy estimators take it)."""
    from scipy.stats import chi2
    return WatchLimits(max_covariance_trace=float(max_covariance_trace),
                       nis_threshold=float(chi2.isf(nis_tail, n_y)),
                       nis_patience=int(nis_patience))


def belief(x0: jax.Array, P0: jax.Array) -> Belief:
    """The record of a filter at its prior ``N(x0, P0)``, before any measurement."""
    return Belief(x=jnp.asarray(x0, dtype=jnp.float64), P=jnp.asarray(P0, dtype=jnp.float64),
                  nis=jnp.asarray(jnp.nan), nis_run=jnp.asarray(0, dtype=jnp.int64),
                  diverged=jnp.asarray(False))


def symmetrize(P: jax.Array) -> jax.Array:
    """``(P + Pᵀ) / 2``."""
    return 0.5 * (P + P.T)


def kf_predict(x: jax.Array, P: jax.Array, F: jax.Array, Q: jax.Array,
               Bu: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
    """``x⁻ = F x (+ B u)``, ``P⁻ = F P Fᵀ + Q``, symmetrised (``Q`` is ``G Q Gᵀ``)."""
    x_new = F @ x if Bu is None else F @ x + Bu
    return x_new, symmetrize(F @ P @ F.T + Q)


def ekf_predict(x: jax.Array, P: jax.Array, u: jax.Array, Q: jax.Array,
                f_and_F: Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array]]
                ) -> tuple[jax.Array, jax.Array]:
    """The EKF's prediction: ``x⁻ = f(x, u)``, ``P⁻ = F P Fᵀ + Q`` with ``F = ∂f/∂x`` at
    ``x`` (``f_and_F`` returns both, as the numpy models' ``fF``)."""
    x_new, F = f_and_F(x, u)
    return x_new, symmetrize(F @ P @ F.T + Q)


def kf_update(x: jax.Array, P: jax.Array, y: jax.Array, H: jax.Array, R: jax.Array
              ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The Joseph-form update of ``N(x, P)`` with ``y = H x + v``, ``v ~ N(0, R)``, and the
    innovation ``e = y − H x``: ``(x⁺, P⁺, nis)`` (NaN where ``S`` is not positive
    definite). For an EKF pass ``e`` through :func:`kf_update_innovation` instead."""
    return kf_update_innovation(x, P, y - H @ x, H, R)


def kf_update_innovation(x: jax.Array, P: jax.Array, e: jax.Array, H: jax.Array,
                         R: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """:func:`kf_update` given the innovation ``e`` (``y − h(x⁻)`` for an EKF, with ``H``
    the Jacobian of ``h`` at ``x⁻``)."""
    PHt = P @ H.T
    S = PHt.T @ H.T + R                                # H P Hᵀ + R (P symmetric)
    W = small_linalg.spd_inverse(S)                    # NaN where S is not PD
    K = PHt @ W
    return x + K @ e, factored_joseph(P, H, R, K), e @ (W @ e)


def factored_joseph(P: jax.Array, H: jax.Array, R: jax.Array, K: jax.Array) -> jax.Array:
    """The Joseph-form update ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` from factors, ``P⁺ =
    M Mᵀ + N Nᵀ`` with ``M = (I − K H) L``, ``N = K L_R``, ``L Lᵀ = P``, ``L_R L_Rᵀ = R``
    (:func:`fir_gym.estimators._kalman_linalg.factored_joseph`; ``small_linalg.psd_factor``,
    ``small_linalg.gram``): exactly symmetric and positive semidefinite by construction for
    any gain. The plain product subtracts terms of the size of ``‖P‖`` to leave ``P⁺`` and
    leaves the PSD cone where ``P⁺`` is far smaller (``P = 1e12 I``, ``R = 1e-12``; a
    CarrierMotion-v0 start near its state limit, ``P ≈ 1e290`` against ``R = 10``); the
    factor carries round-off relative to ``‖P‖^½`` only (docs/architecture.md, covariance
    updates)."""
    M = (jnp.eye(P.shape[0], dtype=P.dtype) - K @ H) @ small_linalg.psd_factor(P)
    return small_linalg.gram(M, K @ small_linalg.psd_factor(R))


def watch(old: Belief, x: jax.Array, P: jax.Array, nis: jax.Array, limits: WatchLimits,
          usable: jax.Array | bool = True) -> Belief:
    """:meth:`fir_gym.estimators.base.Estimator._accept` for one system: the new record.

    ``x``, ``P``, ``nis`` are the step's result; ``usable`` says whether the step had a
    measurement: a NIS above the threshold (or NaN) of a usable one extends the run, any
    other step ends it, as in the numpy watch."""
    finite = jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(P))
    trace = jnp.where(finite, jnp.trace(P), 0.0)
    high = usable & ~(nis <= limits.nis_threshold)     # NaN counts as above
    nis_run = jnp.where(high, old.nis_run + 1, 0)
    blown = ~finite | (trace > limits.max_covariance_trace) | (nis_run >= limits.nis_patience)
    return Belief(x=jnp.where(finite, x, old.x), P=jnp.where(finite, P, old.P), nis=nis,
                  nis_run=nis_run, diverged=old.diverged | blown)
