""":class:`~fir_gym.estimators._fir_bank.WindowBank`'s operations, compiled.

The numpy reference makes ~6 passes over the bank ``Z`` (``B x 2n x W x (2n+1)``) per
update, with temporaries of its size; these loops make one, in place, system by
system and window by window, with the same formulas:

* :func:`predict` — ``x̄ ← A x̄ (+ B u)``, ``T ← A T``, ``P ← A P Aᵀ (+ G Q Gᵀ)``;
* :func:`update` — ``r = C [P | T | x̄] − [0 | 0 | y]``, ``Σ = C P Cᵀ + R``,
  ``Z −= [K; W] ⊗ r`` with ``[K; W] = [P Cᵀ; (C T)ᵀ] Σ⁻¹`` (``Σ⁻¹`` in closed form for
  ``p <= 2``, by Cholesky for larger ``p``);
* :func:`estimate` — the read-out of one window, ``x̄ + T V b`` and ``P + T V Tᵀ`` (or the
  smoother's ``x_ref + V b`` and ``V``), ``V = F⁻¹`` or, with a prior ``Π0``, ``(I + Π0
  F)⁻¹ Π0``, with the regularity test of :func:`~fir_gym.estimators._fir_bank.spd_inverse`.

Arguments come in one layout (leading axes of length 1 are shared): ``A (B|1, W|1, n,
n)``, ``C (B|1, W|1, p, n)``, ``y (B, W|1, p)``, ``Q (B|1, n, n)``, ``Bu (B, W|1, n)``;
``size`` is a tuple of ``n`` zeros (so ``n`` is a compile-time constant). The numpy
reference is the oracle (``tests/estimators/test_compiled.py``; equal to round-off:
BLAS sums in another order).
"""

from __future__ import annotations

import numpy as np

from . import jit


@jit
def cho_solve(S: np.ndarray, L: np.ndarray, G: np.ndarray) -> None:
    """``G ← S⁻¹ G`` for a symmetric positive-definite ``S`` (``L`` receives its factor);
    NaN where ``S`` is not positive definite."""
    p = S.shape[0]
    for j in range(p):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        L[j, j] = np.sqrt(d) if d > 0.0 else np.nan
        for i in range(j + 1, p):
            c = S[i, j]
            for k in range(j):
                c -= L[i, k] * L[j, k]
            L[i, j] = c / L[j, j]
    for col in range(G.shape[1]):
        for i in range(p):                              # forward: L z = g
            c = G[i, col]
            for k in range(i):
                c -= L[i, k] * G[k, col]
            G[i, col] = c / L[i, i]
        for i in range(p - 1, -1, -1):                  # backward: Lᵀ x = z
            c = G[i, col]
            for k in range(i + 1, p):
                c -= L[k, i] * G[k, col]
            G[i, col] = c / L[i, i]


@jit
def times_rows(M: np.ndarray, Z: np.ndarray, b: int, out: np.ndarray,
               size: tuple[int, ...]) -> None:
    """``out[w] = M_w [P | T | x̄]_w`` for every window ``w`` of system ``b``: the window's
    matrix (``M (B|1, W|1, k, n)``) times the first ``n`` rows of its block of ``Z``."""
    n = len(size)
    m = 2 * n + 1
    mb = b if M.shape[0] > 1 else 0
    Zb = Z[b]
    for w in range(out.shape[0]):
        Mw = M[mb, w if M.shape[1] > 1 else 0]
        Ow = out[w]
        for i in range(Mw.shape[0]):
            for j in range(m):
                Ow[i, j] = 0.0
            for k in range(n):
                c = Mw[i, k]
                for j in range(m):
                    Ow[i, j] += c * Zb[k, w, j]


@jit
def predict(Z: np.ndarray, A: np.ndarray, Bu: np.ndarray, Q: np.ndarray,
            has_Bu: bool, has_Q: bool, size: tuple[int, ...]) -> None:
    """``x̄ ← A x̄ (+ B u)``, ``T ← A T``, ``P ← A P Aᵀ (+ G Q Gᵀ)`` of every window, in place."""
    n_b, _, W, _ = Z.shape
    n = len(size)
    m = 2 * n + 1
    AZ = np.empty((W, n, m))
    for b in range(n_b):
        ab, qb = b if A.shape[0] > 1 else 0, b if Q.shape[0] > 1 else 0
        times_rows(A, Z, b, AZ, size)                       # A [P | T | x̄]
        for w in range(W):
            aw = w if A.shape[1] > 1 else 0
            for i in range(n):
                for j in range(m):
                    Z[b, i, w, j] = AZ[w, i, j]
            if has_Q:                                       # (A P) Aᵀ + G Q Gᵀ
                for i in range(n):
                    for j in range(n):
                        c = 0.0
                        for k in range(n):
                            c += AZ[w, i, k] * A[ab, aw, j, k]
                        Z[b, i, w, j] = c + Q[qb, i, j]
            if has_Bu:
                bw = w if Bu.shape[1] > 1 else 0
                for i in range(n):
                    Z[b, i, w, m - 1] += Bu[b, bw, i]


@jit
def update(Z: np.ndarray, C: np.ndarray, R: np.ndarray, y: np.ndarray,
           valid: np.ndarray, size: tuple[int, ...]) -> None:
    """The measurement update of every window of every usable system, in place."""
    n_b, _, W, _ = Z.shape
    n = len(size)
    n2 = 2 * n
    m = n2 + 1
    p = C.shape[-2]
    CZ = np.empty((W, p, m))
    g = np.empty((p, n2))
    Sig, L = np.empty((p, p)), np.empty((p, p))
    for b in range(n_b):
        if not valid[b if valid.shape[0] > 1 else 0]:
            continue
        cb = b if C.shape[0] > 1 else 0
        times_rows(C, Z, b, CZ, size)                       # C [P | T | x̄] of every window
        for w in range(W):
            cw, yw = w if C.shape[1] > 1 else 0, w if y.shape[1] > 1 else 0
            r = CZ[w]                                       # r = C [P | T | x̄] − [0 | 0 | y]
            for q in range(p):
                r[q, m - 1] -= y[b, yw, q]
            if p == 1:                                      # [K; W]ᵀ = Σ⁻¹ [C P | C T]
                s = 0.0
                for k in range(n):
                    s += r[0, k] * C[cb, cw, 0, k]
                s += R[0, 0]
                for i in range(n2):
                    g[0, i] = r[0, i] / s
            elif p == 2:                                    # Σ = (C P) Cᵀ + R, 2 x 2
                s00 = 0.0
                s01 = 0.0
                s10 = 0.0
                s11 = 0.0
                for k in range(n):
                    s00 += r[0, k] * C[cb, cw, 0, k]
                    s01 += r[0, k] * C[cb, cw, 1, k]
                    s10 += r[1, k] * C[cb, cw, 0, k]
                    s11 += r[1, k] * C[cb, cw, 1, k]
                s00 += R[0, 0]
                s01 += R[0, 1]
                s10 += R[1, 0]
                s11 += R[1, 1]
                det = s00 * s11 - s01 * s10
                for i in range(n2):
                    g[0, i] = (s11 * r[0, i] - s01 * r[1, i]) / det
                    g[1, i] = (s00 * r[1, i] - s10 * r[0, i]) / det
            else:                                           # Σ g = [C P | C T], Cholesky
                for i in range(p):
                    for j in range(p):
                        s = R[i, j]
                        for k in range(n):
                            s += r[i, k] * C[cb, cw, j, k]
                        Sig[i, j] = s
                    for j in range(n2):
                        g[i, j] = r[i, j]
                cho_solve(Sig, L, g)
            for q in range(p):                              # Z −= [K; W] ⊗ r
                for i in range(n2):
                    gi = g[q, i]
                    for j in range(m):
                        Z[b, i, w, j] -= gi * r[q, j]


@jit
def regular_inverse(F: np.ndarray, Fi: np.ndarray, threshold: float, d: np.ndarray,
                    Fs: np.ndarray, L: np.ndarray) -> bool:
    """``Fi = F⁻¹`` of a symmetric PSD information matrix and whether ``F`` is regular:
    ``λ_min(Fs) > threshold`` for the unit-diagonal ``Fs = D^(-1/2) F D^(-1/2)``,
    ``D = diag F`` (:func:`~fir_gym.estimators._fir_bank.information_is_regular`).

    ``Fs`` is inverted by Cholesky; ``‖Fs⁻¹‖²_F < threshold⁻²`` settles regularity (it
    bounds ``1/λ_min``), the eigenvalues decide the rest; a failed factor is singular.
    A singular ``F`` gets the identity as its "inverse" (the caller falls back). ``d``,
    ``Fs``, ``L`` are scratch."""
    n = F.shape[0]
    for i in range(n):
        d[i] = np.sqrt(abs(F[i, i])) if F[i, i] != 0.0 else 1.0
    for i in range(n):
        for j in range(n):
            Fs[i, j] = F[i, j] / (d[i] * d[j])
            Fi[i, j] = 1.0 if i == j else 0.0
    cho_solve(Fs, L, Fi)                                # Fi = Fs⁻¹
    frobenius = 0.0
    for i in range(n):
        for j in range(n):
            frobenius += Fi[i, j] * Fi[i, j]
    regular = frobenius < threshold ** -2               # NaN (a failed factor): False
    if not regular and np.isfinite(frobenius):
        regular = np.linalg.eigvalsh(Fs)[0] > threshold
    for i in range(n):
        for j in range(n):
            Fi[i, j] = Fi[i, j] / (d[i] * d[j]) if regular else (1.0 if i == j else 0.0)
    return regular


@jit
def estimate(Z: np.ndarray, ref: np.ndarray, w: int, smoother: bool, prior: np.ndarray,
             has_prior: bool, threshold: float, size: tuple[int, ...]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Window ``w``'s estimate ``(x (B, n), P (B, n, n), regular (B,))`` of every system."""
    n_b = Z.shape[0]
    n = len(size)
    x = np.empty((n_b, n))
    P = np.empty((n_b, n, n))
    ok = np.empty(n_b, dtype=np.bool_)
    F, V = np.empty((n, n)), np.empty((n, n))
    TV, Fs, L, d = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty(n)
    for b in range(n_b):
        Zb = Z[b]
        for i in range(n):
            for j in range(n):
                F[i, j] = -Zb[n + i, w, n + j]
        if has_prior:                                   # V = (I + Π0 F)⁻¹ Π0
            Pi = prior[b if prior.shape[0] > 1 else 0]
            IPF = np.empty((n, n))
            for i in range(n):
                for j in range(n):
                    c = 1.0 if i == j else 0.0
                    for k in range(n):
                        c += Pi[i, k] * F[k, j]
                    IPF[i, j] = c
            V[:, :] = np.linalg.solve(IPF, np.ascontiguousarray(Pi))
            ok[b] = True
        else:
            ok[b] = regular_inverse(F, V, threshold, d, Fs, L)
        if smoother:                                    # x_ref + V b,  V
            for i in range(n):
                c = 0.0
                for k in range(n):
                    c += V[i, k] * Zb[n + k, w, 2 * n]
                x[b, i] = ref[b, w, i] + c
                for j in range(n):
                    P[b, i, j] = V[i, j]
            continue
        for i in range(n):                              # T V
            for j in range(n):
                c = 0.0
                for k in range(n):
                    c += Zb[i, w, n + k] * V[k, j]
                TV[i, j] = c
        for i in range(n):                              # x̄ + T V b,  P + T V Tᵀ
            c = 0.0
            for k in range(n):
                c += TV[i, k] * Zb[n + k, w, 2 * n]
            x[b, i] = Zb[i, w, 2 * n] + c
            for j in range(n):
                c = 0.0
                for k in range(n):
                    c += TV[i, k] * Zb[j, w, n + k]
                P[b, i, j] = Zb[i, w, j] + c
    return x, P, ok
