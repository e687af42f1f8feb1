"""The discrete LQR of a plant's nominal model linearised at its operating point.

The stage cost of a fir-gym reward is a quadratic form in ``z = [δx[k+1]; δu[k]]``
(:class:`~fir_gym.envs.DesignPoint`, the plant's ``design_point()``), and
``δx[k+1] = A δx[k] + B δu[k]`` on the linearisation, so ``z = T [δx; δu]`` with
``T = [[A, B], [0, I]]`` and the cost is ``[δx; δu]ᵀ Tᵀ M T [δx; δu]``: state weight
``Q``, input weight ``R`` and cross term ``N``. The gain solves the discrete algebraic
Riccati equation with the cross term (e.g. Anderson & Moore, *Optimal Control:
Linear Quadratic Methods*, 1990, §2.4; scipy's ``solve_discrete_are`` with ``s = N``):

    P = Aᵀ P A − (Aᵀ P B + N) (R + Bᵀ P B)⁻¹ (Bᵀ P A + Nᵀ) + Q
    K = (R + Bᵀ P B)⁻¹ (Bᵀ P A + Nᵀ),        δu = −K δx.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from fir_gym.envs import DesignPoint
from fir_gym.estimators.model import FD_RELATIVE_STEP

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LQRDesign:
    """The linearisation, the weights and the gain of one plant's LQR."""

    A: FloatArray
    B: FloatArray
    Q: FloatArray
    R: FloatArray
    N: FloatArray
    K: FloatArray          # (n_u, n_x): zero columns for the states the design leaves out
    P: FloatArray
    closed_loop_poles: FloatArray


def linearize(model: Any, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``A = ∂f/∂x`` (the model's Jacobian) and ``B = ∂f/∂u`` (central differences) at
    ``(x, u)``."""
    A = np.asarray(model.F(x, u), dtype=np.float64)
    B = np.zeros((x.shape[0], u.shape[0]))
    for j in range(u.shape[0]):
        h = FD_RELATIVE_STEP * max(1.0, abs(float(u[j])))
        du = np.zeros_like(u)
        du[j] = h
        B[:, j] = (np.asarray(model.f(x, u + du)) - np.asarray(model.f(x, u - du))) / (2 * h)
    return A, B


def lqr_design(model: Any, point: DesignPoint) -> LQRDesign:
    """The LQR of ``model`` at ``point`` (the gain acts on ``point.states`` only)."""
    A_full, B_full = linearize(model, point.x, point.u)
    s = np.asarray(point.states)
    n_x, n_u = A_full.shape[0], B_full.shape[1]
    A, B = A_full[np.ix_(s, s)], B_full[s]
    keep = np.concatenate([s, n_x + np.arange(n_u)])
    M = point.M[np.ix_(keep, keep)]
    T = np.block([[A, B], [np.zeros((n_u, len(s))), np.eye(n_u)]])
    H = T.T @ M @ T
    H = 0.5 * (H + H.T)
    n = len(s)
    Q, N, R = H[:n, :n], H[:n, n:], H[n:, n:]
    try:
        P = scipy.linalg.solve_discrete_are(A, B, Q, R, s=N)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise ValueError(f"no stabilising LQR at the operating point ({point.note}): "
                         f"{err}") from None
    K_s = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A + N.T)
    K = np.zeros((n_u, n_x))
    K[:, s] = K_s
    poles = np.linalg.eigvals(A - B @ K_s)
    return LQRDesign(A=A_full, B=B_full, Q=Q, R=R, N=N, K=K, P=P, closed_loop_poles=poles)
