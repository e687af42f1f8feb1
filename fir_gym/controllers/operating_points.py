"""Each plant's operating point and the LQR weights of its reward (the classical tuning).

A design point (:class:`~fir_gym.envs.DesignPoint`) is what a classical controller needs
from a plant, computed from the plant's *nominal* parameters (what the filter believes,
never the truth):

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
* ``pid`` — default PID gains, tuned by hand on the nominal model;
* ``estimate_input_weight`` — where set, the weight of ``a²`` the LQG uses when it acts
  on an *estimate* instead of the reward's (a detuned LQR). On the true state the LQG
  always uses the reward's weights.

Each plant publishes its own through the public method ``plant.design_point()``
(:meth:`fir_gym.envs._base.PlantEnv.design_point`, overridden in the plant's own file;
docs/architecture.md#design-point), which documents its operating point and weights:

* Orbit-v0 (:meth:`~fir_gym.envs.OrbitEnv.design_point`): ``r = r_ref``, ``v = 0``
  with the nominal hover thrust ``μ / r_ref²``; cost ``(r − r_ref)² + 0.01 a²``.
* UncertainOscillator-v0 (:meth:`~fir_gym.envs.UncertainOscillatorEnv.design_point`):
  ``x1 = s``, ``x2 = 0``, ``x3 = x3(0)``, ``u = (c s − b) / u_max``; cost
  ``(x1 − s)² + 1e-3 a²``; the damping parameter ``x3`` is a constant state (an
  uncontrollable mode at 1), so the design regulates ``(x1, x2)`` only.
* CarrierMotion-v0 (:meth:`~fir_gym.envs.CarrierMotionEnv.design_point`): ``x = 0``,
  ``c = 0`` (the action does not move the deck); cost ``((x1 − c_max a) / σ1)²``: the
  input matrix is zero, so the LQR with the cross term of its cost is the
  certainty-equivalent one-step predictor ``c = C A x̂ / c_max``.
* VanDerPol-v0 (:meth:`~fir_gym.envs.VanDerPolEnv.design_point`): the origin, ``u = 0``
  (unstable: ε = 1); cost ``(x1² + x2²)/4 + 0.01 a²``. On an estimate the input weight
  is 3 instead of 0.01 (a *detuned* LQR; the reasons and the evidence are in its
  docstring).
* PendulumSlider-v0 (:meth:`~fir_gym.envs.PendulumSliderEnv.design_point`): the slider
  at the nominal rest ``x_rest``, the pendulum hanging, ``u = 0``; cost
  ``θ² + 0.1 θ̇² + 100 (x − x_rest)² + 0.01 a²``.

This module keeps :func:`design_point` and :class:`DesignPoint` importable from
``fir_gym.controllers``; both lead to the plant's own method and record.
"""

from __future__ import annotations

from typing import Any

from fir_gym.envs import DesignPoint

__all__ = ["DesignPoint", "design_point"]


def design_point(plant: Any) -> DesignPoint:
    """The :class:`DesignPoint` of a fir-gym plant (``env.unwrapped``): ``plant.design_point()``.

    Raises:
        TypeError: ``plant`` is not a fir-gym plant (it has no ``design_point`` method).
        NotImplementedError: the plant publishes no design point (the message names the
            plant and the method to implement).
    """
    method = getattr(plant, "design_point", None)
    if not callable(method):
        raise TypeError(f"{type(plant).__name__} is not a fir-gym plant: it has no "
                        "design_point() method (docs/architecture.md#design-point)")
    point = method()
    if not isinstance(point, DesignPoint):
        raise TypeError(f"{type(plant).__name__}.design_point() must return a "
                        f"fir_gym.envs.DesignPoint; got {type(point).__name__}")
    return point
