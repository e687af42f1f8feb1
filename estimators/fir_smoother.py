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
from .fir import FIRFilter
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
    """

    name: ClassVar[str] = "fir-smoother"
    _smoother: ClassVar[bool] = True
    reports_nis: ClassVar[bool] = False

    def __init__(self, model: StateSpaceModel, *, horizon: int, gain: str = "two-stage",
                 prior: str | ArrayLike | None = None, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        if gain == "riccati" and prior is None:
            raise ValueError("gain='riccati' needs a prior for the smoother: paper 004 Cor 3.2 "
                             "(no prior) needs [S(n+1) - C'C]^-1, singular when outputs < "
                             "states; use gain='two-stage' or 'batch'")
        super().__init__(model, horizon=horizon, form="filter", gain=gain, prior=prior,
                         x0=x0, P0=P0, **options)

    @property
    def lag(self) -> int:
        """Steps between the newest measurement and the estimated state (``horizon − 1``)."""
        return self.horizon - 1

    def _step_info(self) -> dict[str, Any]:
        t = np.maximum(0, self._age - self.horizon)         # steps since (re)start − lag
        return {**super()._step_info(), "time": int(t[0]) if self._single else t}

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
        x = self._x @ m.A.T + u_old @ m.B.T
        P = m.A @ self._P @ m.A.T + m.G @ m.Q @ m.G.T
        return np.where(start[:, None], x0, x), np.where(start[:, None, None], P0, P)


register_estimator("fir-smoother", FIRSmoother)
