"""The unscented Kalman filter's steps as pure JAX functions, for one system.

The JAX twin of :class:`fir_gym.estimators.unscented.UnscentedKalmanFilter` (the numpy
reference) with its defaults — :class:`~fir_gym.estimators.unscented.MerweScaledSigmaPoints`
``α = 1e-3, β = 2, κ = 0``, ``redraw=True``, no ``jitter`` — as
:class:`~fir_gym.wrappers.EstimatorObservation` runs it (``estimator="ukf"``): ``reset``
consumes ``y[0]`` with an update only (:func:`ukf_update`, the reference's ``_update``),
each ``step`` predicts with the applied action and updates (:func:`ukf_predict_update`,
its ``_predict_update``). A step whose measurement is missing (``missing=``, a traced
bool: the numpy ``step(None)``) predicts only: ``x⁻, P⁻`` (at the reset the prior) and a
NaN NIS. The model is a :class:`~fir_gym.jax._plant.FilterModel`: ``f``
on the sigma points, the linear measurement ``H``, ``Q`` and ``R``.

**Scaled unscented transform** (paper 003, Table 1 and eq 6; Wan & van der Merwe 2000):
``λ = α² (n + κ) − n``, points ``χ₀ = x``, ``χᵢ = x ± (√((n+λ) P))ᵢ``, weights ``W₀ᵐ = λ /
(n + λ)``, ``W₀ᶜ = W₀ᵐ + 1 − α² + β``, ``Wᵢᵐ = Wᵢᶜ = 1 / (2 (n + λ))``
(:func:`merwe_weights`, computed by numpy exactly as the reference computes them), ``√``
the lower Cholesky factor. The moments are taken from deviations from the first point,
``Dᵢ = Zᵢ − Z₀`` (:func:`fir_gym.estimators.unscented._moments`, ``_cross``): ``z̄ = Z₀ +
d``, ``Σ Wᶜ (Aᵢ − ā)(Bᵢ − b̄)ᵀ = Σ Wᶜ Dₐ D_bᵀ − d_a c_bᵀ − c_a d_bᵀ + (Σ Wᶜ) d_a d_bᵀ``
with ``d = Σ Wᵐ D``, ``c = Σ Wᶜ D`` (``c = d`` and the last three terms ``(Σ Wᶜ − 2) d
d_bᵀ`` when the weights differ only at the first point) — the α = 1e-3 weights' ±1e6
cancellation stays out of the sums.

**The step** (paper 003, Table 2, corrected; Särkkä 2013, Alg. 5.14): predict ``χ =
points(x, P)``, ``x⁻, P⁻ = UT(f(χ, u)) + Q``; update from points redrawn at ``(x⁻, P⁻)``:
``Z = χ⁻ Hᵀ``, ``ŷ, S = UT(Z) + R``, ``Pxz = Σ Wᶜ (χ⁻ − x⁻)(Z − ŷ)ᵀ``, ``K = Pxz S⁻¹``
(``S⁻¹`` as :func:`fir_gym.estimators._kalman_linalg.spd_inverse`: closed form for one or
two channels, Cholesky beyond), ``x⁺ = x⁻ + K (y − ŷ)``, ``P⁺ = P⁻ − K Pxzᵀ`` symmetrised
and rebuilt as ``L Lᵀ`` from its semidefinite Cholesky factor (:func:`psd_rebuild`, the
reference's :func:`~fir_gym.estimators._kalman_linalg.psd_rebuild`: PSD by construction),
``nis = eᵀ S⁻¹ e``. Not the Joseph form: the reference uses none.

**Failures, and what the watch makes of them.** Where the reference's
:func:`~fir_gym.estimators.unscented.matrix_sqrt` cannot factor ``P`` by Cholesky, a
positive *semi*-definite ``P`` (smallest eigenvalue ``≥ −1e-9 ×`` the largest, e.g. a
state known exactly) gets the eigen-square-root ``V Λ₊^½`` (:func:`matrix_sqrt` chooses it
with ``jnp.where`` exactly there); an indefinite or non-finite ``P`` gets a NaN square root,
so the points, ``x⁺``, ``P⁺`` and the NIS are NaN — as in the reference, whose filter does
not raise there (the ``ValueError`` is only :meth:`~fir_gym.estimators.unscented.
SigmaPoints.sigma_points`'s). An ``S`` that is not positive definite gives NaN as well. The
divergence watch :func:`fir_gym.jax.kalman.watch` (the reference's ``Estimator._accept``)
then keeps the last finite estimate and raises the sticky ``diverged`` flag, and a NaN NIS
of a usable measurement extends the run of high NIS — the numpy filter's booking.

**Round-off.** With α = 1e-3 the weights are ``≈ ±1/(2nα²)``, and a one-ulp change of a
sigma point or of ``f(χ)`` moves ``x⁻`` by about ``ε |x| / (2 n α²)``: two correct
implementations drift apart by 1e-9 to 1e-7 (relative) over hundreds of steps (the numpy
reference and its own compiled twin differ by 4e-9 on PendulumSlider-v0). XLA's CPU
compiler fuses ``a * b + c`` into one rounding (FMA) where numpy and numba round twice, so
on an FMA machine this module and the numpy filter differ at that level (Orbit-v0, 400
steps: 3e-8 in ``x``, 3e-7 in ``P``); with XLA kept off FMA instructions
(``XLA_FLAGS=--xla_cpu_max_isa=AVX``) they agree to round-off (6e-16). With α = 1 they
agree to ≈ 1e-11 either way.

Every function is pure and shape-static (Python branches only on shapes and options):
``jit``- and ``vmap``-able. The factorisations (Cholesky, the symmetric eigen-decomposition,
Cholesky solves) are :mod:`fir_gym.jax.small_linalg`'s unrolled ones: no LAPACK custom call
in a step (see there why).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import small_linalg
from .filter_model import FilterModel
from .kalman import symmetrize

#: relative tolerance below which negative eigenvalues count as round-off (the reference's
#: :data:`fir_gym.estimators.unscented.PSD_TOL`)
PSD_TOL = 1e-9
#: the pivot tolerance of :func:`psd_factor`, in units of ``n`` times the diagonal
#: (:data:`fir_gym.estimators._kalman_linalg._PIVOT_EPS`: ``4 ε``)
PIVOT_EPS = 4.0 * float(np.finfo(np.float64).eps)


class SigmaWeights(NamedTuple):
    """A sigma-point scheme as the reference's :class:`~fir_gym.estimators.unscented.
    SigmaPoints` holds it: unit points ``xi`` ``(N, n)``, weights ``Wm``, ``Wc`` ``(N,)``,
    ``sum_Wc = Σ Wᶜ`` and ``same_tail`` (``Wm`` and ``Wc`` differ at most at the first
    point). Host-side numpy constants (static under ``jit``)."""

    xi: np.ndarray
    Wm: np.ndarray
    Wc: np.ndarray
    sum_Wc: float
    same_tail: bool


@lru_cache(maxsize=64)
def merwe_weights(n: int, alpha: float = 1e-3, beta: float = 2.0, kappa: float = 0.0
                  ) -> SigmaWeights:
    """The ``2n + 1`` scaled sigma points and weights of
    :class:`fir_gym.estimators.unscented.MerweScaledSigmaPoints` (paper 003, Table 1 and
    eq 6) — read from an instance of it, so the same bits and the same validation
    (``ValueError`` naming the bad argument)."""
    from fir_gym.estimators.unscented import MerweScaledSigmaPoints

    points = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    return SigmaWeights(points.xi, points.Wm, points.Wc, points.sum_Wc, points.same_tail)


# ---------------------------------------------------------------------------- linear algebra
def matrix_sqrt(P: jax.Array) -> jax.Array:
    """A square root ``S Sᵀ = P``: the lower Cholesky factor; where it fails, ``V Λ₊^½`` of a
    positive semi-definite ``P`` (``λ_min ≥ −PSD_TOL · max(λ_max, 0)``); NaN for an
    indefinite or non-finite ``P`` (:func:`fir_gym.estimators.unscented.matrix_sqrt`, no
    jitter)."""
    L = small_linalg.cholesky(P)                     # NaN where P is not PD
    finite = jnp.all(jnp.isfinite(P))
    lam, V = small_linalg.eigh(jnp.where(finite, P, 0.0))
    semidefinite = finite & (lam[0] >= -PSD_TOL * jnp.maximum(lam[-1], 0.0))
    fallback = jnp.where(semidefinite, V * jnp.sqrt(jnp.clip(lam, 0.0, None)), jnp.nan)
    return jnp.where(jnp.all(jnp.isfinite(L)), L, fallback)


def sigma_points(x: jax.Array, P: jax.Array, weights: SigmaWeights) -> jax.Array:
    """The points ``χⱼ = x + S ξⱼ`` ``(N, n)`` with ``S`` = :func:`matrix_sqrt` of ``P``
    (the reference's ``_draw``: ``SigmaPoints.points(x, matrix_sqrt(P))``)."""
    S = matrix_sqrt(P)
    return x[None, :] + (S @ jnp.asarray(weights.xi).T).T


def psd_factor(P: jax.Array) -> jax.Array:
    """A factor ``L Lᵀ = P`` of a symmetric ``P`` that is PSD up to round-off, else of its
    nearest PSD matrix (:func:`fir_gym.estimators._kalman_linalg.psd_factor`; Higham 2002,
    §10.3): the semidefinite Cholesky factor, a pivot at or below ``4 n ε P_jj`` taken as
    zero with its column; a pivot below ``−4 n ε P_jj`` (or NaN) makes ``P`` indefinite and
    the factor ``V Λ₊^½`` of ``(P + Pᵀ)/2`` (Higham 1988), NaN where ``P`` is not finite."""
    n = P.shape[-1]
    tol = (PIVOT_EPS * n) * jnp.abs(jnp.diagonal(P))
    L = jnp.zeros_like(P)
    indefinite = jnp.asarray(False)
    for j in range(n):                               # n is static: unrolled
        Lj = L[j, :j]
        d = P[j, j] - Lj @ Lj if j else P[j, j]
        keep = d > tol[j]
        indefinite = indefinite | ~(d >= -tol[j])    # NaN counts as indefinite
        ljj = jnp.sqrt(jnp.where(keep, d, 1.0))
        L = L.at[j, j].set(jnp.where(keep, ljj, 0.0))
        if j + 1 < n:
            col = P[j + 1:, j] - L[j + 1:, :j] @ Lj if j else P[j + 1:, j]
            L = L.at[j + 1:, j].set(jnp.where(keep, col / ljj, 0.0))
    Ps = 0.5 * (P + P.T)
    finite = jnp.all(jnp.isfinite(Ps))
    lam, V = small_linalg.eigh(jnp.where(finite, Ps, 0.0))
    nearest = jnp.where(finite, V * jnp.sqrt(jnp.maximum(lam, 0.0)), jnp.nan)
    return jnp.where(indefinite, nearest, L)


def gram(L: jax.Array) -> jax.Array:
    """``L Lᵀ`` with its upper triangle the mirror of its lower one (exactly symmetric;
    :func:`fir_gym.estimators._kalman_linalg.gram`)."""
    M = L @ L.T
    return jnp.tril(M) + jnp.tril(M, -1).T


def psd_rebuild(P: jax.Array) -> jax.Array:
    """``L Lᵀ`` of :func:`psd_factor` of ``P``: ``P`` to round-off where it is PSD, else its
    nearest PSD matrix (:func:`fir_gym.estimators._kalman_linalg.psd_rebuild`)."""
    return gram(psd_factor(P))


# ---------------------------------------------------------------------------- moments
def _moments(Z: jax.Array, w: SigmaWeights
             ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """Mean, deviations ``D = Z − Z₀``, ``d = Σ Wᵐ D`` and ``c = Σ Wᶜ D`` of ``Z (N, k)``
    (the reference's ``_moments``)."""
    D = Z - Z[:1]
    d = jnp.asarray(w.Wm) @ D
    c = d if w.same_tail else jnp.asarray(w.Wc) @ D
    return Z[0] + d, D, d, c


def _cross(Da: jax.Array, da: jax.Array, ca: jax.Array, Db: jax.Array, db: jax.Array,
           cb: jax.Array, w: SigmaWeights) -> jax.Array:
    """``Σ Wᶜ (Aᵢ − ā)(Bᵢ − b̄)ᵀ`` from deviations (the reference's ``_cross``)."""
    C = (Da * jnp.asarray(w.Wc)[:, None]).T @ Db
    if w.same_tail:
        return C + (w.sum_Wc - 2.0) * jnp.outer(da, db)
    return C - jnp.outer(da, cb) - jnp.outer(ca, db) + w.sum_Wc * jnp.outer(da, db)


def unscented_transform(Z: jax.Array, weights: SigmaWeights) -> tuple[jax.Array, jax.Array]:
    """``(z̄, Σ Wᶜ (Zᵢ − z̄)(Zᵢ − z̄)ᵀ)`` of the transformed points ``Z (N, k)``, symmetrised
    (:func:`fir_gym.estimators.unscented.unscented_transform` without noise; paper 003,
    eqs 8–9, corrected)."""
    mean, D, d, c = _moments(Z, weights)
    return mean, symmetrize(_cross(D, d, c, D, d, c, weights))


# ---------------------------------------------------------------------------- the steps
def _weights(n: int, weights: SigmaWeights | None) -> SigmaWeights:
    w = merwe_weights(n) if weights is None else weights
    if w.xi.shape[1] != n:
        raise ValueError(f"weights must be for n = {n} (the state's size); got n = "
                         f"{w.xi.shape[1]}")
    return w


def ukf_correct(x: jax.Array, P: jax.Array, X: jax.Array, y: jax.Array, model: FilterModel,
                weights: SigmaWeights, *, missing: jax.Array | bool = False
                ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The measurement update of ``N(x, P)`` from its points ``X (N, n)`` with ``y``
    (``UnscentedKalmanFilter._correct``): ``(x⁺, P⁺, nis)``, NaN where ``S`` is not positive
    definite (or the points are NaN). ``missing`` (a traced bool): ``y`` did not arrive —
    ``x, P`` are kept and the NIS is NaN (the reference's
    :func:`~fir_gym.estimators.kalman.keep_usable` with ``valid`` False), whatever ``y``
    holds; the literal ``False`` (the default) traces no select."""
    Z = X @ model.H.T
    y_hat, DZ, dz, cz = _moments(Z, weights)
    _, DX, dx, cx = _moments(X, weights)
    S = symmetrize(_cross(DZ, dz, cz, DZ, dz, cz, weights))
    Pxz = _cross(DX, dx, cx, DZ, dz, cz, weights)
    S = S + model.R
    W = small_linalg.spd_inverse(S)
    K = Pxz @ W
    e = y - y_hat
    x_new = x + K @ e
    P_new = psd_rebuild(symmetrize(P - K @ Pxz.T))
    nis = (W @ e) @ e
    if missing is False:
        return x_new, P_new, nis
    return (jnp.where(missing, x, x_new), jnp.where(missing, P, P_new),
            jnp.where(missing, jnp.nan, nis))


def ukf_update(x: jax.Array, P: jax.Array, y: jax.Array, model: FilterModel,
               weights: SigmaWeights | None = None, *, missing: jax.Array | bool = False
               ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The measurement update alone, from points drawn at ``(x, P)`` — the env's reset
    (``EstimatorObservation.reset``: the filter at its prior consumes ``y[0]``;
    ``UnscentedKalmanFilter._update``): ``(x⁺, P⁺, nis)``. ``weights`` default to
    :func:`merwe_weights` of the state's size. A ``missing`` ``y[0]`` (the numpy
    ``step(None)``) keeps the prior ``(x, P)``, NIS NaN."""
    w = _weights(x.shape[-1], weights)
    return ukf_correct(x, P, sigma_points(x, P, w), y, model, w, missing=missing)


def ukf_predict(x: jax.Array, P: jax.Array, u: jax.Array, model: FilterModel,
                weights: SigmaWeights | None = None) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The prediction through the sigma points: ``(x⁻, P⁻, Xf)`` with ``Xf = f(χ, u)`` the
    propagated points and ``x⁻, P⁻ = UT(Xf) + Q`` (the first half of
    ``UnscentedKalmanFilter._predict_update``). With no measurement the numpy filter keeps
    ``x⁻, P⁻`` and reports a NaN NIS."""
    w = _weights(x.shape[-1], weights)
    X = sigma_points(x, P, w)
    Xf = jax.vmap(model.f, in_axes=(0, None))(X, u)
    x_pred, P_pred = unscented_transform(Xf, w)
    return x_pred, P_pred + model.Q, Xf


def ukf_predict_update(x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
                       model: FilterModel, weights: SigmaWeights | None = None,
                       redraw: bool = True, *, missing: jax.Array | bool = False
                       ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """One env step (``EstimatorObservation.step`` with the applied action ``u``;
    ``UnscentedKalmanFilter._predict_update``): :func:`ukf_predict`, then
    :func:`ukf_correct` from points redrawn at ``(x⁻, P⁻)`` (``redraw=False``: the
    propagated points, paper 003's Table 2). Returns ``(x⁺, P⁺, nis)``; where ``missing``
    (the numpy ``step(None, u)``) the prediction ``(x⁻, P⁻)`` and a NaN NIS."""
    w = _weights(x.shape[-1], weights)
    x_pred, P_pred, Xf = ukf_predict(x, P, u, model, w)
    X_pred = sigma_points(x_pred, P_pred, w) if redraw else Xf
    return ukf_correct(x_pred, P_pred, X_pred, y, model, w, missing=missing)
