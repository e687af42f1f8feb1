"""Unscented Kalman filter with pluggable sigma-point schemes (paper 003, Section 3).

**Scaled unscented transform** (paper 003, Table 1 and eq 6; Julier 2002; Wan &
van der Merwe 2000): for a state of dimension ``n``,

    λ = α² (n + κ) − n
    χ₀ = x,   χᵢ = x + (√((n+λ) P))ᵢ,   χᵢ₊ₙ = x − (√((n+λ) P))ᵢ      (i = 1..n)
    W₀ᵐ = λ / (n + λ),   W₀ᶜ = λ / (n + λ) + 1 − α² + β,   Wᵢᵐ = Wᵢᶜ = 1 / (2 (n + λ))

with ``√`` the lower Cholesky factor (columns). Paper 003 prints the weight as
``1/2(n+l)`` (read ``1/(2(n+λ))``); its eq 9 drops the outer product —
the covariance is ``Σ Wᵢᶜ (Zᵢ − z̄)(Zᵢ − z̄)ᵀ`` — and its Table 2 drops ``+ Q`` in
``P⁻`` and ``+ R`` in ``Pᶻᶻ``; all three are restored here.

**Defaults** ``α = 1e-3, β = 2, κ = 0``: paper 003 gives the range
``1e-3 ≤ α ≤ 1`` (printed reversed), says κ is "mostly 0" and that β = 2 is
optimal for Gaussian priors, but not the values it used; these are Wan & van der
Merwe's standard values, which fit that description.

**Numerics.** With small α the weights are huge and of mixed sign
(``W₀ᵐ ≈ −1/α²``), and the textbook sums lose up to ``1/α²`` in relative
accuracy. :func:`unscented_transform` therefore works with deviations from the
first point, ``Dᵢ = Zᵢ − Z₀``: ``z̄ = Z₀ + Σ Wᵢᵐ Dᵢ`` and
``Σ Wᵢᶜ (Zᵢ − z̄)(Zᵢ − z̄)ᵀ = Σ Wᵢᶜ Dᵢ Dᵢᵀ − d cᵀ − c dᵀ + (Σ Wᶜ) d dᵀ`` with
``d = Σ Wᵐ D``, ``c = Σ Wᶜ D`` — algebraically identical, but ``W₀`` multiplies
``D₀ = 0``; for the scaled set it reduces to ``Σᵢ>₀ Wᵢ Dᵢ Dᵢᵀ + (β − α²) d dᵀ``,
a sum of positive terms.

**Non-positive-definite covariance.** Sigma points need a square root of ``P``.
When the Cholesky factorisation fails, a positive *semi*-definite ``P`` (smallest
eigenvalue ≥ ``−1e-9 · max eigenvalue``, e.g. a state known exactly) uses the
symmetric eigen-square-root with the negative round-off clipped; an indefinite
``P`` is an error: :meth:`SigmaPoints.sigma_points` raises ``ValueError``, and the
filter flags that system as diverged (it keeps its last finite estimate). The
opt-in ``jitter`` adds ``jitter · max(diag P) · I`` before every factorisation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._batched_check import check_model_batched
from ._hooked_moments import hooked_cross, hooked_moments
from ._kalman_linalg import cholesky, logdet_of_inverse, psd_rebuild, rmul, spd_inverse, symmetrize
from ._validation import FloatArray
from .base import Estimator
from .compiled import unscented as compiled_unscented
from .kalman import keep_usable
from .model import StateSpaceModel
from .public_steps import PublicSteps
from .registry import register_estimator
from .sequences import SmootherResult
from .smoothers import smooth_sequence

__all__ = ["CubatureSigmaPoints", "MerweScaledSigmaPoints", "SigmaPoints",
           "UnscentedKalmanFilter", "matrix_sqrt", "unscented_transform"]

#: relative tolerance below which negative eigenvalues count as round-off
PSD_TOL = 1e-9


def matrix_sqrt(P: FloatArray, jitter: float = 0.0) -> FloatArray:
    """A batch of square roots ``S Sᵀ = P`` (lower Cholesky where possible); NaN if indefinite."""
    if jitter:
        scale = np.max(np.diagonal(P, axis1=-2, axis2=-1), axis=-1)
        P = P + (jitter * scale)[:, None, None] * np.eye(P.shape[-1])
    L = cholesky(P)
    bad = np.isnan(L[:, 0, 0]) if L.shape[1] == 1 else ~np.isfinite(L).all(axis=(1, 2))
    if bad.any():
        for b in np.flatnonzero(bad):
            if not np.isfinite(P[b]).all():
                continue
            lam, V = np.linalg.eigh(P[b])
            if lam[0] >= -PSD_TOL * max(lam[-1], 0.0):
                L[b] = V * np.sqrt(np.clip(lam, 0.0, None))
    return L


class SigmaPoints:
    """A sigma-point scheme: unit points ``ξ`` (N, n) and weights ``Wm, Wc`` (N,).

    The points for mean ``x`` and covariance ``P = S Sᵀ`` are ``χᵢ = x + S ξᵢ``.
    Subclasses set ``xi``, ``Wm`` and ``Wc``; any scheme whose weights satisfy
    ``Σ Wm = 1``, ``Σ Wm ξ = 0`` and ``Σ Wc ξ ξᵀ = I`` plugs into the UKF.
    """

    n: int
    xi: FloatArray
    Wm: FloatArray
    Wc: FloatArray

    @property
    def num_points(self) -> int:
        """Number of sigma points ``N``."""
        return int(self.Wm.shape[0])

    def points(self, x: FloatArray, S: FloatArray) -> FloatArray:
        """Sigma points ``(B, N, n)`` for means ``x (B, n)`` and square roots ``S (B, n, n)``."""
        return x[:, None, :] + rmul(S, self.xi.T).mT

    def sigma_points(self, x: ArrayLike, P: ArrayLike) -> FloatArray:
        """Sigma points ``(N, n)``/``(B, N, n)`` for ``x`` ``(n,)``/``(B, n)`` and covariance ``P``.

        Raises ``ValueError`` when ``P`` is not positive semi-definite.
        """
        x_ = np.asarray(x, dtype=np.float64)
        single = x_.ndim == 1
        X, P_ = (x_[None], np.asarray(P, float)[None]) if single else (x_, np.asarray(P, float))
        if (X.ndim != 2 or X.shape[-1] != self.n
                or P_.shape != (X.shape[0], self.n, self.n)):
            raise ValueError(f"x and P must have shapes (n,), (n, n) with n = {self.n} "
                             f"(or a batch); got {x_.shape} and {np.shape(P)}")
        with np.errstate(invalid="ignore"):
            S = matrix_sqrt(P_)
        if not np.isfinite(S).all():
            raise ValueError("P must be symmetric positive semi-definite to draw sigma points")
        out = self.points(X, S)
        return out[0] if single else out

    def _finish(self) -> None:
        for a in (self.xi, self.Wm, self.Wc):
            a.setflags(write=False)
        #: Wc equals Wm except possibly at the first point (then c = d below)
        self.same_tail = bool(np.array_equal(self.Wm[1:], self.Wc[1:]))
        self.sum_Wc = float(self.Wc.sum())

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n={self.n})"


class MerweScaledSigmaPoints(SigmaPoints):
    """Scaled sigma points (paper 003, Table 1 and eq 6): ``2n + 1`` points.

    Args:
        n: state dimension.
        alpha: spread, ``0 < α ≤ 1`` (default 1e-3).
        beta: prior-knowledge term, 2 for Gaussian priors (default 2).
        kappa: secondary scaling (default 0); ``n + κ > 0`` is required.
    """

    def __init__(self, n: int, alpha: float = 1e-3, beta: float = 2.0, kappa: float = 0.0
                 ) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer; got {n!r}")
        if not np.isfinite(alpha) or alpha <= 0:
            raise ValueError(f"alpha must be positive; got {alpha!r}")
        if not np.isfinite(beta) or not np.isfinite(kappa) or n + kappa <= 0:
            raise ValueError(f"beta must be finite and n + kappa > 0; got beta={beta!r}, "
                             f"kappa={kappa!r}, n={n}")
        self.n, self.alpha, self.beta, self.kappa = int(n), float(alpha), float(beta), float(kappa)
        self.lam = alpha**2 * (n + kappa) - n
        c = n + self.lam
        self.xi = np.vstack([np.zeros(n), np.sqrt(c) * np.eye(n), -np.sqrt(c) * np.eye(n)])
        self.Wm = np.full(2 * n + 1, 0.5 / c)
        self.Wc = self.Wm.copy()
        self.Wm[0] = self.lam / c
        self.Wc[0] = self.lam / c + 1.0 - alpha**2 + beta
        self._finish()

    def __repr__(self) -> str:
        return (f"MerweScaledSigmaPoints(n={self.n}, alpha={self.alpha:g}, beta={self.beta:g}, "
                f"kappa={self.kappa:g})")


class CubatureSigmaPoints(SigmaPoints):
    """Spherical-radial cubature points (Arasaratnam & Haykin 2009).

    ``2n`` points ``±√n eᵢ``, all weights ``1/(2n)``.
    """

    def __init__(self, n: int) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer; got {n!r}")
        self.n = int(n)
        self.xi = np.sqrt(n) * np.vstack([np.eye(n), -np.eye(n)])
        self.Wm = np.full(2 * n, 0.5 / n)
        self.Wc = self.Wm.copy()
        self._finish()


def _moments(Z: FloatArray, sp: SigmaPoints) -> tuple[FloatArray, FloatArray, FloatArray,
                                                      FloatArray]:
    """Mean, deviations ``D = Z − Z₀``, ``d = Σ Wm D`` and ``c = Σ Wc D`` of ``Z (B, N, k)``."""
    D = Z - Z[:, :1]
    d = np.matmul(sp.Wm, D)                             # (B, k)
    c = d if sp.same_tail else np.matmul(sp.Wc, D)
    return Z[:, 0] + d, D, d, c


def _mean_covariance(Z: FloatArray, sp: SigmaPoints) -> tuple[FloatArray, FloatArray]:
    """``z̄ = Σ Wᵐ Zᵢ`` and ``Σ Wᶜ (Zᵢ − z̄)(Zᵢ − z̄)ᵀ`` (symmetric) of ``Z (B, N, k)``."""
    mean, D, d, c = _moments(Z, sp)
    return mean, symmetrize(_cross(D, d, c, D, d, c, sp))


def _outer(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[:, :, None] * b[:, None, :]


def _cross(Da: FloatArray, da: FloatArray, ca: FloatArray, Db: FloatArray, db: FloatArray,
           cb: FloatArray, sp: SigmaPoints) -> FloatArray:
    """``Σ Wc (Aᵢ − ā)(Bᵢ − b̄)ᵀ`` from deviations (see the module docstring)."""
    C = (Da * sp.Wc[:, None]).mT @ Db
    if sp.same_tail:
        return C + (sp.sum_Wc - 2.0) * _outer(da, db)
    return C - _outer(da, cb) - _outer(ca, db) + sp.sum_Wc * _outer(da, db)


def unscented_transform(Z: ArrayLike, Wm: ArrayLike | SigmaPoints, Wc: ArrayLike | None = None,
                        noise_cov: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
    """Mean and covariance of transformed sigma points (paper 003, eqs 8–9, corrected).

    Args:
        Z: transformed points ``(N, k)`` or ``(B, N, k)``.
        Wm: mean weights ``(N,)``, or a :class:`SigmaPoints` (then ``Wc`` is omitted).
        Wc: covariance weights ``(N,)``.
        noise_cov: additive noise covariance ``(k, k)`` (``Q`` or ``R``), added to the result.

    Returns:
        ``(z̄, P_z)``: ``z̄ = Σ Wᵐ Zᵢ`` and ``P_z = Σ Wᶜ (Zᵢ − z̄)(Zᵢ − z̄)ᵀ (+ noise_cov)``.
    """
    if isinstance(Wm, SigmaPoints):
        sp = Wm
    else:
        sp = SigmaPoints()
        sp.xi = np.zeros((np.size(Wm), 0))
        sp.Wm, sp.Wc = np.asarray(Wm, float).ravel(), np.asarray(Wc, float).ravel()
        sp._finish()
    Z_ = np.asarray(Z, dtype=np.float64)
    single = Z_.ndim == 2
    Z_ = Z_[None] if single else Z_
    if Z_.ndim != 3 or Z_.shape[1] != sp.Wm.shape[0] or sp.Wc.shape != sp.Wm.shape:
        raise ValueError(f"Z must have shape (N, k) or (B, N, k) with N = {sp.Wm.shape[0]} "
                         f"weights; got {np.shape(Z)}")
    mean, P = _mean_covariance(Z_, sp)
    if noise_cov is not None:
        P = P + np.asarray(noise_cov, dtype=np.float64)
    return (mean[0], P[0]) if single else (mean, P)


class UnscentedKalmanFilter(PublicSteps, Estimator):
    """Unscented Kalman filter for additive noise (paper 003, Table 2, corrected; batched).

    predict: ``χ = points(x, P)``, ``x⁻, P⁻ = UT(f(χ, u)) + G Q Gᵀ``;
    update: ``Z = h(χ⁻)``, ``ŷ, S = UT(Z) + R``, ``Pxz = Σ Wᶜ (χ⁻ − x⁻)(Z − ŷ)ᵀ``,
    ``K = Pxz S⁻¹``, ``x⁺ = x⁻ + K (y − ŷ)``, ``P⁺ = P⁻ − K S Kᵀ`` (symmetrised, then
    rebuilt as ``L Lᵀ`` from its semidefinite factor,
    :func:`~._kalman_linalg.psd_rebuild`: the difference has no Gram form — Merwe's
    weight ``Wᶜ₀`` may be negative — and loses the PSD cone to round-off when ``P⁻`` is
    huge against ``R``; the rebuild keeps ``P⁺`` symmetric PSD by construction,
    docs/architecture.md#covariance-updates).

    Args:
        model: any :class:`StateSpaceModel`.
        alpha, beta, kappa: scaled-UT parameters (defaults 1e-3, 2, 0; module docstring).
        points: a :class:`SigmaPoints` of size ``n_x`` (e.g. :class:`CubatureSigmaPoints`);
            overrides ``alpha, beta, kappa``.
        redraw: draw fresh points ``χ⁻`` from ``(x⁻, P⁻)`` for the update (default,
            Särkkä 2013, Alg. 5.14: then ``Q`` enters ``S`` and ``Pxz`` and the UKF
            equals the KF on linear models). ``False`` reuses the propagated points,
            as paper 003's Table 2 (and filterpy) do.
        jitter: opt-in relative diagonal loading before each factorisation (default 0).
        **options: those of :class:`~fir_gym.estimators.base.Estimator`.

    The compiled twin (:mod:`~.compiled.unscented`) draws the points, takes the
    moments and updates in three calls around the model's ``f`` and ``h`` (which see
    the same ``(B·N, n)`` points as here).
    """

    name = "ukf"
    has_compiled_step = True
    can_gate = True
    reports_likelihood = True
    model_reassignable = True
    twin_replaces = (*Estimator.twin_replaces, "_draw", "_correct")

    def __init__(self, model: StateSpaceModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, alpha: float = 1e-3, beta: float = 2.0,
                 kappa: float = 0.0, points: SigmaPoints | None = None, redraw: bool = True,
                 jitter: float = 0.0, **options: Any) -> None:
        if isinstance(model, StateSpaceModel) and getattr(model, "time_invariant", True) is False:
            raise TypeError(f"model must have time-free f/h for {type(self).__name__}; got a "
                            f"{type(model).__name__} (use KalmanFilter)")
        if points is None:
            points = MerweScaledSigmaPoints(getattr(model, "n_x", 1), alpha, beta, kappa)
        self._n_x = getattr(model, "n_x", None)
        self.points, self.redraw, self.jitter = points, bool(redraw), jitter
        super().__init__(model, x0=x0, P0=P0, **options)
        self._model_changed()

    @property
    def points(self) -> SigmaPoints:
        """The sigma-point scheme (assignable: the next step uses it)."""
        return self._points

    @points.setter
    def points(self, points: SigmaPoints) -> None:
        if not isinstance(points, SigmaPoints):
            raise TypeError(f"points must be a SigmaPoints instance; got {type(points).__name__}")
        if self._n_x is not None and points.n != self._n_x:
            raise ValueError(f"points must be for n = {self._n_x} (the model's n_x); "
                             f"got n = {points.n}")
        self._points = points
        if getattr(self, "_n_b", 0):
            self._init_batch(self._state.batch)

    @property
    def jitter(self) -> float:
        """Relative diagonal loading before each factorisation (assignable)."""
        return self._jitter

    @jitter.setter
    def jitter(self, jitter: float) -> None:
        if not np.isfinite(jitter) or jitter < 0:
            raise ValueError(f"jitter must be a non-negative number; got {jitter!r}")
        self._jitter = float(jitter)

    def _model_changed(self) -> None:
        model = self.model
        if getattr(model, "time_invariant", True) is False:
            raise TypeError(f"model must have time-free f/h for {type(self).__name__}")
        self._f, _, self._h, _ = model.unchecked_callables()
        check_model_batched(self)
        self._GQGt = np.ascontiguousarray(model.GQGT)
        self._R = np.ascontiguousarray(model.R)
        #: the model's residual and mean hooks (all None for a plain model)
        self._hooks = tuple(getattr(model, a, None) for a in
                            ("residual_x", "residual_y", "mean_x", "mean_y"))
        #: the twin's sums know no hooks: a hooked model steps on the numpy reference
        self._hooked = any(h is not None for h in self._hooks)

    def _init_batch(self, n_batch: int) -> None:
        #: the input of every sigma point when the caller gives none
        self._no_point_input = np.zeros((n_batch * self.points.num_points, self.model.n_u))

    # ------------------------------------------------------------------ numpy reference
    def _draw(self, x: FloatArray, P: FloatArray) -> FloatArray:
        return self.points.points(x, matrix_sqrt(P, self.jitter))

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, ...]:
        return self._correct(x, P, self._draw(x, P), y, valid)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, ...]:
        n_b, n = x.shape
        N = self.points.num_points
        X = self._draw(x, P)
        U = np.repeat(u, N, axis=0)
        Xf = self._f(X.reshape(n_b * N, n), U).reshape(n_b, N, n)
        if self._hooks[0] is not None or self._hooks[2] is not None:
            x_pred, D = hooked_moments(Xf, self.points.Wm, self._hooks[2], self._hooks[0])
            P_pred = symmetrize(hooked_cross(D, D, self.points.Wc))
        else:
            x_pred, P_pred = _mean_covariance(Xf, self.points)
        P_pred = P_pred + self._GQGt
        X_pred = self._draw(x_pred, P_pred) if self.redraw else Xf
        return self._correct(x_pred, P_pred, X_pred, y, valid)

    def _correct(self, x: FloatArray, P: FloatArray, X: FloatArray, y: FloatArray,
                 valid: np.ndarray) -> tuple[FloatArray, ...]:
        n_b, N, n = X.shape
        sp = self.points
        Z = self._h(X.reshape(n_b * N, n)).reshape(n_b, N, -1)
        res_x, res_y, _, mean_y = self._hooks
        if self._hooked:                               # textbook sums through the hooks
            y_hat, DZ = hooked_moments(Z, sp.Wm, mean_y, res_y)
            DX = X - x[:, None] if res_x is None else res_x(X, x[:, None])
            S = symmetrize(hooked_cross(DZ, DZ, sp.Wc))
            Pxz = hooked_cross(DX, DZ, sp.Wc)
        else:
            y_hat, DZ, dz, cz = _moments(Z, sp)
            _, DX, dx, cx = _moments(X, sp)
            S = symmetrize(_cross(DZ, dz, cz, DZ, dz, cz, sp))
            Pxz = _cross(DX, dx, cx, DZ, dz, cz, sp)
        S = S + self.model.R
        W = spd_inverse(S)
        K = Pxz @ W
        e = y - y_hat if res_y is None else res_y(y, y_hat)
        x_new = x + (K @ e[:, :, None])[:, :, 0]
        P_new = psd_rebuild(symmetrize(P - K @ Pxz.mT))       # PSD by construction
        nis = ((W @ e[:, :, None])[:, :, 0] * e).sum(axis=1)
        # a missing measurement, or one the gate rejects: x⁻, P⁻ kept
        x_new, P_new, nis = keep_usable(x_new, P_new, nis, x, P, valid, self._gate_threshold)
        return x_new, P_new, nis, logdet_of_inverse(W, n_b)


    # ------------------------------------------------------------------ smoother
    def smooth(self, ys: ArrayLike, us: ArrayLike | None = None) -> SmootherResult:
        """Unscented Rauch–Tung–Striebel smoother (Särkkä 2008; :mod:`.smoothers`): a forward
        :meth:`filter` (same arguments and alignment), then the backward pass with the
        unscented transform of ``f`` at each filtered estimate (this filter's sigma points)
        and the cross-covariance ``C = Σ Wᶜ (χᵢ − x̂)(f(χᵢ) − x⁻)ᵀ``. Returns a
        :class:`~fir_gym.estimators.sequences.SmootherResult`."""
        return smooth_sequence(self, ys, us, self._smoother_prediction, self._hooks[0])

    def _smoother_prediction(self, k: int, x: FloatArray, P: FloatArray, u: FloatArray
                             ) -> tuple[FloatArray, FloatArray, FloatArray]:
        n_b, n = x.shape
        sp = self.points
        N = sp.num_points
        X = self._draw(x, P)
        Xf = self._f(X.reshape(n_b * N, n), np.repeat(u, N, axis=0)).reshape(n_b, N, n)
        res_x, _, mean_x, _ = self._hooks
        if res_x is not None or mean_x is not None:
            x_pred, DF = hooked_moments(Xf, sp.Wm, mean_x, res_x)
            DX = X - x[:, None] if res_x is None else res_x(X, x[:, None])
            P_pred = symmetrize(hooked_cross(DF, DF, sp.Wc)) + self._GQGt
            return x_pred, P_pred, hooked_cross(DX, DF, sp.Wc)
        x_pred, DF, df, cf = _moments(Xf, sp)
        _, DX, dx, cx = _moments(X, sp)
        P_pred = symmetrize(_cross(DF, df, cf, DF, df, cf, sp)) + self._GQGt
        return x_pred, P_pred, _cross(DX, dx, cx, DF, df, cf, sp)

    # ------------------------------------------------------------------ compiled twin
    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        if self._hooked:
            self._numpy_step(y, self._no_input, valid)
            return
        x, P, sp = self._state.x, self._state.P, self.points
        assert x is not None and P is not None
        X = compiled_unscented.sigma_points(x, P, sp.xi, self.jitter)
        self._compiled_correct(x, P, X, y, valid)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        if self._hooked:
            self._numpy_step(y, u, valid)
            return
        x, P, sp = self._state.x, self._state.P, self.points
        assert x is not None and P is not None
        n_b, n = x.shape
        N = sp.num_points
        X = compiled_unscented.sigma_points(x, P, sp.xi, self.jitter)
        U = self._no_point_input if u is self._no_input else np.repeat(u, N, axis=0)
        with np.errstate(all="ignore"):
            Xf = self._f(X.reshape(n_b * N, n), U).reshape(n_b, N, n)
        x_pred, P_pred, X_pred = compiled_unscented.predict(
            X, Xf, x, P, sp.Wm, sp.Wc, self._GQGt, self._predicting(), self.redraw, sp.xi,
            self.jitter)
        self._compiled_correct(x_pred, P_pred, X_pred, y, valid)

    def _compiled_correct(self, x: FloatArray, P: FloatArray, X: FloatArray, y: FloatArray,
                          valid: np.ndarray) -> None:
        n_b, N, n = X.shape
        sp = self.points
        with np.errstate(all="ignore"):
            Z = self._h(X.reshape(n_b * N, n)).reshape(n_b, N, -1)
        compiled_unscented.update(x, P, X, Z, y, sp.Wm, sp.Wc, self._R, valid, self._state)


register_estimator("ukf", UnscentedKalmanFilter)
