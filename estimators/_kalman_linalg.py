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


#: the pivot tolerance of :func:`psd_factor`, in units of machine epsilon times ``n``
_PIVOT_EPS = 4.0 * float(np.finfo(np.float64).eps)


def psd_factor(P: FloatArray) -> FloatArray:
    """A factor ``L`` with ``L Lᵀ = P`` of a batch of symmetric ``P`` (B, n, n) that is PSD up
    to round-off — or, where it is not, of its nearest PSD matrix.

    The semidefinite Cholesky factor (Higham, *Accuracy and Stability of Numerical
    Algorithms*, 2002, §10.3): a pivot at or below ``4 n ε P_jj`` is taken as zero, with its
    column — a change of ``P`` no larger than its round-off. A pivot below ``−4 n ε P_jj``
    means ``P`` is indefinite beyond round-off; that system's factor is then ``V Λ₊^½`` from
    its eigen-decomposition ``P = V Λ Vᵀ`` with the negative eigenvalues set to zero, the
    nearest PSD matrix in the Frobenius norm (Higham 1988). Only the lower triangle of ``P``
    is read by the Cholesky pass."""
    n = P.shape[-1]
    L = np.zeros_like(P)
    tol = (_PIVOT_EPS * n) * np.abs(np.diagonal(P, axis1=-2, axis2=-1))
    indefinite = np.zeros(P.shape[0], bool)
    for j in range(n):
        Lj = L[:, j, :j]
        d = P[:, j, j] - np.einsum("bk,bk->b", Lj, Lj) if j else P[:, j, j]
        keep = d > tol[:, j]
        indefinite |= ~(d >= -tol[:, j])                   # NaN counts as indefinite
        ljj = np.sqrt(np.where(keep, d, 1.0))
        L[:, j, j] = np.where(keep, ljj, 0.0)
        if j + 1 < n:
            col = P[:, j + 1:, j] - (L[:, j + 1:, :j] @ Lj[:, :, None])[:, :, 0] if j else \
                P[:, j + 1:, j]
            L[:, j + 1:, j] = np.where(keep[:, None], col / ljj[:, None], 0.0)
    if indefinite.any():
        Pi = P[indefinite]
        Pi = 0.5 * (Pi + Pi.swapaxes(-1, -2))
        finite = np.isfinite(Pi).all(axis=(-2, -1))
        lam, V = np.linalg.eigh(np.where(finite[:, None, None], Pi, 0.0))
        Li = V * np.sqrt(np.maximum(lam, 0.0))[:, None, :]
        L[indefinite] = np.where(finite[:, None, None], Li, np.nan)
    return L


def gram(*factors: FloatArray) -> FloatArray:
    """``Σ M Mᵀ`` over the batched factors ``M`` (B, n, ·): symmetric positive semidefinite
    by construction (a sum of Gram matrices; the upper triangle is the lower one's mirror,
    so it is exactly symmetric, and rounding leaves its eigenvalues above ``−γ ‖M‖²``)."""
    P = sum(mul_t(M, M) for M in factors)
    assert isinstance(P, np.ndarray)
    lower = np.tril(P)
    return lower + np.tril(P, -1).swapaxes(-1, -2)


def factored_joseph(P: FloatArray, H: FloatArray, R: FloatArray, K: FloatArray) -> FloatArray:
    """The Joseph-form update ``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` computed from factors,
    ``P⁺ = M Mᵀ + N Nᵀ`` with ``M = (I − K H) L``, ``N = K L_R``, ``L Lᵀ = P``, ``L_R L_Rᵀ = R``
    (:func:`psd_factor`, :func:`gram`): positive semidefinite and exactly symmetric by
    construction for any gain ``K`` and any ``P`` (a ``P`` that round-off left indefinite
    is replaced by its nearest PSD matrix, :func:`psd_factor`). The plain Joseph product
    subtracts terms of the size of ``‖P‖`` to leave ``P⁺``: with ``P0 = 1e12 I`` and
    ``R = 1e-12`` its round-off (``ε ‖P‖ ≈ 1e-4``) exceeds the exact ``P⁺ ≈ R`` and leaves
    the PSD cone; the factor ``M`` is formed with the same round-off relative to ``‖L‖ =
    ‖P‖^½`` only, and ``M Mᵀ`` is a Gram matrix (docs/architecture.md#covariance-updates).
    ``H, R`` 2-D (shared) or batched; ``P`` may be a batch of one shared by many systems
    (then so is ``K``)."""
    n = P.shape[-1]
    L = psd_factor(P)
    IKH = eye(n) - (rmul(K, H) if H.ndim == 2 else K @ H)
    LR = psd_factor(np.broadcast_to(R, (1,) + R.shape) if R.ndim == 2 else R)
    N = rmul(K, LR[0]) if R.ndim == 2 else K @ LR
    return gram(IKH @ L, N)


def psd_rebuild(P: FloatArray) -> FloatArray:
    """``L Lᵀ`` of the factor of ``P`` (:func:`psd_factor`): ``P`` itself (to round-off) when
    it is positive semidefinite, else its nearest PSD matrix — symmetric PSD by
    construction. The repair of an update that cannot be written as a Gram matrix (the
    UKF's ``P⁻ − K S Kᵀ``, the Riccati flows of paper 002)."""
    return gram(psd_factor(P))
