"""The extended FIR filter of paper 000 (Han, Kwon & Han, EFIRF).

The state is split into a nominal trajectory and a perturbation (paper 000
eqs 3-11)::

    x_nom[k] = f(x_nom[k-1], u[k-1])                          (4)
    δx[k] ≈ F[k-1] δx[k-1] + w[k-1],   F[k-1] = ∂f/∂x|x_nom    (5), (6)
    δy[k] = y[k] − h(x_nom[k]) ≈ H[k] δx[k] + v[k]            (7)-(10)
    x̂[k] = x_nom[k] + δx̂[k]                                  (11)

and ``δx̂`` is the time-varying minimum-variance unbiased FIR estimate over the
window (eq 12-13, gain of Theorem 1). Here the gain is never formed: a
:class:`~.fir.WindowBank` runs the two-stage recursion (path (c) of
:mod:`~.fir_gains`, no ``F⁻¹``) for ``horizon`` staggered windows in lock-step,
so one step costs one model linearisation plus O(1) vectorised updates.

Nominal trajectories (``nominal=``):

* ``"open-loop"`` (paper 000): one nominal per system, run open loop from the
  filter's initial state ``x0`` with the inputs it is given. With model error it
  drifts away from the truth; the perturbation model is then linearised far from
  where the system is, and the neglected second-order terms grow with the drift.
* ``"reanchor"``: every window carries its own nominal, started at the window's
  first instant ``s`` from the filter's prediction of ``x[s]`` made before
  ``y[s]`` arrives (``f(x̂[s−1], u[s−1])``; in predictor form ``x̂[s]`` itself).
  Re-anchoring at the window start, never inside a window, keeps each window's
  perturbation model one consistent linearisation. The anchor is *not* used as
  information: the perturbation at the window start stays a free (diffuse)
  parameter, so the estimate is unbiased whatever the anchor, and on a linear
  model it equals :class:`~.fir.FIRFilter` exactly — the window's data alone
  determine it. On a nonlinear model the anchor only moves the linearisation
  point (a second-order effect), and it is never older than ``horizon`` steps.

With ``Q = 0`` (paper 000 sim 1, Orbit-v0) the Kalman part of the recursion is
identically zero (``P = 0``, ``K = 0``) and the minimum-variance unbiased gain
reduces to weighted least squares of the window start on the stacked
observation matrix — the model is trusted exactly within the window, so model
error enters only as a bias that the finite window keeps bounded; with a scalar
``R`` this is Shmaliy's UFIR (:mod:`~.ufir`), independent of ``R``'s size.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._fir_bank import WindowBank
from ._observability import index_along, require_window
from ._validation import FloatArray, as_covariance, one_of, positive
from ._windowed import InnovationTerms, WindowedEstimator
from .fir_gains import WINDOW_FORMS
from .model import StateSpaceModel
from .registry import register_estimator

STARTUPS = ("diffuse", "prior")
NOMINALS = ("open-loop", "reanchor")


class ExtendedFIRFilter(WindowedEstimator):
    """Extended FIR filter (paper 000) on any :class:`~.model.StateSpaceModel` with ``F, H``.

    Args:
        model: the plant model (its ``F``/``H`` are used along the nominal).
        horizon: ``N``, measurements per window (Orbit-v0: one per env step).
        form: ``"filter"`` (window ``y[k-N+1..k]``) or ``"predictor"`` (paper 000,
            window ``y[k-N..k-1]``).
        nominal: ``"open-loop"`` (paper) or ``"reanchor"`` (see the module docstring).
        x0: the nominal's initial state (paper 000: "the filter's initial state").
        P0: the start-up covariance (and, with ``startup="prior"``, the prior's).
        startup: what the filter returns while its window is not yet full:
            ``"diffuse"`` (default) or ``"prior"`` (below).

    Start-up (``last_info["startup"]``), ``startup="diffuse"``: the growing-window
    estimate once the measurements so far determine the perturbation — unbiased
    whatever ``x0`` is, but from two or three samples a velocity is a difference of
    noisy positions (Orbit-v0: σ up to ≈ 4) —, the nominal trajectory before that
    (covariance ``P0`` propagated along it). ``startup="prior"``: the window that
    began at ``x0`` takes ``(x0, P0)`` as the prior of its start state, i.e. the
    two-stage normal equations get ``P0⁻¹`` added (``V = (P0⁻¹ + F)⁻¹``) and the
    estimate is the Kalman filter's from that prior on the linearised model — what
    a controller wants at the start of an episode whose initial distribution is
    known. Once the window is full the filter is the unbiased FIR filter either way
    (the prior has left the window). A full window whose
    linearisation does not determine the state (``last_info["rank_deficient"]``)
    falls back to the previous estimate predicted through ``f`` (and ``F P Fᵀ +
    GQGᵀ``). :meth:`restart` starts chosen systems of a batch again from ``x0``
    (nominal, windows and start-up); the others do not notice.

    One step is one pass over the windows (:meth:`_advance`): the model's ``f, F`` on
    the nominal, the window bank's time update, ``h, H`` on the nominal, its measurement
    update and the read-out of the oldest window — the bank's operations and the
    divergence watch run their compiled twins where numba is enabled, for one system
    and a batch alike.
    """

    name: ClassVar[str] = "efir"
    uses_prior: ClassVar[bool] = False

    def __init__(self, model: StateSpaceModel, *, horizon: int, form: str = "filter",
                 nominal: str = "open-loop", x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, startup: str = "diffuse",
                 **options: Any) -> None:
        if not isinstance(model, StateSpaceModel) or not getattr(model, "time_invariant", True):
            raise TypeError(f"{type(self).__name__} needs a StateSpaceModel with f, h, F, H; "
                            f"got {type(model).__name__}")
        self.horizon = positive("horizon", horizon, integer=True)
        one_of("form", form, WINDOW_FORMS)
        one_of("nominal", nominal, NOMINALS)
        one_of("startup", startup, STARTUPS)
        self.form, self.nominal, self.startup = form, nominal, startup
        self._R = as_covariance("model.R", model.R, definite=True)
        Qx = np.asarray(model.GQGT)
        self._Qx = Qx if np.any(Qx) else None
        super().__init__(model, x0=x0, P0=P0, **options)
        self._f, self._F, self._h, self._H = model.unchecked_callables()
        self._linearize = model.unchecked_linearizer()
        self._require_observable_nominal()

    def _require_observable_nominal(self) -> None:
        """The one observability rule (:mod:`._observability`) along the nominal: ``F, H`` on
        the open-loop trajectory from ``x0`` (every system's, for a batched prior) with zero
        input, over ``max(4 n, horizon)`` measurements."""
        n = self.model.n_x
        steps = max(4 * n, self.horizon)
        X = X0 = np.array(self._x0, dtype=float).reshape(-1, n)
        U = np.zeros((X.shape[0], self.model.n_u))
        pairs = []
        with np.errstate(all="ignore"):
            for _ in range(steps):
                C = self._H(X)
                X, A = self._linearize(X, U)
                pairs.append((A, C))
            index = index_along(pairs, self._R)
        start = np.array2string(X0[0] if len(X0) == 1 else X0, precision=4, separator=", ")
        where = f"its nominal from x0={start}" + ("" if self.nominal == "open-loop" else
                                         " (the first windows' anchor)")
        require_window(self.horizon, index, where, steps)

    @property
    def x_nominal(self) -> FloatArray | None:
        """The open-loop nominal (``"open-loop"``) or the newest window's anchored nominal."""
        if self._nom is None:
            return None
        nom = self._nom if self._nom.ndim == 2 else self._nom[:, self._k_last % self.horizon]
        return nom[0].copy() if self._state.single else nom.copy()

    def _innovation_terms(self, y: FloatArray, u: FloatArray | None, predict: np.ndarray,
                          x: FloatArray) -> InnovationTerms:
        """The model along the previous estimate: ``x⁻ = f(x̂, u)``, ``A = F(x̂, u)``,
        ``e = y − h(x⁻)``, ``H(x⁻)`` — the EKF's prediction from the EFIR's estimate."""
        n = x.shape[1]
        if self._state.k and predict.any():
            x_pred, A = self._linearize(x, u)
            if not predict.all():
                x_pred = np.where(predict[:, None], x_pred, x)
        else:
            x_pred, A = x, np.eye(n)[None]
        Qx = np.zeros((1, n, n)) if self._Qx is None else self._Qx[None]
        return y - self._h(x_pred), A, Qx, self._H(x_pred), self._R

    def _reset_state(self) -> None:
        self._nom: FloatArray | None = None
        self._bank: WindowBank | None = None
        self._pending: np.ndarray | None = None       # systems restarted, not yet stepped
        self._info: dict[str, Any] = {}
        self._k_last = 0

    def _init_batch(self, n_batch: int) -> None:
        s = self._state
        n, L = self.model.n_x, self.horizon
        self._bank = WindowBank(n_batch, L, n)
        self._P_open = s.P.copy()
        self._age = np.zeros(n_batch, int)            # measurements since (re)start
        self._in_startup = True                       # some system's window is not full
        self._no_startup = np.zeros(n_batch, bool)
        if self.nominal == "open-loop":
            self._nom = s.x.copy()
        else:
            self._nom = np.repeat(s.x[:, None, :], L, axis=1)

    def _restart_systems(self, mask: np.ndarray) -> None:
        super()._restart_systems(mask)
        self._in_startup = True

    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        bank, k, L = self._bank, self._state.k, self.horizon
        assert bank is not None and self._nom is not None
        nb, n = y.shape[0], self.model.n_x
        filt = self.form == "filter"
        fresh, self._pending = self._pending, None
        if fresh is not None or self._in_startup:      # per system: window not yet full
            start = self._age < L - filt
            self._in_startup = bool(start.any())
        else:
            start = self._no_startup
        w_out = max(0, k - L + filt) % L               # the oldest window: read out now
        if k:                                          # nominal and perturbation time update
            assert u is not None
            nom = self._nom.reshape(-1, n)
            uu = u if self._nom.ndim == 2 else np.repeat(u, L, axis=0)
            nom_next, A = self._linearize(nom, uu)      # f and F in one pass of the plant
            self._nom = nom_next.reshape(self._nom.shape)
            A = A.reshape(self._nom.shape + (n,))
            bank.predict(A, None, self._Qx)
            if self._in_startup:                       # prior covariance along x0's nominal
                A0 = A if A.ndim == 3 else A[:, w_out]
                self._P_open = A0 @ self._P_open @ A0.swapaxes(1, 2) + (
                    0.0 if self._Qx is None else self._Qx)
        if fresh is not None:                          # restarted systems begin again at x0
            x0 = np.broadcast_to(self._x0, (nb, n))[fresh]
            self._nom[fresh] = x0 if self._nom.ndim == 2 else x0[:, None, :]
            self._P_open[fresh] = np.broadcast_to(self._P0, (nb, n, n))[fresh]
            bank.Z[fresh] = bank.blank[None, :, None, :]
        s = k % L
        if not filt:
            x, P, ok = self._readout(w_out, u, start)
        if self._nom.ndim == 3:                        # re-anchor the window starting now
            anchor = x if not filt else (self._f(self._state.x, u) if k else self._state.x)
            if fresh is not None and filt:
                anchor = np.where(fresh[:, None], self._nom[:, s], anchor)
            self._nom[:, s] = anchor
        bank.restart(s)
        nom = self._nom.reshape(-1, n)
        C, h = self._H(nom), self._h(nom)
        if self._nom.ndim == 3:
            C, dy = C.reshape(nb, L, *C.shape[1:]), y[:, None, :] - h.reshape(nb, L, -1)
        else:
            dy = y - h
        bank.update(C, self._R, dy, None if valid.all() else valid)
        if filt:
            x, P, ok = self._readout(w_out, u, start)
        self._age += 1
        self._last_xP = (x, P)
        self._info = {"startup": bool(start[0]) if self._state.single else start.copy(),
                      "rank_deficient": (not ok[0]) if self._state.single else ~ok}
        self._k_last = k
        return x, P, None

    def _nominal_of(self, w: int) -> FloatArray:
        assert self._nom is not None
        return self._nom if self._nom.ndim == 2 else self._nom[:, w]

    def _readout(self, w: int, u: FloatArray | None, start: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, np.ndarray]:
        """Window ``w``'s estimate ``x_nom + δx̂``, with the documented fallback where singular."""
        s = self._state
        dx, P, ok = self._bank.estimate(w)             # type: ignore[union-attr]
        if self.startup == "prior" and start.any():   # the window that began at x0
            n = dx.shape[1]
            prior = np.broadcast_to(self._P0, (dx.shape[0], n, n))
            dxp, Pp, _ = self._bank.estimate(w, prior=prior)  # type: ignore[union-attr]
            dx = np.where(start[:, None], dxp, dx)
            P = np.where(start[:, None, None], Pp, P)
            ok = ok | start
        x = (self._nom if self._nom.ndim == 2 else self._nom[:, w]) + dx  # type: ignore
        if not ok.all():
            xf, Pf = self._nominal_of(w), self._P_open    # start-up: x0's nominal, P0 along it
            if s.k and not start.all():
                xp, A = self._linearize(s.x, u)
                Pp = A @ s.P @ A.swapaxes(1, 2) + (0.0 if self._Qx is None else self._Qx)
                xf = np.where(start[:, None], xf, xp)
                Pf = np.where(start[:, None, None], Pf, Pp)
            x = np.where(ok[:, None], x, xf)
            P = np.where(ok[:, None, None], P, Pf)
        return x, P, ok


register_estimator("efir", ExtendedFIRFilter)
