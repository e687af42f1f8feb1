"""A known sensor delay: filter ``y[k − d]``, then predict ``d`` steps ahead.

Every filter takes ``delay=d`` (an integer ≥ 0, default 0: no delay). With ``d > 0`` the
measurement handed to :meth:`~fir_gym.estimators.base.Estimator.step` at step ``k`` is
``y[k − d]`` — what :class:`~fir_gym.wrappers.SensorFaults` delivers with ``delay=d`` —
and the estimate returned is still that of the *current* state ``x[k]``
(docs/robustness.md#estimators):

1. **The filter runs ``d`` steps behind.** Its own step (either path, every option
   included) consumes ``y[k − d]`` with the input ``u[k − d − 1]`` that drove the plant
   into ``x[k − d]``: the lagged estimate ``x̂[k − d]`` (``last_info["delayed_estimate"]``)
   is exactly what the same filter fed the undelayed sequence ``d`` steps late gives. For
   ``k < d`` nothing has arrived: the filter has not started (it holds its prior of
   ``x[0]``) and the step's measurement must be missing (``None`` or masked).
2. **The model predicts ``d`` steps ahead** with the inputs ``u[k − d], …, u[k − 1]``
   the filter keeps (:class:`DelayLine`): ``x ← f(x, u)``, ``P ← F P Fᵀ + G Q Gᵀ`` with
   ``F = ∂f/∂x`` at the current ``x`` (:func:`predict_ahead`: the extended Kalman
   filter's prediction; exact for a linear model). ``x``, ``P`` and the returned estimate
   are this prediction; before the filter starts, the prior of ``x[0]`` moved through the
   inputs received so far.

For the Kalman family this is the textbook treatment of a constant, known delay: the
conditional mean of ``x[k]`` given ``y[0..k−d]``, exactly for a linear-Gaussian model
(Gopalakrishnan et al. review the alternatives). For the FIR family the window makes it
natural: the estimate of ``x[k]`` from a window ending at ``k − d`` — paper 000's
``form="predictor"`` is ``d = 1`` of it — is, for a linear model, the window's estimate of
``x[k − d]`` moved ``d`` steps by the model (the best linear unbiased estimate of
``A^d x[k − d] + Σ Aʲ G w``, whose noise terms after ``k − d`` are independent of the
window). A time-varying linear model has no time-free ``f``: the delay is refused there.
A restarted system of a batch starts its own ``d`` steps of waiting.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validation import FloatArray


def check_delay(delay: Any, model: Any) -> int:
    """``delay`` as an integer ≥ 0; ValueError naming it otherwise, or when the model has no
    time-free ``f`` to predict with (a time-varying linear model)."""
    ok = not isinstance(delay, bool) and isinstance(delay, (int, np.integer)) and delay >= 0
    if not ok:
        raise ValueError(f"delay must be an integer >= 0 (steps); got {delay!r}")
    if delay and not getattr(model, "time_invariant", True):
        raise ValueError(f"delay={delay} needs a time-invariant model to predict ahead with "
                         f"(f and F); {getattr(model, 'name', type(model).__name__)!r} "
                         "varies with time")
    return int(delay)


class DelayLine:
    """Per system: the last ``d + 1`` inputs, oldest first (``window[:, 0]`` is ``u[k − d −
    1]``, the lagged filter's input; ``window[:, 1:]`` the ``d`` the prediction uses), and
    the steps taken since the system's (re)start. Plain arrays: copies are exact."""

    def __init__(self, delay: int, n_b: int, n_u: int) -> None:
        self.delay = delay
        self.window = np.zeros((n_b, delay + 1, n_u))
        self.age = np.zeros(n_b, dtype=np.int64)

    def push(self, u: FloatArray) -> FloatArray:
        """Take this step's ``u[k − 1]`` (rows of systems past their first step; a
        restarted system's first step has none) and return the window's oldest input,
        ``u[k − d − 1]``: the lagged filter's input this step."""
        self.window[:, :-1] = self.window[:, 1:]
        self.window[:, -1] = np.where((self.age >= 1)[:, None], u, 0.0)
        return self.window[:, 0].copy()

    def restart(self, mask: np.ndarray) -> None:
        self.window[mask] = 0.0
        self.age[mask] = 0


def predict_ahead(model: Any, x: FloatArray, P: FloatArray | None, window: FloatArray,
                  steps: np.ndarray) -> tuple[FloatArray, FloatArray | None]:
    """Move each system ``steps[b]`` steps ahead with the last ``steps[b]`` inputs of its
    ``window (B, d + 1, n_u)``: ``x ← f(x, u)``, ``P ← F P Fᵀ + G Q Gᵀ`` (module docstring).
    ``x (B, n)``, ``P (B, n, n)`` or ``None``; returns fresh arrays."""
    x = np.array(x, dtype=np.float64)
    P = None if P is None else np.array(P, dtype=np.float64)
    d = window.shape[1] - 1
    Qd = np.asarray(model.GQGT, dtype=np.float64)
    for slot in range(1, d + 1):
        active = steps >= d + 1 - slot                # the last `steps` slots are theirs
        if not active.any():
            continue
        rows = np.flatnonzero(active)
        u = window[rows, slot]
        if P is None:
            x[rows] = model.f(x[rows], u)
            continue
        fx, F = model.f_and_F(x[rows], u)            # one pass where the plant fuses them
        P[rows] = F @ P[rows] @ np.swapaxes(F, -1, -2) + Qd
        P[rows] = 0.5 * (P[rows] + np.swapaxes(P[rows], -1, -2))
        x[rows] = fx
    return x, P
