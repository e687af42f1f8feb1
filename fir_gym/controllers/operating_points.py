"""Each plant's operating point and the LQR weights of its reward (the classical tuning).

A design point is what a classical controller needs from a plant, computed from the
plant's *nominal* parameters (what the filter believes, never the truth):

* ``x``, ``u`` — the operating point: a fixed point ``x = f(x, u)`` of the nominal
  model, with ``u`` in the plant's normalised action units;
* ``M`` — the stage cost as a quadratic form in ``z = [x[k+1] - x; a[k] - u]``, read
  off the plant's reward (the reward is ``-min(zᵀ M z, cost_cap)`` up to the
  constant cost of the operating point): an LQR on these weights minimises the
  plant's own (unsaturated) cost, so there is nothing to tune by hand;
* ``states`` — the states the design regulates (the others are constant parameters
  that neither the input nor the cost touches at the operating point);
* ``output``, ``setpoint`` — for a PID controller: the measurement component that the
  task holds and its target (``output=None`` where no measured quantity is held);
* ``pid`` — default PID gains, tuned by hand on the nominal model (documented below);
* ``estimate_input_weight`` — where set, the weight of ``a²`` the LQG uses when it acts
  on an *estimate* instead of the reward's (a detuned LQR; see VanDerPol-v0 below). On
  the true state the LQG always uses the reward's weights.

* Orbit-v0: ``r = r_ref``, ``v = 0`` with the nominal hover thrust ``μ / r_ref²``;
  cost ``(r − r_ref)² + 0.01 a²``.
* UncertainOscillator-v0: ``x1 = s``, ``x2 = 0``, ``x3 = x3(0)``, ``u = (c s − b) / u_max``;
  cost ``(x1 − s)² + 1e-3 a²``.
* CarrierMotion-v0: ``x = 0``, ``c = 0`` (the action does not move the deck); cost
  ``((x1 − c_max a) / σ1)²``.
* VanDerPol-v0: the origin, ``u = 0`` (unstable: ε = 1); cost ``(x1² + x2²)/4 + 0.01 a²``.
  On an estimate the input weight is 3 instead of 0.01 (a *detuned* LQR). The
  measurement's variance is 50 per step (paper 002's R/h) on a state of amplitude ~2:
  the EKF's x1 error in closed loop (RMSE ≈ 2.7) is as large as the state. With the
  reward's cheap input the LQR is deadbeat in x2 (closed-loop poles 0.905 and 0.010,
  ``K = [0.40, 0.54]``) and passes that error to the plant at full authority
  (``u_max h = 2`` per step against the process noise's 0.7); with weight 3 the poles
  are 0.900 and 0.577 (``K = [0.15, 0.29]``): the same slow x1 mode, half the gain on
  the noisiest estimate. The weight was picked on evaluation seeds 100–139 (held out
  from the tests' seeds 0–39) among 0.01, 0.3, 1, 3, 10 and 30: the mean returns of the
  first five were within one standard error of each other there (−743 to −761, ± ≈ 60;
  30: −805), and 3 beat the
  best constant input (0) on the most seeds (65 %; 0.01: 50 %, 10: 52 %). On seeds
  0–39 the EKF-fed LQG scores −664 with weight 3 and −727 with 0.01; constant 0 scores
  −771, uniform random −948 (``tests/envs/test_honest_tasks.py``).
* PendulumSlider-v0: the slider at the nominal rest ``x_rest``, the pendulum hanging,
  ``u = 0``; cost ``θ² + 0.1 θ̇² + 100 (x − x_rest)² + 0.01 a²``.

On CarrierMotion-v0 the input matrix is zero, so the LQR with the cross term of its
cost is the certainty-equivalent one-step predictor ``c = C A x̂ / c_max``. On
UncertainOscillator-v0 the damping parameter ``x3`` is a constant state (an
uncontrollable mode at 1), so the design regulates ``(x1, x2)`` only; the temporary
uncertainty δ of the truth is not in the nominal model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DesignPoint:
    """A plant's operating point, cost weights and default PID tuning (see the module)."""

    x: FloatArray
    u: FloatArray
    M: FloatArray
    states: tuple[int, ...]
    output: int | None = None
    setpoint: float = 0.0
    pid: dict[str, float] = field(default_factory=dict)
    note: str = ""
    estimate_input_weight: float | None = None


def design_point(plant: Any) -> DesignPoint:
    """The :class:`DesignPoint` of a fir-gym plant (``env.unwrapped``)."""
    name = type(plant).__name__
    builder = _BUILDERS.get(name)
    if builder is None:
        raise TypeError(f"no operating point is known for {name}; known plants: "
                        f"{sorted(_BUILDERS)}")
    return builder(plant)


def _orbit(plant: Any) -> DesignPoint:
    p = plant.nominal_params
    hover = p["mu"] / (plant.r_ref ** 2 * p["thrust_max"])
    M = np.diag([1.0, 0.0, 0.01])
    return DesignPoint(x=np.array([plant.r_ref, 0.0]), u=np.array([hover]), M=M, states=(0, 1),
                       output=0, setpoint=plant.r_ref,
                       pid={"kp": 2.0, "ki": 0.5, "kd": 2.0},
                       note="hover at r_ref with the nominal μ's thrust")


def _oscillator(plant: Any) -> DesignPoint:
    p = plant.nominal_params
    s = plant.setpoint
    u = (p["stiffness"] * s - p["drive"]) / p["u_max"]
    M = np.zeros((4, 4))
    M[0, 0], M[3, 3] = 1.0, 1e-3
    x3 = float(plant.initial_state[2])
    return DesignPoint(x=np.array([s, 0.0, x3]), u=np.array([u]), M=M, states=(0, 1),
                       output=0, setpoint=s, pid={"kp": 1.0, "ki": 2.0, "kd": 0.1},
                       note="x1 at the setpoint; x3 (damping) is a constant parameter")


def _carrier(plant: Any) -> DesignPoint:
    c = plant.c_max / plant._sigma1
    w = np.array([1.0 / plant._sigma1, 0.0, -c])       # z -> (x1[k+1] - c_max a) / σ1
    return DesignPoint(x=np.zeros(2), u=np.zeros(1), M=np.outer(w, w), states=(0, 1),
                       note="compensation: the action predicts the deck, it does not move it")


def _van_der_pol(plant: Any) -> DesignPoint:
    return DesignPoint(x=np.zeros(2), u=np.zeros(1), M=np.diag([0.25, 0.25, 0.01]),
                       states=(0, 1), output=0, setpoint=0.0,
                       pid={"kp": 1.0, "ki": 0.0, "kd": 1.0},
                       note="the unstable origin inside the limit cycle",
                       estimate_input_weight=3.0)


def _pendulum_slider(plant: Any) -> DesignPoint:
    x_rest = plant._rest_position(plant.nominal_params)
    M = np.diag([100.0, 0.0, 1.0, 0.1, 0.01])
    return DesignPoint(x=np.array([x_rest, 0.0, 0.0, 0.0]), u=np.zeros(1), M=M,
                       states=(0, 1, 2, 3), output=0, setpoint=x_rest,
                       pid={"kp": 5.0, "ki": 0.0, "kd": 0.5},
                       note="slider at the nominal rest position, pendulum hanging")


_BUILDERS = {
    "OrbitEnv": _orbit,
    "UncertainOscillatorEnv": _oscillator,
    "CarrierMotionEnv": _carrier,
    "VanDerPolEnv": _van_der_pol,
    "PendulumSliderEnv": _pendulum_slider,
}
