"""Small dense linear algebra of the numpy references, vectorised over a batch axis.

For the tiny matrices of a filter (n ≲ 10) numpy's per-call overhead and its
batched ``matmul``/``linalg`` loops dominate; these helpers use one BLAS call
where a factor is shared by the batch, and closed forms/column loops over the
batch for factorisations of small matrices. Their compiled twins, on blocks of
systems, are in :mod:`~fir_gym.estimators.compiled.linalg`.
"""

from __future__ import annotations

import numpy as np

from ._validation import FloatArray


def rmul(X: FloatArray, M: FloatArray) -> FloatArray:
    """``X @ M`` for a constant 2-D ``M`` and a batched ``X``, as one BLAS call."""
    if X.ndim == 2:
        return np.dot(X, M)
    if X.shape[0] < 8:                      # tiny batch: matmul's overhead is lower
        return X @ M
    return np.dot(X.reshape(-1, X.shape[-1]), M).reshape(X.shape[:-1] + (M.shape[1],))


def mul_t(A: FloatArray, B: FloatArray) -> FloatArray:
    """``A @ Bᵀ`` over a batch; the transpose is made contiguous first (numpy's batched
    ``matmul`` falls back to a slow loop for a transposed operand: 2-3x the copy + BLAS)."""
    return A @ np.ascontiguousarray(B.mT)


_EYE: dict[int, FloatArray] = {}


def eye(n: int) -> FloatArray:
    """A cached read-only identity matrix."""
    I = _EYE.get(n)
    if I is None:
        I = _EYE[n] = np.eye(n)
        I.setflags(write=False)
    return I


def constant_or_batch(M: FloatArray) -> FloatArray:
    """``M[0]`` when ``M`` is a batch made by ``np.broadcast_to`` (stride 0), else ``M``."""
    return M[0] if M.ndim == 3 and M.strides[0] == 0 else M


def as_batch(M: FloatArray) -> FloatArray:
    """A C-contiguous ``(B or 1, r, c)`` view or copy of a 2-D or batched ``M`` (a stride-0
    batch made by ``np.broadcast_to`` becomes its one row): the compiled kernels' layout."""
    M = constant_or_batch(M)
    return np.ascontiguousarray(M[None] if M.ndim == 2 else M)


def cholesky(S: FloatArray) -> FloatArray:
    """Lower Cholesky factor of a batch ``S`` (B, m, m); NaN rows where ``S`` is not PD.

    Small ``m`` (or large batches) use a column-by-column factorisation
    vectorised over the batch; otherwise ``numpy.linalg.cholesky``. Only the
    lower triangle of ``S`` is read. A system whose ``S`` is not positive
    definite gets an all-NaN factor, so callers flag it instead of raising.
    """
    n_b, m, _ = S.shape
    if m > 3 and n_b < 32:
        try:
            return np.linalg.cholesky(S).astype(np.float64, copy=False)
        except np.linalg.LinAlgError:
            out = np.full_like(S, np.nan)
            for b in range(n_b):
                try:
                    out[b] = np.linalg.cholesky(S[b])
                except np.linalg.LinAlgError:
                    pass
            return out
    L = np.zeros_like(S)
    for j in range(m):
        Lj = L[:, j, :j]
        d = S[:, j, j] - np.einsum("bk,bk->b", Lj, Lj) if j else S[:, j, j]
        ljj = np.sqrt(np.where(d > 0.0, d, np.nan))
        L[:, j, j] = ljj
        if j + 1 < m:
            col = S[:, j + 1:, j] - (L[:, j + 1:, :j] @ Lj[:, :, None])[:, :, 0] if j else \
                S[:, j + 1:, j]
            L[:, j + 1:, j] = col / ljj[:, None]
    return L


def cho_solve(L: FloatArray, Y: FloatArray) -> FloatArray:
    """Solve ``L Lᵀ X = Y`` for a batch of lower factors ``L`` (B, m, m) and ``Y`` (B, m, k)."""
    m = L.shape[1]
    if m == 1:
        return Y / (L * L)
    if m > 3:
        Z = np.linalg.solve(L, Y)
        return np.linalg.solve(L.mT, Z)
    Z = np.empty_like(Y)
    for i in range(m):                      # forward: L Z = Y
        acc = Y[:, i] - np.einsum("bj,bjk->bk", L[:, i, :i], Z[:, :i]) if i else Y[:, i]
        Z[:, i] = acc / L[:, i, i, None]
    X = np.empty_like(Y)
    for i in range(m - 1, -1, -1):          # backward: Lᵀ X = Z
        acc = Z[:, i] - np.einsum("bj,bjk->bk", L[:, i + 1:, i], X[:, i + 1:]) if i < m - 1 \
            else Z[:, i]
        X[:, i] = acc / L[:, i, i, None]
    return X


def symmetrize(P: FloatArray) -> FloatArray:
    """``(P + Pᵀ) / 2`` over the last two axes."""
    P = P + P.mT
    P *= 0.5
    return P


def spd_inverse(S: FloatArray) -> FloatArray:
    """``S⁻¹`` of a batch of symmetric positive-definite ``S``; NaN where ``S`` is not PD.

    ``m <= 2`` in closed form (for 2x2, Cramer's rule is forward stable: Higham,
    *Accuracy and Stability of Numerical Algorithms*, 2002, §1.10.1), with the
    PD test ``s11 > 0, det > 0``; larger ``m`` by two triangular solves with the
    Cholesky factor (:func:`cholesky`, :func:`cho_solve`).
    """
    m = S.shape[1]
    if m == 1:
        return np.where(S > 0.0, 1.0 / S, np.nan)
    if m == 2:
        a, b, d = S[:, 0, 0], 0.5 * (S[:, 0, 1] + S[:, 1, 0]), S[:, 1, 1]
        det = a * d - b * b
        det = np.where((a > 0.0) & (det > 0.0), det, np.nan)
        W = np.empty_like(S)
        W[:, 0, 0] = d / det
        W[:, 1, 1] = a / det
        W[:, 0, 1] = W[:, 1, 0] = -b / det
        return W
    return cho_solve(cholesky(S), np.broadcast_to(eye(m), S.shape))


def logdet_of_inverse(W: FloatArray, n_b: int) -> FloatArray:
    """``log det S`` of each system from ``W = S⁻¹`` (``(1 | B, m, m)``): ``−log det W``
    (LU, :func:`numpy.linalg.slogdet`), NaN where ``W`` is not finite or not positive
    definite; ``(B,)``, a shared ``W`` broadcast to the ``n_b`` systems."""
    with np.errstate(all="ignore"):
        sign, logdet = np.linalg.slogdet(W)
    out = np.where(sign > 0, -logdet, np.nan)
    return np.array(np.broadcast_to(out, (n_b,)))
