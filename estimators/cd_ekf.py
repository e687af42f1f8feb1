"""Continuous–discrete extended Kalman filter (the comparison for paper 002).

Between samples the mean and covariance follow the moment equations of the
linearised continuous model ``dx = a(x, u) dt + G dw`` (e.g. Jazwinski,
*Stochastic Processes and Filtering Theory*, 1970, §9.3; Särkkä & Solin,
*Applied Stochastic Differential Equations*, 2019, §9.1):

    ẋ̂ = a(x̂, u),      Ṗ = J P + P Jᵀ + G Q Gᵀ,      J = ∂a/∂x (x̂, u),

integrated over each sample interval ``[t_{k-1}, t_k]`` (length ``h = dt``) by
classical RK4 with at least ``substeps`` steps (input held). RK4 is stable for
real ``λ τ ≥ −2.78`` and the covariance equation has the eigenvalues
``λ_i + λ_j`` of ``J ⊕ J``, so the step count is raised, interval by interval,
until ``2 ‖J(x̂)‖_∞ τ ≤ 1.5`` at the interval's start (Van der Pol is stiff far
from its cycle: ``J22 = 1 − x1²``). Too coarse a fixed step made the covariance
blow up numerically — a failure of the integrator, not of the EKF.

**The measurement is an interval average** ``ȳ[k] = (1/h) ∫ h(x) dt + v̄``,
``v̄ ~ N(0, R/h)`` (see :mod:`~fir_gym.estimators.continuous`). Two models of it:

* ``measurement="average"`` (default, exact for a linear model): the state is
  augmented with the running average ``s(t) = (1/h) ∫_{t_{k-1}}^t h(x) dt``,
  ``ṡ = h(x)/h``, ``s(t_{k-1}) = 0``, whose covariance block and cross-covariance
  with ``x`` are propagated with the augmented Jacobian ``[[J, 0], [H/h, 0]]``;
  the update is the linear measurement ``ȳ = s + v̄``. It accounts both for the
  lag of the average (about ``h/2``) and for its correlation with the process
  noise inside the interval.
* ``measurement="end"``: the simplest choice, ``ȳ[k] ≈ h(x(t_k)) + v̄``. It
  ignores that the average lags the end value by about ``h/2 · ḣ`` (for Van der
  Pol ``h x2 / 2``, a bias up to about 0.1–0.3 against a noise std of 7 with the
  paper's values) and that the averaged signal carries information about the
  intra-interval noise; the Monte Carlo of ``fir_gym.scenarios.paper002``
  reports what it costs.

The first step is the Kalman update of the prior with the point measurement
``y[0]`` of ``h(x(t0))``, covariance ``R/h`` (the Gymnasium plant's convention), that
of every :class:`~.continuous_estimator.ContinuousEstimator`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._kalman_linalg import psd_rebuild
from ._validation import FloatArray, one_of, positive
from .continuous import ContinuousModel
from .continuous_estimator import ContinuousEstimator
from .kalman import update_kernel
from .registry import register_estimator

__all__ = ["ContinuousDiscreteEKF", "cd_ekf_propagate"]

MEASUREMENT_MODELS = ("average", "end")


def cd_ekf_propagate(
    model: ContinuousModel,
    x: ArrayLike,
    P: ArrayLike,
    u: ArrayLike | None = None,
    *,
    substeps: int = 20,
    average: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Propagate the mean and covariance over one sample interval ``model.dt`` (RK4).

    Args:
        model: the continuous model.
        x: mean ``(n,)`` or ``(B, n)`` at the interval's start.
        P: covariance ``(n, n)`` or ``(B, n, n)``.
        u: input held over the interval.
        substeps: the minimum number of RK4 steps per interval (raised for stiffness).
        average: also propagate the running average ``s`` of ``h(x)`` (see the
            module docstring); then the result is the augmented mean
            ``[x; s]`` and covariance (``n + n_y`` wide), with ``s = 0`` and zero
            covariance rows for ``s`` at the start.

    Returns:
        ``(x, P)`` at the end of the interval (augmented when ``average``).
    """
    x = np.asarray(x, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    single = x.ndim == 1
    X, Pb = (x[None], P[None]) if single else (x, P)
    if u is None or model.n_u == 0:
        U = np.zeros((X.shape[0], model.n_u))
    else:
        U = np.broadcast_to(np.asarray(u, dtype=np.float64).reshape(-1, model.n_u),
                            (X.shape[0], model.n_u))
    n, m = model.n_x, model.n_y if average else 0
    z = np.concatenate([X, np.zeros((X.shape[0], m))], axis=1)
    S = np.zeros((X.shape[0], n + m, n + m))
    S[:, :n, :n] = Pb
    W = np.zeros((n + m, n + m))
    W[:n, :n] = model.GQGT
    h = model.dt
    # RK4 is stable for real λτ >= -2.78; the covariance equation's eigenvalues are
    # λ_i + λ_j, so take 2 ρ(J) τ <= 1.5, with ρ(J) <= ‖J‖_∞ at the start (margin for motion).
    rho = float(np.max(np.abs(model.J(X, U)).sum(axis=-1), initial=0.0))
    substeps = max(positive("substeps", substeps, integer=True), int(np.ceil(2.0 * rho * h / 1.5)))
    tau = h / substeps

    def rates(z: FloatArray, S: FloatArray) -> tuple[FloatArray, FloatArray]:
        xs = z[:, :n]
        Ja = np.zeros_like(S)
        Ja[:, :n, :n] = model.J(xs, U)
        dz = [model.a(xs, U)]
        if m:
            Ja[:, n:, :n] = model.H(xs) / h
            dz.append(model.h(xs) / h)
        JS = Ja @ S
        return np.concatenate(dz, axis=1), JS + np.swapaxes(JS, 1, 2) + W

    for _ in range(substeps):
        k1 = rates(z, S)
        k2 = rates(z + 0.5 * tau * k1[0], S + 0.5 * tau * k1[1])
        k3 = rates(z + 0.5 * tau * k2[0], S + 0.5 * tau * k2[1])
        k4 = rates(z + tau * k3[0], S + tau * k3[1])
        z = z + tau / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        S = S + tau / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
    # RK4 of the covariance flow is not PSD-preserving: from P0 = 1e12 I on CarrierMotion one
    # interval left an eigenvalue of -1.4 (whose exact Joseph update is indefinite too). The
    # flow's end is rebuilt from its PSD factor (its nearest PSD matrix where it is not PSD;
    # docs/architecture.md#covariance-updates)
    S = psd_rebuild(S)
    return (z[0], S[0]) if single else (z, S)


class ContinuousDiscreteEKF(ContinuousEstimator):
    """Continuous–discrete EKF on a :class:`ContinuousModel` (batched).

    Args:
        model: the continuous model; its ``dt`` is the sample interval.
        x0, P0: prior of ``x(t0)``.
        measurement: ``"average"`` (default) or ``"end"`` — how the
            interval-average measurement is modelled (module docstring).
        substeps: the minimum number of RK4 steps per interval.
        **options: those of :class:`~fir_gym.estimators.base.Estimator`.

    ``model`` (the attribute) is the sampled discrete view the base class reads;
    the continuous model is :attr:`continuous_model`.

    The innovation gate (``gate=``, :class:`~fir_gym.estimators.base.Estimator`) acts on the
    Kalman update that ends each interval (and on the first step's): a rejected measurement
    leaves the propagated mean and covariance, as a missing one does.
    """

    name = "cd-ekf"

    def __init__(self, model: ContinuousModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, measurement: str = "average",
                 substeps: int = 20, **options: Any) -> None:
        self.measurement = one_of("measurement", measurement, MEASUREMENT_MODELS)
        self.substeps = positive("substeps", substeps, integer=True)
        super().__init__(model, x0=x0, P0=P0, **options)

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray]:
        cm = self.continuous_model
        R_bar = cm.R / cm.dt
        if self.measurement == "end":
            x, P = cd_ekf_propagate(cm, x, P, u, substeps=self.substeps)
            x, P, _, nis = update_kernel(x, P, y - cm.h(x), cm.H(x), R_bar, valid,
                                         self._gate_threshold)
            return x, P, nis
        n = cm.n_x
        z, S = cd_ekf_propagate(cm, x, P, u, substeps=self.substeps, average=True)
        H_s = np.concatenate([np.zeros((cm.n_y, n)), np.eye(cm.n_y)], axis=1)   # ȳ = s + v̄
        z, S, _, nis = update_kernel(z, S, y - z[:, n:], H_s, R_bar, valid,
                                     self._gate_threshold)
        return z[:, :n], S[:, :n, :n], nis


register_estimator("cd-ekf", ContinuousDiscreteEKF)
