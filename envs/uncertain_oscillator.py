"""Three-state oscillator with temporary model uncertainty: paper 000, simulation 2."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators._validation import FloatArray, as_covariance, one_of, positive

from . import _draw
from ._base import FirstStateMeasured, PlantEnv, saturated_cost
from ._conditions import Window, burst_delta, check_burst
from ._design import DesignPoint

UNCERTAINTY_READINGS = ("state", "rate")
PAPER_DELTA_SCHEDULE = ((350, 400, 0.15),)


class OscillatorDynamics(FirstStateMeasured):
    """Paper 000, eq (29): ``x[k+1] = D_k x[k] + r(x[k], u) Δ + [0; Δ; 0] w[k]``.

    ``r(x, u) = [x2; -c x1 - d x2 x3 + b + u_phys; 0]`` with ``c = 25``, ``d = 10``,
    ``b = 12`` (so ``x1`` settles at ``b / c = 0.48``; ``x3`` is a constant damping
    parameter, ω = 5). ``D_k = diag(1 + δ_k, 1 + δ_k, 1)``.

    Two readings of eq (29) (docs/papers.md#000-eq-29-readings):

    * ``"state"`` (the printed one): ``x⁺ = D x + r(x) Δ`` — the uncertainty scales
      the state itself, so the truth grows about 12.6 % per step while δ = 0.15;
    * ``"rate"`` (the milder one): ``x⁺ = x + D r(x) Δ`` — it scales the rate term.

    With δ = 0 both are the same Euler step. Jacobian: ``D + Δ ∂r/∂x`` ("state") or
    ``I + Δ D ∂r/∂x`` ("rate"), with ``∂r/∂x = [[0, 1, 0], [-c, -d x3, -d x2], [0, 0, 0]]``.
    """

    n_x = 3

    def __init__(self, dt: float, stiffness: float, damping_gain: float, drive: float,
                 u_max: float, uncertainty: str) -> None:
        self.dt, self.c, self.d, self.b = dt, stiffness, damping_gain, drive
        self.u_max, self.uncertainty = u_max, uncertainty

    def rate(self, x: FloatArray, u: FloatArray) -> FloatArray:
        x1, x2, x3 = x[..., 0], x[..., 1], x[..., 2]
        acc = -self.c * x1 - self.d * x2 * x3 + self.b + u[..., 0] * self.u_max
        return np.stack([x2, acc, np.zeros_like(x1)], axis=-1)

    def step(self, x: FloatArray, u: FloatArray, delta: Any = 0.0) -> FloatArray:
        """One transition; ``delta`` is a number or one δ per system of a batch."""
        scale = 1.0 + np.asarray(delta, dtype=np.float64)[..., None] * np.array([1.0, 1.0, 0.0])
        if self.uncertainty == "state":
            return scale * x + self.rate(x, u) * self.dt
        return x + scale * self.rate(x, u) * self.dt

    def jacobian(self, x: FloatArray, u: FloatArray, delta: float = 0.0) -> FloatArray:
        dr = np.zeros(x.shape[:-1] + (3, 3))
        dr[..., 0, 1] = 1.0
        dr[..., 1, 0] = -self.c
        dr[..., 1, 1] = -self.d * x[..., 2]
        dr[..., 1, 2] = -self.d * x[..., 1]
        scale = np.array([1.0 + delta, 1.0 + delta, 1.0])
        if self.uncertainty == "state":
            return np.diag(scale) + self.dt * dr
        return np.eye(3) + self.dt * scale[:, None] * dr

    def f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.step(x, u)

    def F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.jacobian(x, u)


class UncertainOscillatorEnv(PlantEnv):
    """
    ## Description

    A damped oscillator driven by a constant input, whose model is temporarily
    wrong. Paper 000 (Han, Kwon & Han, "An Extended FIR Filter for Discrete-time
    Nonlinear Systems", simulation 2, eqs (29)–(31)) uses it to compare the extended
    FIR filter with the LKF, EKF and UKF: during ``350 <= k <= 400`` the true
    system is multiplied by ``1 + δ`` (δ = 0.15) while every filter keeps the
    nominal model (δ = 0). After the uncertainty ends, a FIR filter forgets it
    within one window; an IIR filter takes longer.

        x[k+1] = diag(1+δ_k, 1+δ_k, 1) x[k] + [x2; -25 x1 - 10 x2 x3 + 12 + u; 0] Δ
                 + [0; Δ; 0] w[k]                                   (printed reading)
        y[k]   = x1[k] + v[k]

    ``uncertainty="rate"`` selects the milder reading
    ``x[k+1] = x[k] + diag(1+δ, 1+δ, 1) [·] Δ + [0; Δ; 0] w``. Under the printed
    reading the truth grows about 12.6 % per step while δ = 0.15 (|x2| reaches
    ~1.3e3 by k = 400), which is why the domain bound is wide.
    Parameters: Q = 0.4, R = 0.1, Δ = 0.01, x0 = [0, 0, 0.5].

    ## Action Space

    | Num | Action                                          | Min | Max |
    |-----|-------------------------------------------------|-----|-----|
    | 0   | force on the x2 equation, in units of `u_max`   | -1  | 1   |

    The input ``u = action * u_max`` (u_max = 25) is added to the x2 rate, like
    the constant drive 12. Out-of-bounds actions are clipped.

    ## Observation Space

    | Num | Observation          | Min  | Max |
    |-----|----------------------|------|-----|
    | 0   | x1 + v, v ~ N(0, R)  | -Inf | Inf |

    (±inf bounds: the measurement noise is Gaussian; Gymnasium's checker warns.)

    ## State (``info["state"]``)

    ``[x1, x2, x3]``: position, velocity, and the constant damping parameter.
    ``info["delta"]`` is the uncertainty δ applied in the step.

    ## Rewards

    Regulate x1 to ``setpoint`` (default 1.0, away from the natural rest 0.48): the
    cost ``(x1[k+1] - setpoint)² + 1e-3 action²``, saturated at ``cost_cap = 2.25``
    (an x1 error of 1.5, half again the distance from the start to the setpoint), so
    the reward ``-min(cost, cost_cap)`` lies in ``[-2.25, 0]``. Holding the setpoint
    needs ``u = c·setpoint - b`` (action 0.52 with the defaults). The cap is low on
    purpose: under the printed reading the uncertainty window multiplies the state by
    1.15 per step (1.15⁵¹ ≈ 1.3e3), faster than the bounded input can counter near
    the setpoint, and no controller brings the state back within the episode; a
    higher cap would make the return measure how far the blow-up went (smallest for a
    state parked near the origin, the one point δ cannot move) rather than the
    regulation the task asks for.

    ## Starting State

    ``[0, 0, 0.5]`` (the paper's) plus a draw from ``N(0, initial_state_cov)``
    (zero by default).

    ## Episode End

    Termination when any ``|x_i| > state_bound`` (1e4); the terminating step is paid
    ``-cost_cap * (1 + steps left to max_episode_steps)``, so leaving early never
    pays. Truncation at ``max_episode_steps`` = 500 steps by the registered
    ``TimeLimit`` (the paper's experiment runs to k = 500).

    ## Arguments

    ``gym.make("fir_gym/UncertainOscillator-v0", uncertainty="state",
    delta_schedule=((350, 400, 0.15),), Q=0.4, R=0.1, dt=0.01, stiffness=25.0,
    damping_gain=10.0, drive=12.0, u_max=25.0, setpoint=1.0, state_bound=1e4,
    nominal=None, initial_state=(0, 0, 0.5), initial_state_cov=None,
    max_episode_steps=500, render_mode=None)``. ``delta_schedule`` is a sequence of
    ``(k_first, k_last, δ)`` (inclusive; ``k`` indexes the transition from
    ``x[k]`` to ``x[k+1]``); overlapping windows add. The model always uses
    δ = 0; ``nominal`` may change ``Q, R, dt, stiffness, damping_gain, drive,
    u_max`` for the model. ``randomize`` draws the true ``stiffness``,
    ``damping_gain``, ``drive`` and ``u_max`` around the nominal ones every episode;
    ``burst`` windows (docs/robustness.md#plant-conditions) are added to the δ schedule,
    so they act through eq (29) in the plant's reading (``info["burst"]`` is their part,
    ``info["delta"]`` the whole δ).

    ## Version History

    * v0: initial version.
    """

    state_names: ClassVar[tuple[str, ...]] = ("x1", "x2", "x3")
    measurement_names: ClassVar[tuple[str, ...]] = ("x1_measured",)
    action_names: ClassVar[tuple[str, ...]] = ("force",)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}  # noqa: RUF012
    default_max_episode_steps: ClassVar[int] = 500
    cost_cap: float = 2.25
    #: the spring, the damping gain, the constant drive and the actuator's gain
    randomizable: ClassVar[tuple[str, ...]] = ("stiffness", "damping_gain", "drive", "u_max")

    def __init__(
        self,
        *,
        uncertainty: str = "state",
        delta_schedule: Sequence[Window] = PAPER_DELTA_SCHEDULE,
        Q: float = 0.4,
        R: float = 0.1,
        dt: float = 0.01,
        stiffness: float = 25.0,
        damping_gain: float = 10.0,
        drive: float = 12.0,
        u_max: float = 25.0,
        setpoint: float = 1.0,
        state_bound: float = 1e4,
        nominal: Mapping[str, Any] | None = None,
        initial_state: ArrayLike = (0.0, 0.0, 0.5),
        initial_state_cov: ArrayLike | None = None,
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
    ) -> None:
        one_of("uncertainty", uncertainty, UNCERTAINTY_READINGS)
        self.uncertainty = uncertainty
        self.delta_schedule = check_burst(delta_schedule, "delta_schedule")
        params = {
            "Q": as_covariance("Q", Q, 1),
            "R": as_covariance("R", R, 1, definite=True),
            "dt": positive("dt", dt),
            "stiffness": positive("stiffness", stiffness),
            "damping_gain": float(damping_gain),
            "drive": float(drive),
            "u_max": positive("u_max", u_max),
        }
        self.setpoint = float(setpoint)
        self.state_bound = positive("state_bound", state_bound)
        super().__init__(params=params, nominal=nominal, default_nominal=None,
                         initial_state=initial_state, initial_state_cov=initial_state_cov,
                         measurement_cov=params["R"], render_mode=render_mode,
                         max_episode_steps=max_episode_steps, randomize=randomize, burst=burst)
        self._noise_std = float(np.sqrt(self.params["Q"][0, 0]))
        self._apply_params(self.params)

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        self._dynamics = self._make_dynamics(params, self.uncertainty)

    def delta(self, k: Any) -> Any:
        """The true uncertainty δ_k of the transition from x[k] to x[k+1] (k: int or array):
        the δ schedule's and the burst's windows, added."""
        k_ = np.asarray(k)
        total = np.zeros(k_.shape)
        for first, last, d in self.delta_schedule:
            total = total + d * ((first <= k_) & (k_ <= last))
        if self.burst:
            total = total + burst_delta(self.burst, k_)
        return float(total) if total.ndim == 0 else total

    def _perturb(self, x: FloatArray, x_next: FloatArray, extra: dict[str, Any], delta: Any
                 ) -> tuple[FloatArray, dict[str, Any]]:
        """The burst is already in the transition's δ (:meth:`delta`): nothing to add."""
        return x_next, extra

    @staticmethod
    def _make_dynamics(params: Mapping[str, Any], uncertainty: str) -> OscillatorDynamics:
        return OscillatorDynamics(params["dt"], params["stiffness"], params["damping_gain"],
                                  params["drive"], params["u_max"], uncertainty)

    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        delta = self.delta(k)
        x_next = self._dynamics.step(x, a, delta)
        x_next[..., 1] += self.params["dt"] * self._noise_std * rng.standard_normal(x.shape[:-1])
        return x_next, {"delta": delta}

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        return OscillatorDynamics.h(x)

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        e, u = x_next[..., 0] - self.setpoint, a[..., 0]
        return -saturated_cost(e * e + 1e-3 * u * u, self.cost_cap)

    def _in_domain(self, x: FloatArray) -> Any:
        return np.all(np.isfinite(x) & (np.abs(x) <= self.state_bound), axis=-1)

    def _build_model(self, params: Mapping[str, Any]) -> StateSpaceModel:
        dyn = self._make_dynamics(params, self.uncertainty)
        G = np.array([[0.0], [params["dt"]], [0.0]])
        return StateSpaceModel(f=dyn.f, h=dyn.h, F=dyn.F, H=dyn.H, G=G, Q=params["Q"],
                               R=params["R"], dt=params["dt"], n_u=1,
                               name="UncertainOscillator(nominal, δ=0)")

    def design_point(self) -> DesignPoint:
        """``x1 = setpoint``, ``x2 = 0``, ``x3 = x3(0)``, ``u = (c·setpoint − b) / u_max``.

        The holding force of the nominal model, eq (29) of paper 000 with δ = 0 (the
        temporary uncertainty of the truth is not in the model); the damping parameter
        ``x3`` is a constant state (an uncontrollable mode at 1), so the design regulates
        ``(x1, x2)`` only. The weights are the reward's, ``(x1 − setpoint)² + 1e-3 a²``;
        PID holds the measured x1 at the setpoint.
        """
        p = self.nominal_params
        s = self.setpoint
        u = (p["stiffness"] * s - p["drive"]) / p["u_max"]
        M = np.zeros((4, 4))
        M[0, 0], M[3, 3] = 1.0, 1e-3
        x3 = float(self.initial_state[2])
        return DesignPoint(x=np.array([s, 0.0, x3]), u=np.array([u]), M=M, states=(0, 1),
                           output=0, setpoint=s, pid={"kp": 1.0, "ki": 2.0, "kd": 0.1},
                           note="x1 at the setpoint; x3 (damping) is a constant parameter")

    def _draw(self, canvas: _draw.Canvas) -> None:
        canvas.set_view((-0.5, 2.5), (-1.0, 1.0))
        x1 = float(np.clip(self.state[0], -0.4, 2.4))
        canvas.rect(-0.5, -0.45, -0.42, 0.45, _draw.INK)                  # wall
        canvas.line(-0.5, -0.3, 2.5, -0.3, _draw.GREY, width=1.0)          # floor
        coils = np.linspace(-0.42, x1 - 0.1, 14)
        ys = np.where(np.arange(14) % 2 == 0, -0.05, 0.05)
        ys[0] = ys[-1] = 0.0
        canvas.polyline(coils, ys, _draw.INK, width=2.0)                   # spring
        canvas.rect(x1 - 0.1, -0.3, x1 + 0.1, 0.1, _draw.ACCENT)          # mass
        canvas.line(self.setpoint, -0.45, self.setpoint, 0.3, _draw.GREEN, width=2.0)
        delta = self.delta(self.time_step)
        if delta:
            canvas.rect(2.0, 0.6, 2.0 + min(abs(delta), 1.0) * 2.0, 0.75, _draw.BLUE)

    def _picture(self, x: FloatArray) -> FloatArray:
        """The centre of the mass at position ``x1`` (the rectangle :meth:`_draw` draws)."""
        return np.array([[float(x[0]), -0.1]])

    def _measurement_picture(self, y: FloatArray) -> list[tuple[FloatArray, FloatArray | None]]:
        """The measured position ``x1``."""
        return [(np.array([float(y[0]), -0.1]), None)]
