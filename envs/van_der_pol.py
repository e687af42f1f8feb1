"""Stochastic Van der Pol oscillator with a continuous measurement: paper 002's example."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any, ClassVar, cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from fir_gym.estimators import StateSpaceModel, compiled
from fir_gym.estimators._validation import FloatArray, positive
from fir_gym.estimators.continuous import ContinuousModel

from . import _draw
from ._base import FirstStateMeasured, PlantEnv, saturated_cost
from ._conditions import column, entry, per_system
from ._design import DesignPoint
from ._interval_kernels import heun_interval

NOISE_INPUT = np.array([1.0, 1.0])
#: batches up to this size are integrated row by row in Python floats (faster than numpy)
SMALL_BATCH = 32
_NO_NOISE = np.zeros((1, 1))


class VanDerPolDynamics(FirstStateMeasured):
    """``ẋ1 = x2``, ``ẋ2 = -x1 + ε (1 - x1²) x2 + u_max·u`` integrated by Heun's method.

    Paper 002, §4 (ε = 1). One env step of length ``h`` is ``substeps`` Heun steps of
    ``τ = h / substeps``; with additive noise ``[1, 1]ᵀ dW`` each Heun step is the
    stochastic Heun scheme (strong order 1 for additive noise):
    ``x̃ = x + a(x) τ + g ΔW``, ``x⁺ = x + (a(x) + a(x̃)) τ / 2 + g ΔW``.
    The Jacobian of the noise-free interval map is the product of the Heun step
    Jacobians ``I + τ/2 (J(x) + J(x̃)(I + τ J(x)))``, ``J = ∂a/∂x``.

    :meth:`A_of_x` is the state-dependent factorisation ``a(x) = A(x) x`` (for
    ``u = 0``) that paper 002's adaptive piecewise linearisation freezes on each
    block-pulse interval: ``A(x) = [[0, 1], [-1, ε (1 - x1²)]]``.

    ``epsilon`` and ``u_max`` are numbers, or one per system of a batch (``(B,)`` arrays: a
    native vector env's per-episode true parameters, :mod:`._conditions`).
    """

    def __init__(self, epsilon: Any, h: float, substeps: int, u_max: Any) -> None:
        self.epsilon, self.interval, self.substeps, self.u_max = epsilon, h, substeps, u_max
        self.tau = h / substeps
        self._per_system = per_system(epsilon, u_max)
        #: the parameters as the compiled loop takes them
        self._columns = (column(epsilon), column(u_max))

    def row(self, i: int) -> VanDerPolDynamics:
        """The dynamics of system ``i`` (numbers for its parameters)."""
        if not self._per_system:
            return self
        return VanDerPolDynamics(entry(self.epsilon, i), self.interval, self.substeps,
                                 entry(self.u_max, i))

    def drift(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """The continuous drift ``a(x, u) = [x2, -x1 + ε (1 - x1²) x2 + u_max u]``."""
        x1, x2 = x[..., 0], x[..., 1]
        return np.stack([x2, -x1 + self.epsilon * (1.0 - x1 * x1) * x2 + self.u_max * u[..., 0]],
                        axis=-1)

    def drift_jacobian(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """``∂a/∂x = A(x) + [[0, 0], [-2 ε x1 x2, 0]]``."""
        J = self.A_of_x(x)
        J[..., 1, 0] -= 2.0 * self.epsilon * x[..., 0] * x[..., 1]
        return J

    def A_of_x(self, x: FloatArray) -> FloatArray:
        """``A(x)`` with ``a(x, 0) = A(x) x`` (paper 002, eqs 2.9–2.10)."""
        x1 = x[..., 0]
        A = np.zeros(x.shape[:-1] + (2, 2))
        A[..., 0, 1] = 1.0
        A[..., 1, 0] = -1.0
        A[..., 1, 1] = self.epsilon * (1.0 - x1 * x1)
        return A

    def integrate(
        self, x: FloatArray, u: FloatArray, dW: FloatArray | None = None, jacobian: bool = False
    ) -> tuple[FloatArray, Any, FloatArray | None]:
        """Integrate one interval; returns ``(x_end, mean of x1 over the interval, Jacobian)``.

        The mean is a float for one unbatched system, else an array of the batch's shape.

        ``dW`` holds the ``substeps`` Wiener increments (``None`` for noise-free).
        The interval mean of ``x1`` uses the trapezoid rule on the Heun grid.
        The loop runs on components, so one code path serves a single system
        (Python floats: fast for the plant) and a batch (numpy arrays: the model).
        """
        lead = x.shape[:-1]
        single = x.size == 2                       # one system, batched as (1, 2) or not
        if compiled.ENABLED:
            return self._integrate_compiled(x, u, dW, jacobian)
        if x.ndim == 2 and 1 < x.shape[0] <= SMALL_BATCH:
            return self._integrate_rows(x, u, dW, jacobian)
        x1: Any                                    # floats (one system) or arrays (a batch)
        x2: Any
        force: Any
        eps: Any
        if single:
            x1, x2 = float(x.flat[0]), float(x.flat[1])
            force = float(np.asarray(u).flat[0]) * entry(self.u_max, 0)
            eps = entry(self.epsilon, 0)
        else:
            x1, x2 = x[..., 0], x[..., 1]
            force = u[..., 0] * self.u_max
            eps = self.epsilon
        tau, half = self.tau, 0.5 * self.tau
        if dW is None:
            noise: list[Any] = [0.0] * self.substeps
        else:  # floats for one system, (B,) rows for a batch
            noise = dW.reshape(self.substeps).tolist() if single else list(dW)
        x1_sum = 0.5 * x1
        if jacobian:  # Φ = [[p11, p12], [p21, p22]], the product of Heun step Jacobians
            p11, p12, p21, p22 = 1.0, 0.0, 0.0, 1.0
        for dw in noise:
            a1 = -x1 + eps * (1.0 - x1 * x1) * x2 + force          # drift at x
            y1 = x1 + x2 * tau + dw                                  # Euler predictor x̃
            y2 = x2 + a1 * tau + dw
            b1 = -y1 + eps * (1.0 - y1 * y1) * y2 + force          # drift at x̃
            if jacobian:
                # J(z) = [[0, 1], [c(z), d(z)]]; step Jacobian I + τ/2 (J0 + J1 (I + τ J0))
                c0, d0 = -1.0 - 2.0 * eps * x1 * x2, eps * (1.0 - x1 * x1)
                c1, d1 = -1.0 - 2.0 * eps * y1 * y2, eps * (1.0 - y1 * y1)
                m11, m12 = 1.0, tau                                  # I + τ J0
                m21, m22 = tau * c0, 1.0 + tau * d0
                s11 = 1.0 + half * m21                               # row 1 of J1 is [0, 1]
                s12 = half * (1.0 + m22)
                s21 = half * (c0 + c1 * m11 + d1 * m21)
                s22 = 1.0 + half * (d0 + c1 * m12 + d1 * m22)
                p11, p12, p21, p22 = (s11 * p11 + s12 * p21, s11 * p12 + s12 * p22,
                                      s21 * p11 + s22 * p21, s21 * p12 + s22 * p22)
            x1, x2 = x1 + 0.5 * (x2 + y2) * tau + dw, x2 + 0.5 * (a1 + b1) * tau + dw
            x1_sum = x1_sum + x1
        x1_mean = (x1_sum - 0.5 * x1) / self.substeps
        if single:
            x_end = np.array([x1, x2]).reshape(lead + (2,))
            x1_mean = x1_mean if not lead else np.full(lead, x1_mean)
        else:
            x_end = np.stack([x1, x2], axis=-1)
        if not jacobian:
            return x_end, x1_mean, None
        if single:
            return x_end, x1_mean, np.array([[p11, p12], [p21, p22]]).reshape(lead + (2, 2))
        Phi = np.stack([np.stack(np.broadcast_arrays(p11, p12), -1),
                        np.stack(np.broadcast_arrays(p21, p22), -1)], -2)
        return x_end, x1_mean, Phi

    def _integrate_compiled(self, x: FloatArray, u: FloatArray, dW: FloatArray | None,
                            jacobian: bool) -> tuple[FloatArray, Any, FloatArray | None]:
        """:meth:`integrate` by the compiled loop (:mod:`._interval_kernels`), same bits."""
        lead = x.shape[:-1]
        u = np.asarray(u, dtype=np.float64)
        x_end, x1_mean, Phi = heun_interval(
            np.asarray(x, dtype=np.float64).reshape(-1, 2), u.reshape(-1, u.shape[-1]),
            _NO_NOISE if dW is None else np.asarray(dW, dtype=np.float64).reshape(
                self.substeps, -1), dW is not None, self.substeps, self._columns[0], self.tau,
            self._columns[1], jacobian)
        return (x_end.reshape(lead + (2,)), x1_mean.reshape(lead) if lead else float(x1_mean[0]),
                Phi.reshape(lead + (2, 2)) if jacobian else None)

    def _integrate_rows(self, x: FloatArray, u: FloatArray, dW: FloatArray | None,
                        jacobian: bool) -> tuple[FloatArray, Any, FloatArray | None]:
        """A small batch ``(B, 2)`` row by row on the float path (e.g. a UKF's sigma points).

        Bit for bit the batched loop (the same operations in the same order on each row),
        and about ten times faster below :data:`SMALL_BATCH` rows, where numpy's per-call
        cost dominates the ~30 array operations of each Heun step.
        """
        U = np.broadcast_to(u, (x.shape[0], u.shape[-1]))
        rows = [self.row(i).integrate(x[i], U[i], None if dW is None else dW[:, i], jacobian)
                for i in range(x.shape[0])]
        x_end = np.array([r[0] for r in rows])
        x1_mean = np.array([r[1] for r in rows], dtype=np.float64)
        return x_end, x1_mean, np.array([r[2] for r in rows]) if jacobian else None

    def f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.integrate(x, u)[0]

    def F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return cast(FloatArray, self.integrate(x, u, jacobian=True)[2])   # not None: jacobian

    def f_and_F(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``f`` and ``F`` in one pass of the Heun loop."""
        x_end, _, Phi = self.integrate(x, u, jacobian=True)
        return x_end, cast(FloatArray, Phi)


class VanDerPolEnv(PlantEnv):
    """
    ## Description

    The stochastic Van der Pol oscillator of paper 002 ("Kalman filter for a
    nonlinear stochastic system via block pulse functions", §4):

        ẋ1 = x2
        ẋ2 = -x1 + ε (1 - x1²) x2 + u          (ε = 1)
        dx = a(x) dt + [1, 1]ᵀ dW,  E[dW²] = Q dt,  Q = 5
        z  = x1 + v,                 continuous white noise of intensity R = 5

    Without noise it settles on a limit cycle of amplitude ≈ 2. The plant is
    integrated with ``substeps`` (100) stochastic Heun steps per env step of
    ``h = 0.1 s`` (paper: m = 100 block-pulse intervals over t_f = 10 s). The
    measurement is continuous, so each env step returns its block-pulse
    coefficient — the average of ``z`` over the interval just ended:
    ``y[k] = (1/h) ∫ x1 dt + v̄[k]``, ``v̄ ~ N(0, R/h)`` (variance 50 with the
    paper's values; the signal is deeply buried). The observation returned by
    ``reset`` is ``x1(0) + v̄[0]`` (the degenerate interval).

    The filter's :attr:`model` is the noise-free Heun map over one interval
    (``f``, with its exact Jacobian ``F``), ``h(x) = x1`` at the interval's end
    (the interval average differs from it by about ``h x2 / 2``; a filter that
    wants the exact average can use the block-pulse formulation of paper 002),
    ``R_model = R/h`` and, with ``G = I``, the process noise the plant's
    ``[1, 1]ᵀ dW`` accumulates over one interval: Van Loan's integral
    ``∫₀ʰ e^{J s} [1, 1]ᵀ Q [1, 1] e^{Jᵀ s} ds`` of the linearisation ``J`` at the
    states of the noise-free limit cycle, averaged over one period
    (:func:`process_noise_covariance`; ≈ ``[[0.548, 0.472], [0.472, 0.425]]`` with the
    paper's values). It is full rank, where the first-order ``Q h [1, 1]ᵀ[1, 1]`` it
    replaces is rank one and let the EKF's ``P`` collapse to ``1e-9`` across
    ``[1, −1]`` (docs/envs/van-der-pol.md#process-noise).

    ## Action Space

    | Num | Action                                    | Min | Max |
    |-----|-------------------------------------------|-----|-----|
    | 0   | force on the x2 equation, units of u_max  | -1  | 1   |

    ``u = action * u_max`` with ``u_max = 20`` (not in the paper, which has no input):
    enough authority per step (``u_max h = 2``) to dominate the process noise
    (``√(Q h) ≈ 0.7`` per step in each state); with 5, a controller on the true state
    saturated 85 % of the time and barely beat a constant input.

    ## Observation Space

    | Num | Observation                          | Min  | Max |
    |-----|--------------------------------------|------|-----|
    | 0   | interval average of x1 + v̄           | -Inf | Inf |

    (±inf bounds: the measurement noise is Gaussian; Gymnasium's checker warns.)

    ## State (``info["state"]``)

    ``[x1, x2]``; ``info["x1_average"]`` is the noise-free interval average of x1.

    ## Rewards

    Suppress the limit cycle: the cost ``(x1² + x2²)/4 + 0.01 action²`` at the end of
    the step (about 1 on the noise-free limit cycle), saturated at
    ``cost_cap = state_bound² / 2 + 0.01`` (200.01: the largest cost inside the
    domain, so the reward ``-min(cost, cost_cap)`` is the plain cost there).

    ## Starting State

    ``[1, 1]`` (the paper's) plus a draw from ``N(0, initial_state_cov)`` (zero by
    default).

    ## Episode End

    Termination when ``|x1|`` or ``|x2|`` exceeds ``state_bound`` (20), which
    also keeps the integrator accurate (the stiff eigenvalue near ``|x1| = b`` is
    about ``-ε b²``; the constructor checks ``ε b² τ <= 0.5``); the terminating step
    is paid ``-cost_cap * (1 + steps left to max_episode_steps)``, so leaving early
    never pays. Truncation at ``max_episode_steps`` = 100 steps (10 s, the paper's
    t_f) by the registered ``TimeLimit``.

    Because the noise enters ``x1`` directly, the stochastic oscillator does not
    stay near its limit cycle on long runs: away from it ``x2`` relaxes onto the
    slow manifold ``x2 ≈ -x1 / (ε (x1² - 1))`` and ``x1`` diffuses with only the
    weak restoring drift ``≈ -1/x1``, spreading like ``√(Q t)`` (≈ 7 after the
    paper's 10 s, ≈ 45 after 400 s). Long uncontrolled runs therefore end at the
    domain bound; a controller that suppresses the cycle keeps the state small.

    ## Arguments

    ``gym.make("fir_gym/VanDerPol-v0", epsilon=1.0, Q=5.0, R=5.0, h=0.1,
    substeps=100, u_max=20.0, state_bound=20.0, nominal=None,
    initial_state=(1, 1), initial_state_cov=None, max_episode_steps=100,
    randomize=None, burst=None, render_mode=None)``.
    ``nominal`` may change ``epsilon, Q, R, h, substeps, u_max`` for the model.
    ``randomize`` draws the true ``epsilon`` and ``u_max`` around the nominal ones every
    episode (the Heun check above then uses the largest ``ε`` it can draw); ``burst``
    stretches the path over a window of steps, its end and the interval average alike
    (docs/robustness.md#plant-conditions).

    ## Version History

    * v0: initial version.
    """

    state_names: ClassVar[tuple[str, ...]] = ("x1", "x2")
    measurement_names: ClassVar[tuple[str, ...]] = ("x1_average_measured",)
    action_names: ClassVar[tuple[str, ...]] = ("force",)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012
    default_max_episode_steps: ClassVar[int] = 100
    #: the nonlinearity and the actuator's gain
    randomizable: ClassVar[tuple[str, ...]] = ("epsilon", "u_max")

    def __init__(
        self,
        *,
        epsilon: float = 1.0,
        Q: float = 5.0,
        R: float = 5.0,
        h: float = 0.1,
        substeps: int = 100,
        u_max: float = 20.0,
        state_bound: float = 20.0,
        nominal: Mapping[str, Any] | None = None,
        initial_state: ArrayLike = (1.0, 1.0),
        initial_state_cov: ArrayLike | None = None,
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
    ) -> None:
        Q_ = float(Q)
        if not np.isfinite(Q_) or Q_ < 0:
            raise ValueError(f"Q must be a non-negative spectral density; got {Q!r}")
        params = {
            "epsilon": float(epsilon),
            "Q": Q_,
            "R": positive("R", R),
            "h": positive("h", h),
            "substeps": positive("substeps", substeps, integer=True),
            "u_max": positive("u_max", u_max),
        }
        self.state_bound = positive("state_bound", state_bound)
        self.cost_cap = self.state_bound ** 2 / 2.0 + 0.01
        # Heun is stable for real eigenvalues z = λτ in [-2, 0]; near |x1| = b the
        # stiff eigenvalue is about -ε b², so keep ε b² τ <= 0.5 for accuracy.
        super().__init__(params=params, nominal=nominal, default_nominal=None,
                         initial_state=initial_state, initial_state_cov=initial_state_cov,
                         measurement_cov=params["R"] / params["h"], render_mode=render_mode,
                         max_episode_steps=max_episode_steps, randomize=randomize, burst=burst)
        tau = params["h"] / params["substeps"]
        # the largest ε an episode can have (a randomized one is drawn around the nominal)
        eps_max = max(abs(params["epsilon"]), abs(self.nominal_params["epsilon"])
                      * (1.0 + self.randomize.get("epsilon", 0.0)))
        if eps_max * self.state_bound**2 * tau > 0.5:
            raise ValueError(
                f"state_bound={state_bound} is too large for substeps={substeps}: the Heun "
                f"step needs |epsilon| * state_bound² * h / substeps <= 0.5 (got "
                f"{eps_max * self.state_bound**2 * tau:.3g}"
                + (" with randomize's largest epsilon" if "epsilon" in self.randomize else "")
                + "); raise substeps"
            )
        self._apply_params(self.params)
        self._trail: list[tuple[float, float]] = []

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        self._dynamics = self._make_dynamics(params)

    @staticmethod
    def _make_dynamics(params: Mapping[str, Any]) -> VanDerPolDynamics:
        return VanDerPolDynamics(params["epsilon"], params["h"], params["substeps"],
                                 params["u_max"])

    @property
    def dynamics(self) -> VanDerPolDynamics:
        """The true dynamics (exposes ``A_of_x`` for block-pulse filters)."""
        return self._dynamics

    @property
    def continuous_model(self) -> ContinuousModel:
        """The filter's continuous-time belief (paper 002's form, with ``A(x)``).

        Drift ``a(x, u)``, its Jacobian, the factorisation ``A(x)``, noise input
        ``[1, 1]ᵀ`` with spectral density ``Q``, ``h(x) = x1`` with intensity ``R``, and
        the block-pulse interval ``h`` — from the nominal parameters. The continuous
        filters (``bpf-kf``, ``cd-ekf``) read this instead of :attr:`model`.
        """
        return van_der_pol_continuous_model(self.nominal_params)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[FloatArray, dict[str, Any]]:
        self._trail = []
        return super().reset(seed=seed, options=options)

    def step(self, action: ArrayLike) -> tuple[FloatArray, float, bool, bool, dict[str, Any]]:
        out = super().step(action)
        self._trail.append((float(self.state[0]), float(self.state[1])))
        return out

    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        dyn = self._dynamics
        # drawn batch first, as every plant draws (one system's increments in a row), then
        # laid out (substeps, ...) as the integrator reads them
        dW = np.sqrt(self.params["Q"] * dyn.tau) * np.moveaxis(
            rng.standard_normal(x.shape[:-1] + (dyn.substeps,)), -1, 0)
        x_next, x1_average, _ = dyn.integrate(x, a, dW)
        return x_next, {"x1_average": x1_average}

    def _perturb(self, x: FloatArray, x_next: FloatArray, extra: dict[str, Any], delta: Any
                 ) -> tuple[FloatArray, dict[str, Any]]:
        """The burst stretches the whole path over the step about its start: its end and the
        interval average of ``x1`` (what the sensor integrates) alike."""
        x_next, extra = super()._perturb(x, x_next, extra, delta)
        x1 = x[..., 0]
        average = x1 + (1.0 + np.asarray(delta)) * (np.asarray(extra["x1_average"]) - x1)
        return x_next, {**extra, "x1_average": average if np.ndim(average) else float(average)}

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        if extra is None:                        # the measurement reset returns: x1(0)
            return x[..., :1].copy()
        return np.asarray(extra["x1_average"], dtype=np.float64)[..., None]

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        u = a[..., 0]
        return -saturated_cost(0.25 * np.sum(x_next * x_next, axis=-1) + 0.01 * u * u,
                               self.cost_cap)

    def _in_domain(self, x: FloatArray) -> Any:
        return np.all(np.isfinite(x) & (np.abs(x) <= self.state_bound), axis=-1)

    def _build_model(self, params: Mapping[str, Any]) -> StateSpaceModel:
        """The Heun map, ``h(x) = x1``, ``R/h``, and the integrated process noise
        :func:`process_noise_covariance` with ``G = I`` (docs/envs/van-der-pol.md#process-noise)."""
        dyn = self._make_dynamics(params)
        return StateSpaceModel(f=dyn.f, h=dyn.h, F=dyn.F, H=dyn.H, fF=dyn.f_and_F,
                               Q=process_noise_covariance(params), R=params["R"] / params["h"],
                               dt=params["h"], n_u=1, name="VanDerPol")

    def design_point(self) -> DesignPoint:
        """The unstable origin inside the limit cycle, ``u = 0`` (ε = 1, paper 002 §4).

        The weights are the reward's, ``(x1² + x2²)/4 + 0.01 a²``; PID holds the
        measured x1 at 0. On an estimate the LQG weights the input 3 instead of 0.01
        (``estimate_input_weight``: a *detuned* LQR). The measurement's variance is 50
        per step (paper 002's R/h) on a state of amplitude ~2: the EKF's x1 error in
        closed loop (RMSE ≈ 2.7) is as large as the state. With the reward's cheap input
        the LQR is deadbeat in x2 (closed-loop poles 0.905 and 0.010,
        ``K = [0.40, 0.54]``) and passes that error to the plant at full authority
        (``u_max h = 2`` per step against the process noise's 0.7); with weight 3 the
        poles are 0.900 and 0.577 (``K = [0.15, 0.29]``): the same slow x1 mode, half the
        gain on the noisiest estimate. The weight was picked on evaluation seeds 100–139
        (held out from the tests' seeds 0–39) among 0.01, 0.3, 1, 3, 10 and 30: the mean
        returns of the first five were within one standard error of each other there
        (−743 to −761, ± ≈ 60; 30: −805), and 3 beat the best constant input (0) on the
        most seeds (65 %; 0.01: 50 %, 10: 52 %). On seeds 0–39 the EKF-fed LQG scores
        −664 with weight 3 and −727 with 0.01; constant 0 scores −771, uniform random
        −948 (``tests/envs/test_honest_tasks.py``).
        """
        return DesignPoint(x=np.zeros(2), u=np.zeros(1), M=np.diag([0.25, 0.25, 0.01]),
                           states=(0, 1), output=0, setpoint=0.0,
                           pid={"kp": 1.0, "ki": 0.0, "kd": 1.0},
                           note="the unstable origin inside the limit cycle",
                           estimate_input_weight=3.0)

    def _draw(self, canvas: _draw.Canvas) -> None:
        trail = np.array(self._trail[-60:] + [tuple(self.state)])
        extent = max(3.0, 1.1 * float(np.max(np.abs(trail))))
        canvas.set_view((-extent * 4 / 3, extent * 4 / 3), (-extent, extent))
        canvas.line(-2 * extent, 0.0, 2 * extent, 0.0, _draw.GREY, width=1.0)
        canvas.line(0.0, -extent, 0.0, extent, _draw.GREY, width=1.0)
        cycle = _limit_cycle(self.params["epsilon"])
        canvas.polyline(cycle[:, 0], cycle[:, 1], _draw.GREY, width=1.0)   # noise-free cycle
        if len(trail) > 1:
            canvas.polyline(trail[:, 0], trail[:, 1], _draw.BLUE, width=1.5)
        canvas.circle(float(self.state[0]), float(self.state[1]), 0.03 * extent, _draw.ACCENT)

    def _picture(self, x: FloatArray) -> FloatArray:
        """The phase point ``(x1, x2)``."""
        return np.array([[float(x[0]), float(x[1])]])

    def _measurement_picture(self, y: FloatArray) -> list[tuple[FloatArray, FloatArray | None]]:
        """The measured ``x1`` (an interval average) leaves ``x2`` open: a vertical line."""
        return [(np.array([float(y[0]), 0.0]), np.array([0.0, 1.0]))]


def van_der_pol_continuous_model(params: Mapping[str, Any]) -> ContinuousModel:
    """VanDerPol-v0's continuous model from its parameters (``epsilon, u_max, Q, R, h``).

    ``a(x, u) = [x2, −x1 + ε (1 − x1²) x2 + u_max u]``, its Jacobian, the factorisation
    ``A(x) = [[0, 1], [−1, ε (1 − x1²)]]`` (paper 002, eq 2.2), ``G = [1, 1]ᵀ``,
    ``h(x) = x1``, spectral density ``Q`` and intensity ``R``, interval ``h``. The
    callables are methods of :class:`VanDerPolDynamics`, so the model pickles. The env's
    discrete :attr:`~VanDerPolEnv.model` carries this noise integrated over ``h``
    (:func:`process_noise_covariance`, from this model's :meth:`~ContinuousModel.integrated_noise`).
    """
    dyn = VanDerPolDynamics(float(params["epsilon"]), float(params["h"]), 1,
                            float(params["u_max"]))
    return ContinuousModel(a=dyn.drift, J=dyn.drift_jacobian, A_of_x=dyn.A_of_x, h=dyn.h,
                           H=dyn.H, G=NOISE_INPUT.reshape(2, 1), Q=params["Q"], R=params["R"],
                           dt=params["h"], n_u=1, name="VanDerPol (continuous)")


def process_noise_covariance(params: Mapping[str, Any]) -> FloatArray:
    """The model's process noise: the noise ``[1, 1]ᵀ dW`` integrated over one interval ``h``.

    ``Q_d = mean over x of ∫₀ʰ e^{J(x) s} g Q gᵀ e^{J(x)ᵀ s} ds``, ``g = [1, 1]ᵀ``,
    ``J = ∂a/∂x`` at zero input (Van Loan's method, :meth:`ContinuousModel.integrated_noise
    <fir_gym.estimators.ContinuousModel.integrated_noise>`), averaged over the states of
    :func:`limit_cycle_states` (one period of the noise-free limit cycle, uniform in time);
    at the origin when ``ε ≤ 0`` (no limit cycle). From ``epsilon, Q, h`` of ``params``.

    The integral depends on the state and the model contract has one constant ``G Q Gᵀ``;
    the limit cycle's average was chosen among the origin, the limit cycle and the states
    that zero-action and LQG episodes visit by the EKF's closed-loop NEES
    (docs/envs/van-der-pol.md#process-noise; ``scripts/van_der_pol_nees.py``). Unlike the
    first-order ``Q h g gᵀ`` (rank one) it is full rank: the noise on ``x2`` reaches ``x1``
    within the interval, and paper 002's plant integrates it so (§4, eq 3.1).
    """
    cm = van_der_pol_continuous_model(params)
    epsilon = float(params["epsilon"])
    states = limit_cycle_states(epsilon) if epsilon > 0 else np.zeros((1, 2))
    return np.asarray(np.mean(cm.integrated_noise(states), axis=0))


@functools.lru_cache(maxsize=8)
def _limit_cycle(epsilon: float) -> FloatArray:
    """Points on the noise-free limit cycle (for drawing), after a 40 s transient."""
    dyn = VanDerPolDynamics(epsilon, 0.05, 50, 1.0)
    x, u, points = np.array([2.0, 0.0]), np.zeros(1), []
    for k in range(1000):
        x = dyn.f(x, u)
        if k >= 800:
            points.append(x)
    return np.array(points)


@functools.lru_cache(maxsize=8)
def limit_cycle_states(epsilon: float, points: int = 256) -> FloatArray:
    """``points`` states of the noise-free, unforced limit cycle, equally spaced in time over
    one period (``ε > 0``; an average over them is the time average over the cycle).

    Integrated by ``scipy.integrate.solve_ivp`` (LSODA, tolerances 1e-10) from ``[2, 0]``
    through a transient of ``20 (2π + (3 − 2 ln 2) ε)`` seconds, more than 20 periods (the
    period is 2π at ε = 0, 6.66 at ε = 1 and about ``(3 − 2 ln 2) ε`` for large ε); one
    period runs between two successive downward crossings of ``x2 = 0`` (where
    ``ẋ2 = −x1``: they lie at ``x1 > 0``). The result is read-only (it is cached).
    """
    epsilon = float(epsilon)
    if not epsilon > 0:
        raise ValueError(f"the Van der Pol oscillator has a limit cycle for epsilon > 0 only; "
                         f"got {epsilon!r}")
    points = positive("points", points, integer=True)

    def drift(t: float, x: FloatArray) -> list[float]:
        return [x[1], -x[0] + epsilon * (1.0 - x[0] * x[0]) * x[1]]

    def crossing(t: float, x: FloatArray) -> float:
        return float(x[1])
    crossing.direction = -1.0                     # type: ignore[attr-defined]

    span = 2.0 * np.pi + (3.0 - 2.0 * np.log(2.0)) * epsilon      # more than one period
    start = solve_ivp(drift, (0.0, 20.0 * span), [2.0, 0.0], method="LSODA", rtol=1e-10,
                      atol=1e-10).y[:, -1]
    sol = solve_ivp(drift, (0.0, 3.0 * span), start, method="LSODA", rtol=1e-10, atol=1e-10,
                    events=crossing, dense_output=True)
    t0, t1 = sol.t_events[0][:2]
    out = np.ascontiguousarray(sol.sol(t0 + (t1 - t0) * np.arange(points) / points).T)
    out.setflags(write=False)
    return out
