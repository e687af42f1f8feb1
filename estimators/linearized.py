"""Paper 000's linearised Kalman filter (Section 4, the "LKF" of Table 1).

A Kalman filter on the perturbation about a nominal trajectory run open loop from the
filter's initial state, over the pure functions of :mod:`.kalman` (numpy reference) and
:func:`~.compiled.kalman.predict_update` (compiled twin).
"""

from __future__ import annotations

import numpy as np

from ._kalman_linalg import logdet_of_inverse
from ._validation import FloatArray
from .base import Estimator
from .compiled import kalman as compiled_kalman
from .kalman import predict_kernel, update_kernel
from .public_steps import PublicSteps
from .registry import register_estimator

__all__ = ["LinearizedKalmanFilter"]


class LinearizedKalmanFilter(PublicSteps, Estimator):
    """Paper 000's linearised Kalman filter (LKF): a KF on the perturbation about a nominal path.

    The nominal trajectory starts at the filter's initial state and runs open
    loop with the inputs the filter is given, ``x_nom[k] = f(x_nom[k-1], u[k-1])``,
    ``x_nom[0] = x0``. The perturbation ``δx = x − x_nom`` follows
    ``δx[k] = F(x_nom[k-1], u[k-1]) δx[k-1] + G w``,
    ``y[k] − h(x_nom[k]) = H(x_nom[k]) δx[k] + v`` (paper 000, Section 2), and the
    estimate is ``x̂ = x_nom + δx̂``. Unlike the EKF the linearisation point never
    sees the measurements, so the LKF is exact on linear models and degrades as
    the truth leaves the nominal path.

    The compiled twin hands the covariance algebra to
    :func:`~.compiled.kalman.predict_update` with ``x⁻ = x_nom + F δx`` and ``ŷ =
    h(x_nom) + H δx⁻`` (the same update: ``x⁺ = x⁻ + K (y − ŷ)``).
    """

    name = "lkf"
    has_compiled_step = True
    can_gate = True
    reports_likelihood = True
    model_reassignable = True

    _x_nom: FloatArray

    def _init_batch(self, n_batch: int) -> None:
        self._x_nom = self._state.x.copy()

    def _reset_state(self) -> None:
        self._x_nom = np.empty((0, self.model.n_x))
        self._model_changed()

    def _model_changed(self) -> None:
        self._GQGt = self.model.GQGT
        self._R_batch = self.model.R[None]

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, ...]:
        return self._correct(x - self._x_nom, P, y, valid)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, ...]:
        model = self.model
        F = model.F(self._x_nom, u)
        dx, P = predict_kernel(x - self._x_nom, P, F, self._GQGt)
        self._x_nom = model.f(self._x_nom, u)
        return self._correct(dx, P, y, valid)

    def _update_systems(self, idx: np.ndarray, x: FloatArray, P: FloatArray, y: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, ...]:
        # a restarted system's nominal path starts again at its prior
        self._x_nom[idx] = x
        return self._correct(np.zeros_like(x), P, y, valid, self._x_nom[idx])

    def _correct(self, dx: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray,
                 x_nom: FloatArray | None = None) -> tuple[FloatArray, ...]:
        x_nom = self._x_nom if x_nom is None else x_nom
        H = self.model.H(x_nom)
        e = y - self.model.h(x_nom) - (H @ dx[:, :, None])[:, :, 0]
        dx, P, W, nis = update_kernel(dx, P, e, H, self.model.R, valid, self._gate_threshold)
        return x_nom + dx, P, nis, logdet_of_inverse(W, dx.shape[0])

    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        self._compiled_step(y, self._no_input, valid, predict=False)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        self._compiled_step(y, u, valid, predict=True)

    def _compiled_step(self, y: FloatArray, u: FloatArray, valid: np.ndarray, predict: bool
                       ) -> None:
        s = self._state
        model, x, nom = self.model, s.x, self._x_nom
        with np.errstate(all="ignore"):
            if predict:                                # the nominal moves on, open loop
                F = model.F(nom, u)
                nom_next = model.f(nom, u)
                xp = nom_next + (F @ (x - nom)[:, :, None])[:, :, 0]   # x_nom + F δx
                if s.restarting:                   # a restarted nominal starts again
                    fresh = s.fresh[:, None]
                    nom_next = np.where(fresh, x, nom_next)
                    xp = np.where(fresh, x, xp)
                self._x_nom = nom_next
            else:
                F, nom_next, xp = np.eye(model.n_x)[None], nom, x
            H = model.H(nom_next)
            hx = model.h(nom_next) + (H @ (xp - nom_next)[:, :, None])[:, :, 0]
        compiled_kalman.predict_update(s, xp, F, self._GQGt, y, hx, H, self._R_batch, valid,
                                       self._predicting())

    @property
    def x_nominal(self) -> FloatArray | None:
        """The nominal trajectory's current point (``None`` before the first step)."""
        if not self._state.batch:
            return None
        return self._x_nom[0].copy() if self._state.single else self._x_nom.copy()


register_estimator("lkf", LinearizedKalmanFilter)
