"""PendulumSlider-v0 as a gymnax environment: paper 003's plant, with its EKF in the state.

The JAX twin of :class:`fir_gym.envs.pendulum_slider.PendulumSliderEnv` (the numpy
reference) seen through :func:`fir_gym.wrappers.factory.wrap_observation` — one of three
observation kinds:

* ``"true"``: the true state ``[x, ẋ, θ, θ̇]`` (:class:`~fir_gym.wrappers.baselines.
  TrueStateObservation`);
* ``"measurement"``: the raw measurement ``x + v`` of all four states (the plant's own
  observation);
* ``"ekf"``: the extended Kalman filter's estimate (:class:`~fir_gym.wrappers.
  EstimatorObservation` with :class:`~fir_gym.estimators.extended.ExtendedKalmanFilter` on
  the env's :attr:`~fir_gym.envs.pendulum_slider.PendulumSliderEnv.model`); the filter's
  mean, covariance and divergence watch live in :class:`PendulumSliderState`. As there,
  ``observation`` may instead be ``"estimate+covariance"`` (a dict: ``estimate`` and
  ``covariance``, the upper triangle of ``P`` row by row, 10 numbers) or
  ``"estimate+measurement"`` (``estimate`` and ``measurement``).

**Plant: the analytic equations of motion, not MuJoCo.** The numpy plant is MuJoCo's RK4
at 1 ms with paper 003's friction force applied at every stage
(:class:`fir_gym.envs._mujoco_rk4.StageRK4`). This module integrates the same ODE — the
Lagrangian's equations of :mod:`fir_gym.envs.pendulum_slider_dynamics` with the same
friction law (``friction="paper"``: the sign-free ``−μ N`` with the true normal force
``N = (m1+m2) g + m2 l (cosθ θ̇² + sinθ θ̈)``, or ``"none"``) — by the same classical RK4,
``h = 1 ms``, ``frame_skip`` steps per env step with the force ``U = action · force_max``
held: :func:`slider_interval`, which mirrors
:meth:`~fir_gym.envs.pendulum_slider_dynamics.PendulumSliderDynamics.propagate` (its
compiled twin :func:`fir_gym.envs._interval_kernels.slider_rk4`, operation for
operation), i.e. the plant of the numpy *native vector env* and the EKF's model. MuJoCo's
rail contact (``friction="coulomb"``) is not an ODE and paper 003's printed equations
(``dynamics="printed-eq15"``/``"printed-eq5"``) are not ported: both are refused. Measured
agreement with the MuJoCo plant (tests/jax/test_pendulum_slider_parity.py, same actions and
noise): at the benchmark settings (``frame_skip=10``, 500 steps) the two trajectories
differ by at most 1.6e-15 of each component's range over an episode (max |Δθ̇| = 8.2e-15
rad/s on a range of ~6 rad/s, max |Δx| = 8.3e-17 m) for free, resonant, random-hold and
bang-bang forcing and with process noise — at every step at least 47 times inside the
worst-case round-off bound propagated along the trajectory, i.e. round-off: the same RK4
of the same ODE, the operations in another order. MuJoCo's warnings (``mjWARN_BADQPOS``
and friends, which reset its data) have no counterpart here: a non-finite new state is
``"nonfinite_state"``, one beyond ``±state_limit`` (MuJoCo's ``mjMAXVAL`` = 1e10,
:attr:`PendulumSliderEnv.state_limit`) ``"state_overflow"``.

**Step** (:meth:`fir_gym.envs._base.PlantEnv.step`): ``x' = RK4(x, U) + w``, ``w ~ N(0,
Q)`` (Q = 0 by default: MuJoCo is deterministic); ``y = x' + v``, ``v ~ N(0, R)``, ``R =
diag([0.003, 0.03, 0.03, 0.3]²)``. Reward ``−min(θ² + 0.1 θ̇² + 100 (x − x_rest)² +
0.01 action², 20) · frame_skip · 0.1`` (``x_rest = l0 − μ (m1+m2) g / 2k`` of the
constructor's parameters with the paper's friction, ``l0`` otherwise; it stays put when a
parameter is vmapped, as the numpy ``randomize`` leaves it); termination when the slider
leaves the rail, ``|x − l0| > 0.3`` (or the state is not finite), paid ``−cost_cap (1 +
steps left to max_steps_in_episode)`` with ``cost_cap = 20 · frame_skip · 0.1``; a failed
step (``info["simulation_failure"]``: 0 none, 1 nonfinite_state, 2 state_overflow, 3
nonfinite_observation, 4 nonfinite_reward — :data:`SIMULATION_FAILURES`) keeps the last
valid state and observation, pays the terminal penalty and terminates. Truncation at
``max_steps_in_episode`` (gymnax's ``is_truncated``). Actions are clipped to ``[-1, 1]``
(``info["action_clipped"]``); a NaN action (a ``ValueError`` in numpy) makes the state NaN,
a simulation failure. The penalty counts the steps left to ``max_steps_in_episode``: the
numpy plant's own ``max_episode_steps`` (``gym.make(id, max_episode_steps=N)`` sets only
the ``TimeLimit``; fir-gym's tools set both, as the parity tests do).

**EKF** (:mod:`fir_gym.estimators.extended` on the model
:meth:`PendulumSliderEnv._build_model` builds from the nominal parameters; ``nominal=``
may change any physical parameter, ``force_max``, ``frame_skip``, ``friction`` — here also
``"coulomb"``, the model's smooth ``tanh(ẋ / 0.01)`` — ``R`` and ``Q``, whose model default
is paper 003's ``1e-6 I``). Prior: the plant's initial-state mean and covariance, floored
(:func:`fir_gym.wrappers.estimator_observation.prior_of`). ``reset`` consumes ``y[0]``
(update only); each step predicts with the applied action — ``x⁻ = f(x̂, u)``, ``P⁻ = F P
Fᵀ + Q`` with ``F`` the exact Jacobian of the RK4 map (stage-wise sensitivities,
:func:`slider_interval_and_jacobian`) — then makes the Joseph-form update with ``h(x) =
x``, ``H = I`` (:mod:`fir_gym.jax.kalman`: :func:`~fir_gym.jax.kalman.ekf_predict`,
:func:`~fir_gym.jax.kalman.kf_update_innovation`, :func:`~fir_gym.jax.kalman.watch`).
The watch is the numpy one with its defaults: χ² quantile of ``nis_tail = 1e-9`` for 4
channels, ``nis_patience = 10``, ``max_covariance_trace = 1e12``.

**Parity** (the numpy env as the oracle, over whole episodes of 500 steps with process
noise and a random start, a model mismatch, a diverging filter and a termination): given
the MuJoCo plant's states (:meth:`PendulumSlider.step_with_transition`) observations,
rewards and terminated/truncated agree to 4e-16 relative, the EKF's estimate to 5.4e-13, its
covariance to 7.2e-12, its NIS to 4e-14 (1 + nis) and its divergence flag exactly; the
interval map and Jacobian are the numpy model's to 2.4e-14 and 8.5e-13.

**Noise contract.** Every random number comes from the ``key`` of ``reset_env`` /
``step_env`` (gymnax's ``step`` splits its key into the step's and the auto-reset's):
:func:`pendulum_slider_reset_noise` and :func:`pendulum_slider_noise` each make one draw
``z = jax.random.normal(key, (8,))`` — ``z[:4]`` for the state (the initial-state spread,
or the process noise ``w``), ``z[4:]`` for the measurement ``v`` — that the square roots of
the covariances (``V Λ^½`` from ``eigh``, as :func:`fir_gym.envs._base.psd_sqrt`) turn into
the physical increments ``S z``. The pure functions :meth:`PendulumSlider.reset_with_noise`
and :meth:`PendulumSlider.step_with_noise` take those increments
(:class:`PendulumSliderResetNoise`, :class:`PendulumSliderNoise`) instead of a key, so a
caller can drive the JAX env with any noise sequence; :meth:`PendulumSlider.
step_with_transition` takes the plant's new state itself (the MuJoCo plant's, in the
parity tests) and does the rest of the step.

Everything is a pure function of its arguments: ``jit``-able, ``vmap``-able over keys,
states and parameters (:class:`PendulumSliderParams` is a pytree; ``frame_skip``,
``friction`` and their nominal twins are static).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import gymnax.environments.environment as gymnax_env
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from ._plant import SIMULATION_FAILURES as SIMULATION_FAILURES  # (the numpy plants' codes)
from ._plant import (
    FilteredPlant,
    PlantState,
    Reading,
    belief_of,
    filter_prior,
    numpy_sqrt,
    sqrt_of,
    watch_limits_of,
    with_belief,
)
from ._x64 import require_x64
from .filter_model import FilterModel
from .kalman import (
    Belief,
    ekf_predict,
    kf_update_innovation,
    symmetrize,
    watch,
)

#: Table 3 of paper 003 (:data:`fir_gym.envs.pendulum_slider_dynamics.PAPER_PARAMS`)
PAPER_PARAMS: dict[str, float] = {"m1": 0.654, "m2": 0.7925, "l": 0.2, "I_c": 0.0014, "k": 100.0,
                                  "l0": 0.025, "M0": 0.2, "mu": 0.2, "g": 9.8}
#: the measurement noise's standard deviations (:data:`fir_gym.envs.pendulum_slider.PAPER_R_STD`)
PAPER_R_STD = (0.003, 0.03, 0.03, 0.3)
#: MuJoCo's ``mjMAXVAL`` (:attr:`PendulumSliderEnv.state_limit`)
STATE_LIMIT = 1e10
#: the RK4 step (s): MuJoCo's timestep in ``envs/assets/pendulum_slider.xml``
TIMESTEP = 1e-3
#: the friction laws the plant (``"paper"``, ``"none"``) and the model (also ``"coulomb"``)
#: can have (:data:`fir_gym.envs.pendulum_slider_dynamics.FRICTION_MODES`, same order)
FRICTION_MODES = ("paper", "coulomb", "none")
#: the smoothing velocity of the model's Coulomb friction (``PendulumSliderDynamics``'s
#: default ``coulomb_velocity``, which the env's model keeps)
COULOMB_VELOCITY = 0.01
#: the cap of the bracketed cost (``PendulumSliderEnv.BRACKET_CAP``)
BRACKET_CAP = 20.0
#: the observation kinds
KINDS = ("true", "measurement", "measurement-stack", "ekf", "ukf", "efir")
#: the physical parameters, in the order of :class:`Physics`
PHYSICAL = ("m1", "m2", "l", "I_c", "k", "l0", "M0", "mu", "g")
_TRIU = np.triu_indices(4)


@struct.dataclass
class PendulumSliderParams(gymnax_env.EnvParams):
    """The physical, noise and filter parameters (a pytree: any float field can be vmapped).

    The first group is the truth (:class:`fir_gym.envs.pendulum_slider.PendulumSliderEnv`'s
    keywords), the ``nominal_*`` fields what the EKF's model believes (its ``nominal=``
    dict), then the filter's divergence watch (:class:`fir_gym.estimators.base.Estimator`'s
    defaults). Build one with :func:`pendulum_slider_params`, which also validates.
    """

    max_steps_in_episode: int = 5000
    m1: Any = PAPER_PARAMS["m1"]
    m2: Any = PAPER_PARAMS["m2"]
    l: Any = PAPER_PARAMS["l"]
    I_c: Any = PAPER_PARAMS["I_c"]
    k: Any = PAPER_PARAMS["k"]
    l0: Any = PAPER_PARAMS["l0"]
    M0: Any = PAPER_PARAMS["M0"]
    mu: Any = PAPER_PARAMS["mu"]
    g: Any = PAPER_PARAMS["g"]
    force_max: Any = 10.0
    R: Any = struct.field(default_factory=lambda: jnp.diag(jnp.square(jnp.array(PAPER_R_STD))))
    Q: Any = struct.field(default_factory=lambda: jnp.zeros((4, 4)))
    x_rest: Any = 0.025 - 0.2 * (0.654 + 0.7925) * 9.8 / (2.0 * 100.0)
    initial_state: Any = struct.field(default_factory=lambda: jnp.array(
        [0.025 - 0.2 * (0.654 + 0.7925) * 9.8 / (2.0 * 100.0), 0.0, 0.5, 0.0]))
    initial_state_cov: Any = struct.field(
        default_factory=lambda: jnp.diag(jnp.array([0.0, 0.0, 0.1 ** 2, 0.0])))
    state_limit: Any = STATE_LIMIT
    nominal_m1: Any = PAPER_PARAMS["m1"]
    nominal_m2: Any = PAPER_PARAMS["m2"]
    nominal_l: Any = PAPER_PARAMS["l"]
    nominal_I_c: Any = PAPER_PARAMS["I_c"]
    nominal_k: Any = PAPER_PARAMS["k"]
    nominal_l0: Any = PAPER_PARAMS["l0"]
    nominal_M0: Any = PAPER_PARAMS["M0"]
    nominal_mu: Any = PAPER_PARAMS["mu"]
    nominal_g: Any = PAPER_PARAMS["g"]
    nominal_force_max: Any = 10.0
    nominal_R: Any = struct.field(
        default_factory=lambda: jnp.diag(jnp.square(jnp.array(PAPER_R_STD))))
    nominal_Q: Any = struct.field(default_factory=lambda: 1e-6 * jnp.eye(4))
    max_covariance_trace: Any = 1e12
    #: ``scipy.stats.chi2.isf(nis_tail, 4)`` for the default ``nis_tail = 1e-9``
    nis_threshold: Any = 47.41574837223604
    nis_patience: Any = 10
    frame_skip: int = struct.field(pytree_node=False, default=1)
    friction: str = struct.field(pytree_node=False, default="paper")
    nominal_frame_skip: int = struct.field(pytree_node=False, default=1)
    nominal_friction: str = struct.field(pytree_node=False, default="paper")
    #: square root(s) of the noise covariance(s) (:func:`~fir_gym.jax._plant.sqrt_of`: the
    #: builder computes them; ``None`` computes them in the trace)
    initial_sqrt: Any = None
    process_sqrt: Any = None
    measurement_sqrt: Any = None


@struct.dataclass
class PendulumSliderState(PlantState):
    """The plant, its last observation and the EKF (mean, covariance, watch)."""


@struct.dataclass
class PendulumSliderResetNoise:
    """The physical noise of a reset: ``initial`` (4,) added to ``initial_state``,
    ``measurement`` (4,) added to the state."""

    initial: Any
    measurement: Any


@struct.dataclass
class PendulumSliderNoise:
    """The physical noise of a step: ``process`` (4,) added to the new state (``w``),
    ``measurement`` (4,) added to it (``v``)."""

    process: Any
    measurement: Any


@struct.dataclass
class Physics:
    """The ODE's constants (one set: the plant's or the model's)."""

    m1: Any
    m2: Any
    l: Any
    I_c: Any
    k: Any
    l0: Any
    M0: Any
    mu: Any
    g: Any


def _physics(params: PendulumSliderParams, nominal: bool) -> Physics:
    prefix = "nominal_" if nominal else ""
    return Physics(*(getattr(params, prefix + name) for name in PHYSICAL))


# ---------------------------------------------------------------------------- parameters
def _positive(name: str, value: Any) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be positive and finite; got {value!r}")
    return v


def _positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        raise ValueError(f"{name} must be a positive integer; got {value!r}")
    return int(value)


def _covariance(name: str, value: Any, *, definite: bool = False) -> np.ndarray:
    """``value`` as a 4x4 symmetric PSD (or PD) matrix; a scalar is ``value I`` and a vector
    a diagonal (:func:`fir_gym.estimators._validation.as_covariance`'s reading, except that a
    scalar fills the diagonal as the model's ``Q`` does)."""
    try:
        M = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 4x4 covariance (or its diagonal); got {value!r}")\
            from None
    if M.ndim == 0:
        M = np.full(4, float(M))
    if M.ndim == 1 and M.shape == (4,):
        M = np.diag(M)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise ValueError(f"{name} must be a finite 4x4 covariance (or its diagonal); got "
                         f"shape {M.shape}")
    scale = max(float(np.max(np.abs(M))), np.finfo(float).tiny)
    if np.max(np.abs(M - M.T)) > 1e-9 * scale:
        raise ValueError(f"{name} must be symmetric")
    M = 0.5 * (M + M.T)
    low = float(np.linalg.eigvalsh(M)[0])
    if (definite and low <= 1e-9 * scale) or low < -1e-9 * scale:
        raise ValueError(f"{name} must be positive {'definite' if definite else 'semidefinite'}; "
                         f"smallest eigenvalue is {low:.3g}")
    return M


def _physical(where: str, values: Mapping[str, Any]) -> dict[str, float]:
    """The physical parameters, checked as :class:`PendulumSliderEnv` checks them."""
    out = {name: float(values[name]) for name in PHYSICAL}
    for name in ("m1", "m2", "l", "I_c", "k", "g"):
        _positive(f"{where}{name}", out[name])
    for name in ("M0", "mu"):
        if not (math.isfinite(out[name]) and out[name] >= 0):
            raise ValueError(f"{where}{name} must be a finite non-negative number; "
                             f"got {out[name]!r}")
    if not math.isfinite(out["l0"]):
        raise ValueError(f"{where}l0 must be finite; got {out['l0']!r}")
    return out


def pendulum_slider_params(*, friction: str = "paper", dynamics: str = "physical",
                           frame_skip: int = 1, force_max: float = 10.0, R: Any = None,
                           Q: Any = None, nominal: Mapping[str, Any] | None = None,
                           initial_state: Any = None, initial_state_cov: Any = "swing",
                           max_episode_steps: int = 5000, max_covariance_trace: float = 1e12,
                           nis_tail: float = 1e-9, nis_patience: int = 10,
                           **physical: float) -> PendulumSliderParams:
    """:class:`PendulumSliderParams` from :class:`fir_gym.envs.pendulum_slider.
    PendulumSliderEnv`'s keywords (``physical`` among ``m1, m2, l, I_c, k, l0, M0, mu, g``)
    and the EKF's watch options; ``nominal`` as there (keys: the physical parameters,
    ``friction``, ``dynamics``, ``frame_skip``, ``force_max``, ``R``, ``Q``; the model's
    ``Q`` defaults to ``1e-6 I``). Host-side: validates (a ``ValueError`` naming the
    argument; an unknown keyword is a ``TypeError``, as in numpy) and converts.

    Refused (``ValueError``): ``friction="coulomb"`` for the plant (MuJoCo's rail contact,
    not an ODE) and ``dynamics`` other than ``"physical"`` (paper 003's printed equations
    are not ported), for the plant or the model."""
    require_x64()
    from scipy.stats import chi2

    unknown = sorted(set(physical) - set(PAPER_PARAMS))
    if unknown:
        raise TypeError(f"unexpected keyword argument(s) {unknown}; physical parameters are "
                        f"{sorted(PAPER_PARAMS)}")
    if nominal is not None and not isinstance(nominal, Mapping):
        raise ValueError(f"nominal must be a mapping of parameter names to values; got "
                         f"{type(nominal).__name__}")
    truth: dict[str, Any] = {**PAPER_PARAMS, **physical, "friction": friction,
                             "dynamics": dynamics, "frame_skip": frame_skip,
                             "force_max": force_max,
                             "R": np.square(PAPER_R_STD) if R is None else R,
                             "Q": np.zeros((4, 4)) if Q is None else Q}
    unknown = sorted(set(nominal or {}) - set(truth))
    if unknown:
        raise ValueError(f"nominal has unknown parameter(s) {unknown}; known parameters are "
                         f"{sorted(truth)}")
    believed = {**truth, "Q": np.full(4, 1e-6), **(nominal or {})}
    for where, values, frictions in (("", truth, ("paper", "none")),
                                     ("nominal ", believed, FRICTION_MODES)):
        if values["friction"] not in frictions:
            raise ValueError(f"{where}friction must be one of {frictions} (friction='coulomb' "
                             "of the plant is MuJoCo's rail contact, which the analytic "
                             f"equations do not reproduce); got {values['friction']!r}")
        if values["dynamics"] != "physical":
            raise ValueError(f"{where}dynamics must be 'physical' (paper 003's printed "
                             f"equations are not ported to JAX); got {values['dynamics']!r}")
    phys, phys_model = _physical("", truth), _physical("nominal ", believed)
    skip = _positive_int("frame_skip", frame_skip)
    skip_model = _positive_int("nominal frame_skip", believed["frame_skip"])
    x_rest = (phys["l0"] - phys["mu"] * (phys["m1"] + phys["m2"]) * phys["g"]
              / (2.0 * phys["k"]) if friction == "paper" else phys["l0"])
    x0 = np.asarray((x_rest, 0.0, 0.5, 0.0) if initial_state is None else initial_state,
                    dtype=np.float64)
    if x0.shape != (4,) or not np.all(np.isfinite(x0)):
        raise ValueError(f"initial_state must be 4 finite numbers; got {initial_state!r}")
    if isinstance(initial_state_cov, str):
        if initial_state_cov != "swing":
            raise ValueError(f"initial_state_cov must be 'swing', None or a 4x4 covariance; "
                             f"got {initial_state_cov!r}")
        initial_state_cov = np.diag([0.0, 0.0, 0.1 ** 2, 0.0])
    P0 = np.zeros((4, 4)) if initial_state_cov is None else _covariance(
        "initial_state_cov", initial_state_cov)
    R_truth = _covariance("R", truth["R"], definite=True)
    Q_truth = _covariance("Q", truth["Q"])
    return PendulumSliderParams(
        max_steps_in_episode=_positive_int("max_episode_steps", max_episode_steps),
        **phys, force_max=_positive("force_max", force_max),
        R=jnp.asarray(R_truth), Q=jnp.asarray(Q_truth), x_rest=float(x_rest),
        initial_state=jnp.asarray(x0), initial_state_cov=jnp.asarray(P0),
        **{f"nominal_{name}": value for name, value in phys_model.items()},
        nominal_force_max=_positive("nominal force_max", believed["force_max"]),
        nominal_R=jnp.asarray(_covariance("nominal R", believed["R"])),
        nominal_Q=jnp.asarray(_covariance("nominal Q", believed["Q"])),
        max_covariance_trace=_positive("max_covariance_trace", max_covariance_trace),
        nis_threshold=float(chi2.isf(_positive("nis_tail", nis_tail), 4)),
        nis_patience=_positive_int("nis_patience", nis_patience),
        frame_skip=skip, friction=friction, nominal_frame_skip=skip_model,
        nominal_friction=str(believed["friction"]), initial_sqrt=numpy_sqrt(P0),
        process_sqrt=numpy_sqrt(Q_truth), measurement_sqrt=numpy_sqrt(R_truth))


# ---------------------------------------------------------------------------- the ODE
def _friction_sign(xd: jax.Array, friction: str) -> tuple[Any, Any]:
    """``(s, ∂s/∂ẋ)`` of the friction mode (``PendulumSliderDynamics._friction_sign``)."""
    if friction == "paper":
        return 1.0, 0.0
    if friction == "none":
        return 0.0, 0.0
    t = jnp.tanh(xd / COULOMB_VELOCITY)
    return t, (1.0 - t * t) / COULOMB_VELOCITY


def slider_derivatives(z: jax.Array, U: jax.Array, p: Physics, friction: str
                       ) -> jax.Array:
    """``ż = a(z, U)``: :func:`slider_derivatives_and_jacobian` without the Jacobian."""
    return _derivatives(z, U, p, friction, jacobian=False)[0]


def slider_derivatives_and_jacobian(z: jax.Array, U: jax.Array, p: Physics, friction: str
                                    ) -> tuple[jax.Array, jax.Array]:
    """``ż = a(z, U)`` of paper 003's pendulum slider (the Lagrangian's eq (15) with its
    errata, docs/papers.md#003-eq-15) and the rows ``∂ẍ/∂z`` and ``∂θ̈/∂z`` (2, 4) of its
    Jacobian — :func:`fir_gym.envs._interval_kernels._slider_derivatives` for the
    physical equations, the same formulas in the same order:
    ``M [ẍ, θ̈]ᵀ = b`` with ``M = [[m1+m2, −m2 l cosθ + s μ m2 l sinθ], [−m2 l cosθ, I_c +
    m2 l²]]``, ``b = [U − 2k (x − l0) − m2 l sinθ θ̇² − s μ ((m1+m2) g + m2 l cosθ θ̇²),
    −M0 θ̇ − m2 g l sinθ]``; ``∂q̈/∂z = M⁻¹ (∂b/∂z − (∂M/∂z) q̈)``."""
    a, rows = _derivatives(z, U, p, friction, jacobian=True)
    assert rows is not None                                  # jacobian=True: the rows
    return a, rows


def _derivatives(z: jax.Array, U: jax.Array, p: Physics, friction: str, jacobian: bool
                 ) -> tuple[jax.Array, jax.Array | None]:
    m1, m2, l, g, k = p.m1, p.m2, p.l, p.g, p.k
    xd, th, w = z[1], z[2], z[3]
    c, sn = jnp.cos(th), jnp.sin(th)
    s, ds = _friction_sign(xd, friction)
    mu, M0 = p.mu, p.M0
    mt, m2l = m1 + m2, m2 * l
    N0 = mt * g + m2l * c * w * w
    M11, M22 = mt, p.I_c + m2l * l
    M12 = -m2l * c + s * mu * m2l * sn
    M21 = -m2l * c
    b1 = U - 2.0 * k * (z[0] - p.l0) - m2l * sn * w * w - s * mu * N0
    b2 = -M0 * w - m2l * g * sn
    det = M11 * M22 - M12 * M21
    xdd = (M22 * b1 - M12 * b2) / det
    thdd = (M11 * b2 - M21 * b1) / det
    a = jnp.stack([xd, xdd, w, thdd])
    if not jacobian:
        return a, None
    zero = jnp.zeros_like(xdd)
    r1 = (zero + (0.0 - 2.0 * k),
          -mu * ds * N0 - mu * ds * m2l * sn * thdd,
          -m2l * c * w * w + s * mu * m2l * sn * w * w - (m2l * sn + s * mu * m2l * c) * thdd,
          -2.0 * m2l * w * (sn + s * mu * c))
    r2 = (zero, zero, -m2l * g * c - m2l * sn * xdd, zero + (0.0 - M0))
    row1 = jnp.stack([(M22 * r1[j] - M12 * r2[j]) / det for j in range(4)])
    row3 = jnp.stack([(M11 * r2[j] - M21 * r1[j]) / det for j in range(4)])
    return a, jnp.stack([row1, row3])


_RK4_COEFS = (0.0, 0.5, 0.5, 1.0)


def _rk4_step(z: jax.Array, U: jax.Array, p: Physics, friction: str, h: float) -> jax.Array:
    """One classical RK4 step of :func:`slider_derivatives` (the input held)."""
    stages: list[jax.Array] = []
    for coef in _RK4_COEFS:
        zi = z if coef == 0.0 else z + (coef * h) * stages[-1]
        stages.append(slider_derivatives(zi, U, p, friction))
    return z + (h / 6.0) * (stages[0] + 2.0 * stages[1] + 2.0 * stages[2] + stages[3])


def _rk4_step_jacobian(z: jax.Array, Fz: jax.Array, U: jax.Array, p: Physics, friction: str,
                       h: float) -> tuple[jax.Array, jax.Array]:
    """:func:`_rk4_step` and the product of its Jacobian with ``Fz``: stage sensitivities
    ``∂k_i/∂z0 = A_i (Fz + c_i h ∂k_{i−1}/∂z0)`` (``A_i``'s rows 0 and 2 are unit rows),
    combined with the RK4 weights."""
    stages: list[jax.Array] = []
    sens: list[jax.Array] = []
    for coef in _RK4_COEFS:
        zi = z if coef == 0.0 else z + (coef * h) * stages[-1]
        a, A = slider_derivatives_and_jacobian(zi, U, p, friction)
        stages.append(a)
        dz = Fz if coef == 0.0 else Fz + (coef * h) * sens[-1]
        rows = [A[r, 0] * dz[0] + A[r, 1] * dz[1] + A[r, 2] * dz[2] + A[r, 3] * dz[3]
                for r in (0, 1)]
        sens.append(jnp.stack([dz[1], rows[0], dz[3], rows[1]]))
    z_new = z + (h / 6.0) * (stages[0] + 2.0 * stages[1] + 2.0 * stages[2] + stages[3])
    F_new = Fz + (h / 6.0) * (sens[0] + 2.0 * sens[1] + 2.0 * sens[2] + sens[3])
    return z_new, F_new


def _step_length(frame_skip: int) -> float:
    """``dt / substeps`` as the numpy model computes it (``dt = 1e-3 · frame_skip``)."""
    return (TIMESTEP * frame_skip) / frame_skip


def slider_interval(z: jax.Array, U: jax.Array, p: Physics, friction: str, frame_skip: int
                    ) -> jax.Array:
    """One env step of the ODE: ``frame_skip`` RK4 steps of ``h = 1 ms`` from ``z`` under the
    held force ``U`` (newtons) — :meth:`fir_gym.envs.pendulum_slider_dynamics.
    PendulumSliderDynamics.propagate`, the numpy model's (and native vector env's) interval
    map."""
    h = _step_length(frame_skip)
    return jax.lax.fori_loop(0, frame_skip, lambda _, z: _rk4_step(z, U, p, friction, h), z)


def slider_interval_and_jacobian(z: jax.Array, U: jax.Array, p: Physics, friction: str,
                                 frame_skip: int) -> tuple[jax.Array, jax.Array]:
    """:func:`slider_interval` and the exact Jacobian ``∂z⁺/∂z`` of that map (stage-wise
    sensitivities, as ``PendulumSliderDynamics.propagate(..., jacobian=True)``)."""
    h = _step_length(frame_skip)

    def body(_: Any, carry: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
        return _rk4_step_jacobian(*carry, U, p, friction, h)

    return jax.lax.fori_loop(0, frame_skip, body, (z, jnp.eye(4, dtype=z.dtype)))


def slider_plant_and_model_intervals(x: jax.Array, U: jax.Array, p: Physics, friction: str,
                                     xf: jax.Array, Uf: jax.Array, pf: Physics,
                                     friction_f: str, frame_skip: int
                                     ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """:func:`slider_interval` of the plant and :func:`slider_interval_and_jacobian` of the
    filter's model
    (from its estimate ``xf``, with its force ``Uf`` and constants ``pf``) in one loop, when
    both take ``frame_skip`` steps: the same numbers as the two loops. Returns ``(x_next,
    xf_next, F)``."""
    h = _step_length(frame_skip)

    def body(_: Any, carry: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
        z, zf, F = carry
        return (_rk4_step(z, U, p, friction, h),
                *_rk4_step_jacobian(zf, F, Uf, pf, friction_f, h))

    return jax.lax.fori_loop(0, frame_skip, body, (x, xf, jnp.eye(4, dtype=xf.dtype)))


# ---------------------------------------------------------------------------- reward, noise
def pendulum_slider_reward(x_next: jax.Array, u: jax.Array, params: PendulumSliderParams
                           ) -> jax.Array:
    """``−min(θ² + 0.1 θ̇² + 100 (x − x_rest)² + 0.01 u², 20) · frame_skip · 0.1`` of the new
    state (a NaN cost counts as the cap): :meth:`PendulumSliderEnv._reward`."""
    e = x_next[0] - params.x_rest
    th, w = x_next[2], x_next[3]
    cost = th * th + 0.1 * w * w + 100.0 * e * e + 0.01 * u * u
    return -jnp.where(cost < BRACKET_CAP, cost, BRACKET_CAP) * _reward_scale(params)


def _reward_scale(params: PendulumSliderParams) -> float:
    return params.frame_skip * 0.1


def pendulum_slider_in_domain(x: jax.Array, params: PendulumSliderParams) -> jax.Array:
    """The slider on the rail, ``|x − l0| ≤ 0.3``, and the state finite
    (:meth:`PendulumSliderEnv._in_domain`)."""
    return jnp.all(jnp.isfinite(x)) & (jnp.abs(x[0] - params.l0) <= 0.3)


def pendulum_slider_reset_noise(key: jax.Array, params: PendulumSliderParams
                                ) -> PendulumSliderResetNoise:
    """The noise of a reset from one draw ``z = jax.random.normal(key, (8,))``:
    ``initial = sqrt(initial_state_cov) z[:4]``, ``measurement = sqrt(R) z[4:]``."""
    z = jax.random.normal(key, (8,), dtype=jnp.float64)
    return PendulumSliderResetNoise(
        sqrt_of(params.initial_sqrt, params.initial_state_cov) @ z[:4],
        sqrt_of(params.measurement_sqrt, params.R) @ z[4:])


def pendulum_slider_noise(key: jax.Array, params: PendulumSliderParams) -> PendulumSliderNoise:
    """The noise of a step from one draw ``z = jax.random.normal(key, (8,))``:
    ``process = sqrt(Q) z[:4]`` (zero for the default Q = 0), ``measurement = sqrt(R)
    z[4:]``."""
    z = jax.random.normal(key, (8,), dtype=jnp.float64)
    return PendulumSliderNoise(sqrt_of(params.process_sqrt, params.Q) @ z[:4],
                               sqrt_of(params.measurement_sqrt, params.R) @ z[4:])


# ---------------------------------------------------------------------------- the EKF
def ekf_correct(b: Belief, xp: jax.Array, Pp: jax.Array, y: jax.Array,
                params: PendulumSliderParams) -> Belief:
    """The Joseph-form update of the prior ``(xp, Pp)`` with ``y`` (``h(x) = x``, ``H = I``,
    the model's ``R``), then the divergence watch against the record ``b``
    (``ExtendedKalmanFilter._correct`` and ``Estimator._accept``)."""
    x_new, P_new, nis = kf_update_innovation(xp, Pp, y - xp, jnp.eye(4), params.nominal_R)
    return watch(b, x_new, P_new, nis, watch_limits_of(params))


def ekf_model(params: PendulumSliderParams
              ) -> Callable[[jax.Array, jax.Array], tuple[jax.Array, jax.Array]]:
    """``(x, u) -> (f(x, u), F)``: the model's interval map and its Jacobian
    (:meth:`PendulumSliderDynamics.f_jac_f` at the nominal parameters)."""
    pf = _physics(params, nominal=True)

    def f_and_F(x: jax.Array, u: jax.Array) -> tuple[jax.Array, jax.Array]:
        return slider_interval_and_jacobian(x, u[0] * params.nominal_force_max, pf,
                                            params.nominal_friction, params.nominal_frame_skip)
    return f_and_F


# ---------------------------------------------------------------------------- the environment
class PendulumSlider(FilteredPlant):
    """``fir_gym/PendulumSlider-v0`` as a gymnax environment observing ``kind`` (see the
    module docstring): ``"true"``, ``"measurement"`` or ``"ekf"`` (the default, observing
    ``observation``: ``"estimate"``, ``"estimate+covariance"`` or ``"estimate+measurement"``).

    ``reset_env(key, params)`` and ``step_env(key, state, action, params)`` draw their noise
    from ``key`` (:func:`pendulum_slider_reset_noise`, :func:`pendulum_slider_noise`) and
    call the pure :meth:`reset_with_noise` / :meth:`step_with_noise`. gymnax's ``step``
    adds the auto-reset and ``is_truncated`` (``time >= max_steps_in_episode``). ``info``
    has ``state`` (the true state), ``action`` (applied, float64), ``action_clipped``,
    ``force`` (newtons), ``simulation_failure`` (a code, 0 for none) and, for ``"ekf"``,
    ``estimate``, ``estimation_error``, ``estimator_diverged`` and ``nis``.
    """

    kinds = KINDS
    randomizable = ("mu", "M0", "force_max")
    estimator = "ekf"
    default_horizon = 20
    n_x, n_y = 4, 4

    @property
    def default_params(self) -> PendulumSliderParams:
        return pendulum_slider_params()

    @property
    def name(self) -> str:
        return "fir_gym/PendulumSlider-v0"

    def filter_model(self, params: PendulumSliderParams) -> FilterModel:
        """The EKF's model (the numpy plant's ``model``): the slider's RK4 interval at the
        nominal physics (:func:`ekf_model`), ``H = I``, the nominal ``Q`` and ``R``."""
        pf = _physics(params, nominal=True)

        def f(x: jax.Array, u: jax.Array) -> jax.Array:
            return slider_interval(x, u[0] * params.nominal_force_max, pf,
                                   params.nominal_friction, params.nominal_frame_skip)

        return FilterModel(f, ekf_model(params), jnp.eye(4), jnp.asarray(params.nominal_Q),
                           jnp.asarray(params.nominal_R))

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """The true measurement noise's square root (the outliers' scale)."""
        return sqrt_of(params.measurement_sqrt, params.R)

    # ------------------------------------------------------------------ reset
    def reset_env(self, key: jax.Array, params: PendulumSliderParams
                  ) -> tuple[Any, PendulumSliderState]:
        return self.reset_with_noise(pendulum_slider_reset_noise(key, params), params,
                                     self.sensor_reading(key, 0, params))

    def reset_with_noise(self, noise: PendulumSliderResetNoise, params: PendulumSliderParams,
                         missing: Reading | jax.Array | bool = False
                         ) -> tuple[Any, PendulumSliderState]:
        """The reset with the given noise: ``x = initial_state + noise.initial``,
        ``y = x + noise.measurement`` (held where ``missing``, with dropout); the EKF (for
        ``"ekf"``) consumes ``y`` from its prior."""
        require_x64()
        x = jnp.asarray(params.initial_state, dtype=jnp.float64) + noise.initial
        y = self.deliver(missing, x + noise.measurement, self.first_hold(params))
        x0, P0 = filter_prior(params)
        state = PendulumSliderState.start(x, y, x0, P0)
        if self.runs_own_filter:
            updated = with_belief(state, ekf_correct(belief_of(state), x0, P0, y, params))
            state = self.own_update(missing, state, updated, x0, P0, params)
        state = self.finish_reset(state, params, missing)
        return self.get_obs(state, params), state

    # ------------------------------------------------------------------ step
    def step_env(self, key: jax.Array, state: PendulumSliderState, action: Any,
                 params: PendulumSliderParams
                 ) -> tuple[Any, PendulumSliderState, jax.Array, jax.Array, dict[str, Any]]:
        obs, state, reward, terminated, info = self.step_with_noise(
            state, action, pendulum_slider_noise(key, params), params,
            self.sensor_reading(key, state.time + 1, params, state.sensor_stuck))
        # gymnax's rule: transitions are detached unless gradients were asked for
        obs, state = self._apply_transition_gradient_policy(obs, state)
        return obs, state, reward, terminated, info

    def step_with_noise(self, state: PendulumSliderState, action: Any,
                        noise: PendulumSliderNoise, params: PendulumSliderParams,
                        missing: Reading | jax.Array | bool = False
                        ) -> tuple[Any, PendulumSliderState, jax.Array, jax.Array,
                                   dict[str, Any]]:
        """One env step with the given noise: ``(obs, state, reward, terminated, info)``;
        with dropout, a ``missing`` reading holds the last delivered one.

        :meth:`fir_gym.envs._base.PlantEnv.step` of :class:`PendulumSliderEnv` with the
        analytic plant (and, for ``"ekf"``, the EKF step of
        :class:`~fir_gym.wrappers.EstimatorObservation`); its only Python branches are on
        static things (the kind, the frame skips, the friction modes), none on data.
        """
        require_x64()
        u_in, u = _action(action)
        p = _physics(params, nominal=False)
        U = u[0] * params.force_max
        prediction = None
        if self.runs_own_filter and params.frame_skip == params.nominal_frame_skip:
            # the plant's and the model's RK4 loops as one (same numbers)
            x_det, xp, F = slider_plant_and_model_intervals(
                state.x, U, p, params.friction, state.filter_x, u[0] * params.nominal_force_max,
                _physics(params, nominal=True), params.nominal_friction, params.frame_skip)
            prediction = (xp, F)
        else:
            x_det = slider_interval(state.x, U, p, params.friction, params.frame_skip)
        return self._finish_step(state, u_in, u, x_det + noise.process, noise.measurement,
                                 prediction, params, missing)

    def step_with_transition(self, state: PendulumSliderState, action: Any, x_next: Any,
                             measurement_noise: Any, params: PendulumSliderParams
                             ) -> tuple[Any, PendulumSliderState, jax.Array, jax.Array,
                                        dict[str, Any]]:
        """:meth:`step_with_noise` with the plant's transition given: ``x_next`` is the new
        state (process noise included) of some plant — the MuJoCo plant's in the parity
        tests; the plant's own transition, which a ``burst`` then stretches, as the numpy
        plant's ``_transition`` — and the step does the rest as :meth:`PlantEnv.step` does (the
        burst, failure checks,
        termination, reward, the measurement ``x_next + measurement_noise``, the EKF)."""
        require_x64()
        u_in, u = _action(action)
        return self._finish_step(state, u_in, u, jnp.asarray(x_next, dtype=jnp.float64),
                                 jnp.asarray(measurement_noise, dtype=jnp.float64), None,
                                 params)

    def _finish_step(self, state: PendulumSliderState, u_in: jax.Array, u: jax.Array,
                     x_next: jax.Array, v: jax.Array, prediction: Any,
                     params: PendulumSliderParams, missing: Reading | jax.Array | bool = False
                     ) -> tuple[Any, PendulumSliderState, jax.Array, jax.Array, dict[str, Any]]:
        x = state.x
        burst = self.burst_delta(state.time)
        x_next = self.stretch(x, x_next, burst)
        time = state.time + 1
        left = jnp.maximum(params.max_steps_in_episode - time, 0)
        cost_cap = BRACKET_CAP * _reward_scale(params)
        penalty = -cost_cap * (1.0 + left)
        finite_state = jnp.all(jnp.isfinite(x_next))
        overflow = jnp.any(jnp.abs(x_next) > params.state_limit)
        in_domain = pendulum_slider_in_domain(x_next, params)
        reward = jnp.where(in_domain, pendulum_slider_reward(x_next, u[0], params), penalty)
        y_next = x_next + v
        failure = jnp.select(
            [~finite_state, overflow, ~jnp.isfinite(reward), ~jnp.all(jnp.isfinite(y_next))],
            [1, 2, 4, 3], 0)
        failed = failure > 0
        x_kept = jnp.where(failed, x, x_next)
        y = self.deliver(missing, jnp.where(failed, state.y, y_next), state.y)
        reward = jnp.where(failed, penalty, reward)
        terminated = failed | ~in_domain
        new = state.replace(time=time, x=x_kept, y=y, terminated=terminated)
        info: dict[str, Any] = {"state": x_kept, "action": u, "action_clipped": jnp.any(u != u_in),
                                "force": u[0] * params.force_max, "simulation_failure": failure}
        if self.runs_own_filter:
            if prediction is None:
                xp, Pp = ekf_predict(state.filter_x, state.filter_P, u, params.nominal_Q,
                                     ekf_model(params))
            else:                 # the model's interval came from the fused loop
                xp, F = prediction
                Pp = symmetrize(F @ state.filter_P @ F.T + params.nominal_Q)
            updated = with_belief(new, ekf_correct(belief_of(state), xp, Pp, y, params))
            new = self.own_update(missing, new, updated, xp, Pp, params)
        obs, new, info = self.finish_step(state, new, u, params, info, missing)
        return obs, new, reward, terminated, info


def _action(action: Any) -> tuple[jax.Array, jax.Array]:
    """The action as given (float64, shape (1,)) and clipped to ``[-1, 1]``."""
    u_in = jnp.reshape(jnp.asarray(action, dtype=jnp.float64), (1,))
    return u_in, jnp.clip(u_in, -1.0, 1.0)
