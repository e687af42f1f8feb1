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

:func:`integrated_noise` is that ``Q_d`` alone, for one ``A`` or a stack of them: the
covariance that white noise entering through ``G`` accumulates over one sample period
when it is integrated through the dynamics. A nonlinear model sampled from a continuous
one uses it with ``A`` the drift's Jacobian at a linearisation point
(:meth:`~fir_gym.estimators.ContinuousModel.sampled`,
docs/estimators/models.md#process-noise). The first-order ``G Q Gᵀ dt`` it replaces is
its leading term, and has the rank of ``G``: a single noise input gives a rank-one
covariance, where the integrated noise is full rank whenever ``(A, G)`` is controllable.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_covariance, as_matrix, positive, real_array
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
    return A_d, B_d, integrated_noise(A_, dt, G=G, Q=Q)


def integrated_noise(A: ArrayLike, dt: float, *, Q: ArrayLike, G: ArrayLike | None = None
                     ) -> FloatArray:
    """``Q_d = ∫₀^dt e^{A s} G Q Gᵀ e^{Aᵀ s} ds``: white noise integrated over ``dt``.

    The covariance at ``t + dt`` of ``ẋ = A x + G w`` started from a known state, for
    ``w`` of spectral density ``Q`` — what the discrete model ``x[k+1] = A_d x[k] +
    w_d[k]``, ``w_d ~ N(0, Q_d)`` needs. Computed by Van Loan's method (one matrix
    exponential of ``[[-A, G Q Gᵀ], [0, Aᵀ]] dt``; module docstring).

    Args:
        A: the continuous state matrix ``(n, n)``, or a stack ``(..., n, n)`` of them
            (e.g. the Jacobians of a nonlinear drift at several states): the result
            then has the stack's shape.
        dt: the sample period (> 0).
        Q: spectral density of ``w`` (``q x q``; a scalar or a 1-D array of densities
            is accepted), positive semi-definite.
        G: noise input ``(n, q)``; defaults to the identity.

    Returns:
        ``Q_d`` (symmetrised), shape ``(n, n)`` or ``(..., n, n)``.
    """
    A_ = real_array("A", A)
    if A_.ndim < 2 or A_.shape[-1] != A_.shape[-2]:
        raise ValueError(f"A must be square, or a stack of square matrices; got shape "
                         f"{A_.shape}")
    if not np.all(np.isfinite(A_)):
        raise ValueError("A must be finite; it contains NaN or inf")
    n = A_.shape[-1]
    dt = positive("dt", dt)
    Q_ = as_covariance("Q", Q)
    G_ = np.eye(n) if G is None else as_matrix("G", np.reshape(G, (n, -1)), (n, Q_.shape[0]))
    if G is None and Q_.shape[0] != n:
        raise ValueError(f"Q must be {n}x{n} when G is absent; got {Q_.shape}")
    W = G_ @ Q_ @ G_.T
    # Q_d is linear in W. expm chooses its scaling and squaring from the norm of the whole
    # block, so a large W (≫ 1) would set it and cost accuracy (1e-12 relative at 1e5,
    # garbage past 1e50): a W larger than 1 runs scaled to unit size and is scaled back.
    # A W up to 1 runs as it is (so the carrier's Q_d keeps its bits).
    scale = max(1.0, float(np.max(np.abs(W))))
    van_loan = np.zeros(A_.shape[:-2] + (2 * n, 2 * n))
    van_loan[..., :n, :n] = -A_
    van_loan[..., :n, n:] = W / scale
    van_loan[..., n:, n:] = np.swapaxes(A_, -1, -2)
    V = scipy.linalg.expm(van_loan * dt)
    Q_d = np.swapaxes(V[..., n:, n:], -1, -2) @ V[..., :n, n:]
    return scale * 0.5 * (Q_d + np.swapaxes(Q_d, -1, -2))


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
