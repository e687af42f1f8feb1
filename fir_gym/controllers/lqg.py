"""LQG: the LQR of the nominal model applied to an estimate (certainty equivalence).

``LQGController(env)`` designs the discrete LQR of the plant's *nominal* model
linearised at its operating point, with the weights of the plant's own reward
(the plant's ``design_point()``, :mod:`.operating_points`; :mod:`.lqr`), and applies
it to what ``env`` observes:

    a = clip(u* − K (x̂ − x*), −1, 1)

where ``x̂`` is the estimate of whatever estimator wraps ``env`` (any registry name:
``gym.make(id, estimator="ekf")``) — the separation principle's certainty-equivalent
controller, exact for a linear plant with Gaussian noise (the Kalman filter plus the
LQR), an approximation otherwise. On an env that observes the true state it is the
LQR itself. It does not apply to the raw measurement (the gain needs a state): give
it an estimator.

On an estimate, a plant may detune the design: VanDerPol-v0 weights the input 3 instead
of the reward's 0.01, because its estimates are as noisy as its state (the reasons and
the evidence: :meth:`fir_gym.envs.VanDerPolEnv.design_point`). ``input_weight`` sets that
weight by hand.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ._policy import Controller, FloatArray
from .lqr import LQRDesign, lqr_design
from .operating_points import design_point


class LQGController(Controller):
    """Certainty-equivalent LQR on the estimate (or the true state) ``env`` observes.

    Args:
        env: a fir-gym plant wrapped to observe an estimate or the true state (a
            Gymnasium env or a stable-baselines3 ``VecEnv`` of such envs).
        input_weight: the weight of ``a²`` in the design's stage cost (a positive
            number; on a single-input plant). Default: the reward's, or on an estimate
            the plant's ``estimate_input_weight`` where it has one.

    Attributes: ``point`` (the operating point and weights), ``design`` (``A``, ``B``,
    ``Q``, ``R``, ``N``, the gain ``K`` and the closed-loop poles of the linearisation).
    """

    def __init__(self, env: Any, *, input_weight: float | None = None) -> None:
        super().__init__(env)
        if self.observed == "measurement":
            raise ValueError("LQGController needs an env that observes a state estimate or "
                             "the true state; this one observes the raw measurement (wrap it "
                             "with an estimator, e.g. gym.make(id, estimator='ekf'))")
        point = design_point(self.plant)
        if input_weight is None and self.observed == "estimate":
            input_weight = point.estimate_input_weight
        if input_weight is not None:
            try:
                weight = float(input_weight)
            except (TypeError, ValueError):
                weight = float("nan")
            if not (np.isfinite(weight) and weight > 0):
                raise ValueError(f"input_weight must be a positive number; got {input_weight!r}")
            M = point.M.copy()
            n_x = len(point.x)
            M[n_x:, n_x:] = weight * np.eye(M.shape[0] - n_x)
            point = replace(point, M=M)
        self.point = point
        self.design: LQRDesign = lqr_design(self.plant.model, self.point)

    def act(self, observation: FloatArray, state: Any, episode_start: np.ndarray
            ) -> tuple[FloatArray, Any]:
        return self.point.u - (observation - self.point.x) @ self.design.K.T, None

    def __repr__(self) -> str:
        return (f"LQGController({type(self.plant).__name__}, observes {self.observed}, "
                f"K={np.array2string(self.design.K, precision=4)})")
