"""Exact discretisation of continuous-time linear time-invariant models.

For ``ẋ = A x + B u + G w`` with white noise ``w`` of spectral density ``Q``
and the input held constant over each sample period ``dt`` (zero-order hold):

    A_d = e^{A dt}
    B_d = ∫₀^dt e^{A s} ds B
    Q_d = ∫₀^dt e^{A s} G Q Gᵀ e^{Aᵀ s} ds

``A_d`` and ``B_d`` come from one matrix exponential of ``[[A, B], [0, 0]] dt``;
``Q_d`` from Van Loan's construction (C. F. Van Loan, "Computing integrals
involving the matrix exponential", IEEE TAC 23(3), 1978):
``expm([[-A, G Q Gᵀ], [0, Aᵀ]] dt) = [[·, A_d⁻¹ Q_d], [0, A_dᵀ]]``, hence
``Q_d = A_d · (upper-right block)``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_covariance, as_matrix, positive
from .model import LinearModel


def discretize_lti(
    A: ArrayLike,
    dt: float,
    *,
    B: ArrayLike | None = None,
    G: ArrayLike | None = None,
    Q: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Zero-order-hold discretisation ``(A_d, B_d, Q_d)`` of ``ẋ = A x + B u + G w``.

    Args:
        A: continuous state matrix ``(n, n)``.
        dt: sample period (> 0).
        B: continuous input matrix ``(n, m)``; absent gives ``B_d`` of shape ``(n, 0)``.
        G: noise input matrix ``(n, q)``; defaults to the identity.
        Q: spectral density of ``w`` (``q x q``); absent means no noise (``Q_d = 0``).

    Returns:
        ``A_d = e^{A dt}``, ``B_d = ∫₀^dt e^{As} ds B``, and the discrete process
        noise covariance ``Q_d`` (symmetrised), so that ``x[k+1] = A_d x[k] +
        B_d u[k] + w_d[k]`` with ``w_d ~ N(0, Q_d)``.
    """
    A_ = as_matrix("A", A, (None, None))
    n = A_.shape[0]
    if A_.shape[1] != n:
        raise ValueError(f"A must be square; got shape {A_.shape}")
    dt = positive("dt", dt)
    B_ = np.zeros((n, 0)) if B is None else as_matrix("B", np.reshape(B, (n, -1)), (n, None))
    m = B_.shape[1]
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A_
    block[:n, n:] = B_
    E = scipy.linalg.expm(block * dt)
    A_d = E[:n, :n]
    B_d = E[:n, n:]
    if Q is None:
        return A_d, B_d, np.zeros((n, n))
    Q_ = as_covariance("Q", Q)
    G_ = np.eye(n) if G is None else as_matrix("G", np.reshape(G, (n, -1)), (n, Q_.shape[0]))
    if G is None and Q_.shape[0] != n:
        raise ValueError(f"Q must be {n}x{n} when G is absent; got {Q_.shape}")
    van_loan = np.zeros((2 * n, 2 * n))
    van_loan[:n, :n] = -A_
    van_loan[:n, n:] = G_ @ Q_ @ G_.T
    van_loan[n:, n:] = A_.T
    V = scipy.linalg.expm(van_loan * dt)
    Q_d = V[n:, n:].T @ V[:n, n:]
    return A_d, B_d, 0.5 * (Q_d + Q_d.T)


def linear_model_from_continuous(
    *,
    A: ArrayLike,
    C: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike,
    dt: float,
    B: ArrayLike | None = None,
    G: ArrayLike | None = None,
    name: str | None = None,
) -> LinearModel:
    """A :class:`LinearModel` sampled exactly from a continuous LTI model.

    ``Q`` is the continuous spectral density of ``w`` and is converted with
    :func:`discretize_lti`; the discrete model's ``G`` is the identity and its
    ``Q`` is ``Q_d``. ``R`` is taken as the covariance of the *discrete*
    measurement noise (for a continuous measurement of intensity ``V`` read
    through an integrate-and-dump of length ``dt`` it is ``V / dt``).
    """
    A_d, B_d, Q_d = discretize_lti(A, dt, B=B, G=G, Q=Q)
    return LinearModel(A=A_d, C=C, Q=Q_d, R=R, B=B_d if B_d.shape[1] else None, dt=dt, name=name)
