"""The FIR smoother of paper 004 §III: the window-start state from the window.

Over the window ``y[k-L+1..k]`` it estimates ``x[k-L+1]``, the state at the first
measurement (paper 004 eq 3.1: ``x̂_s(i−N|N) = Σ_{k=i−N}^{i} H_s(i−N, k; N) z(k)``,
with ``L = N + 1``).

* **No prior** (the unbiased, diffuse-start smoother): the generalised
  least-squares estimate of the window-start state,
  ``x̂_s = (C̃ᵀΠ⁻¹C̃)⁻¹C̃ᵀΠ⁻¹ (Y − D̃ U)``. Paper 004's Cor 3.2 computes it through
  ``[S(n+1) − CᵀC]⁻¹``, which is singular whenever there are fewer outputs than
  states (docs/papers.md#004-cor-3-2), so it is computed stably instead: by the two-stage
  recursion, where it is ``F⁻¹ b`` — the start-state estimate the FIR filter
  already forms (path (c), default) — or by the batch formula (path (a)).
* **With a prior** ``x[k-L+1] ~ N(0, Π0)`` (``prior="stationary"``: Cor 3.1's
  stationary covariance): paper 004 Theorem 3.1 (``gain="riccati"``; its first form
  of ``W(i, n+1)``, the printed second form drops a trailing ``M(i, n)``), or
  ``(Π0⁻¹ + F)⁻¹ b`` by the two-stage recursion, or the batch formula
  ``Π0 C̃ᵀ (C̃ Π0 C̃ᵀ + Π)⁻¹``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray
from .fir import FIRFilter, _combined_gain
from .fir_gains import input_gain
from .model import StateSpaceModel
from .registry import register_estimator


class FIRSmoother(FIRFilter):
    """Fixed-lag FIR smoother (paper 004 §III): ``step`` returns the estimate of ``x[k-L+1]``.

    Args:
        model: a :class:`~.model.LinearModel` or :class:`~.model.TimeVaryingLinearModel`.
        horizon: ``L``, measurements in the window ``y[k-L+1..k]``; the lag is ``L − 1``.
        gain: ``"two-stage"`` (default), ``"batch"`` or ``"riccati"`` (Theorem 3.1,
            only with a prior — the no-prior Cor 3.2 is singular when outputs < states).
        prior: ``None`` (unbiased), ``"stationary"`` or a covariance of the
            window-start state (time-invariant models only).
        x0, P0: the prior of ``x[0]``, returned until the window determines it.

    ``last_info["time"]`` is the index of the estimated state. Start-up: until
    the window is full the target is ``x[0]``, estimated from the measurements so
    far once they determine it (else ``x0``, ``P0``). After start-up a
    rank-deficient window (``last_info["rank_deficient"]``) returns the previous
    smoothed estimate predicted one step.

    **Consistency** (docs/architecture.md#windowed-consistency). The smoothed estimate
    lags the newest measurement, so the innovation test predicts ``y[k]`` from the FIR
    *filter* estimate of ``x[k−1]`` over the same window — the same data, the filter's
    gain and error covariance — and, during start-up, from the prior propagated open loop
    (the filter's start-up fallback). The test does not count for a time-varying model,
    a window with a missing measurement or a rank-deficient one (``nis`` is NaN there).
    """

    name: ClassVar[str] = "fir-smoother"
    _smoother: ClassVar[bool] = True

    def __init__(self, model: StateSpaceModel, *, horizon: int, gain: str = "two-stage",
                 prior: str | ArrayLike | None = None, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        if gain == "riccati" and prior is None:
            raise ValueError("gain='riccati' needs a prior for the smoother: paper 004 Cor 3.2 "
                             "(no prior) needs [S(n+1) - C'C]^-1, singular when outputs < "
                             "states; use gain='two-stage' or 'batch'")
        super().__init__(model, horizon=horizon, form="filter", gain=gain, prior=prior,
                         x0=x0, P0=P0, **options)

    def _fixed_gain(self) -> None:
        super()._fixed_gain()                          # the smoother's gain, self._G
        self._target = "filter"                        # the filter's, for the test
        try:
            res = self._compute_gain(self._win, self._prior)
        finally:
            self._target = "smoother"
        self._G_filter = _combined_gain(res.S, input_gain(self._win, res.S, "filter"),
                                        "filter", self._p, self._nu)
        self._P_filter = res.P

    def _init_batch(self, n_batch: int) -> None:
        super()._init_batch(n_batch)
        self._x_test, self._P_test = self._state.x.copy(), self._state.P.copy()
        self._test_ok = np.ones(n_batch, bool)

    def _consistency_prior(self) -> tuple[FloatArray, FloatArray, np.ndarray | None]:
        x, P, ok = self._x_test, self._P_test, self._test_ok
        if self._state.restarting:                           # restarted systems: their prior
            fresh = self._state.fresh
            nb, n = x.shape
            x = np.where(fresh[:, None], np.broadcast_to(self._x0, (nb, n)), x)
            P = np.where(fresh[:, None, None], np.broadcast_to(self._P0, (nb, n, n)), P)
            ok = ok | fresh
        return x, P, ok

    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        start = self._age < self._window_slots - 1     # before the pass counts this sample
        x, P, _ = super()._advance(y, u, valid)
        ok = (~np.atleast_1d(self._info["rank_deficient"]) | start) & self.time_invariant
        x_f, P_f = self._x_open.copy(), self._P_open.copy()
        full = ~start
        if self.time_invariant and full.any():        # the filter over the same window
            Z, V = self._window_data(self._G_filter.shape[1])
            xw = Z.reshape(Z.shape[0], -1) @ self._G_filter.reshape(self._n, -1).T
            x_f[full], P_f[full] = xw[full], self._P_filter
            ok &= V[:, -self.horizon:].all(axis=1) | start
        self._x_test, self._P_test, self._test_ok = x_f, P_f, ok
        return x, P, None

    @property
    def lag(self) -> int:
        """Steps between the newest measurement and the estimated state (``horizon − 1``)."""
        return self.horizon - 1

    def _step_info(self) -> dict[str, Any]:
        t = np.maximum(0, self._age - self.horizon)         # steps since (re)start − lag
        return {**super()._step_info(), "time": int(t[0]) if self._state.single else t}

    def _fallback(self, start: np.ndarray, prev: Any, Bu: FloatArray | None
                  ) -> tuple[FloatArray, FloatArray]:
        nb, n = self._buf.shape[0], self._n
        x0 = np.broadcast_to(self._x0, (nb, n))
        P0 = np.broadcast_to(self._P0, (nb, n, n))
        if prev is None or start.all():
            return x0, P0
        m = self._evicted                                  # matrices at time k − L
        assert m is not None
        Z, _ = self._window_data(self._slots)
        u_old = Z[:, 0, self._p:]                          # u[k − L]
        x = self._state.x @ m.A.T + u_old @ m.B.T
        P = m.A @ self._state.P @ m.A.T + m.G @ m.Q @ m.G.T
        return np.where(start[:, None], x0, x), np.where(start[:, None, None], P0, P)


register_estimator("fir-smoother", FIRSmoother)
