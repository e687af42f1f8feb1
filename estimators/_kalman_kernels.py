"""The batched EKF/KF step as one compiled loop over systems (numba; ``None`` without it).

:func:`predict_update` is :func:`~.kalman.predict_covariance` followed by
:func:`~.kalman.update_kernel` — ``P⁻ = F P Fᵀ + Q``, ``S = H P⁻ Hᵀ + R``,
``K = P⁻ Hᵀ S⁻¹``, the Joseph form ``P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ``,
``x⁺ = x⁻ + K e``, ``NIS = eᵀ S⁻¹ e`` — in chunks of :data:`CHUNK` systems
held "structure of arrays" (``M[i, j, system]``), so every innermost loop runs
over independent systems and vectorises, and the scratch stays in the L1 cache —
instead of ~20 numpy calls on ``(B, n, n)`` arrays. The inverse of ``S`` is
the closed form for ``m ≤ 2`` (PD test ``s11 > 0, det > 0``, as
:func:`~._kalman_linalg.spd_inverse`) and
Cholesky otherwise; a system whose ``S`` is not positive definite gets NaN, a
system with ``valid`` False keeps ``x⁻, P⁻`` and a NaN NIS — the numpy path's
rules. The numpy path is the oracle (``tests/estimators/test_compiled.py``; equal
to round-off: BLAS sums in another order).
"""

from __future__ import annotations

import numpy as np

from ._compiled import kernel

#: systems per chunk: the chunk's scratch (~15 matrices of n x n x CHUNK floats) stays in L1
CHUNK = 64


def _mul_loops(A: np.ndarray, B: np.ndarray, C: np.ndarray, nb: int, transpose: bool
               ) -> None:
    """``C = A B`` (or ``A Bᵀ``) for each of the first ``nb`` systems of SoA blocks."""
    for i in range(C.shape[0]):
        for j in range(C.shape[1]):
            c = C[i, j]
            for t in range(nb):
                c[t] = 0.0
            for k in range(A.shape[1]):
                a = A[i, k]
                bk = B[j, k] if transpose else B[k, j]
                for t in range(nb):
                    c[t] += a[t] * bk[t]


def _symmetrize_sum_loops(A: np.ndarray, B: np.ndarray, nb: int) -> None:
    """``A = ((A + B) + (A + B)ᵀ) / 2`` in place on SoA blocks."""
    for i in range(A.shape[0]):
        for j in range(i + 1):
            aij, aji, bij, bji = A[i, j], A[j, i], B[i, j], B[j, i]
            for t in range(nb):
                v = 0.5 * ((aij[t] + bij[t]) + (aji[t] + bji[t]))
                aij[t] = v
                aji[t] = v


def _cholesky_loops(S: np.ndarray, L: np.ndarray, ok: np.ndarray, nb: int) -> None:
    """The lower Cholesky factor ``L`` (lower triangle written) of symmetric SoA blocks
    ``S`` (lower triangle read); ``ok`` False where ``S`` is not positive definite (its
    pivot is then taken as 1 so the loop runs on; the caller discards that factor)."""
    m = S.shape[0]
    for t in range(nb):
        ok[t] = True
    for j in range(m):
        for t in range(nb):
            d = S[j, j, t]
            for k in range(j):
                d -= L[j, k, t] * L[j, k, t]
            ok[t] = ok[t] and d > 0.0
            L[j, j, t] = np.sqrt(d) if d > 0.0 else 1.0
        for i in range(j + 1, m):
            for t in range(nb):
                c = S[i, j, t]
                for k in range(j):
                    c -= L[i, k, t] * L[j, k, t]
                L[i, j, t] = c / L[j, j, t]


_cholesky = kernel(_cholesky_loops)


def _spd_inverse_loops(S: np.ndarray, W: np.ndarray, L: np.ndarray, ok: np.ndarray,
                       nb: int) -> None:
    """``W = S⁻¹`` for symmetric SoA blocks ``S`` (lower triangle read); ``ok`` False where
    ``S`` is not positive definite (closed form for m <= 2, else Cholesky)."""
    m = S.shape[0]
    if m == 1:
        for t in range(nb):
            ok[t] = S[0, 0, t] > 0.0
            W[0, 0, t] = 1.0 / S[0, 0, t]
        return
    if m == 2:
        for t in range(nb):
            a, b, d = S[0, 0, t], 0.5 * (S[0, 1, t] + S[1, 0, t]), S[1, 1, t]
            det = a * d - b * b
            ok[t] = a > 0.0 and det > 0.0
            W[0, 0, t] = d / det
            W[1, 1, t] = a / det
            W[0, 1, t] = -b / det
            W[1, 0, t] = -b / det
        return
    _cholesky(S, L, ok, nb)
    for col in range(m):                                 # W = L⁻ᵀ L⁻¹, column by column
        for i in range(m):                               # forward: L z = e_col
            for t in range(nb):
                c = 1.0 if i == col else 0.0
                for k in range(i):
                    c -= L[i, k, t] * W[k, col, t]
                W[i, col, t] = c / L[i, i, t]
        for i in range(m - 1, -1, -1):                   # backward: Lᵀ w = z
            for t in range(nb):
                c = W[i, col, t]
                for k in range(i + 1, m):
                    c -= L[k, i, t] * W[k, col, t]
                W[i, col, t] = c / L[i, i, t]


def _load_loops(M: np.ndarray, b0: int, nb: int, out: np.ndarray) -> None:
    """Systems ``b0 .. b0+nb`` of ``M`` (``(B, r, c)``, or ``(1, r, c)`` shared by all) into
    the SoA block ``out``."""
    shared = M.shape[0] == 1
    for t in range(nb):
        Mb = M[0 if shared else b0 + t]
        for i in range(M.shape[1]):
            for j in range(M.shape[2]):
                out[i, j, t] = Mb[i, j]


def _cholesky_rows(S: np.ndarray) -> np.ndarray:
    n_b, m, _ = S.shape
    L = np.zeros_like(S)
    c = CHUNK
    Ss, Ls, ok = np.empty((m, m, c)), np.empty((m, m, c)), np.empty(c, dtype=np.bool_)
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        _load(S, b0, nb, Ss)
        _cholesky(Ss, Ls, ok, nb)
        for t in range(nb):
            for i in range(m):
                for j in range(i + 1):
                    L[b0 + t, i, j] = Ls[i, j, t] if ok[t] else np.nan
                if not ok[t]:
                    for j in range(i + 1, m):
                        L[b0 + t, i, j] = np.nan
    return L


_mul = kernel(_mul_loops)
_symmetrize_sum = kernel(_symmetrize_sum_loops)
_spd_inverse = kernel(_spd_inverse_loops)
_load = kernel(_load_loops)


def _predict_update(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray,
                    e: np.ndarray, H: np.ndarray, R: np.ndarray, valid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b, n = x.shape
    m = e.shape[1]
    x_new = np.empty_like(x)
    P_new = np.empty((n_b, n, n))
    nis = np.empty(n_b)
    c = CHUNK
    Ps, Fs, FP, Pm = (np.empty((n, n, c)), np.empty((n, n, c)), np.empty((n, n, c)),
                      np.empty((n, n, c)))
    Qs, IKH, T, U = np.empty((n, n, c)), np.empty((n, n, c)), np.empty((n, n, c)), \
        np.empty((n, n, c))
    Hs, PHt, K, KR = np.empty((m, n, c)), np.empty((n, m, c)), np.empty((n, m, c)), \
        np.empty((n, m, c))
    Rs, S, W, L = np.empty((m, m, c)), np.empty((m, m, c)), np.empty((m, m, c)), \
        np.ones((m, m, c))
    ok = np.empty(c, dtype=np.bool_)
    Q1 = Q.reshape(1, n, n)
    _load(Q1, 0, c, Qs)
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        _load(P, b0, nb, Ps)
        _load(F, b0, nb, Fs)
        _load(H, b0, nb, Hs)
        _load(R, b0, nb, Rs)
        _mul(Ps, Fs, FP, nb, True)                       # P Fᵀ
        _mul(Fs, FP, Pm, nb, False)                      # F P Fᵀ
        _symmetrize_sum(Pm, Qs, nb)                      # + Q, symmetrised
        _mul(Pm, Hs, PHt, nb, True)                      # P⁻ Hᵀ
        _mul(Hs, PHt, S, nb, False)                      # H P⁻ Hᵀ
        for i in range(m):                               # S = H P⁻ Hᵀ + R
            for j in range(m):
                for t in range(nb):
                    S[i, j, t] += Rs[i, j, t]
        _spd_inverse(S, W, L, ok, nb)
        _mul(PHt, W, K, nb, False)                       # K = P⁻ Hᵀ S⁻¹
        _mul(K, Hs, IKH, nb, False)                      # I − K H
        for i in range(n):
            for j in range(n):
                for t in range(nb):
                    IKH[i, j, t] = (1.0 if i == j else 0.0) - IKH[i, j, t]
        _mul(Pm, IKH, T, nb, True)                       # P⁻ (I − K H)ᵀ
        _mul(IKH, T, U, nb, False)                       # (I − K H) P⁻ (I − K H)ᵀ
        _mul(K, Rs, KR, nb, False)
        _mul(KR, K, T, nb, True)                         # K R Kᵀ
        _symmetrize_sum(U, T, nb)                        # Joseph form, symmetrised
        for t in range(nb):
            b = b0 + t
            if not valid[b]:                             # no measurement: keep x⁻, P⁻
                for i in range(n):
                    x_new[b, i] = x[b, i]
                    for j in range(n):
                        P_new[b, i, j] = Pm[i, j, t]
                nis[b] = np.nan
            elif not ok[t]:                              # S not positive definite
                x_new[b] = np.nan
                P_new[b] = np.nan
                nis[b] = np.nan
            else:
                q = 0.0                                  # NIS = eᵀ S⁻¹ e
                for i in range(m):
                    for k in range(m):
                        q += e[b, i] * W[i, k, t] * e[b, k]
                nis[b] = q
                for i in range(n):                       # x⁺ = x⁻ + K e
                    v = 0.0
                    for k in range(m):
                        v += K[i, k, t] * e[b, k]
                    x_new[b, i] = x[b, i] + v
                    for j in range(n):
                        P_new[b, i, j] = U[i, j, t]
    return x_new, P_new, nis


#: ``predict_update(x⁻ (B, n), P (B or 1, n, n), F (B or 1, n, n), Q (n, n), e (B, m),
#: H (B or 1, m, n), R (B or 1, m, m), valid (B,)) -> (x⁺, P⁺, NIS)``; ``None`` without numba
predict_update = kernel(_predict_update)
#: ``cholesky_rows(S (B, m, m)) -> L`` (lower), all-NaN where ``S`` is not positive definite:
#: :func:`~._kalman_linalg.cholesky` system by system; ``None`` without numba
cholesky_rows = kernel(_cholesky_rows)


def _spd_inverse_batch(S: np.ndarray) -> np.ndarray:
    n_b, m, _ = S.shape
    W = np.empty((n_b, m, m))
    c = CHUNK
    Ss, Ws, L, ok = np.empty((m, m, c)), np.empty((m, m, c)), np.ones((m, m, c)), \
        np.empty(c, dtype=np.bool_)
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        _load(S, b0, nb, Ss)
        _spd_inverse(Ss, Ws, L, ok, nb)
        for t in range(nb):
            for i in range(m):
                for j in range(m):
                    W[b0 + t, i, j] = Ws[i, j, t] if ok[t] else np.nan
    return W


#: ``spd_inverse_batch(S (B, m, m)) -> S⁻¹``, all-NaN where ``S`` is not positive definite:
#: :func:`~._kalman_linalg.spd_inverse` (closed form for m <= 2, else Cholesky) in one
#: compiled pass; ``None`` without numba
spd_inverse_batch = kernel(_spd_inverse_batch)
