"""The minimum-variance unbiased FIR filter for linear models (papers 000 and 004).

Over a window of the last ``horizon = L`` measurements the estimate is
``x̂ = S Y + S_u U`` with ``S`` the minimum-variance gain subject to the
unbiasedness constraint ``S C̃ = Φ`` (paper 000 Theorem 1, corrected; paper 004
Cor 2.2) and ``S_u`` the known-input correction (:func:`~.fir_gains.input_gain`).
It uses no prior: the window's start state is a free parameter, so the estimate
depends on the last ``L`` measurements only (finite memory, BIBO). Optionally
(``prior=``) paper 004's minimum-variance FIR filter for a zero-mean process with
a prior on the window-start state (Theorem 2.1; Cor 2.1 for the stationary one).
"""

from __future__ import annotations

from collections import deque
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._fir_bank import WindowBank
from ._observability import index_along, observability_index, require_window
from ._validation import FloatArray, as_covariance, one_of, positive
from ._windowed import InnovationTerms, WindowedEstimator
from .errors import needs_linear
from .fir_gains import (
    WINDOW_FORMS,
    GainResult,
    Window,
    batch_gain,
    input_gain,
    make_window,
    riccati_gain,
    stationary_prior,
    two_stage_gain,
    window_from_matrices,
)
from .model import StateSpaceModel
from .registry import register_estimator

GAINS = {"two-stage": two_stage_gain, "batch": batch_gain, "riccati": riccati_gain}


class FIRFilter(WindowedEstimator):
    """Minimum-variance unbiased FIR filter (papers 000 and 004) for linear models.

    Args:
        model: a :class:`~.model.LinearModel` or :class:`~.model.TimeVaryingLinearModel`
            (``R`` positive definite).
        horizon: ``L``, the number of measurements in the window (paper 004's ``N``
            counts intervals: its window is ``horizon = N + 1``).
        form: ``"filter"`` — window ``y[k-L+1..k]``, estimates ``x[k]``;
            ``"predictor"`` — window ``y[k-L..k-1]`` (paper 000's form).
        gain: ``"two-stage"`` (path (c), default), ``"batch"`` (path (a), paper 000
            Theorem 1) or ``"riccati"`` (path (b), paper 004 Cor 2.2 — needs an
            invertible A — or Theorem 2.1 with a prior). All agree to round-off.
        prior: ``None`` (unbiased, default); ``"stationary"`` (paper 004 Cor 2.1: the
            window-start state has the stationary covariance, stable A) or a
            covariance ``Π0`` of the window-start state about the zero-input
            response. Time-invariant models only.
        x0, P0: used only while the window is not yet informative (start-up, below).

    **Time-invariant models** compute ``S`` and ``S_u`` once (without a prior a
    window shorter than the observability index raises ``ValueError`` here) and
    apply them as one matmul over a ring buffer of ``[y_t, u_{t−1}]``.
    **Time-varying models**: with ``gain="two-stage"`` a
    :class:`~._fir_bank.WindowBank` of ``L`` staggered windows (no explicit gain);
    otherwise the gain of the current window is recomputed every step.

    **Inputs.** ``x̂ = S (Y − D̃ U) + M_B U = S Y + S_u U``: the gain acts on the
    measurements minus their known input response, which keeps ``x̂`` exact on
    noise-free data whatever the inputs.

    **Start-up** (``last_info["startup"]``, while fewer than ``L`` measurements are
    in the window): the growing-window estimate — the same estimator over the
    measurements so far, computed by the two-stage recursion whatever ``gain`` —
    once they determine the state; before that the prior mean ``x0`` propagated
    open loop (``A x + B u``) with covariance ``A P Aᵀ + GQGᵀ`` from ``P0``.
    :meth:`restart` sends chosen systems of a batch through start-up again (their
    windows restart; the others do not notice). A time-varying model's matrices
    stay indexed by the filter's step count for every system.

    **Rank deficiency at run time** (a time-varying window, or missing
    measurements under ``nan_policy="skip"``, that does not determine the state):
    ``last_info["rank_deficient"]`` is True for that system and the estimate is the
    previous one predicted through the model, ``A x̂ + B u``, ``A P Aᵀ + GQGᵀ``.
    A window with a missing measurement but still of full rank is estimated
    exactly from the remaining ones (the two-stage recursion skips the gap).
    """

    name: ClassVar[str] = "fir"
    uses_prior: ClassVar[bool] = False
    _smoother: ClassVar[bool] = False
    _extra_slots: ClassVar[int] = 0          # buffer slots kept beyond the window

    def __init__(self, model: StateSpaceModel, *, horizon: int, form: str = "filter",
                 gain: str = "two-stage", prior: str | ArrayLike | None = None,
                 x0: ArrayLike | None = None, P0: ArrayLike | None = None,
                 **options: Any) -> None:
        if not (isinstance(model, StateSpaceModel) and model.is_linear
                and hasattr(model, "matrices")):
            raise needs_linear(type(self).__name__, model,
                               "'efir' (ExtendedFIRFilter), the FIR filter of a nonlinear model")
        self.horizon = positive("horizon", horizon, integer=True)
        one_of("form", form, WINDOW_FORMS)
        one_of("gain", gain, sorted(GAINS))
        self.form, self.gain = form, gain
        self._target = "smoother" if self._smoother else form
        self.time_invariant = bool(getattr(model, "time_invariant", False))
        self._window_slots = self.horizon + (form == "predictor")
        self._slots = self._window_slots + self._extra_slots
        self._n, self._p, self._nu = model.n_x, model.n_y, model.n_u
        self._model = self._fir_model(model)
        as_covariance("model.R", self._model.matrices(0).R, definite=True)  # type: ignore
        self._prior = self._prior_covariance(prior)
        if self.time_invariant:
            self._fixed_gain()
        elif self._prior is None:                     # the one rule, along k = 0, 1, ...
            steps = max(self._n, self.horizon)
            mats = [self._model.matrices(k) for k in range(steps)]  # type: ignore[attr-defined]
            require_window(self.horizon, index_along(((m.A, m.C) for m in mats), mats[0].R),
                           "(A_k, C_k) from k = 0", steps)
        super().__init__(model, x0=x0, P0=P0, **options)

    @staticmethod
    def _fir_model(model: StateSpaceModel) -> StateSpaceModel:
        """The model whose matrices define the gain (UFIR swaps in ``Q = 0, R = I``)."""
        return model

    def _prior_covariance(self, prior: str | ArrayLike | None) -> FloatArray | None:
        if prior is None:
            return None
        if not self.time_invariant:
            raise ValueError("prior= needs a time-invariant model")
        m = self._model.matrices(0)  # type: ignore[attr-defined]
        if isinstance(prior, str):
            if prior != "stationary":
                raise ValueError(f"prior must be None, 'stationary' or a covariance; "
                                 f"got {prior!r}")
            return stationary_prior(m.A, m.G @ m.Q @ m.G.T)
        return as_covariance("prior", prior, self._n)

    # ------------------------------------------------------------------ set-up
    def _fixed_gain(self) -> None:
        L, mats = self.horizon, self._model.matrices(0)  # type: ignore[attr-defined]
        self._win = make_window(mats.A, mats.C, mats.G @ mats.Q @ mats.G.T, mats.R, L, mats.B)
        if self._prior is None:                       # the one rule (_observability)
            require_window(L, observability_index(mats.A, mats.C, mats.R), "(A, C)",
                           self._n)
        try:
            res = self._compute_gain(self._win, self._prior)
        except ValueError as err:
            raise ValueError(f"horizon={L}: {err}") from None
        self._G = _combined_gain(res.S, input_gain(self._win, res.S, self._target),
                                 self.form, self._p, self._nu)
        self._P_fir = res.P

    def _compute_gain(self, win: Window, prior: FloatArray | None = None) -> GainResult:
        """The gain of one window for this filter's target (``gain=`` path)."""
        return GAINS[self.gain](win, self._target, prior)

    def _innovation_terms(self, y: FloatArray, u: FloatArray | None, predict: np.ndarray,
                          x: FloatArray) -> InnovationTerms:
        """The plant model's (``model``, not UFIR's ``Q = 0, R = I``) one-step prediction
        from the previous estimate: ``x⁻ = A x̂ + B u``, ``e = y − C x⁻`` (matrices of
        ``k − 1`` and ``k``; a time-invariant model's are prepared once)."""
        k = self._state.k
        if self.time_invariant:
            terms = getattr(self, "_test_matrices", None)
            if terms is None:
                m = self.model.matrices(0)  # type: ignore[attr-defined]
                # fresh C-ordered copies: a view's stride-0 leading axis (``A[None]``) would
                # take another matmul loop than its pickled copy (make_window says why)
                terms = self._test_matrices = tuple(M.copy(order="C") for M in (
                    m.A.T, m.B.T, m.C.T, m.A[None], (m.G @ m.Q @ m.G.T)[None], m.C[None], m.R))
            At, Bt, Ct, A, Qx, C, R = terms
        else:
            now = self.model.matrices(k)  # type: ignore[attr-defined]
            prev = self.model.matrices(max(k - 1, 0))  # type: ignore[attr-defined]
            At, Bt, Ct, A, Qx, C, R = (prev.A.T, prev.B.T, now.C.T, prev.A[None],
                                       (prev.G @ prev.Q @ prev.G.T)[None], now.C[None], now.R)
        if not k:
            return y - x @ Ct, A, Qx, C, R                 # the prior (predict is False)
        x_pred = x @ At
        if u is not None and self._nu:
            x_pred += u @ Bt
        if not predict.all():
            x_pred = np.where(predict[:, None], x_pred, x)
        return y - x_pred @ Ct, A, Qx, C, R

    def _reset_state(self) -> None:
        self._hist: deque[Any] = deque(maxlen=self._slots)
        self._bank: WindowBank | None = None          # staggered windows (time-varying)
        self._growing: WindowBank | None = None       # the start-up (growing) window
        self._pending: np.ndarray | None = None       # systems restarted, not yet stepped
        self._info: dict[str, Any] = {}

    def _init_batch(self, n_batch: int) -> None:
        d = self._p + self._nu
        self._buf = np.zeros((n_batch, 2 * self._slots, d))
        self._vbuf = np.ones((n_batch, 2 * self._slots), bool)
        self._x_open, self._P_open = self._state.x.copy(), self._state.P.copy()
        self._age = np.zeros(n_batch, int)            # measurements since (re)start
        if not self.time_invariant and self.gain == "two-stage":
            self._bank = WindowBank(n_batch, self.horizon, self._n)
        else:
            self._growing = WindowBank(n_batch, 1, self._n)

    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        s = self._state
        k, nb, n = s.k, y.shape[0], self._n
        mats = self._model.matrices(0 if self.time_invariant else k)  # type: ignore[attr-defined]
        prev = self._hist[-1] if self._hist else None
        self._evicted = self._hist[0] if len(self._hist) == self._slots else prev
        self._hist.append(mats)
        Bu = None if (u is None or not self._nu or prev is None) else u @ prev.B.T
        fresh, self._pending = self._pending, None
        start = self._age < self._window_slots - 1    # per system: window not yet full
        any_start = bool(start.any())
        if prev is not None and any_start:            # the prior mean, propagated open loop
            self._x_open, self._P_open = _predict(prev, self._x_open, self._P_open, Bu)
        if fresh is not None:
            self._x_open[fresh] = np.broadcast_to(self._x0, (nb, n))[fresh]
            self._P_open[fresh] = np.broadcast_to(self._P0, (nb, n, n))[fresh]
        self._push(y, u, valid)
        if self._bank is not None:
            x, P, ok = self._bank_step(self._bank, mats, prev, y, Bu, valid, fresh, None)
            P = 0.5 * (P + P.swapaxes(1, 2))
        else:
            if k >= self._window_slots - 1:
                x, P, ok = self._gain_step()
            else:
                x, P, ok = np.zeros((nb, n)), np.zeros((nb, n, n)), np.zeros(nb, bool)
            if any_start:
                assert self._growing is not None
                xs, Ps, oks = self._bank_step(self._growing, mats, prev, y, Bu, valid, fresh,
                                              ~start)
                x, ok = np.where(start[:, None], xs, x), np.where(start, oks, ok)
                P = np.where(start[:, None, None], 0.5 * (Ps + Ps.swapaxes(1, 2)), P)
        if not ok.all():
            xf, Pf = self._fallback(start, prev, Bu)
            x = np.where(ok[:, None], x, xf)
            P = np.where(ok[:, None, None], P, 0.5 * (Pf + Pf.swapaxes(1, 2)))
        self._age += 1
        self._last_xP = (x, P)
        self._info = {"startup": bool(start[0]) if s.single else start,
                      "rank_deficient": (not ok[0]) if s.single else ~ok}
        return x, P, None

    def _fallback(self, start: np.ndarray, prev: Any, Bu: FloatArray | None
                  ) -> tuple[FloatArray, FloatArray]:
        """Start-up: the propagated prior; later: the previous estimate predicted."""
        if prev is None or start.all():
            return self._x_open, self._P_open
        x, P = _predict(prev, self._state.x, self._state.P, Bu)
        return (np.where(start[:, None], self._x_open, x),
                np.where(start[:, None, None], self._P_open, P))

    def _push(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray) -> None:
        pos, s, p = self._state.k % self._slots, self._slots, self._p
        for q in (pos, pos + s):
            self._buf[:, q, :p] = y
            self._buf[:, q, p:] = 0.0 if u is None else u
            self._vbuf[:, q] = valid

    def _window_data(self, h: int) -> tuple[FloatArray, np.ndarray]:
        """The last ``h`` slots ``[y_t, u_{t−1}]`` (oldest first) and their y-validity."""
        end = self._state.k % self._slots + self._slots + 1
        return self._buf[:, end - h:end], self._vbuf[:, end - h:end]

    def _bank_step(self, bank: WindowBank, mats: Any, prev: Any, y: FloatArray,
                   Bu: FloatArray | None, valid: np.ndarray, fresh: np.ndarray | None,
                   idle: np.ndarray | None) -> tuple[FloatArray, FloatArray, np.ndarray]:
        """Advance a window bank by one measurement and read out its oldest window.

        A staggered bank (``W = L``) restarts the window that starts now; the growing
        bank (``W = 1``) only restarts systems that are ``fresh`` (restarted) or
        ``idle`` (past start-up, kept clean), so for the others it grows.
        """
        k, W = self._state.k, bank.W
        if prev is not None:
            Qx = prev.G @ prev.Q @ prev.G.T
            bank.predict(prev.A[None], Bu, Qx if np.any(Qx) else None)
        clear = fresh if idle is None else (idle if fresh is None else idle | fresh)
        if clear is not None and clear.any():
            bank.Z[clear] = bank.blank[None, :, None, :]
        smoother = self._smoother
        if self.form == "predictor":
            x, P, ok = bank.estimate(max(0, k - W) % W, smoother, self._prior)
        if idle is None:
            bank.restart(k % W)
        bank.update(mats.C[None], mats.R, y, valid)
        if self.form == "filter":
            x, P, ok = bank.estimate(max(0, k - W + 1) % W, smoother, self._prior)
        return x, P, ok

    def _gain_step(self) -> tuple[FloatArray, FloatArray, np.ndarray]:
        h = min(self._state.k + (self.form == "filter"), self.horizon)
        nb, n = self._buf.shape[0], self._n
        win: Window | None
        if self.time_invariant:
            G, P, win = self._G, self._P_fir, self._win
        else:
            win = _window_from_history(self._hist, h, self.form) if h else None
            try:
                res = self._compute_gain(win) if win else None
            except ValueError:
                res = None
            if win is None or res is None:
                return np.zeros((nb, n)), np.zeros((nb, n, n)), np.zeros(nb, bool)
            G = _combined_gain(res.S, input_gain(win, res.S, self._target), self.form,
                               self._p, self._nu)
            P = res.P
        Z, V = self._window_data(G.shape[1])
        x = Z.reshape(nb, -1) @ G.reshape(n, -1).T
        P = np.broadcast_to(P, (nb, n, n))
        ok = np.ones(nb, bool)
        gaps = ~V[:, :h].all(axis=1)
        if gaps.any():
            xg, Pg, okg = masked_window_estimate(win, Z[gaps], V[gaps], self._p,
                                                 self._target, self._prior)
            x, P = x.copy(), P.copy()
            x[gaps], P[gaps], ok[gaps] = xg, Pg, okg
        return x, P, ok


def _predict(m: Any, x: FloatArray, P: FloatArray, Bu: FloatArray | None
             ) -> tuple[FloatArray, FloatArray]:
    """``A x + B u``, ``A P Aᵀ + GQGᵀ`` (batched)."""
    x = x @ m.A.T + (0.0 if Bu is None else Bu)
    return x, m.A @ P @ m.A.T + m.G @ m.Q @ m.G.T


def _combined_gain(S: FloatArray, Su: FloatArray, form: str, p: int, nu: int) -> FloatArray:
    """Gain over buffer slots ``[y_t, u_{t−1}]`` (``(n, slots, p + n_u)``, oldest slot first)."""
    n, h = S.shape[0], S.shape[1] // p
    slots = h + (form == "predictor")
    G = np.zeros((n, slots, p + nu))
    G[:, :h, :p] = S.reshape(n, h, p)
    if nu:
        G[:, 1:, p:] = Su.reshape(n, h, nu)[:, :slots - 1]
    return G


def _window_from_history(hist: deque, h: int, form: str) -> Window:
    """The :class:`Window` of the last ``h`` measurement instants from stored matrices."""
    return window_from_matrices(list(hist)[-h - 1:-1] if form == "predictor" else list(hist)[-h:])


def masked_window_estimate(win: Window, Z: FloatArray, V: np.ndarray, p: int, form: str,
                           prior: FloatArray | None = None
                           ) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Two-stage estimate over one stored window, skipping missing measurements.

    ``Z[:, t] = [y_t, u_{t−1}]`` (oldest slot first, one extra slot in predictor
    form), ``V[:, t]`` whether ``y_t`` is usable; ``form`` names the target.
    """
    h, n = win.horizon, win.A.shape[1]
    bank = WindowBank(Z.shape[0], 1, n)
    for j in range(h):
        if j:
            bank.predict(win.A[j - 1][None], Z[:, j, p:] @ win.B[j - 1].T, win.Qx[j - 1])
        bank.update(win.C[j][None], win.R[j], Z[:, j, :p], V[:, j])
    if form == "predictor":
        bank.predict(win.A[h - 1][None], Z[:, h, p:] @ win.B[h - 1].T, win.Qx[h - 1])
    return bank.estimate(0, form == "smoother", prior)


register_estimator("fir", FIRFilter)
