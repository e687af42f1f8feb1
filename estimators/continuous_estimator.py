"""The base of the filters that run on a continuous model (paper 002's two filters).

A :class:`ContinuousEstimator` takes a :class:`~.continuous.ContinuousModel`, keeps
it as :attr:`continuous_model` and hands the base class its sampled discrete view
(:meth:`ContinuousModel.sampled`, which carries the sizes). Its first step is the
Kalman update of the prior with the point measurement ``y[0]`` of ``h(x(t0))``,
covariance ``R/h`` (the Gymnasium plant's convention: ``reset`` returns a point
sample, every later measurement an interval average).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray
from .base import Estimator
from .continuous import ContinuousModel
from .kalman import update_kernel


class ContinuousEstimator(Estimator):
    """An :class:`Estimator` on a :class:`ContinuousModel` (see the module docstring)."""

    model_attribute: ClassVar[str] = "continuous_model"
    can_gate: ClassVar[bool] = True

    def __init__(self, model: ContinuousModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        if not isinstance(model, ContinuousModel):
            raise TypeError(f"model must be a ContinuousModel (e.g. env.unwrapped."
                            f"continuous_model); got {type(model).__name__}")
        self.continuous_model = model
        super().__init__(model.sampled(), x0=x0, P0=P0, **options)

    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        cm = self.continuous_model
        x, P, _, nis = update_kernel(x, P, y - cm.h(x), cm.H(x), cm.R / cm.dt, valid,
                                     self._gate_threshold)
        return x, P, nis
