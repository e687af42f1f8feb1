"""The continuous-time optimal FIR filter over a horizon T (paper 001, §II; Kwon, Kwon & Lee 1990).

For ``ẋ = A x + G w``, ``z = C x + v`` (``E[w wᵀ] = Q δ``, ``E[v vᵀ] = V δ``; paper 001
writes ``B`` for ``G``), the filter ``x̂(t|T) = ∫_{t−T}^t H(t, τ; T) z(τ) dτ`` (eq 2.2)
is computed in the window time ``σ ∈ [0, T]``:

    ∂R/∂σ = A R + R Aᵀ + G Q Gᵀ − R Cᵀ V⁻¹ C R,      R(0) = Π = Cov[x(t − T)]   (2.4, 2.5)
    K(σ) = R(σ) Cᵀ V⁻¹   (V⁻¹ is missing in print),   F(σ) = A − K(σ) C,
    H(σ) = Φ_F(T, σ) K(σ)                                                      (2.4)

with ``Π`` the stationary covariance (``A Π + Π Aᵀ + G Q Gᵀ = 0``). It is the
Kalman–Bucy filter started at ``t − T`` from ``x̂ = 0``, ``P = Π``; ``R(T)`` is its
error covariance and tends, as ``T → ∞``, to the CARE solution of the steady-state
Kalman–Bucy filter (:func:`kalman_bucy`).

:func:`fir_riccati` solves the Riccati equation exactly on a grid through the
Hamiltonian system of paper 002 (eq 3.8): with ``M = [[−Aᵀ, CᵀV⁻¹C], [G Q Gᵀ, A]]``
and ``[U; V] = e^{M δ} [I; R_j]``, ``R_{j+1} = V U⁻¹``, restarted every step, and
the closed-loop transition is ``Φ_F(σ_{j+1}, σ_j) = U⁻ᵀ`` (because ``U̇ = −Fᵀ U``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from ._validation import FloatArray, as_covariance, positive
from .bpf import hamiltonian
from .continuous import ContinuousModel

__all__ = ["FIRSolution", "fir_riccati", "kalman_bucy", "linear_matrices",
           "stationary_covariance"]

#: grid steps per second of window (and at least 200) when ``n_steps`` is not given
STEPS_PER_SECOND = 100


class FIRSolution(NamedTuple):
    """The optimal FIR filter on the window grid ``σ_j = j T / N``.

    ``R (N+1, n, n)``, ``K (N+1, n, r)``, ``step[j] = Φ_F(σ_{j+1}, σ_j)`` ``(N, n, n)``.
    """

    sigma: FloatArray
    R: FloatArray
    K: FloatArray
    step: FloatArray

    def to_end(self) -> FloatArray:
        """``Φ_F(T, σ_j)`` for every grid point, ``(N+1, n, n)``."""
        out = np.empty((len(self.sigma),) + self.step.shape[1:])
        out[-1] = np.eye(self.step.shape[1])
        for j in range(len(self.step) - 1, -1, -1):
            out[j] = out[j + 1] @ self.step[j]
        return out

    def from_start(self) -> FloatArray:
        """``Φ_F(σ_j, 0)`` for every grid point, ``(N+1, n, n)``: the transition from the window
        start (the reading of paper 001's eqs 3.2–3.4 that integrates eq 3.3 from ``σ = 0``)."""
        out = np.empty((len(self.sigma),) + self.step.shape[1:])
        out[0] = np.eye(self.step.shape[1])
        for j in range(len(self.step)):
            out[j + 1] = self.step[j] @ out[j]
        return out

    def impulse_response(self) -> FloatArray:
        """``H(σ_j) = Φ_F(T, σ_j) K(σ_j)`` (eq 2.4): ``x̂ = ∫_0^T H(σ) z(t − T + σ) dσ``."""
        return self.to_end() @ self.K


def linear_matrices(
    model: ContinuousModel,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(A, C, G Q Gᵀ, V)`` of a linear :class:`ContinuousModel` (paper 001's eq 2.1)."""
    if not isinstance(model, ContinuousModel) or model.A is None or model.C is None:
        raise TypeError("a linear ContinuousModel (ContinuousModel.linear) is needed; "
                        f"got {model!r}")
    return model.A, model.C, model.GQGT, model.R


def stationary_covariance(model: ContinuousModel) -> FloatArray:
    """``Π`` with ``A Π + Π Aᵀ + G Q Gᵀ = 0`` (eq 2.5's ``Cov[x(t − T)]``); ``A`` must be stable."""
    A, _, W, _ = linear_matrices(model)
    if np.max(np.linalg.eigvals(A).real) >= 0:
        raise ValueError(f"A of {model.name!r} must be stable for a stationary covariance")
    Pi = scipy.linalg.solve_continuous_lyapunov(A, -W)
    return 0.5 * (Pi + Pi.T)


def kalman_bucy(model: ContinuousModel) -> FloatArray:
    """Steady-state Kalman–Bucy covariance: ``A P + P Aᵀ + G Q Gᵀ − P Cᵀ V⁻¹ C P = 0`` (CARE)."""
    A, C, W, V = linear_matrices(model)
    P = scipy.linalg.solve_continuous_are(A.T, C.T, W, V)
    return 0.5 * (P + P.T)


def fir_riccati(model: ContinuousModel, horizon: float, n_steps: int | None = None,
                R0: FloatArray | None = None) -> FIRSolution:
    """The optimal FIR filter over ``horizon`` (eqs 2.4–2.5), exact on ``n_steps`` grid steps.

    ``R0`` defaults to the stationary covariance :func:`stationary_covariance`.
    """
    A, C, W, V = linear_matrices(model)
    horizon = positive("horizon", horizon)
    N = grid_steps(horizon, n_steps)
    n = A.shape[0]
    V_inv_C = np.linalg.solve(V, C)
    E = scipy.linalg.expm(horizon / N * hamiltonian(A, C.T @ V_inv_C, W))
    R = np.empty((N + 1, n, n))
    step = np.empty((N, n, n))
    R[0] = stationary_covariance(model) if R0 is None else as_covariance("R0", R0, n)
    for j in range(N):
        U = E[:n, :n] + E[:n, n:] @ R[j]
        Vj = E[n:, :n] + E[n:, n:] @ R[j]
        Rj = np.linalg.solve(U.T, Vj.T).T                       # V U⁻¹ (eq 3.11 of paper 002)
        R[j + 1] = 0.5 * (Rj + Rj.T)
        step[j] = np.linalg.solve(U.T, np.eye(n))                # Φ_F(σ_{j+1}, σ_j) = U⁻ᵀ
    return FIRSolution(np.linspace(0.0, horizon, N + 1), R, R @ V_inv_C.T, step)


def grid_steps(horizon: float, n_steps: int | None) -> int:
    """The (even) number of grid steps: ``n_steps``, or 100 per second of window (≥ 200)."""
    if n_steps is None:
        n_steps = max(200, int(np.ceil(STEPS_PER_SECOND * horizon)))
    n_steps = positive("n_steps", n_steps, integer=True)
    return n_steps + n_steps % 2                        # even, for Simpson's rule
