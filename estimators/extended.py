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

from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from ._batched_check import check_model_batched
from ._kalman_linalg import logdet_of_inverse
from ._validation import FloatArray
from .base import Estimator
from .compiled import kalman as compiled_kalman
from .kalman import LinearGains, StepMatrices, predict_covariance, update_kernel
from .model import LinearModel, StateSpaceModel
from .public_steps import PublicSteps
from .registry import register_estimator
from .sequences import SmootherResult
from .smoothers import smooth_sequence

__all__ = ["ExtendedKalmanFilter"]


class ExtendedKalmanFilter(PublicSteps, Estimator):
    """Extended Kalman filter on any :class:`StateSpaceModel` (batched).

    Args:
        model: the filter's model (a ``TimeVaryingLinearModel`` is not accepted:
            use :class:`~fir_gym.estimators.kalman.KalmanFilter`).
        x0, P0: prior of ``x[0]``.
        **options: those of :class:`~fir_gym.estimators.base.Estimator`.

    The compiled twin evaluates the model (``f, F`` in one pass where the plant fuses
    them, ``h``, ``H``) and hands the covariance algebra to
    :func:`~.compiled.kalman.predict_update`; on a plain :class:`LinearModel` — where
    ``f = A x + B u``, ``F = A``, ``h = C x``, ``H = C`` and the EKF is the Kalman filter —
    it runs :func:`~.compiled.kalman.linear_step` on the matrices instead of calling the
    model, with the KF's exact shared covariance (systems started from one prior; their
    covariance recursion does not depend on the data) and no steady-state shortcut.
    """

    name = "ekf"
    has_compiled_step = True
    can_gate = True
    reports_likelihood = True
    model_reassignable = True

    def __init__(self, model: StateSpaceModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        if isinstance(model, StateSpaceModel) and getattr(model, "time_invariant", True) is False:
            raise TypeError(f"model must have time-free f/h for {type(self).__name__}; got a "
                            f"{type(model).__name__} (use KalmanFilter)")
        super().__init__(model, x0=x0, P0=P0, **options)
        self._model_changed()

    def _model_changed(self) -> None:
        model = self.model
        if getattr(model, "time_invariant", True) is False:
            raise TypeError(f"model must have time-free f/h for {type(self).__name__}")
        self._f, self._F, self._h, self._H = model.unchecked_callables()
        self._linearize = model.unchecked_linearizer()
        self._GQGt = np.ascontiguousarray(model.GQGT)
        self._R_batch = np.ascontiguousarray(model.R)[None]       # the compiled step's layout
        self._plain_linear = isinstance(model, LinearModel) and model.is_plain
        if not self._plain_linear:
            check_model_batched(self)
        self._residual_x = getattr(model, "residual_x", None)
        self._residual_y = getattr(model, "residual_y", None)
        if self._state.batch:
            self._bind_linear()

    def _init_batch(self, n_batch: int) -> None:
        self._identity = np.eye(self.model.n_x)[None]
        if self._plain_linear and self._P0.ndim == 2:
            # the covariance recursion of a linear model does not depend on the data:
            # systems started from one prior share it (the KF's exact shortcut)
            self._state.P = self._P0[None].copy()
        self._bind_linear()

    def _bind_linear(self) -> None:
        """The matrices of a plain linear model's compiled step; a covariance shared by the
        batch becomes one per system when the model is not (or no longer) plain linear."""
        s = self._state
        if self._plain_linear:
            model = cast(LinearModel, self.model)
            self._mats = StepMatrices(model.A, model.B, model.C, self._GQGt, model.R)
            self._gains = LinearGains(model.n_x, model.n_y, may_settle=False)  # no steady state
        elif s.P.shape[0] < s.batch:
            s.P = np.repeat(s.P, s.batch, axis=0)

    # ------------------------------------------------------------------ numpy reference
    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, ...]:
        return self._correct(x, P, y, valid)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, ...]:
        x, F = self._linearize(x, u)
        P = predict_covariance(P, F, self._GQGt)
        return self._correct(x, P, y, valid)

    def _correct(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                 ) -> tuple[FloatArray, ...]:
        """The Joseph-form update of the prior ``(x, P)``: ``(x⁺, P⁺, nis, log det S)``."""
        hx = self._h(x)
        e = y - hx if self._residual_y is None else self._residual_y(y, hx)
        x, P, W, nis = update_kernel(x, P, e, self._H(x), self.model.R, valid,
                                     self._gate_threshold)
        return x, P, nis, logdet_of_inverse(W, x.shape[0])

    # ------------------------------------------------------------------ smoother
    def smooth(self, ys: ArrayLike, us: ArrayLike | None = None) -> SmootherResult:
        """Extended Rauch–Tung–Striebel smoother (:mod:`.smoothers`): a forward
        :meth:`filter` (same arguments and alignment), then the backward pass with
        ``x⁻ = f(x̂, u)`` and ``F = ∂f/∂x`` at each filtered estimate (differences through
        the model's ``residual_x``). Returns a
        :class:`~fir_gym.estimators.sequences.SmootherResult`."""
        return smooth_sequence(self, ys, us, self._smoother_prediction, self._residual_x)

    def _smoother_prediction(self, k: int, x: FloatArray, P: FloatArray, u: FloatArray
                             ) -> tuple[FloatArray, FloatArray, FloatArray]:
        x_pred, F = self._linearize(x, u)
        F = np.broadcast_to(F, (x.shape[0], *F.shape[-2:]))
        return x_pred, predict_covariance(P, F, self._GQGt), P @ F.mT

    # ------------------------------------------------------------------ compiled twin
    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        if self._plain_linear:
            self._gains.step(self._state, self._predicting(), self._mats, self._mats,
                             self._no_input, y, valid)
            return
        x = self._state.x
        with np.errstate(all="ignore"):
            hx, H = self._h(x), self._H(x)
        self._kalman_step(x, self._identity, y, hx, H, valid)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        s = self._state
        if self._plain_linear:
            self._gains.step(s, self._predicting(), self._mats, self._mats, u, y, valid)
            return
        x = s.x
        with np.errstate(all="ignore"):
            xp, F = self._linearize(x, u)
            if s.restarting:                       # restarted systems: their prior
                xp = np.where(s.fresh[:, None], x, xp)
            hx, H = self._h(xp), self._H(xp)
        self._kalman_step(xp, F, y, hx, H, valid)

    def _kalman_step(self, xp: FloatArray, F: FloatArray, y: FloatArray, hx: FloatArray,
                     H: FloatArray, valid: np.ndarray) -> None:
        """:func:`~.compiled.kalman.predict_update` on the model's values (a 2-D ``F`` or ``H``
        is shared by the batch). The kernel's innovation is ``y − hx``: with the model's
        ``residual_y`` it is handed ``hx + residual_y(y, hx)``."""
        s = self._state
        if self._residual_y is not None:
            with np.errstate(all="ignore"):
                y = hx + self._residual_y(y, hx)
        compiled_kalman.predict_update(
            s, xp, F if F.ndim == 3 else F[None], self._GQGt, y, hx,
            H if H.ndim == 3 else H[None], self._R_batch, valid, self._predicting())


register_estimator("ekf", ExtendedKalmanFilter)
