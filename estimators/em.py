"""Expectation–maximisation of a linear model's noise covariances ``Q`` and ``R``.

Shumway & Stoffer (1982); the M-step of Ghahramani & Hinton (1996), as pykalman's ``em``
with ``em_vars=["transition_covariance", "observation_covariance"]``. Each iteration runs
the Kalman filter and RTS smoother (:meth:`KalmanFilter.smooth
<fir_gym.estimators.kalman.KalmanFilter.smooth>`) with the current model (E-step), then

    Q ← 1/(T−1) Σₖ [ eₖ eₖᵀ + A P[k|N] Aᵀ + P[k+1|N] − P[k+1,k|N] Aᵀ − A P[k+1,k|N]ᵀ ],
        eₖ = x̂[k+1|N] − A x̂[k|N] − B u[k],   P[k+1,k|N] = P[k+1|N] G[k]ᵀ
    R ← 1/#obs Σₖ (measured k) [ rₖ rₖᵀ + C P[k|N] Cᵀ ],   rₖ = y[k] − C x̂[k|N]

with ``G[k] = P[k|k] Aᵀ P⁻[k+1]⁻¹`` the smoother gain (M-step). The log-likelihood of the
data never decreases from one iteration to the next.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray
from .kalman import KalmanFilter, predict_covariance
from .model import LinearModel
from .sequences import input_sequence, measurement_sequence

__all__ = ["EMResult", "em"]


class EMResult(NamedTuple):
    """The fitted model and the log-likelihood of the data *before* each iteration."""

    model: LinearModel
    log_likelihoods: FloatArray


def em(model: LinearModel, ys: ArrayLike, us: ArrayLike | None = None, *, x0: ArrayLike,
       P0: ArrayLike, n_iter: int = 10) -> EMResult:
    """Fit ``Q`` and ``R`` of ``model`` to one sequence by EM (module docstring).

    Args:
        model: a :class:`LinearModel` with ``G = I`` (``Q`` is the state noise covariance).
        ys, us: one sequence, as :meth:`Estimator.filter` takes it (``(T, n_y)``, missing
            entries NaN or masked; ``us`` ``(T − 1, n_u)``).
        x0, P0: the prior of ``x[0]``.
        n_iter: number of iterations.

    Returns:
        :class:`EMResult`: the model with the fitted ``Q, R`` and the log-likelihood before
        each iteration (``log_likelihoods[0]`` is the starting model's).
    """
    if not isinstance(model, LinearModel):
        raise TypeError(f"model must be a LinearModel; got {type(model).__name__}")
    if model.G.shape != (model.n_x, model.n_x) or not np.array_equal(model.G, np.eye(model.n_x)):
        raise ValueError("model.G must be the identity (EM fits Q as the state noise covariance)")
    if isinstance(n_iter, bool) or not isinstance(n_iter, int) or n_iter < 1:
        raise ValueError(f"n_iter must be a positive integer; got {n_iter!r}")
    Y = measurement_sequence(ys, model.n_y)
    if Y.ndim != 2:
        raise ValueError(f"ys must be one sequence (T, {model.n_y}); got shape {Y.shape}")
    T = Y.shape[0]
    U = input_sequence(us, T, model.n_u)
    Bu = np.zeros((T - 1, model.n_x)) if U is None else U[:T - 1] @ model.B.T
    measured = ~np.ma.getmaskarray(Y).any(axis=1)
    if not measured.any():
        raise ValueError("ys must hold at least one measurement")
    lls = []
    for _ in range(n_iter):
        sm = KalmanFilter(model, x0=x0, P0=P0).smooth(Y, U)
        lls.append(sm.filtered.log_likelihood)
        A, C = model.A, model.C
        P = sm.filtered.P
        assert P is not None                           # a Kalman filter has a covariance
        xs, Ps = sm.x, sm.P
        P_pred = predict_covariance(P[:-1], A, model.GQGT)           # P⁻[k+1]
        G = np.linalg.solve(P_pred, A @ P[:-1]).mT                    # P Aᵀ P⁻⁻¹
        cross = Ps[1:] @ G.mT                                         # P[k+1,k|N]
        e = xs[1:] - xs[:-1] @ A.T - Bu
        cross_A = cross @ A.T
        Q = (e[:, :, None] * e[:, None, :] + A @ Ps[:-1] @ A.T + Ps[1:] - cross_A
             - cross_A.mT).mean(axis=0)
        r = Y.data[measured] - xs[measured] @ C.T
        R = (r[:, :, None] * r[:, None, :] + C @ Ps[measured] @ C.T).mean(axis=0)
        model = model.replace(Q=0.5 * (Q + Q.T), R=0.5 * (R + R.T))
    return EMResult(model, np.array(lls))
