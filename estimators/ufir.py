"""Shmaliy's unbiased FIR (UFIR) filter: no noise statistics, no initial state.

Over the window the UFIR estimate is ordinary least squares of the window-start
state on the stacked observation matrix, propagated to the estimation time
(docs/papers.md#beyond-ufir)::

    x̂ = Φ (C̃ᵀC̃)⁻¹ C̃ᵀ (Y − D̃ U) + M_B U,      C̃ = [C_j Φ_j]_j,  Φ_j = A_{j−1}⋯A_0

It ignores ``Q`` and ``R``: it is the minimum-variance unbiased FIR filter of a
model with ``Q = 0`` and ``R = I`` (the test oracle against
:class:`~.fir.FIRFilter`), and its window length trades noise (the noise power
gain ``NPG = Φ (C̃ᵀC̃)⁻¹ Φᵀ`` falls with ``N``) against model-error bias (grows
with ``N``). Two forms:

* ``method="batch"`` — the OLS gain (``numpy.linalg.lstsq`` on ``C̃``), computed
  once for a time-invariant model and applied as one matmul;
* ``method="iterative"`` — Shmaliy's Kalman-like recursion over the window: a
  batch start on the first ``s`` measurements (the fewest that determine the
  state; Shmaliy uses ``s = n``), then for ``l = s … L−1``::

      x⁻ = A x + B u,   G_l = [C_lᵀ C_l + (A G_{l−1} Aᵀ)⁻¹]⁻¹,   x = x⁻ + G_l C_lᵀ (y_l − C_l x⁻)

  ``G`` is the NPG. ``G_l`` is evaluated in the algebraically identical form
  ``M − M Cᵀ (I + C M Cᵀ)⁻¹ C M``, ``M = A G_{l−1} Aᵀ`` (Woodbury): it needs no
  ``M⁻¹``, so a singular ``A`` is fine and round-off is that of a Kalman update.

``P`` is ``r̄ · NPG`` with ``r̄`` the mean measurement variance of the model —
the error covariance when ``R = r̄ I`` and ``Q = 0``, UFIR's own assumptions.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, one_of
from .errors import needs_linear
from .fir import FIRFilter, _window_from_history
from .fir_gains import GainResult, Window, information_is_regular
from .model import StateSpaceModel
from .registry import register_estimator

METHODS = ("batch", "iterative")


def _stacked_observation(win: Window, t: int) -> tuple[FloatArray, FloatArray]:
    """``C̃`` (rows ``C_j Φ_j``, ``Φ_j = A_{j−1} ⋯ A_0``) and ``Φ_t``, by running the
    transition products forward (``t`` from 0, the smoother's target, to ``L``)."""
    Phi, rows, Phi_t = np.eye(win.A.shape[1]), [], None
    for j in range(win.horizon):
        if j == t:
            Phi_t = Phi
        rows.append(win.C[j] @ Phi)
        Phi = win.A[j] @ Phi
    return np.vstack(rows), Phi if Phi_t is None else Phi_t


def ufir_gain(win: Window, form: str = "filter") -> GainResult:
    """Batch UFIR gain ``S = Φ_t C̃⁺`` (OLS) and its noise power gain ``S Sᵀ``.

    ``form``: ``"filter"`` (``t = L−1``), ``"predictor"`` (``t = L``) or
    ``"smoother"`` (``t = 0``). A rank-deficient ``C̃`` raises ``ValueError``.
    """
    L = win.horizon
    t = {"filter": L - 1, "predictor": L, "smoother": 0}[form]
    Ct, Phi = _stacked_observation(win, t)
    if not information_is_regular(Ct.T @ Ct):
        raise ValueError(f"the stacked observation matrix of the window (horizon={L}) is "
                         "rank-deficient: the UFIR estimate is not defined")
    S = Phi @ np.linalg.lstsq(Ct, np.eye(Ct.shape[0]), rcond=None)[0]
    return GainResult(S, S @ S.T)


def ufir_iterative(win: Window, Z: FloatArray, p: int, form: str = "filter"
                   ) -> tuple[FloatArray, FloatArray]:
    """Shmaliy's iterative UFIR over one window of data (batched over systems).

    ``Z[:, t] = [y_t, u_{t−1}]`` for the window's slots (one extra slot in
    predictor form, carrying the last input). Returns ``(x̂, NPG)``.
    """
    L, n = win.horizon, win.A.shape[1]
    F, Phi, xu = np.zeros((n, n)), np.eye(n), np.zeros((Z.shape[0], n))
    b = np.zeros((Z.shape[0], n))
    for s in range(1, L + 1):                         # batch start on the first s samples
        H = win.C[s - 1] @ Phi
        F = F + H.T @ H
        b = b + (Z[:, s - 1, :p] - xu @ win.C[s - 1].T) @ H
        if information_is_regular(F):
            break
        if s == L:
            raise ValueError(f"the window (horizon={L}) does not determine the state")
        Phi = win.A[s - 1] @ Phi
        xu = xu @ win.A[s - 1].T + Z[:, s, p:] @ win.B[s - 1].T
    x = np.linalg.solve(F, b.T).T @ Phi.T + xu       # x̂_{s−1} = Φ F⁻¹ b + x^u
    G = Phi @ np.linalg.solve(F, Phi.T)
    for j in range(s, L):
        A, C = win.A[j - 1], win.C[j]
        xm = x @ A.T + Z[:, j, p:] @ win.B[j - 1].T
        M = A @ G @ A.T                               # [CᵀC + M⁻¹]⁻¹ by Woodbury:
        MC = M @ C.T
        G = M - MC @ np.linalg.solve(np.eye(C.shape[0]) + C @ MC, MC.T)
        x = xm + (Z[:, j, :p] - xm @ C.T) @ (G @ C.T).T
    if form == "predictor":
        A = win.A[L - 1]
        x, G = x @ A.T + Z[:, L, p:] @ win.B[L - 1].T, A @ G @ A.T
    return x, 0.5 * (G + G.T)


class UFIRFilter(FIRFilter):
    """Unbiased FIR filter (Shmaliy) for linear models; needs no ``Q``, ``R`` or prior.

    Args:
        model: a :class:`~.model.LinearModel` or :class:`~.model.TimeVaryingLinearModel`.
        horizon: measurements in the window; ``form`` as for :class:`~.fir.FIRFilter`.
        method: ``"batch"`` (OLS gain) or ``"iterative"`` (Kalman-like recursion).

    Start-up, inputs, missing data and rank-deficiency fallbacks are those of
    :class:`~.fir.FIRFilter` with ``Q = 0, R = I``. The estimate needs no noise statistics;
    the reported ``P`` is the noise power gain times the measurement variance ``σ² = mean
    diag R`` of the model at ``k = 0`` (:attr:`noise_scale`; for a time-varying ``R``, the
    first step's).
    """

    name: ClassVar[str] = "ufir"

    def __init__(self, model: StateSpaceModel, *, horizon: int, form: str = "filter",
                 method: str = "batch", x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        one_of("method", method, METHODS)
        self.method = method
        super().__init__(model, horizon=horizon, form=form, gain="batch", x0=x0, P0=P0,
                         **options)
        R = self.model.matrices(0).R  # type: ignore[attr-defined]
        self.noise_scale = float(np.mean(np.diag(R)))

    @staticmethod
    def _fir_model(model: StateSpaceModel) -> StateSpaceModel:
        if not hasattr(model, "matrices"):
            raise needs_linear("UFIRFilter", model,
                               "'efir' (ExtendedFIRFilter), the FIR filter of a nonlinear model")
        return model.replace(Q=np.zeros((model.n_w, model.n_w)), R=np.eye(model.n_y))

    def _compute_gain(self, win: Window, prior: FloatArray | None = None) -> GainResult:
        return ufir_gain(win, self._target)

    def _gain_step(self) -> tuple[FloatArray, FloatArray, np.ndarray]:
        h = min(self._state.k + (self.form == "filter"), self.horizon)
        Z, V = self._window_data(h + (self.form == "predictor"))
        if self.method == "batch" or h == 0 or not V[:, :h].all():
            return super()._gain_step()
        if self.time_invariant:
            win = self._win
        else:
            win = _window_from_history(self._hist, h, self.form)
        try:
            x, G = ufir_iterative(win, Z, self._p, self.form)
        except ValueError:
            nb, n = Z.shape[0], self._n
            return np.zeros((nb, n)), np.zeros((nb, n, n)), np.zeros(nb, bool)
        return x, np.broadcast_to(G, (Z.shape[0], self._n, self._n)), np.ones(len(x), bool)

    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        x, P, _ = super()._advance(y, u, valid)
        bad = np.atleast_1d(self._info["rank_deficient"])
        return x, np.where(bad[:, None, None], P, self.noise_scale * P), None


register_estimator("ufir", UFIRFilter)
