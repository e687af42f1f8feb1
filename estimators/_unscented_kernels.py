"""The unscented moments of a batch as one compiled loop (numba; ``None`` without it).

:func:`cross_moments` is the
numpy path's ``_moments`` + ``_cross`` of :mod:`.unscented` in one pass: with
deviations from the first point ``D = Z − Z₀`` (which keeps the α = 1e-3 weights'
±1e6 cancellation out of the sums), ``d = Σ Wᵐ D``, ``c = Σ Wᶜ D``, the means are
``Z₀ + d`` and ``Σ Wᶜ (Aᵢ − ā)(Bᵢ − b̄)ᵀ = Σ Wᶜ Dₐ D_bᵀ − d_a c_bᵀ − c_a d_bᵀ +
(Σ Wᶜ) d_a d_bᵀ``. The numpy path is the oracle (``tests/estimators/test_compiled.py``).
"""

from __future__ import annotations

import numpy as np

from ._compiled import kernel
from ._kalman_kernels import CHUNK


def _weighted_sums_loops(D: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, d: np.ndarray,
                        c: np.ndarray, nb: int) -> None:
    """``d = Σᵢ Wᵐᵢ Dᵢ`` and ``c = Σᵢ Wᶜᵢ Dᵢ`` of SoA deviations ``D[point, j, system]``."""
    for j in range(D.shape[1]):
        dj, cj = d[j], c[j]
        for t in range(nb):
            dj[t] = 0.0
            cj[t] = 0.0
        for i in range(D.shape[0]):
            wm, wc, Dij = Wm[i], Wc[i], D[i, j]
            for t in range(nb):
                dj[t] += wm * Dij[t]
                cj[t] += wc * Dij[t]


_weighted_sums = kernel(_weighted_sums_loops)


def _cross_moments(A: np.ndarray, Z: np.ndarray, Wm: np.ndarray, Wc: np.ndarray,
                   symmetric: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b, N, p = A.shape
    q = Z.shape[2]
    sum_Wc = 0.0
    for i in range(N):
        sum_Wc += Wc[i]
    mean_a = np.empty((n_b, p))
    mean_z = np.empty((n_b, q))
    C = np.empty((n_b, p, q))
    c = CHUNK                                  # systems per block, held D[point, j, system]
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
        _weighted_sums(Da, Wm, Wc, da, ca, nb)
        if not symmetric:
            _weighted_sums(Dz, Wm, Wc, dz, cz, nb)
        for j in range(p):
            for k in range(j + 1 if symmetric else q):
                acc = Cs[j, k]
                for t in range(nb):
                    acc[t] = 0.0
                for i in range(N):
                    wc, Daj, Dzk = Wc[i], Da[i, j], Dz[i, k]
                    for t in range(nb):
                        acc[t] += (wc * Daj[t]) * Dzk[t]
                daj, caj, dzk, czk = da[j], ca[j], dz[k], cz[k]
                for t in range(nb):
                    acc[t] = acc[t] - daj[t] * czk[t] - caj[t] * dzk[t] + sum_Wc * (daj[t] *
                                                                                  dzk[t])
        for t in range(nb):
            for j in range(p):
                mean_a[b0 + t, j] = A[b0 + t, 0, j] + da[j, t]
                for k in range(q):            # a covariance: its lower triangle, mirrored
                    C[b0 + t, j, k] = Cs[max(j, k), min(j, k), t] if symmetric else \
                        Cs[j, k, t]
            for k in range(q):
                mean_z[b0 + t, k] = Z[b0 + t, 0, k] + dz[k, t]
    return mean_a, mean_z, C


#: ``cross_moments(A (B, N, p), Z (B, N, q), Wm, Wc, symmetric) -> (ā, z̄, Σ Wᶜ (Aᵢ − ā)(Zᵢ −
#: z̄)ᵀ)``; ``symmetric`` says ``Z`` is ``A`` (a covariance: computed once, exactly symmetric)
cross_moments = kernel(_cross_moments)
