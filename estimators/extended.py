"""Extended Kalman filter (paper 000, Section 4, and paper 003's baseline).

First-order linearisation about the current estimate (e.g. Simon, *Optimal
State Estimation*, 2006, §13.2):

    predict   x⁻ = f(x, u),            F = ∂f/∂x (x, u),    P⁻ = F P Fᵀ + G Q Gᵀ
    update    e = y − h(x⁻),           H = ∂h/∂x (x⁻),
              the Joseph-form update of :func:`~fir_gym.estimators.kalman.kf_update`.

On a linear model the EKF is the Kalman filter exactly. Jacobians are the
model's analytic ones where the plant provides them, otherwise its central
finite differences (:meth:`StateSpaceModel.F`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from . import _lean, _small
from ._compiled import active
from ._kalman_kernels import predict_update
from ._kalman_linalg import as_batch
from ._validation import FloatArray
from .base import Estimator
from .kalman import predict_covariance, update_kernel
from .model import LinearModel, StateSpaceModel
from .registry import register_estimator

__all__ = ["ExtendedKalmanFilter", "model_callables", "model_linearizer"]


def model_callables(model: StateSpaceModel) -> tuple[Any, Any, Any, Any]:
    """The model's ``f, F, h, H`` for the hot path, skipping the per-call shape checks.

    The model's public methods validate their arguments on every call; a filter
    already holds arrays of the right shape, so it calls the plant's functions
    directly. A model subclass that overrides a public method keeps it.
    """
    cls = type(model)
    f = model._f if cls.f is StateSpaceModel.f else model.f
    h = model._h if cls.h is StateSpaceModel.h else model.h
    F = model._F if (cls.F is StateSpaceModel.F and model._F is not None) else model.F
    H = model._H if (cls.H is StateSpaceModel.H and model._H is not None) else model.H
    return f, F, h, H


def model_linearizer(model: StateSpaceModel) -> Any:
    """``(x, u) -> (f(x, u), F(x, u))`` for the hot path: the model's fused ``fF`` when it has
    one (one pass of the plant's integrator instead of two), else ``f`` and ``F`` apart."""
    cls = type(model)
    if cls.linearize is StateSpaceModel.linearize and getattr(model, "_fF", None) is not None:
        return model._fF
    if cls.linearize is not StateSpaceModel.linearize:
        return model.linearize
    f, F, _, _ = model_callables(model)
    return lambda x, u: (f(x, u), F(x, u))


class ExtendedKalmanFilter(Estimator):
    """Extended Kalman filter on any :class:`StateSpaceModel` (batched).

    Args:
        model: the filter's model (a ``TimeVaryingLinearModel`` is not accepted:
            use :class:`~fir_gym.estimators.kalman.KalmanFilter`).
        x0, P0: prior of ``x[0]``.
        **options: those of :class:`~fir_gym.estimators.base.Estimator`.

    One system of ``n_x, n_y <= 4`` with analytic Jacobians steps through generated
    float kernels (:mod:`~._lean`), to round-off the same numbers.
    """

    name = "ekf"

    def __init__(self, model: StateSpaceModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        if isinstance(model, StateSpaceModel) and getattr(model, "time_invariant", True) is False:
            raise TypeError(f"model must have time-free f/h for {type(self).__name__}; got a "
                            f"{type(model).__name__} (use KalmanFilter)")
        super().__init__(model, x0=x0, P0=P0, **options)
        self._f, self._F, self._h, self._H = model_callables(model)
        self._linearize = model_linearizer(model)
        self._GQGt = model.GQGT
        self._R_batch = as_batch(model.R)                  # the compiled step's layout

    def _make_lean(self) -> Any:
        if not _small.same_hooks(self, ExtendedKalmanFilter):
            return None
        plain = _is_plain_linear(self.model, self._f, self._F, self._h, self._H)
        return _lean.extended(self, plain)

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        e = y - self._h(x)
        x, P, _, nis = update_kernel(x, P, e, self._H(x), self.model.R, valid)
        return x, P, nis

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray]:
        x, F = self._linearize(x, u)
        if x.shape[0] > 1 and active(predict_update):      # one compiled loop over systems
            return predict_update(x, as_batch(P), as_batch(F), self._GQGt, y - self._h(x),
                                  as_batch(self._H(x)), self._R_batch, valid)
        P = predict_covariance(P, F, self._GQGt)
        e = y - self._h(x)
        x, P, _, nis = update_kernel(x, P, e, self._H(x), self.model.R, valid)
        return x, P, nis


def _is_plain_linear(model: StateSpaceModel, f: Any, F: Any, h: Any, H: Any) -> bool:
    """Whether the callables are :class:`LinearModel`'s own (``A x + B u``, ``A``, ``C x``,
    ``C``)."""
    if not isinstance(model, LinearModel) or type(model).linearize is not LinearModel.linearize:
        return False
    own = (LinearModel._linear_f, LinearModel._linear_F, LinearModel._linear_h,
           LinearModel._linear_H)
    return all(getattr(c, "__func__", None) is o and getattr(c, "__self__", None) is model
               for c, o in zip((f, F, h, H), own, strict=True))


register_estimator("ekf", ExtendedKalmanFilter)
