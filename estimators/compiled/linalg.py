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
