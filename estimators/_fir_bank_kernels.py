""":class:`~._fir_bank.WindowBank`'s time and measurement updates as compiled loops.

The numpy path makes ~6 passes over the bank ``Z`` (``B x 2n x W x (2n+1)``) per
update, with temporaries of its size; these loops make one, in place, system by
system and window by window, with the same formulas:

* :func:`bank_predict` — ``x̄ ← A x̄ (+ B u)``, ``T ← A T``, ``P ← A P Aᵀ (+ G Q Gᵀ)``;
* :func:`bank_update` — ``r = C [P | T | x̄] − [0 | 0 | y]``, ``Σ = C P Cᵀ + R``,
  ``Z −= [K; W] ⊗ r`` with ``[K; W] = [P Cᵀ; (C T)ᵀ] Σ⁻¹`` (``Σ⁻¹`` in closed form for
  ``p <= 2``; larger ``p`` stay on the numpy path).

Arguments come in one layout (leading axes of length 1 are shared): ``A (B|1, W|1, n,
n)``, ``C (B|1, W|1, p, n)``, ``y (B, W|1, p)``, ``Q (B|1, n, n)``, ``Bu (B, W|1, n)``.
The numpy path is the oracle (``tests/estimators/test_compiled.py``; equal to
round-off: BLAS sums in another order). ``None`` without numba.
"""

from __future__ import annotations

import numpy as np

from ._compiled import kernel


def _bank_predict(Z: np.ndarray, A: np.ndarray, Bu: np.ndarray, Q: np.ndarray,
                  has_Bu: bool, has_Q: bool, size: tuple[int, ...]) -> None:
    n_b, _, W, _ = Z.shape
    n = len(size)
    m = 2 * n + 1
    tmp = np.empty((n, m))
    for b in range(n_b):
        Ab = A[b if A.shape[0] > 1 else 0]
        Qb = Q[b if Q.shape[0] > 1 else 0]
        Zb = Z[b]
        for w in range(W):
            Aw = Ab[w if Ab.shape[0] > 1 else 0]
            tmp[:, :] = 0.0
            for i in range(n):                              # A [P | T | x̄]
                for k in range(n):
                    a = Aw[i, k]
                    for j in range(m):
                        tmp[i, j] += a * Zb[k, w, j]
            for i in range(n):
                for j in range(m):
                    Zb[i, w, j] = tmp[i, j]
            if has_Q:                                       # (A P) Aᵀ + G Q Gᵀ
                for i in range(n):
                    for j in range(n):
                        c = 0.0
                        for k in range(n):
                            c += tmp[i, k] * Aw[j, k]
                        Zb[i, w, j] = c + Qb[i, j]
            if has_Bu:
                Bb = Bu[b]
                Bw = Bb[w if Bb.shape[0] > 1 else 0]
                for i in range(n):
                    Zb[i, w, m - 1] += Bw[i]


def _bank_update(Z: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray,
                 valid: np.ndarray, size: tuple[int, ...]) -> None:
    n_b, _, W, _ = Z.shape
    n = len(size)
    n2 = 2 * n
    m = n2 + 1
    p = C.shape[-2]
    r = np.empty((p, m))
    g = np.empty((p, n2))
    for b in range(n_b):
        if not valid[b if valid.shape[0] > 1 else 0]:
            continue
        Cb = C[b if C.shape[0] > 1 else 0]
        yb = y[b]
        Zb = Z[b]
        for w in range(W):
            Cw = Cb[w if Cb.shape[0] > 1 else 0]
            yw = yb[w if yb.shape[0] > 1 else 0]
            r[:, :] = 0.0
            for q in range(p):                              # r = C [P | T | x̄] − [0 | 0 | y]
                for k in range(n):
                    c = Cw[q, k]
                    for j in range(m):
                        r[q, j] += c * Zb[k, w, j]
                r[q, m - 1] -= yw[q]
            if p == 1:                                      # [K; W]ᵀ = Σ⁻¹ [C P | C T]
                s = 0.0
                for k in range(n):
                    s += r[0, k] * Cw[0, k]
                s += R[0, 0]
                for i in range(n2):
                    g[0, i] = r[0, i] / s
            else:                                           # Σ = (C P) Cᵀ + R, 2 x 2
                s00 = 0.0
                s01 = 0.0
                s10 = 0.0
                s11 = 0.0
                for k in range(n):
                    s00 += r[0, k] * Cw[0, k]
                    s01 += r[0, k] * Cw[1, k]
                    s10 += r[1, k] * Cw[0, k]
                    s11 += r[1, k] * Cw[1, k]
                s00 += R[0, 0]
                s01 += R[0, 1]
                s10 += R[1, 0]
                s11 += R[1, 1]
                det = s00 * s11 - s01 * s10
                for i in range(n2):
                    g[0, i] = (s11 * r[0, i] - s01 * r[1, i]) / det
                    g[1, i] = (s00 * r[1, i] - s10 * r[0, i]) / det
            for q in range(p):                              # Z −= [K; W] ⊗ r
                for i in range(n2):
                    gi = g[q, i]
                    for j in range(m):
                        Zb[i, w, j] -= gi * r[q, j]


def _bank_estimate(Z: np.ndarray, w: int, threshold: float, size: tuple[int, ...]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b = Z.shape[0]
    n = len(size)
    x = np.empty((n_b, n))
    P = np.empty((n_b, n, n))
    ok = np.empty(n_b, dtype=np.bool_)
    F = np.empty((n, n))
    Fi = np.empty((n, n))
    TFi = np.empty((n, n))
    for b in range(n_b):
        Zb = Z[b]
        for i in range(n):
            for j in range(n):
                F[i, j] = -Zb[n + i, w, n + j]
        if n == 1:
            det = F[0, 0]
            Fi[0, 0] = 1.0
        elif n == 2:
            det = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
            Fi[0, 0] = F[1, 1]
            Fi[0, 1] = -F[1, 0]
            Fi[1, 0] = -F[0, 1]
            Fi[1, 1] = F[0, 0]
        else:                                   # cofactors, as spd_inverse's _COFACTOR3
            for i in range(3):
                for j in range(3):
                    Fi[i, j] = (F[(i + 1) % 3, (j + 1) % 3] * F[(i + 2) % 3, (j + 2) % 3]
                                - F[(i + 1) % 3, (j + 2) % 3] * F[(i + 2) % 3, (j + 1) % 3])
            det = 0.0
            for j in range(3):
                det += F[0, j] * Fi[0, j]
        scale = 1.0
        for i in range(n):
            scale *= F[i, i]
        ok[b] = det > threshold * max(scale, 1e-300)
        for i in range(n):
            for j in range(n):
                Fi[i, j] = Fi[i, j] / det
        for i in range(n):                      # T F⁻¹
            for j in range(n):
                c = 0.0
                for k in range(n):
                    c += Zb[i, w, n + k] * Fi[k, j]
                TFi[i, j] = c
        for i in range(n):                      # x̄ + T F⁻¹ b,  P + T F⁻¹ Tᵀ
            c = 0.0
            for k in range(n):
                c += TFi[i, k] * Zb[n + k, w, 2 * n]
            x[b, i] = Zb[i, w, 2 * n] + c
            for j in range(n):
                c = 0.0
                for k in range(n):
                    c += TFi[i, k] * Zb[j, w, n + k]
                P[b, i, j] = Zb[i, w, j] + c
    return x, P, ok


#: ``bank_estimate(Z, w, RANK_RTOL·n^(n−1), size) -> (x, P, regular)``: the diffuse readout
#: of window ``w`` for ``n <= 3`` by the adjugate (:func:`~._fir_bank.spd_inverse`'s test)
bank_estimate = kernel(_bank_estimate)
#: ``bank_predict(Z, A, Bu, Q, has_Bu, has_Q)``, in place; ``None`` without numba
bank_predict = kernel(_bank_predict)
#: ``bank_update(Z, C, R, y, valid)``, in place (``p <= 2``); ``None`` without numba
bank_update = kernel(_bank_update)
