"""Random symmetric positive definite matrices and the unit-diagonal (Jacobi) scaling the
FIR rank test uses, shared by the linear-algebra tests."""

from __future__ import annotations

import numpy as np


def spd(rng: np.random.Generator, shape: tuple[int, ...], n: int, scale: float = 1.0
        ) -> np.ndarray:
    """Symmetric positive definite ``(*shape, n, n)``: ``scale · G Gᵀ / n + 0.1 I``."""
    G = rng.normal(size=shape + (n, n))
    return scale * (G @ G.swapaxes(-1, -2)) / n + 0.1 * np.eye(n)


def unit_diagonal(F: np.ndarray) -> np.ndarray:
    """``D⁻¹ F D⁻¹`` with ``D = diag(√|F_ii|)`` (a zero diagonal entry scales by 1), over a
    leading batch axis: the scale-free matrix whose smallest eigenvalue the rank test reads."""
    d = np.sqrt(np.abs(np.diagonal(F, axis1=-2, axis2=-1)))
    d = np.where(d > 0, d, 1.0)
    return F / (d[..., :, None] * d[..., None, :])
