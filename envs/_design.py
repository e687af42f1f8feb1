"""A plant's design point: what a classical controller needs to know about it.

A plant publishes its design point through :meth:`PlantEnv.design_point
<fir_gym.envs._base.PlantEnv.design_point>`, computed from its *nominal* parameters
(what the filter believes, never the truth); :class:`~fir_gym.controllers.LQGController`
and :class:`~fir_gym.controllers.PIDController` read it there and nowhere else. The
record lives here, below both the plants and the controllers, so that a plant can build
one without importing :mod:`fir_gym.controllers` (docs/architecture.md#imports).

The LQR on :attr:`DesignPoint.M` minimises the plant's own (unsaturated) cost, so a
plant whose reward is a quadratic form in the deviation from its operating point has
nothing to tune by hand: it writes down its operating point and the weights its reward
already uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DesignPoint:
    """A plant's operating point, the quadratic weights of its reward and its PID tuning.

    Attributes:
        x: the operating state, shape ``(n_x,)``: a fixed point ``x = f(x, u)`` of the
            nominal model.
        u: the operating input, shape ``(n_u,)``, in the plant's normalised action units
            (the action as applied, ``[-1, 1]``).
        M: the stage cost as a quadratic form in ``z = [x[k+1] - x; a[k] - u]``, shape
            ``(n_x + n_u, n_x + n_u)``, symmetric positive semi-definite, read off the
            plant's reward (the reward is ``-min(zᵀ M z, cost_cap)`` up to the constant
            cost of the operating point).
        states: the indices of the states the design regulates (the others are constant
            parameters that neither the input nor the cost touches at the operating
            point; the LQR's gain is zero on them).
        output: for a PID controller, the index of the measurement component the task
            holds; ``None`` where no measured quantity is held (PID does not apply).
        setpoint: the target of that measurement component.
        pid: default PID gains ``{"kp": ..., "ki": ..., "kd": ...}``, tuned by hand on
            the nominal model (missing gains are 0).
        note: one line saying what the operating point is (quoted in error messages).
        estimate_input_weight: where set, the weight of ``a²`` the LQG uses when it acts
            on an *estimate* instead of the reward's (a detuned LQR); on the true state
            the LQG always uses the reward's weights.
    """

    x: FloatArray
    u: FloatArray
    M: FloatArray
    states: tuple[int, ...]
    output: int | None = None
    setpoint: float = 0.0
    pid: dict[str, float] = field(default_factory=dict)
    note: str = ""
    estimate_input_weight: float | None = None
