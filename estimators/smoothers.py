"""Fixed-interval smoothers: Rauch–Tung–Striebel and its unscented form (numpy reference).

A forward pass (:meth:`Estimator.filter <fir_gym.estimators.base.Estimator.filter>`, on
the compiled or the numpy path) gives ``x̂[k|k]``, ``P[k|k]``; the backward pass
(Rauch, Tung & Striebel 1965; Särkkä, *Bayesian Filtering and Smoothing*, 2013, Thm 8.2
and, for the unscented smoother, Alg. 9.3) is

    x⁻[k+1], P⁻[k+1], C[k]     the prediction from (x̂[k|k], P[k|k]) with u[k], and the
                               cross-covariance C[k] = Cov(x[k], x[k+1] | y[0..k])
    G[k]     = C[k] P⁻[k+1]⁻¹
    x̂[k|N]  = x̂[k|k] + G[k] (x̂[k+1|N] − x⁻[k+1])      (the model's residual_x)
    P[k|N]   = P[k|k] + G[k] (P[k+1|N] − P⁻[k+1]) G[k]ᵀ  (symmetrised)

for ``k = N−2 … 0``. Each filter supplies its own prediction: the KF ``A x + B u`` with
``C = P Aᵀ`` (``model.matrices(k)``), the EKF ``f(x, u)`` with ``C = P Fᵀ`` (``F`` at the
filtered estimate), the UKF the unscented transform of ``f`` with ``C = Σ Wᶜ (χᵢ − x̂)(f(χᵢ)
− x⁻)ᵀ``. Batched over systems like the filters.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ._kalman_linalg import symmetrize
from ._validation import FloatArray
from .sequences import SmootherResult, input_sequence

if TYPE_CHECKING:
    from .base import Estimator

__all__ = ["Prediction", "smooth_sequence"]

#: ``(k, x̂[k|k] (B, n), P[k|k] (B, n, n), u[k] (B, n_u)) -> (x⁻[k+1], P⁻[k+1], C[k])``
Prediction = Callable[[int, FloatArray, FloatArray, FloatArray],
                      tuple[FloatArray, FloatArray, FloatArray]]


def smooth_sequence(est: Estimator, ys: ArrayLike, us: ArrayLike | None,
                    prediction: Prediction,
                    residual: Callable[[FloatArray, FloatArray], FloatArray] | None = None
                    ) -> SmootherResult:
    """Filter ``ys`` forward with ``est`` (from its current state), then smooth backward with
    the filter's ``prediction`` (module docstring). ``residual(a, b)`` is ``a − b`` by default
    (a model's ``residual_x``, e.g. wrapping an angle)."""
    if est.delay:
        raise ValueError(f"smooth: a filter with delay={est.delay} returns predictions of the "
                         "current state, not the filtered estimates the backward pass needs; "
                         "smooth the undelayed sequence with delay=0")
    k0 = est.time_step
    forward = est.filter(ys, us)
    if forward.P is None:
        raise TypeError(f"{type(est).__name__} has no covariance to smooth with")
    single = forward.x.ndim == 2
    X = forward.x[:, None] if single else forward.x
    P = forward.P[:, None] if single else forward.P
    T, n_b, _ = X.shape
    U = input_sequence(us, T, est.model.n_u)
    if U is None:
        U = np.zeros((T, n_b, est.model.n_u))
    elif U.ndim == 2:
        U = np.broadcast_to(U[:, None], (U.shape[0], n_b, U.shape[1]))
    xs, Ps = X.copy(), P.copy()
    with np.errstate(all="ignore"):
        for k in range(T - 2, -1, -1):
            x_pred, P_pred, C = prediction(k0 + k, X[k], P[k], np.ascontiguousarray(U[k]))
            G = np.linalg.solve(P_pred, C.mT).mT                  # C P⁻⁻¹ (P⁻ symmetric)
            d = xs[k + 1] - x_pred if residual is None else residual(xs[k + 1], x_pred)
            xs[k] = X[k] + (G @ d[:, :, None])[:, :, 0]
            Ps[k] = symmetrize(P[k] + G @ (Ps[k + 1] - P_pred) @ G.mT)
    if single:
        xs, Ps = xs[:, 0], Ps[:, 0]
    return SmootherResult(x=xs, P=Ps, filtered=forward)
