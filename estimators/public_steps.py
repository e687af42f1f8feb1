"""``predict`` and ``update`` as public steps of the Kalman family (filterpy's two calls).

``step(y, u)`` is ``predict(u)`` then ``update(y)`` after the first step; the first ``step``
after ``reset`` is an ``update`` only (``x0, P0`` are the prior of ``x[0]``: the
docs/architecture.md#first-step-rule). A filterpy user who predicts first calls
``predict()`` then ``update(y)`` from the start: ``x0, P0`` are then the prior of the state
*before* the first measurement, as in filterpy.

Both are the filter's own step — compiled twin or numpy reference, the divergence watch
included: ``predict`` is a step without a measurement (a prediction is not an innovation:
the NIS run of the watch is left as it was), ``update`` is a measurement update of the
current state (the first-step branch). With ``redraw=False`` a UKF's ``update`` draws fresh
sigma points from ``(x⁻, P⁻)`` (``step`` reuses the propagated ones).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

from numpy.typing import ArrayLike

from ._validation import FloatArray, as_covariance, as_matrix

if TYPE_CHECKING:
    from .base import Estimator

__all__ = ["PublicSteps"]


class PublicSteps:
    """Mixin of the Kalman family: :meth:`predict` and :meth:`update` next to ``step``."""

    #: the model argument ``update(y, H=...)`` replaces (``"C"`` on a linear model), or
    #: ``None`` where ``H`` is the Jacobian of ``model.h`` (EKF, UKF: no per-call ``H``)
    per_call_H: ClassVar[str | None] = None

    def predict(self, u: ArrayLike | None = None) -> FloatArray:
        """Time update only: ``x⁻ = f(x, u)``, ``P⁻ = F P Fᵀ + G Q Gᵀ`` (the filter's own
        prediction); returns ``x⁻``. The next :meth:`update` (or ``step``) is then a
        measurement update only. ``u`` is the input that drives the plant into the next
        state. Before the first step the prior ``x0, P0`` is moved one step (filterpy's
        predict-first habit).
        """
        est: Estimator = self  # type: ignore[assignment]
        _undelayed(est, "predict")
        with est.state.branch(update_only=False, keep_nis_run=True):
            return est.step(None, u)                   # a step without a measurement

    def update(self, y: ArrayLike | None, R: ArrayLike | Callable[[FloatArray], Any] | None = None,
               H: ArrayLike | None = None) -> FloatArray:
        """Measurement update of the current state with ``y``; returns ``x⁺``.

        Args:
            y: the measurement (``None``, NaN or masked entries: missing, as in ``step``).
            R: this call's measurement noise covariance ``(n_y, n_y)`` instead of
                ``model.R`` — or a callable ``R(x)`` of the current estimate (``(n_x,)``, or
                ``(B, n_x)`` for a batch) returning one ``(n_y, n_y)`` matrix. Must be
                symmetric positive semi-definite (``ValueError`` naming ``R``).
            H: this call's measurement matrix ``(n_y, n_x)`` instead of ``model.C``
                (:class:`~fir_gym.estimators.kalman.KalmanFilter` only: the EKF and UKF
                measure through ``model.h``).

        ``predict(u)`` then ``update(y)`` equals ``step(y, u)`` after the first step.
        """
        est: Estimator = self  # type: ignore[assignment]
        _undelayed(est, "update")
        model = est.model
        changes: dict[str, Any] = {}
        if R is not None:
            value = R(est.x) if callable(R) else R
            changes["R"] = as_covariance("R", value, model.n_y)
        if H is not None:
            if self.per_call_H is None:
                raise TypeError(f"H: {type(self).__name__} linearises model.h; a per-call H is a "
                                f"KalmanFilter option (pass R only, or change model.h)")
            changes[self.per_call_H] = as_matrix("H", H, (model.n_y, model.n_x))
        with est._stepping_with(model.replace(**changes) if changes else None), \
                est.state.branch(update_only=True):
            return est.step(y)


def _undelayed(est: Estimator, name: str) -> None:
    """``predict``/``update`` split the step of a filter without a delay; refuse otherwise."""
    if est.delay:
        raise ValueError(f"{name}: predict and update split the step of a filter without a "
                         f"delay; this one has delay={est.delay} (use step)")
