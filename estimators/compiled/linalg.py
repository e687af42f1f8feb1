"""Small dense algebra on blocks of systems, the pieces every compiled twin is made of.

A *block* holds up to :data:`CHUNK` systems "structure of arrays": ``M[i, j, t]`` is
entry ``(i, j)`` of system ``t``, so every innermost loop runs over independent
systems (it vectorises) and a block's scratch stays in the L1 cache. A single system
is a block of one. The formulas are those of the numpy references in
:mod:`~fir_gym.estimators._kalman_linalg` (closed-form inverse for ``m <= 2`` with
the PD test ``s11 > 0, det > 0``, Cholesky otherwise, ``(A + Aᵀ)/2`` symmetrisation).
"""

from __future__ import annotations

import numpy as np

from . import jit

#: systems per block: ~15 scratch matrices of n x n x CHUNK floats stay in L1
CHUNK = 64


@jit
def load(M: np.ndarray, b0: int, nb: int, out: np.ndarray) -> None:
    """Systems ``b0 .. b0+nb`` of ``M`` (``(B, r, c)``, or ``(1, r, c)`` shared by all) into
    the block ``out``."""
    shared = M.shape[0] == 1
    for t in range(nb):
        b = 0 if shared else b0 + t
        for i in range(M.shape[1]):
            for j in range(M.shape[2]):
                out[i, j, t] = M[b, i, j]


@jit
def store(block: np.ndarray, b0: int, nb: int, M: np.ndarray) -> None:
    """The block's ``nb`` systems into rows ``b0 ..`` of ``M`` (``(B, r, c)``)."""
    for t in range(nb):
        for i in range(M.shape[1]):
            for j in range(M.shape[2]):
                M[b0 + t, i, j] = block[i, j, t]


@jit
def mul(A: np.ndarray, B: np.ndarray, C: np.ndarray, nb: int, transpose: bool) -> None:
    """``C = A B`` (or ``A Bᵀ``) for each of the first ``nb`` systems of blocks."""
    for i in range(C.shape[0]):
        for j in range(C.shape[1]):
            for t in range(nb):
                C[i, j, t] = 0.0
            for k in range(A.shape[1]):
                if transpose:
                    for t in range(nb):
                        C[i, j, t] += A[i, k, t] * B[j, k, t]
                else:
                    for t in range(nb):
                        C[i, j, t] += A[i, k, t] * B[k, j, t]


@jit
def symmetrize_sum(A: np.ndarray, B: np.ndarray, nb: int) -> None:
    """``A = ((A + B) + (A + B)ᵀ) / 2`` in place on blocks."""
    for i in range(A.shape[0]):
        for j in range(i + 1):
            for t in range(nb):
                v = 0.5 * ((A[i, j, t] + B[i, j, t]) + (A[j, i, t] + B[j, i, t]))
                A[i, j, t] = v
                A[j, i, t] = v


@jit
def cholesky(S: np.ndarray, L: np.ndarray, ok: np.ndarray, nb: int) -> None:
    """The lower Cholesky factor ``L`` (lower triangle written) of symmetric blocks ``S``
    (lower triangle read); ``ok`` False where ``S`` is not positive definite (its pivot is
    then taken as 1 so the loop runs on; the caller discards that factor)."""
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


@jit
def spd_inverse(S: np.ndarray, W: np.ndarray, L: np.ndarray, ok: np.ndarray, nb: int
                ) -> None:
    """``W = S⁻¹`` for symmetric blocks ``S`` (lower triangle read); ``ok`` False where ``S``
    is not positive definite (closed form for m <= 2, else Cholesky and two triangular
    solves per column)."""
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
    cholesky(S, L, ok, nb)
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


@jit
def logdet_of_inverse(W: np.ndarray, col: int) -> float:
    """``log det S`` from ``W = S⁻¹`` (block column ``col``, symmetric positive definite):
    ``−log det W``, closed form for m <= 2, else ``−2 Σ log Lᵢᵢ`` of W's Cholesky factor;
    NaN where W is not positive definite."""
    m = W.shape[0]
    if m == 1:
        return -np.log(W[0, 0, col]) if W[0, 0, col] > 0.0 else np.nan
    if m == 2:
        a, b, d = W[0, 0, col], 0.5 * (W[0, 1, col] + W[1, 0, col]), W[1, 1, col]
        det = a * d - b * b
        return -np.log(det) if a > 0.0 and det > 0.0 else np.nan
    L = np.zeros((m, m))
    total = 0.0
    for j in range(m):
        d = W[j, j, col]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return np.nan
        L[j, j] = np.sqrt(d)
        total += np.log(L[j, j])
        for i in range(j + 1, m):
            c = 0.5 * (W[i, j, col] + W[j, i, col])
            for k in range(j):
                c -= L[i, k] * L[j, k]
            L[i, j] = c / L[j, j]
    return -2.0 * total


PIVOT_EPS = 4.0 * float(np.finfo(np.float64).eps)


@jit
def psd_factor(P: np.ndarray, L: np.ndarray, nb: int) -> None:
    """The factor ``L`` (every entry written) of symmetric blocks ``P`` (lower triangle read by
    the Cholesky pass): the semidefinite Cholesky factor (a pivot at or below ``4 n ε P_jj``
    is zero, with its column) where ``P`` is PSD up to round-off, ``V Λ₊^½`` of the nearest
    PSD matrix where a pivot is below ``−4 n ε P_jj`` — the twin of
    :func:`~fir_gym.estimators._kalman_linalg.psd_factor`. The systems run innermost, as in
    :func:`cholesky`."""
    n = P.shape[0]
    indefinite = np.zeros(nb, dtype=np.bool_)
    keep = np.empty(nb, dtype=np.bool_)
    for i in range(n):
        for j in range(n):
            for t in range(nb):
                L[i, j, t] = 0.0
    for j in range(n):
        for t in range(nb):
            d = P[j, j, t]
            for k in range(j):
                d -= L[j, k, t] * L[j, k, t]
            tol = (PIVOT_EPS * n) * abs(P[j, j, t])
            keep[t] = d > tol
            indefinite[t] = indefinite[t] or not d >= -tol
            L[j, j, t] = np.sqrt(d) if keep[t] else 0.0
        for i in range(j + 1, n):
            for t in range(nb):
                c = P[i, j, t]
                for k in range(j):
                    c -= L[i, k, t] * L[j, k, t]
                L[i, j, t] = c / L[j, j, t] if keep[t] else 0.0
    for t in range(nb):
        if indefinite[t]:                            # the nearest PSD matrix's factor
            M = np.empty((n, n))
            finite = True
            for i in range(n):
                for j in range(n):
                    M[i, j] = 0.5 * (P[i, j, t] + P[j, i, t])
                    finite = finite and np.isfinite(M[i, j])
            if not finite:
                for i in range(n):
                    for j in range(n):
                        L[i, j, t] = np.nan
                continue
            lam, V = np.linalg.eigh(M)
            for i in range(n):
                for j in range(n):
                    L[i, j, t] = V[i, j] * np.sqrt(max(lam[j], 0.0))


@jit
def gram_lower(M: np.ndarray, N: np.ndarray, out: np.ndarray, nb: int) -> None:
    """``out = M Mᵀ + N Nᵀ`` on blocks, lower triangle computed and mirrored: exactly
    symmetric, positive semidefinite by construction (the twin of
    :func:`~fir_gym.estimators._kalman_linalg.gram`)."""
    n = out.shape[0]
    for i in range(n):
        for j in range(i + 1):
            for t in range(nb):
                c = 0.0
                for k in range(M.shape[1]):
                    c += M[i, k, t] * M[j, k, t]
                d = 0.0
                for k in range(N.shape[1]):
                    d += N[i, k, t] * N[j, k, t]
                out[i, j, t] = c + d
                out[j, i, t] = c + d


@jit
def factored_joseph(Pm: np.ndarray, Hs: np.ndarray, Rs: np.ndarray, K: np.ndarray, nb: int,
                    IKH: np.ndarray, T: np.ndarray, U: np.ndarray, KR: np.ndarray) -> None:
    """``U = P⁺ = M Mᵀ + N Nᵀ``, ``M = (I − K H) L``, ``N = K L_R`` on blocks (``L``, ``L_R``
    the semidefinite factors of ``P⁻``, ``R``): the Joseph form from factors, the twin of
    :func:`~fir_gym.estimators._kalman_linalg.factored_joseph`. ``IKH``, ``T`` (``n x n``)
    and ``KR`` (``n x m``) are scratch."""
    n, m = Pm.shape[0], Hs.shape[0]
    mul(K, Hs, IKH, nb, False)                       # I − K H
    for i in range(n):
        for j in range(n):
            for t in range(nb):
                IKH[i, j, t] = (1.0 if i == j else 0.0) - IKH[i, j, t]
    psd_factor(Pm, T, nb)                            # L
    mul(IKH, T, U, nb, False)                        # M = (I − K H) L, into U for now
    LR = np.empty((m, m, nb))
    psd_factor(Rs, LR, nb)
    mul(K, LR, KR, nb, False)                        # N = K L_R
    for i in range(n):                               # M out of U (gram writes U)
        for j in range(n):
            for t in range(nb):
                T[i, j, t] = U[i, j, t]
    gram_lower(T, KR, U, nb)


@jit
def psd_rebuild(P: np.ndarray, T: np.ndarray, nb: int) -> None:
    """``P ← L Lᵀ`` with ``L`` (into ``T``) the semidefinite factor of ``P`` (lower triangle
    read), in place on blocks: symmetric PSD by construction — the twin of
    :func:`~fir_gym.estimators._kalman_linalg.psd_rebuild`."""
    n = P.shape[0]
    psd_factor(P, T, nb)
    for i in range(n):
        for j in range(i + 1):
            for t in range(nb):
                c = 0.0
                for k in range(n):
                    c += T[i, k, t] * T[j, k, t]
                P[i, j, t] = c
                P[j, i, t] = c
