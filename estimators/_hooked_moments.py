"""Sigma-point moments through a model's residual and mean hooks (the UKF on angles).

The textbook sums of the unscented transform with the model's ``mean`` and ``residual``
in place of ``Σ Wᵐ Zᵢ`` and ``Zᵢ − z̄`` (filterpy's ``x_mean_fn``/``residual_x``, Stone
Soup's angle types): ``z̄ = mean(Z, Wᵐ)``, ``Dᵢ = residual(Zᵢ, z̄)``,
``Σ Wᶜ Dᵢ Dᵢᵀ``. Used only for a model that sets a hook; the plain path keeps its
deviation-from-the-first-point sums (:mod:`.unscented`, *Numerics*).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validation import FloatArray

__all__ = ["hooked_cross", "hooked_moments"]


def hooked_moments(Z: FloatArray, Wm: FloatArray, mean: Any, residual: Any
                   ) -> tuple[FloatArray, FloatArray]:
    """``(z̄ (B, k), D (B, N, k))`` of points ``Z (B, N, k)``: ``mean(Z, Wm)`` (default ``Σ Wᵐ
    Zᵢ``) and ``residual(Z, z̄)`` (default ``Z − z̄``; ``z̄`` broadcast as ``(B, 1, k)``)."""
    z = np.einsum("n,bnk->bk", Wm, Z) if mean is None else np.asarray(mean(Z, Wm))
    D = Z - z[:, None] if residual is None else np.asarray(residual(Z, z[:, None]))
    return z, D


def hooked_cross(Da: FloatArray, Db: FloatArray, Wc: FloatArray) -> FloatArray:
    """``Σ Wᶜᵢ Daᵢ Dbᵢᵀ`` over the points of every system: ``(B, ka, kb)``."""
    return np.einsum("n,bni,bnj->bij", Wc, Da, Db)
