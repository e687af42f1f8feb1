"""fir-gym's optional JAX backend: the plants and their estimators as gymnax environments.

Needs the ``jax`` extra (``pip install ".[jax]"`` in the fir-gym checkout; the CUDA build of
JAX is ``pip install "jax[cuda12]"`` after it). Nothing else in fir-gym imports this
package, so fir-gym works without JAX.

**Float64.** The environments compute in float64, as the numpy plants and filters do (the
Orbit plant's 100 Euler substeps and its EKF covariance lose too much in float32 to match
them). Importing :mod:`fir_gym.jax` therefore turns on ``jax_enable_x64``
(``jax.config.update("jax_enable_x64", True)``): a process-wide JAX setting, chosen at
import rather than through a context because a jitted function is traced lazily, at its
first call, long after any ``with`` block would have closed; gymnax environments run
unchanged in x64 mode (their default dtypes become 64-bit). Every environment checks the
flag when it is built and when it traces, and raises if it was turned off later.

Environments: :func:`make` (``fir_gym.jax.make(env_id, kind, **kwargs)`` → ``(env, params)``,
as ``gymnax.make``) over :data:`PLANTS` (:mod:`fir_gym.jax.registry`):
:class:`fir_gym.jax.orbit.Orbit` (``fir_gym/Orbit-v0``, paper 000, simulation 1),
:class:`fir_gym.jax.uncertain_oscillator.UncertainOscillator` (``fir_gym/UncertainOscillator-v0``,
paper 000, simulation 2), :class:`fir_gym.jax.carrier_motion.CarrierMotion`
(``fir_gym/CarrierMotion-v0``, paper 001), :class:`fir_gym.jax.van_der_pol.VanDerPol`
(``fir_gym/VanDerPol-v0``, paper 002) and :class:`fir_gym.jax.pendulum_slider.PendulumSlider`
(``fir_gym/PendulumSlider-v0``: the slider's analytic equations of motion, integrated as
the numpy plant's MuJoCo scene is, RK4 at 1 ms). Each module's docstring states its noise contract.

Kinds (what the controller observes; ``kind_kwargs`` carries a kind's options): ``true``,
``measurement``, ``measurement-stack`` (:mod:`fir_gym.jax.measurement_stack`), the plant's
own filter run inside its step (``ekf``; ``kf`` on CarrierMotion-v0), and the generic filters
of :mod:`fir_gym.jax.filters` run on the plant's ``filter_model`` — ``ukf``
(:mod:`fir_gym.jax.unscented`) and ``efir`` (``fir`` on CarrierMotion-v0;
:mod:`fir_gym.jax.fir`). Training: :mod:`fir_gym.jax.train` (``train``, ``save``, ``load``);
the benchmark beside stable-baselines3: :mod:`fir_gym.jax.benchmark`.
"""

from __future__ import annotations

from fir_gym._extras import MissingExtra, install_hint


def _missing(error: ImportError) -> MissingExtra:
    # (jax's own ImportError for a missing jaxlib names no module: the hint is JAX's)
    return MissingExtra("fir_gym.jax: " + str(install_hint(error.name) or install_hint("jax")))


# jax first, then gymnax: without the extra at all, JAX is what is named missing
# (exercised without the extra: tests/jax/test_jax_boundary.py)
try:
    import jax
except ImportError as error:
    raise _missing(error) from None
try:
    import gymnax  # noqa: F401
except ImportError as error:
    raise _missing(error) from None

jax.config.update("jax_enable_x64", True)

from ._x64 import require_x64  # noqa: E402  (after the x64 switch)
from .carrier_motion import (  # noqa: E402
    CarrierMotion,
    CarrierMotionParams,
    CarrierMotionState,
    carrier_motion_params,
)
from .orbit import (  # noqa: E402
    Orbit,
    OrbitNoise,
    OrbitParams,
    OrbitResetNoise,
    OrbitState,
    orbit_noise,
    orbit_params,
    orbit_reset_noise,
)
from .pendulum_slider import (  # noqa: E402
    PendulumSlider,
    PendulumSliderParams,
    PendulumSliderState,
    pendulum_slider_params,
)
from .registry import PLANTS, make  # noqa: E402
from .uncertain_oscillator import (  # noqa: E402
    UncertainOscillator,
    UncertainOscillatorParams,
    UncertainOscillatorState,
    uncertain_oscillator_params,
)
from .van_der_pol import VanDerPol, VanDerPolParams, VanDerPolState, van_der_pol_params  # noqa: E402

__all__ = [
    "PLANTS",
    "CarrierMotion",
    "CarrierMotionParams",
    "CarrierMotionState",
    "Orbit",
    "OrbitNoise",
    "OrbitParams",
    "OrbitResetNoise",
    "OrbitState",
    "PendulumSlider",
    "PendulumSliderParams",
    "PendulumSliderState",
    "UncertainOscillator",
    "UncertainOscillatorParams",
    "UncertainOscillatorState",
    "VanDerPol",
    "VanDerPolParams",
    "VanDerPolState",
    "carrier_motion_params",
    "make",
    "orbit_noise",
    "orbit_params",
    "orbit_reset_noise",
    "pendulum_slider_params",
    "require_x64",
    "uncertain_oscillator_params",
    "van_der_pol_params",
]
