"""The consistency test of the windowed (FIR-family) filters.

A FIR filter has no innovation of its own — its estimate is a weighted sum of the
window — so it is tested the way a Kalman filter tests itself: the newest measurement
against the filter's own one-step prediction made *before* it arrives. With ``x̂[k−1]``,
``P[k−1]`` the filter's previous estimate and error covariance::

    x⁻ = f(x̂[k−1], u[k−1]),      P⁻ = F P[k−1] Fᵀ + G Q Gᵀ,      F = ∂f/∂x at x̂[k−1]
    e  = y[k] − h(x⁻),           S  = H P⁻ Hᵀ + R,               H = ∂h/∂x at x⁻
    NIS = eᵀ S⁻¹ e

**Why it is χ²(n_y).** On a linear model, ``e = C A (x[k−1] − x̂[k−1]) + C G w[k−1] +
v[k]``. The estimate ``x̂[k−1]`` uses measurements up to ``y[k−1]`` only, so its error
is independent of ``w[k−1]`` and ``v[k]``; it is zero-mean because the FIR filter is
unbiased (the window-start state is a free parameter, so no prior can bias it), and
its covariance is ``P[k−1]`` exactly when the filter reports its true error covariance
(the minimum-variance unbiased FIR filter's ``P`` is; so is the start-up's propagated
prior's). Hence ``e ~ N(0, S)`` and ``NIS ~ χ²(n_y)`` at every step — the same
marginal law as the Kalman filter's innovation test, which is why the windowed filters
share the Kalman family's watch (:class:`~.base.Estimator`): a system is flagged when
its NIS stays above the ``1 − nis_tail`` quantile of χ²(n_y) for ``nis_patience``
steps running. Unlike a Kalman filter's, consecutive FIR innovations are correlated
(neighbouring windows share measurements), but the threshold is a marginal tail
probability (``nis_tail = 1e-9`` by default) and the run of ``nis_patience`` such
steps is rarer still, whatever the correlation: the false-alarm rate per step is at
most ``nis_tail``. On a nonlinear model (EFIR) the law holds to first order about
the estimate, as it does for the EKF.

The FIR smoother's estimate lags; its test uses the FIR filter estimate over the same
window in place of ``x̂[k−1]`` (:class:`~.fir_smoother.FIRSmoother`).

A system taking its first step (after ``reset`` or ``restart``) has no previous
estimate: its prior ``(x0, P0)`` takes the place of ``(x⁻, P⁻)`` (the Kalman filter's
first-step NIS). A skipped measurement (``nan_policy="skip"``) has a NaN NIS that does
not count; a NaN NIS of a usable measurement (``S`` not positive definite, a
non-finite prediction) counts as above the threshold.

**The growth bound.** Independently, a windowed filter flags a system whose estimate
has a component beyond ``max_estimate`` in magnitude (default ``1e12``): the backstop
for an estimate that grows together with its covariance, which the innovation test
cannot see until ``trace P`` crosses ``max_covariance_trace``.

:func:`innovation_nis` is the numpy reference; its compiled twin is
:func:`.compiled.watch.innovation_nis`.
"""

from __future__ import annotations

import numpy as np

from ._kalman_linalg import spd_inverse
from ._validation import FloatArray

#: the default of ``max_estimate``: an estimate component beyond it is a divergence
MAX_ESTIMATE = 1e12


def innovation_nis(P: FloatArray, A: FloatArray, Qx: FloatArray, H: FloatArray,
                   R: FloatArray, e: FloatArray, predict: np.ndarray, valid: np.ndarray
                   ) -> FloatArray:
    """The one-step NIS ``eᵀ S⁻¹ e`` of every system (module docstring), batched.

    ``P (B, n, n)`` is the previous error covariance; ``A (B|1, n, n)`` the transition
    (``∂f/∂x``) at the previous estimate, ``Qx (B|1, n, n)`` the state noise ``G Q Gᵀ``,
    ``H (B|1, p, n)``, ``R (p, p)``, ``e (B, p)`` the innovation ``y − h(x⁻)``; systems
    with ``predict`` False take ``P⁻ = P`` (their prior); NaN where ``valid`` is False
    or ``S`` is not positive definite.
    """
    Pm = A @ P @ A.swapaxes(-1, -2) + Qx
    Pm = np.where(predict[:, None, None], Pm, P)
    S = H @ Pm @ H.swapaxes(-1, -2) + R
    S = 0.5 * (S + S.swapaxes(-1, -2))
    W = spd_inverse(S)
    nis = np.einsum("bi,bij,bj->b", e, W, e)
    return np.where(valid, nis, np.nan)
