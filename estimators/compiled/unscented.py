"""The unscented Kalman filter's step, compiled: sigma points, moments and the update.

The twins of :class:`~fir_gym.estimators.unscented.UnscentedKalmanFilter`'s numpy
step, in three calls around the two model evaluations (``f`` on the sigma points,
``h`` on the predicted ones), each one loop over the batch:

* :func:`sigma_points` — ``χⱼ = x + S ξⱼ`` with ``S`` the lower Cholesky factor of ``P``
  (after the opt-in ``jitter``), the symmetric eigen-square-root where ``P`` is only
  semi-definite, NaN where it is indefinite — :func:`~fir_gym.estimators.unscented.matrix_sqrt`'s
  rules;
* :func:`predict` — ``x⁻, P⁻ = UT(f(χ)) + G Q Gᵀ`` and the points of the update
  (redrawn from ``x⁻, P⁻`` or the propagated ones);
* :func:`update` — ``ŷ, S = UT(h(χ⁻)) + R``, ``Pxz``, ``K = Pxz S⁻¹``, ``x⁺ = x⁻ + K (y − ŷ)``,
  ``P⁺ = P⁻ − K Pxzᵀ`` (symmetrised, rebuilt through its PSD factor), then the watch, in
  place.

:func:`cross_moments` is the numpy reference's ``_moments`` + ``_cross`` in one pass:
with deviations from the first point ``D = Z − Z₀`` (which keeps the α = 1e-3 weights'
±1e6 cancellation out of the sums), ``d = Σ Wᵐ D``, ``c = Σ Wᶜ D``, the means are
``Z₀ + d`` and ``Σ Wᶜ (Aᵢ − ā)(Bᵢ − b̄)ᵀ = Σ Wᶜ Dₐ D_bᵀ − d_a c_bᵀ − c_a d_bᵀ +
(Σ Wᶜ) d_a d_bᵀ``. A system whose ``predict`` is False (its first step) keeps its prior
as ``x⁻, P⁻`` and draws the update's points from it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import jit
from .kalman import Block, finish
from .linalg import CHUNK, cholesky, load, psd_rebuild, spd_inverse
from .watch import Watched

if TYPE_CHECKING:
    from ..state import FilterState

#: relative tolerance below which negative eigenvalues count as round-off (as the numpy
#: reference's ``PSD_TOL``)
PSD_TOL = 1e-9


@jit
def weighted_sums(D: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, d: np.ndarray,
                  c: np.ndarray, nb: int) -> None:
    """``d = Σᵢ Wᵐᵢ Dᵢ`` and ``c = Σᵢ Wᶜᵢ Dᵢ`` of SoA deviations ``D[point, j, system]``."""
    for j in range(D.shape[1]):
        for t in range(nb):
            d[j, t] = 0.0
            c[j, t] = 0.0
        for i in range(D.shape[0]):
            wm, wc = Wm[i], Wc[i]
            for t in range(nb):
                d[j, t] += wm * D[i, j, t]
                c[j, t] += wc * D[i, j, t]


@jit
def cross_moments(A: np.ndarray, Z: np.ndarray, Wm: np.ndarray, Wc: np.ndarray,
                  symmetric: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ā, z̄, Σ Wᶜ (Aᵢ − ā)(Zᵢ − z̄)ᵀ)`` of ``A (B, N, p)`` and ``Z (B, N, q)``; ``symmetric``
    says ``Z`` is ``A`` (a covariance: computed once, its lower triangle mirrored)."""
    n_b, N, p = A.shape
    q = Z.shape[2]
    sum_Wc = 0.0
    for i in range(N):
        sum_Wc += Wc[i]
    mean_a = np.empty((n_b, p))
    mean_z = np.empty((n_b, q))
    C = np.empty((n_b, p, q))
    c = min(CHUNK, n_b)                        # systems per block, held D[point, j, system]
    Da, da, ca = np.empty((N, p, c)), np.empty((p, c)), np.empty((p, c))
    # the covariance of one set of points (A is Z): its deviations and sums once
    Dz, dz, cz = (Da, da, ca) if symmetric else (np.empty((N, q, c)), np.empty((q, c)),
                                                  np.empty((q, c)))
    Cs = np.empty((p, q, c))
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        for t in range(nb):
            for i in range(N):
                for j in range(p):
                    Da[i, j, t] = A[b0 + t, i, j] - A[b0 + t, 0, j]
                if not symmetric:
                    for j in range(q):
                        Dz[i, j, t] = Z[b0 + t, i, j] - Z[b0 + t, 0, j]
        weighted_sums(Da, Wm, Wc, da, ca, nb)
        if not symmetric:
            weighted_sums(Dz, Wm, Wc, dz, cz, nb)
        for j in range(p):
            for k in range(j + 1 if symmetric else q):
                for t in range(nb):
                    Cs[j, k, t] = 0.0
                for i in range(N):
                    wc = Wc[i]
                    for t in range(nb):
                        Cs[j, k, t] += (wc * Da[i, j, t]) * Dz[i, k, t]
                for t in range(nb):
                    Cs[j, k, t] = (Cs[j, k, t] - da[j, t] * cz[k, t] - ca[j, t] * dz[k, t]
                                   + sum_Wc * (da[j, t] * dz[k, t]))
        for t in range(nb):
            for j in range(p):
                mean_a[b0 + t, j] = A[b0 + t, 0, j] + da[j, t]
                for k in range(q):            # a covariance: its lower triangle, mirrored
                    C[b0 + t, j, k] = Cs[max(j, k), min(j, k), t] if symmetric else \
                        Cs[j, k, t]
            for k in range(q):
                mean_z[b0 + t, k] = Z[b0 + t, 0, k] + dz[k, t]
    return mean_a, mean_z, C


@jit
def square_root(P: np.ndarray, jitter: float, b0: int, nb: int, Ps: np.ndarray,
                Ls: np.ndarray, ok: np.ndarray) -> None:
    """Square roots of systems ``b0 .. b0+nb`` of ``P`` into the block ``Ls``: lower Cholesky
    (after ``jitter · max(diag P) · I``), else the eigen-square-root of a semi-definite
    ``P``, else NaN."""
    n = P.shape[1]
    load(P, b0, nb, Ps)
    if jitter:
        for t in range(nb):
            scale = Ps[0, 0, t]
            for i in range(1, n):
                scale = max(scale, Ps[i, i, t])
            for i in range(n):
                Ps[i, i, t] += jitter * scale
    cholesky(Ps, Ls, ok, nb)
    for t in range(nb):
        for i in range(n):
            for j in range(i + 1, n):
                Ls[i, j, t] = 0.0
        if ok[t]:
            continue
        Pt = np.ascontiguousarray(Ps[:, :, t])
        for i in range(n):
            for j in range(i + 1, n):          # the lower triangle, as the factor reads it
                Pt[i, j] = Pt[j, i]
        Ls[:, :, t] = np.nan
        if not np.isfinite(Pt).all():
            continue
        lam, V = np.linalg.eigh(Pt)
        if lam[0] >= -PSD_TOL * max(lam[n - 1], 0.0):
            for i in range(n):
                for j in range(n):
                    Ls[i, j, t] = V[i, j] * np.sqrt(max(lam[j], 0.0))


@jit
def sigma_points(x: np.ndarray, P: np.ndarray, xi: np.ndarray, jitter: float) -> np.ndarray:
    """The points ``χⱼ = x + S ξⱼ`` ``(B, N, n)`` of every system (``xi (N, n)``)."""
    n_b, n = x.shape
    N = xi.shape[0]
    X = np.empty((n_b, N, n))
    c = min(CHUNK, n_b)
    Ps, Ls, ok = np.empty((n, n, c)), np.empty((n, n, c)), np.empty(c, dtype=np.bool_)
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        square_root(P, jitter, b0, nb, Ps, Ls, ok)
        draw(x, Ls, xi, b0, nb, X)
    return X


@jit
def draw(x: np.ndarray, Ls: np.ndarray, xi: np.ndarray, b0: int, nb: int, X: np.ndarray
         ) -> None:
    """``X[b, j] = x[b] + S_b ξⱼ`` for the block's systems (square roots ``Ls``)."""
    n = x.shape[1]
    for t in range(nb):
        b = b0 + t
        for j in range(xi.shape[0]):
            for i in range(n):
                v = 0.0
                for k in range(n):
                    v += Ls[i, k, t] * xi[j, k]
                X[b, j, i] = x[b, i] + v


@jit
def predict(X: np.ndarray, Xf: np.ndarray, x: np.ndarray, P: np.ndarray, Wm: np.ndarray,
            Wc: np.ndarray, Q: np.ndarray, predicting: np.ndarray, redraw: bool,
            xi: np.ndarray, jitter: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x⁻, P⁻, χ⁻)``: the unscented moments of the propagated points ``Xf = f(X)`` plus
    ``Q`` (the prior ``x, P`` where ``predicting`` is False) and the update's points,
    redrawn from ``x⁻, P⁻`` or (``redraw`` False) ``Xf`` (``X`` where not predicting)."""
    n_b, _, n = Xf.shape
    x_pred, _, P_pred = cross_moments(Xf, Xf, Wm, Wc, True)
    for b in range(n_b):
        if predicting[b]:
            for i in range(n):
                for j in range(n):
                    P_pred[b, i, j] += Q[i, j]
        else:
            for i in range(n):
                x_pred[b, i] = x[b, i]
                for j in range(n):
                    P_pred[b, i, j] = P[b, i, j]
    if not redraw:
        X_pred = Xf.copy()
        for b in range(n_b):
            if not predicting[b]:
                X_pred[b] = X[b]
        return x_pred, P_pred, X_pred
    return x_pred, P_pred, sigma_points(x_pred, P_pred, xi, jitter)


def update(x_pred: np.ndarray, P_pred: np.ndarray, X: np.ndarray, Z: np.ndarray,
           y: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, R: np.ndarray, valid: np.ndarray,
           state: FilterState) -> None:
    """The measurement update of every system from its points ``X (B, N, n)`` and ``Z = h(X)``,
    then the watch, written into the record ``state`` (whose ``x``, ``P`` may be ``x_pred``,
    ``P_pred``)."""
    update_kernel(x_pred, P_pred, X, Z, y, Wm, Wc, R, valid, state.x, state.P, state.diverged,
                  state.nis_run, state.nis, state.logdet, state.limits)


@jit
def update_kernel(x_pred: np.ndarray, P_pred: np.ndarray, X: np.ndarray, Z: np.ndarray,
                  y: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, R: np.ndarray,
                  valid: np.ndarray, x: np.ndarray, P: np.ndarray, diverged: np.ndarray,
                  nis_run: np.ndarray, nis: np.ndarray, logdet: np.ndarray, limits: np.ndarray
                  ) -> None:
    """The kernel of :func:`update`: the step's inputs, then the record's arrays (in the order
    of :class:`~.watch.Watched`)."""
    out = Watched(x, P, diverged, nis_run, nis, logdet, limits)
    n_b, _, n = X.shape
    m = Z.shape[2]
    if not (x_pred.shape[0] == P_pred.shape[0] == Z.shape[0] == y.shape[0] == valid.shape[0]
            == x.shape[0] == P.shape[0] == diverged.shape[0] == nis_run.shape[0]
            == nis.shape[0] == n_b):
        raise ValueError("update: the arrays must have a row per system")
    _, y_hat, Pxz = cross_moments(X, Z, Wm, Wc, False)
    _, _, S_all = cross_moments(Z, Z, Wm, Wc, True)
    c = min(CHUNK, n_b)
    Ss, Ws, L, ok = np.empty((m, m, c)), np.empty((m, m, c)), np.ones((m, m, c)), \
        np.empty(c, dtype=np.bool_)
    K, Pm, Pp = np.empty((n, m, c)), np.empty((n, n, c)), np.empty((n, n, c))
    Tp = np.empty((n, n, c))
    Xm, E = np.empty((n, c)), np.empty((m, c))
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        load(S_all, b0, nb, Ss)
        for i in range(m):                           # S = UT(Z) + R
            for j in range(m):
                for t in range(nb):
                    Ss[i, j, t] += R[i, j]
        spd_inverse(Ss, Ws, L, ok, nb)
        for t in range(nb):
            b = b0 + t
            for i in range(n):                       # K = Pxz S⁻¹
                for j in range(m):
                    v = 0.0
                    for k in range(m):
                        v += Pxz[b, i, k] * Ws[k, j, t]
                    K[i, j, t] = v
            for i in range(n):                       # P⁺ = P⁻ − K Pxzᵀ, symmetrised
                Xm[i, t] = x_pred[b, i]
                for j in range(n):
                    v = 0.0
                    for k in range(m):
                        v += K[i, k, t] * Pxz[b, j, k]
                    Pm[i, j, t] = P_pred[b, i, j]
                    Pp[i, j, t] = P_pred[b, i, j] - v
            for i in range(n):
                for j in range(i):
                    s = 0.5 * (Pp[i, j, t] + Pp[j, i, t])
                    Pp[i, j, t] = s
                    Pp[j, i, t] = s
            for i in range(m):
                E[i, t] = y[b, i] - y_hat[b, i]
        psd_rebuild(Pp, Tp, nb)                      # P⁺ through its PSD factor
        finish(b0, nb, Xm, E, valid, Block(ok, K, Ws, Pm, Pp), 0, False, True, out)
