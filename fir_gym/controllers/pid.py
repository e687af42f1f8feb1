"""PID control of a measured output: the classical controller without a model.

``PIDController(env, kp=..., ki=..., kd=...)`` holds one measured quantity at its
setpoint — the task of Orbit-v0 (the radius), UncertainOscillator-v0 (x1),
VanDerPol-v0 (x1 at 0) and PendulumSlider-v0 (the slider's position) — from the raw
measurement the plant returns (an env that observes the measurement):

    e[k] = setpoint − y[k]
    I[k] = I[k−1] + e[k] Δt                       (clamped while the output saturates)
    D[k] = α D[k−1] − (1 − α) (y[k] − y[k−1]) / Δt,   α = τ / (τ + Δt)
    a[k] = clip(u_ff + kp e[k] + ki I[k] + kd D[k], −1, 1)

in the plant's normalised action units, with the derivative on the measurement (no
kick at a setpoint change) low-passed with time constant ``tau`` (the measurements
are noisy), clamping against wind-up (while the output would pass a limit, the
integral goes no further than the value that puts it at the limit), and the operating
point's input
``u_ff`` as feed-forward (the hover thrust, the oscillator's holding force). The
memory ``(I, y[k−1], D)`` of each env travels in ``predict``'s ``state``, as a
recurrent policy's does, and is cleared where ``episode_start`` is set. Defaults for
the gains come from the plant's ``design_point()`` (tuned by hand on the nominal model).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._policy import Controller, FloatArray
from .operating_points import design_point


class PIDController(Controller):
    """PID on one measured output of the plant (see the module docstring).

    Args:
        env: a fir-gym plant that observes its raw measurement.
        kp, ki, kd: gains, in action units per measurement unit (per unit·time for
            ``ki``, per unit/time for ``kd``); default: the plant's tuning.
        setpoint: the target of the measured output (default: the task's).
        output: index of the measured component held (default: the task's).
        tau: time constant of the derivative's low-pass filter (default ``5 Δt``).
        feedforward: the constant input added (default: the operating point's).
    """

    def __init__(self, env: Any, *, kp: float | None = None, ki: float | None = None,
                 kd: float | None = None, setpoint: float | None = None,
                 output: int | None = None, tau: float | None = None,
                 feedforward: float | None = None) -> None:
        super().__init__(env)
        if self.observed != "measurement":
            raise ValueError(f"PIDController acts on the raw measurement; this env observes "
                             f"the {self.observed} (use the plant's own observation)")
        point = design_point(self.plant)
        if point.output is None and output is None:
            raise ValueError(f"{type(self.plant).__name__} holds no measured quantity (its "
                             "task is not a setpoint); PID does not apply, use LQG")
        gains = {"kp": kp, "ki": ki, "kd": kd}
        self.gains = {k: float(point.pid.get(k, 0.0) if v is None else v)
                      for k, v in gains.items()}
        for name, value in self.gains.items():
            if not np.isfinite(value):
                raise ValueError(f"{name} must be finite; got {value!r}")
        index = point.output if output is None else output
        n_y = len(self.plant.measurement_names)
        if index is None or not 0 <= int(index) < n_y:
            raise ValueError(f"output must be a measurement index in [0, {n_y}); got {output!r}")
        self.output = int(index)
        self.setpoint = point.setpoint if setpoint is None else float(setpoint)
        self.dt = float(self.plant.model.dt)
        self.tau = 5.0 * self.dt if tau is None else float(tau)
        if not self.tau >= 0:
            raise ValueError(f"tau must be a non-negative time; got {tau!r}")
        self.feedforward = float(point.u[0]) if feedforward is None else float(feedforward)

    def act(self, observation: FloatArray, state: Any, episode_start: np.ndarray
            ) -> tuple[FloatArray, Any]:
        y = observation[:, self.output]
        n = len(y)
        memory = np.zeros((n, 3)) if state is None else np.array(state, dtype=np.float64)
        integral, previous, derivative = memory.T
        fresh = episode_start | (state is None)
        previous = np.where(fresh, y, previous)              # no derivative kick at a start
        integral = np.where(fresh, 0.0, integral)
        derivative = np.where(fresh, 0.0, derivative)
        alpha = self.tau / (self.tau + self.dt)
        derivative = alpha * derivative - (1.0 - alpha) * (y - previous) / self.dt
        error = self.setpoint - y
        g = self.gains
        trial = integral + error * self.dt
        rest = self.feedforward + g["kp"] * error + g["kd"] * derivative
        if g["ki"] != 0.0:
            # clamping against wind-up, on the integral's share of the output c = ki I: where
            # the output would pass a limit while the error pushes it on, c goes no further
            # than the limit (and never back); elsewhere it integrates
            low, high = self._low[0] - rest, self._high[0] - rest
            old, new = g["ki"] * integral, g["ki"] * trial
            up, down = (rest + new > self._high[0]) & (new > old), \
                (rest + new < self._low[0]) & (new < old)
            share = np.where(up, np.maximum(old, np.minimum(new, high)),
                             np.where(down, np.minimum(old, np.maximum(new, low)), new))
            integral = share / g["ki"]
        else:
            integral = trial
        action = rest + g["ki"] * integral
        return action[:, None], np.stack([integral, y, derivative], axis=1)

    def __repr__(self) -> str:
        return (f"PIDController({type(self.plant).__name__}, output {self.output} -> "
                f"{self.setpoint:g}, kp={self.gains['kp']:g}, ki={self.gains['ki']:g}, "
                f"kd={self.gains['kd']:g})")
