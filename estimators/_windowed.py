"""The step shape shared by the sliding-window (FIR-family) estimators."""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, ClassVar

import numpy as np

from ._validation import FloatArray
from .base import Estimator
from .compiled import watch


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

    Subclasses implement :meth:`_advance` and keep ``_age`` (samples in each window)
    and ``_last_xP``.
    """

    reports_nis: ClassVar[bool] = False
    has_compiled_step: ClassVar[bool] = True
    _pending: np.ndarray | None = None
    _info: dict[str, Any]
    _age: np.ndarray
    _last_xP: tuple[FloatArray, FloatArray]

    @abstractmethod
    def _advance(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray
                 ) -> tuple[FloatArray, FloatArray, None]:
        """Push ``y[k]`` (and ``u[k-1]``) into the window and estimate ``x[k]``."""

    def _step_info(self) -> dict[str, Any]:
        return {key: value.copy() if isinstance(value, np.ndarray) else value
                for key, value in self._info.items()}

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        return self._advance(y, None, valid)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        return self._advance(y, u, valid)

    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        self._compiled_pass(y, None, valid)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        self._compiled_pass(y, u, valid)

    def _compiled_pass(self, y: FloatArray, u: FloatArray | None, valid: np.ndarray) -> None:
        with np.errstate(all="ignore"):
            x, P, _ = self._advance(y, u, valid)
        watch.accept(x, P, self._nis, valid, False, self._x, self._P, self._diverged,
                     self._nis_run, self._nis, self._limits)

    def _restart_systems(self, mask: np.ndarray) -> None:
        self._pending = mask.copy() if self._pending is None else self._pending | mask
        self._age[mask] = 0

    def _update_systems(self, idx: np.ndarray, x: FloatArray, P: FloatArray, y: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        # the pass already treated the restarted systems as starting afresh
        return self._last_xP[0][idx], self._last_xP[1][idx], None
