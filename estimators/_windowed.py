"""The step shape shared by the sliding-window (FIR-family) estimators."""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, ClassVar

import numpy as np

from . import _consistency
from ._validation import FloatArray, positive
from .base import Estimator
from .compiled import watch
from .model import StateSpaceModel
from .state import GATE, MAX_ESTIMATE

#: ``(e, A, Qx, H, R)`` of the one-step innovation test (:mod:`._consistency`)
InnovationTerms = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


class WindowedEstimator(Estimator):
    """An estimator whose every step is one pass over its sliding window.

    A FIR filter consumes ``y[k]`` the same way on the first step and on later ones —
    its window just grows — so both hooks of :class:`Estimator` call :meth:`_advance`.
    A restarted system (:meth:`Estimator.restart`) is marked ``_pending`` and its
    window restarts inside that pass, so its first-step result is already in the
    pass's ``(x, P)``, which :meth:`_update_systems` returns. ``_info`` (the start-up
    and rank flags of the last pass) is merged into ``last_info``.

    The compiled step is the same pass — its window-bank operations run their
    compiled twins (:class:`~._fir_bank.WindowBank`) — followed by the compiled
    divergence watch (:func:`.compiled.watch.accept`) instead of :meth:`_accept`.

    **Consistency.** Before the pass, the newest measurement is tested against the
    filter's one-step prediction from its previous estimate and covariance
    (:mod:`._consistency`: the NIS, ``last_info["nis"]``, χ²(n_y) for a consistent
    filter), and the watch flags a system whose NIS stays above the threshold for
    ``nis_patience`` steps — the Kalman family's contract — or whose estimate has a
    component beyond ``max_estimate`` (the growth bound). Subclasses say how the model
    predicts (:meth:`_innovation_terms`); the NIS is
    :func:`._consistency.innovation_nis` on numpy and its twin
    :func:`.compiled.watch.innovation_nis` on the compiled step.

    **Innovation gate** (``gate=``, :class:`~.base.Estimator`). The NIS is known before the
    pass, so a rejected measurement (NIS above the gate's threshold) enters the pass as a
    missing one — ``valid &= ~gated``, its row of ``y`` zeroed as a masked entry's is — on
    both paths: the windows, ages and every other state are exactly those of a step with
    that measurement missing. The watch still books the rejected NIS. A system without a
    NIS this step (NaN: no usable previous estimate, e.g. the FIR smoother's test over a
    window with a gap) is not gated.

    Subclasses implement :meth:`_advance` and :meth:`_innovation_terms` and keep
    ``_age`` (samples in each window) and ``_last_xP``.
    """

    reports_nis: ClassVar[bool] = True
    has_compiled_step: ClassVar[bool] = True
    can_gate: ClassVar[bool] = True
    _pending: np.ndarray | None = None
    _info: dict[str, Any]
    _age: np.ndarray
    _last_xP: tuple[FloatArray, FloatArray]
    _last_nis: FloatArray

    def __init__(self, model: StateSpaceModel, *, max_estimate: float = _consistency.MAX_ESTIMATE,
                 **options: Any) -> None:
        self.max_estimate = positive("max_estimate", max_estimate)
        super().__init__(model, **options)
        #: the watch's limits with the growth bound (:mod:`.compiled.watch`)
        self._limits[MAX_ESTIMATE] = self.max_estimate

    @abstractmethod
    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        """Push ``y[k]`` (and ``u[k-1]``) into the window and estimate ``x[k]``."""

    @abstractmethod
    def _innovation_terms(self, y: FloatArray, u: FloatArray | None, predict: np.ndarray,
                          x: FloatArray) -> InnovationTerms:
        """The model along the previous estimate ``x`` (``x̂[k−1]``): the innovation ``e = y −
        h(x⁻)`` with ``x⁻ = f(x, u)`` where ``predict`` (else ``x⁻ = x``, the prior of a first
        step), ``A = ∂f/∂x`` at ``x``, ``Qx = G Q Gᵀ``, ``H = ∂h/∂x`` at ``x⁻`` and ``R`` — the
        arguments of :func:`._consistency.innovation_nis`."""

    def _consistency_prior(self) -> tuple[FloatArray, FloatArray, np.ndarray | None]:
        """The previous estimate the innovation test predicts from, its covariance, and where
        it is usable (``None``: everywhere). Default: the filter's own ``x̂``, ``P``."""
        return self._state.x, self._state.P, None

    def _nis_inputs(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                    ) -> tuple[FloatArray, ...]:
        """The arguments of :func:`._consistency.innovation_nis` (and of its twin) for this
        step; ``self._nis_valid`` becomes the systems whose NIS counts (a measurement, and a
        usable previous estimate)."""
        predict = self._predicting()
        x, P, usable = self._consistency_prior()
        e, A, Qx, H, R = self._innovation_terms(y, u, predict, x)
        self._nis_valid = valid if usable is None else valid & usable
        return P, A, Qx, H, R, e, predict, self._nis_valid

    def _step_info(self) -> dict[str, Any]:
        return {key: value.copy() if isinstance(value, np.ndarray) else value
                for key, value in self._info.items()}

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        return self._numpy_pass(y, None, valid)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        return self._numpy_pass(y, u, valid)

    def _numpy_pass(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        nis = _consistency.innovation_nis(*self._nis_inputs(y, u, valid)) \
            if self.reports_nis else None
        if nis is not None and self._gate_threshold is not None:
            y, valid = self._gated_measurement(y, valid, nis)
        x, P, _ = self._advance(y, u, valid)
        if nis is not None:
            self._last_nis = nis
        return x, P, nis

    def _gated_measurement(self, y: FloatArray, valid: np.ndarray, nis: FloatArray
                           ) -> tuple[FloatArray, np.ndarray]:
        """The gate (class docstring): ``y`` and ``valid`` for the pass, the measurements whose
        NIS exceeds the threshold made missing (NaN NIS compares False: not gated)."""
        rejected = nis > self._limits[GATE]
        if not rejected.any():
            return y, valid
        return np.where(rejected[:, None], 0.0, y), valid & ~rejected

    def _accept(self, x: FloatArray, P: FloatArray | None, nis: FloatArray | None,
                valid: np.ndarray) -> None:
        """The base watch (the NIS counted where it is usable), plus the growth bound: a
        component beyond ``max_estimate``."""
        super()._accept(x, P, nis, self._nis_valid if self.reports_nis else valid)
        grown = ~(np.abs(x).max(axis=1) <= self.max_estimate)
        if grown.any():
            self._state.diverged |= grown

    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        self._compiled_pass(y, None, valid)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        self._compiled_pass(y, u, valid)

    def _compiled_pass(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray) -> None:
        s = self._state
        has_nis = self.reports_nis
        with np.errstate(all="ignore"):
            if has_nis:
                P_prev, A, Qx, H, R, e, predict, usable = self._nis_inputs(y, u, valid)
                nis = np.empty(y.shape[0])
                watch.innovation_nis(_batch(P_prev), _batch(A), _batch(Qx), _batch(H),
                                     _batch(R), _batch(e), predict, usable, nis)
                self._last_nis = nis
                if self._gate_threshold is not None:
                    y, valid = self._gated_measurement(y, valid, nis)
            else:
                nis, usable = s.nis, valid
            x, P, _ = self._advance(y, u, valid)
        watch.accept(x, P, nis, usable, has_nis, s)

    def _restart_systems(self, mask: np.ndarray) -> None:
        self._pending = mask.copy() if self._pending is None else self._pending | mask
        self._age[mask] = 0

    def _update_systems(self, idx: np.ndarray, x: FloatArray, P: FloatArray, y: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        # the pass already treated the restarted systems as starting afresh (their NIS
        # against their prior included)
        nis = self._last_nis[idx] if self.reports_nis else None
        return self._last_xP[0][idx], self._last_xP[1][idx], nis


def _batch(M: FloatArray) -> FloatArray:
    """``M`` as a C-contiguous float64 array (the compiled kernel's layout); ``M`` itself when
    it is one already. Matrices come as ``(B|1, r, c)``, a 2-D matrix as ``(1, r, c)`` —
    except ``R`` and ``e``, which the kernel takes 2-D (callers pass them as they are)."""
    if type(M) is np.ndarray and M.dtype == np.float64 and M.flags.c_contiguous:
        return M
    return np.ascontiguousarray(M, dtype=np.float64)
