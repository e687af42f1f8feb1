"""Path (c) on data: two-stage recursions over staggered windows (the FIR engine).

:class:`WindowBank` runs the two-stage recursion of :mod:`~.fir_gains` (path (c))
on measurements for ``W`` windows at once: every new measurement updates all of
them in one vectorised call, the oldest is read out and restarted. With ``W``
equal to the horizon this yields one window estimate per step at O(L·n³) work
but O(1) numpy calls — the engine of the time-varying
:class:`~.fir.FIRFilter`, of :class:`~.efir.ExtendedFIRFilter` and of every
start-up (growing-window) estimate.
"""

from __future__ import annotations

import numpy as np

from . import compiled
from ._validation import FloatArray
from .compiled import window_bank as compiled_bank

#: An information matrix ``F`` counts as singular when the smallest eigenvalue of
#: its unit-diagonal (Jacobi-scaled) version is below this: the estimate would
#: then keep fewer than ~4 significant digits. Scaling makes the test unit-free.
RANK_RTOL = 1e-12


def information_is_regular(F: FloatArray) -> np.ndarray:
    """Whether ``F`` is numerically invertible by the :data:`RANK_RTOL` criterion (batched).

    Fast path: with ``Fs`` the unit-diagonal version, ``λ_min(Fs) ≥ det(Fs) / n^(n−1)``
    (its other eigenvalues sum to at most ``n``), so ``det(Fs) > RANK_RTOL·n^(n−1)``
    settles most cases with one LU; the rest get the eigenvalue test.
    """
    F = np.asarray(F)
    n = F.shape[-1]
    d = np.sqrt(np.abs(np.diagonal(F, axis1=-2, axis2=-1)))
    d = np.where(d > 0, d, 1.0)
    Fs = F / (d[..., :, None] * d[..., None, :])
    ok = np.linalg.det(Fs) > RANK_RTOL * n ** (n - 1)
    if not ok.all():
        finite = np.isfinite(Fs).all(axis=(-2, -1))
        lam = np.linalg.eigvalsh(np.where(finite[..., None, None], Fs, 0.0))[..., 0]
        ok = finite & (lam > RANK_RTOL)
    return ok


class WindowBank:
    """``W`` two-stage recursions over staggered windows, batched, advanced in lock-step.

    Window ``w`` of system ``b`` runs a Kalman filter from ``x̄ = x_ref, P = 0`` with
    the sensitivity ``T = ∂x̄/∂x_start`` and the normal equations ``F = Σ (C T⁻)ᵀ
    Σ⁻¹ (C T⁻)``, ``b = Σ (C T⁻)ᵀ Σ⁻¹ e`` (docs/papers.md#000-two-stage-form).
    One array holds it all,
    ``Z[b, :, w] = [[P | T | x̄], [· | −F | b]]`` (``2n x (2n+1)``), so a measurement
    update is one matmul ``r = C [P | T | x̄] − [0 | 0 | y] = [C P | C T | −e]`` and
    one rank-``p`` correction ``Z −= [K; W] ⊗ r`` with ``[K; W] = [P Cᵀ; (C T)ᵀ] Σ⁻¹``.

    Each operation has a compiled twin (:mod:`.compiled.window_bank`), one pass over
    ``Z`` for any batch, a single system included; it runs exactly when
    :data:`compiled.ENABLED <fir_gym.estimators.compiled.ENABLED>`.
    """

    def __init__(self, n_batch: int, n_windows: int, n: int) -> None:
        self.n, self.W = n, n_windows
        #: a window as it starts: ``x̄ = 0, P = 0, T = I, F = b = 0`` (rows of ``Z[b, :, w]``)
        self.blank = np.zeros((2 * n, 2 * n + 1))
        self.blank[:n, n:2 * n] = np.eye(n)                      # T = I, all else 0
        self.Z = np.empty((n_batch, 2 * n, n_windows, 2 * n + 1))
        self.Z[...] = self.blank[None, :, None, :]
        self.ref = np.zeros((n_batch, n_windows, n))
        self._has_ref = False

    def restart(self, w: int, x_ref: FloatArray | None = None) -> None:
        """Start window ``w`` afresh: ``x̄ = x_ref`` (default 0), ``P = 0, T = I, F = b = 0``."""
        self.Z[:, :, w, :] = self.blank
        if x_ref is not None or self._has_ref:
            self.ref[:, w] = 0.0 if x_ref is None else x_ref
            self.Z[:, :self.n, w, 2 * self.n] = self.ref[:, w]
            self._has_ref = True

    def update(self, C: FloatArray, R: FloatArray, y: FloatArray,
               valid: np.ndarray | None = None) -> None:
        """Measurement update of every window.

        ``C``: ``(B|1, p, n)`` shared by the windows or ``(B, W, p, n)``; ``R``: ``(p, p)``;
        ``y``: ``(B, p)`` or ``(B, W, p)``; ``valid``: ``(B,)`` — invalid systems skip.
        """
        n, Z = self.n, self.Z
        if compiled.ENABLED:                                    # one compiled pass over Z
            compiled_bank.update(Z, _windows(C), np.ascontiguousarray(R),
                                 y[:, None] if y.ndim == 2 else y,
                                 _ALL if valid is None else valid, (0,) * n)
            return
        r = _lmul(C, Z[:, :n])                                  # (B, p, W, 2n+1)
        r[..., 2 * n] -= y[:, :, None] if y.ndim == 2 else y.swapaxes(1, 2)
        p = r.shape[1]
        if p == 1:
            c = C[..., 0, :]                                    # (B|1, n) or (B, W, n)
            CPC = r[:, 0, :, :n] @ c[:, :, None] if C.ndim == 3 else \
                (r[:, 0, :, :n] * c).sum(-1, keepdims=True)
            g = (r[:, 0, :, :2 * n] / (CPC + R[0, 0]))[:, None]  # (B, 1, W, 2n)
        else:
            rt = r.swapaxes(1, 2)                               # (B, W, p, m)
            Ct = C.swapaxes(-1, -2)
            Sig = rt[..., :n] @ (Ct[:, None] if C.ndim == 3 else Ct) + R
            g = np.linalg.solve(Sig, rt[..., :2 * n]).swapaxes(1, 2)
        if valid is not None and not valid.all():
            g = g * valid[:, None, None, None]
        for q in range(p):                                      # Z −= [K; W] ⊗ r
            # g repeated along the last axis first: numpy's broadcast of a length-1 last
            # axis runs one 7-element inner loop per (b, i, w), ~3x slower than this
            G = np.repeat(g[:, q].swapaxes(1, 2)[..., None], r.shape[-1], axis=3)
            G *= r[:, q:q + 1]
            Z -= G

    def predict(self, A: FloatArray, Bu: FloatArray | None, Qx: FloatArray | None) -> None:
        """Time update ``x̄ ← A x̄ + B u``, ``T ← A T``, ``P ← A P Aᵀ + GQGᵀ`` of every window.

        ``A``: ``(B|1, n, n)`` or ``(B, W, n, n)``; ``Bu``: ``(B, n)`` or ``(B, W, n)``;
        ``Qx``: ``(n, n)`` or ``(B, n, n)`` (``None``: no process noise, ``P`` stays 0).
        """
        n, Z = self.n, self.Z
        if compiled.ENABLED:                                    # one compiled pass over Z
            compiled_bank.predict(Z, _windows(A), _NONE if Bu is None else
                                  (Bu[:, None] if Bu.ndim == 2 else Bu),
                                  _NONE if Qx is None else (Qx[None] if Qx.ndim == 2 else Qx),
                                  Bu is not None, Qx is not None, (0,) * n)
            return
        Z[:, :n] = _lmul(A, Z[:, :n])
        if Qx is not None:
            P = Z[:, :n, :, :n]
            if A.ndim == 3:                 # one (n·W x n) @ (n x n) product per system
                B_, W_ = P.shape[0], P.shape[2]
                P = (P.reshape(B_, n * W_, n) @ np.ascontiguousarray(A.swapaxes(-1, -2))
                     ).reshape(B_, n, W_, n)
            else:
                P = (P.swapaxes(1, 2) @ A.swapaxes(-1, -2)).swapaxes(1, 2)
            Z[:, :n, :, :n] = P + (Qx[..., :, None, :] if Qx.ndim == 3 else Qx[:, None, :])
        if Bu is not None:
            Z[:, :n, :, 2 * n] += Bu[:, :, None] if Bu.ndim == 2 else Bu.swapaxes(1, 2)

    def estimate(self, w: int, smoother: bool = False, prior: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray, np.ndarray]:
        """Estimate of window ``w``: ``x̄ + T V b`` and ``P + T V Tᵀ``.

        ``V = F⁻¹`` (diffuse start) or, with a ``prior`` covariance ``Π0`` of the
        start state about ``x_ref``, ``V = (Π0⁻¹ + F)⁻¹ = (I + Π0 F)⁻¹ Π0``. With
        ``smoother`` the window-start estimate ``x_ref + V b`` and ``V``. Returns
        ``(x, P, regular)``; where ``F`` is singular (``regular`` False) the
        values are meaningless and the caller falls back.
        """
        n = self.n
        if compiled.ENABLED:
            return compiled_bank.estimate(
                self.Z, self.ref, w, smoother, _NONE if prior is None else
                (prior[None] if prior.ndim == 2 else prior), prior is not None, RANK_RTOL,
                (0,) * n)
        Zs = self.Z[:, :, w, :]
        if prior is None:
            Fi, regular = spd_inverse(-Zs[:, n:, n:2 * n])
        else:
            Fi = np.linalg.solve(np.eye(n) - prior @ Zs[:, n:, n:2 * n], prior).astype(
                np.float64, copy=False)
            regular = np.ones(Zs.shape[0], bool)
        b = Zs[:, n:, 2 * n:]                                   # (B, n, 1)
        if smoother:
            return self.ref[:, w] + (Fi @ b)[..., 0], Fi, regular
        T = Zs[:, :n, n:2 * n]
        TFi = T @ Fi
        return (Zs[:, :n, 2 * n] + (TFi @ b)[..., 0],
                Zs[:, :n, :n] + TFi @ np.ascontiguousarray(T.swapaxes(1, 2)), regular)


_FROBENIUS_LIMIT = RANK_RTOL ** -2
_COFACTOR3 = np.array([[3 * ((i + a) % 3) + (j + b) % 3 for i in range(3) for j in range(3)]
                       for a, b in ((1, 1), (2, 2), (1, 2), (2, 1))]).ravel()


def spd_inverse(F: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Inverse of a batch of symmetric PSD ``F`` ``(B, n, n)`` and whether each is regular.

    Regular means ``λ_min(Fs) > RANK_RTOL`` for the unit-diagonal ``Fs = D⁻¹ F D⁻¹``
    (:func:`~.fir_gains.information_is_regular`). Two sufficient tests settle it
    cheaply, the eigenvalues decide the rest: ``‖Fs⁻¹‖²_F = Σ (F⁻¹)²_ij F_ii F_jj <
    RANK_RTOL⁻²`` after a LAPACK inverse (small batches), or, for ``n <= 3`` and
    large batches, ``det(Fs) = det(F)/Π F_ii > RANK_RTOL·n^(n−1)`` (as ``λ_max(Fs)
    <= n``) with the inverse as adjugate over determinant — a few vector
    operations for the whole batch. Singular members get the identity's inverse.
    The explicit ``n x n`` inverse is wanted here: its norm is the rank test and
    it enters both the estimate ``T F⁻¹ b`` and its covariance ``T F⁻¹ Tᵀ``.
    """
    nb, n = F.shape[0], F.shape[-1]
    if nb < 32 or n > 3:                    # LAPACK; regular if ‖Fs⁻¹‖_F < 1/RANK_RTOL
        try:
            Fi = np.linalg.inv(F)
            d = F.diagonal(0, 1, 2)
            ok = (d[:, None, :] @ (Fi * Fi) @ d[:, :, None])[:, 0, 0] < _FROBENIUS_LIMIT
        except np.linalg.LinAlgError:
            ok = np.zeros(nb, bool)
        if not ok.all():
            ok = information_is_regular(F)
            Fi = np.linalg.inv(np.where(ok[:, None, None], F, np.eye(n)))
        return Fi.astype(np.float64, copy=False), ok
    if n == 1:
        det, adj = F[:, 0, 0], np.ones((nb, 1, 1))
    elif n == 2:
        det = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
        adj = F[:, ::-1, ::-1] * np.array([[1.0, -1.0], [-1.0, 1.0]])
    else:
        c = F.reshape(nb, 9)[:, _COFACTOR3].reshape(nb, 4, 9)
        adj = (c[:, 0] * c[:, 1] - c[:, 2] * c[:, 3]).reshape(nb, 3, 3)
        det = (F[:, 0] * adj[:, 0]).sum(-1)
    scale = np.maximum(F.diagonal(0, 1, 2).prod(1), 1e-300)
    ok = det > (RANK_RTOL * n ** (n - 1)) * scale
    if not ok.all():
        ok = information_is_regular(F)
        det = np.where(ok, det, 1.0)
        adj = np.where(ok[:, None, None], adj, np.eye(n))
    return adj / det[:, None, None], ok


def _lmul(M: FloatArray, X: FloatArray) -> FloatArray:
    """``M_w X_w`` for every window: ``M`` ``(B|1, k, n)`` shared or ``(B, W, k, n)``."""
    B, n, W, m = X.shape
    if M.ndim == 3:
        return (M @ X.reshape(B, n, W * m)).reshape(B, M.shape[1], W, m)
    return (M @ X.swapaxes(1, 2)).swapaxes(1, 2)


_ALL = np.ones(1, dtype=bool)
_NONE = np.zeros((1, 1, 1))


def _windows(M: FloatArray) -> FloatArray:
    """``M`` as ``(B|1, W|1, k, n)`` (a ``(B|1, k, n)`` matrix is shared by the windows)."""
    return np.ascontiguousarray(M[:, None] if M.ndim == 3 else M, dtype=np.float64)
