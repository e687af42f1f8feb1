"""Rectilinear orbit determination: paper 000, simulation 1 (after Jazwinski 1968)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, cast

import numpy as np
from numpy.typing import ArrayLike

from fir_gym.estimators import StateSpaceModel, compiled
from fir_gym.estimators._validation import FloatArray, as_covariance, positive

from . import _draw
from ._base import FirstStateMeasured, PlantEnv, saturated_cost
from ._conditions import column, entry, per_system
from ._design import DesignPoint
from ._interval_kernels import orbit_interval

TRUE_MU = 19.92244165
NOMINAL_MU = 19.91


#: batches up to this size are propagated row by row in Python floats (faster than numpy)
SMALL_BATCH = 32


class OrbitDynamics(FirstStateMeasured):
    """Euler-discretised radial motion under gravity and radial thrust, one measurement interval.

    Paper 000, eq (27): ``x[j+1] = x[j] + [x2; -μ/x1² + a] Δ`` with ``Δ = euler_dt``,
    repeated ``substeps`` (M = 100) times per measurement interval; ``a`` is the
    thrust acceleration, held over the interval. The Jacobian of the interval map is
    the product of the Euler Jacobians ``I + Δ [[0, 1], [2μ/x1³, 0]]`` along the path.
    Batched over a leading axis; picklable (the model's callables are its methods).
    ``mu`` and ``thrust_max`` are numbers, or one per system of a batch (``(B,)`` arrays: a
    native vector env's per-episode true parameters, :mod:`._conditions`).
    """

    def __init__(self, mu: Any, euler_dt: float, substeps: int, thrust_max: Any) -> None:
        self.mu, self.euler_dt, self.substeps, self.thrust_max = mu, euler_dt, substeps, thrust_max
        self._per_system = per_system(mu, thrust_max)
        #: the parameters as the compiled loop takes them
        self._columns = (column(mu), column(thrust_max))

    def row(self, i: int) -> OrbitDynamics:
        """The dynamics of system ``i`` (numbers for its parameters)."""
        if not self._per_system:
            return self
        return OrbitDynamics(entry(self.mu, i), self.euler_dt, self.substeps,
                             entry(self.thrust_max, i))

    def propagate(self, x: FloatArray, u: FloatArray, jacobian: bool = False
                  ) -> tuple[FloatArray, FloatArray | None]:
        """The interval map and, optionally, its Jacobian.

        The loop runs on components, so one code path serves a single system (Python
        floats: fast for the plant) and a batch (numpy arrays: the model, the vector env).
        """
        lead = x.shape[:-1]
        single = x.size == 2                       # one system, batched as (1, 2) or not
        if compiled.ENABLED:                 # the same loop compiled: same bits
            u = np.asarray(u, dtype=np.float64)
            x_next, J = orbit_interval(np.asarray(x, dtype=np.float64).reshape(-1, 2),
                                       u.reshape(-1, u.shape[-1]), self.substeps,
                                       self._columns[0], self.euler_dt, self._columns[1],
                                       jacobian)
            return x_next.reshape(lead + (2,)), J.reshape(lead + (2, 2)) if jacobian else None
        if x.ndim == 2 and 1 < x.shape[0] <= SMALL_BATCH:
            # a few systems (e.g. a UKF's sigma points): row by row in floats, bit for bit
            # the batched loop and ~10x faster where numpy's per-call cost dominates
            U = np.broadcast_to(u, (x.shape[0], u.shape[-1]))
            rows = [self.row(i).propagate(x[i], U[i], jacobian) for i in range(x.shape[0])]
            return (np.array([r[0] for r in rows]),
                    np.array([r[1] for r in rows]) if jacobian else None)
        r: Any                                     # floats (one system) or arrays (a batch)
        v: Any
        a: Any
        mu: Any
        if single:
            r, v = float(x.flat[0]), float(x.flat[1])
            a = float(np.asarray(u).flat[0]) * entry(self.thrust_max, 0)
            mu = entry(self.mu, 0)
        else:
            r, v = x[..., 0], x[..., 1]
            a = u[..., 0] * self.thrust_max
            mu = self.mu
        d = self.euler_dt
        j11, j12, j21, j22 = 1.0, 0.0, 0.0, 1.0
        for _ in range(self.substeps):
            if jacobian:
                # J ← (I + Δ [[0, 1], [2μ/r³, 0]]) J
                g = 2.0 * mu / (r * r * r) * d
                j11, j12, j21, j22 = j11 + d * j21, j12 + d * j22, j21 + g * j11, j22 + g * j12
            r, v = r + v * d, v + (a - mu / (r * r)) * d
        x_next = np.array([r, v]).reshape(lead + (2,)) if single else np.stack([r, v], axis=-1)
        if not jacobian:
            return x_next, None
        if single:
            return x_next, np.array([[j11, j12], [j21, j22]]).reshape(lead + (2, 2))
        J = np.stack([np.stack(np.broadcast_arrays(j11, j12), -1),
                      np.stack(np.broadcast_arrays(j21, j22), -1)], -2)
        return x_next, J

    def f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.propagate(x, u)[0]

    def F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return cast(FloatArray, self.propagate(x, u, jacobian=True)[1])   # not None: jacobian

    def f_and_F(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``f`` and ``F`` in one pass of the Euler loop."""
        x_next, J = self.propagate(x, u, jacobian=True)
        return x_next, cast(FloatArray, J)


class OrbitEnv(PlantEnv):
    """
    ## Description

    A body moves along a straight line through the centre of a planet (rectilinear
    orbit, Jazwinski 1968). Paper 000 (Han, Kwon & Han, "An Extended FIR Filter for
    Discrete-time Nonlinear Systems", simulation 1) uses it to show an extended
    Kalman filter diverging under a wrong gravitational parameter while the
    extended FIR filter stays bounded. The plant is the paper's Euler
    discretisation, eq (27), with a radial thrust added:

        r[j+1] = r[j] + v[j] Δ
        v[j+1] = v[j] + (-μ / r[j]² + a) Δ,       Δ = 1e-4

    and the range is measured every M = 100 Euler steps, eq (28):
    ``y[k] = r + v[k]``, ``v[k] ~ N(0, R)``, R = 1e-3. One env step is one
    measurement interval (0.01 time units). The true μ = 19.92244165; the
    filter's :attr:`model` believes μ = 19.91 unless ``nominal`` says otherwise.
    Process noise is off by default, as in the paper; when ``Q`` is given, a
    ``N(0, Q)`` draw is added to the state once per measurement interval, so the
    model ``x[k+1] = f(x[k], u[k]) + w[k]`` is exactly the plant's law.

    ## Action Space

    | Num | Action                                  | Min | Max |
    |-----|-----------------------------------------|-----|-----|
    | 0   | radial thrust, in units of `thrust_max` | -1  | 1   |

    The thrust acceleration ``a = action * thrust_max`` is held over the interval.
    Actions outside ``[-1, 1]`` are clipped (``info["action_clipped"]``).

    ## Observation Space

    | Num | Observation                 | Min  | Max |
    |-----|-----------------------------|------|-----|
    | 0   | measured radius r + v       | -Inf | Inf |

    ## State (``info["state"]``)

    ``[r, v]``: radius and radial velocity.

    ## Rewards

    Hold the reference radius: the cost ``(r[k+1] - r_ref)² + 0.01 action²``,
    saturated at ``cost_cap = (r_ref - r_min)² + 0.01`` (49.01 by default: the cost of
    lying on the planet's surface at full thrust), so the reward
    ``-min(cost, cost_cap)`` lies in ``[-cost_cap, 0]``. Hovering at ``r_ref`` needs
    the thrust ``μ / r_ref²`` (action ≈ 0.311), which costs 0.001 per step.

    ## Starting State

    ``[7.99, 1.99]`` (the paper's), plus a draw from ``N(0, initial_state_cov)``
    (zero by default, so only the measurement noise depends on the seed).

    ## Episode End

    Termination when ``r <= r_min`` (the body reaches the planet, 1.0) or
    ``r >= r_max`` (100.0); the terminating step is paid
    ``-cost_cap * (1 + steps left to max_episode_steps)``, so crashing early never
    pays (a constant full reverse thrust reaches the planet in about 500 steps).
    Truncation at ``max_episode_steps`` = 1000 steps (10 time units) by the
    registered ``TimeLimit``.

    ## Arguments

    ``gym.make("fir_gym/Orbit-v0", mu=19.92244165, R=1e-3, Q=None, euler_dt=1e-4,
    substeps=100, thrust_max=1.0, r_ref=8.0, nominal={"mu": 19.91},
    initial_state=(7.99, 1.99), initial_state_cov=None, max_episode_steps=1000,
    randomize=None, burst=None, render_mode=None)``.
    ``nominal`` lists parameters the model believes differently from the truth
    (keys: ``mu, R, Q, euler_dt, substeps, thrust_max``). ``randomize`` draws the true
    ``mu`` and ``thrust_max`` around the nominal ones every episode (the ``mismatch``
    condition draws both), ``burst`` stretches the increments over a window of steps
    (docs/robustness.md#plant-conditions).

    ## Version History

    * v0: initial version.
    """

    state_names: ClassVar[tuple[str, ...]] = ("r", "v")
    measurement_names: ClassVar[tuple[str, ...]] = ("r_measured",)
    action_names: ClassVar[tuple[str, ...]] = ("thrust",)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}  # noqa: RUF012
    default_max_episode_steps: ClassVar[int] = 1000
    #: the gravitational parameter and the thruster's gain
    randomizable: ClassVar[tuple[str, ...]] = ("mu", "thrust_max")

    def __init__(
        self,
        *,
        mu: float = TRUE_MU,
        R: float = 1e-3,
        Q: ArrayLike | None = None,
        euler_dt: float = 1e-4,
        substeps: int = 100,
        thrust_max: float = 1.0,
        r_ref: float = 8.0,
        r_min: float = 1.0,
        r_max: float = 100.0,
        nominal: Mapping[str, Any] | None = None,
        initial_state: ArrayLike = (7.99, 1.99),
        initial_state_cov: ArrayLike | None = None,
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
    ) -> None:
        params = {
            "mu": positive("mu", mu),
            "R": as_covariance("R", R, 1, definite=True),
            "Q": np.zeros((2, 2)) if Q is None else as_covariance("Q", Q, 2),
            "euler_dt": positive("euler_dt", euler_dt),
            "substeps": positive("substeps", substeps, integer=True),
            "thrust_max": positive("thrust_max", thrust_max),
        }
        self.r_ref = positive("r_ref", r_ref)
        self.r_min, self.r_max = positive("r_min", r_min), positive("r_max", r_max)
        if not self.r_min < self.r_ref < self.r_max:
            raise ValueError(f"need r_min < r_ref < r_max; got {r_min}, {r_ref}, {r_max}")
        self.cost_cap = (self.r_ref - self.r_min) ** 2 + 0.01
        super().__init__(params=params, nominal=nominal, default_nominal={"mu": NOMINAL_MU},
                         initial_state=initial_state, initial_state_cov=initial_state_cov,
                         measurement_cov=params["R"], render_mode=render_mode,
                         max_episode_steps=max_episode_steps, randomize=randomize, burst=burst)
        self._set_process_noise(self.params["Q"])
        self._apply_params(self.params)

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        self._dynamics = OrbitDynamics(params["mu"], params["euler_dt"], params["substeps"],
                                       params["thrust_max"])

    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        return self._add_process_noise(self._dynamics.f(x, a), rng), {}

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        return OrbitDynamics.h(x)

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        e, u = x_next[..., 0] - self.r_ref, a[..., 0]
        return -saturated_cost(e * e + 0.01 * u * u, self.cost_cap)

    def _in_domain(self, x: FloatArray) -> Any:
        r = x[..., 0]
        return np.isfinite(x).all(axis=-1) & (self.r_min < r) & (r < self.r_max)

    def _build_model(self, params: Mapping[str, Any]) -> StateSpaceModel:
        dyn = OrbitDynamics(positive("nominal mu", params["mu"]), params["euler_dt"],
                            params["substeps"], params["thrust_max"])
        dt = params["euler_dt"] * params["substeps"]
        return StateSpaceModel(f=dyn.f, h=dyn.h, F=dyn.F, H=dyn.H, fF=dyn.f_and_F, Q=params["Q"],
                               R=params["R"], dt=dt, n_u=1, name=f"Orbit(mu={params['mu']:g})")

    def design_point(self) -> DesignPoint:
        """Hover at ``r = r_ref``, ``v = 0`` with the nominal thrust ``μ / r_ref²``.

        The input is that thrust in units of ``thrust_max`` (the nominal μ's, what the
        model believes: the LQG's operating point is a fixed point of the model, eq (27)
        of paper 000 with the thrust added). The weights are the reward's,
        ``(r[k+1] − r_ref)² + 0.01 a²``; PID holds the measured radius at ``r_ref``.
        """
        p = self.nominal_params
        hover = p["mu"] / (self.r_ref ** 2 * p["thrust_max"])
        M = np.diag([1.0, 0.0, 0.01])
        return DesignPoint(x=np.array([self.r_ref, 0.0]), u=np.array([hover]), M=M,
                           states=(0, 1), output=0, setpoint=self.r_ref,
                           pid={"kp": 2.0, "ki": 0.5, "kd": 2.0},
                           note="hover at r_ref with the nominal μ's thrust")

    def _draw(self, canvas: _draw.Canvas) -> None:
        r = float(self.state[0])
        extent = max(12.0, 1.15 * max(r, self.r_ref))
        canvas.set_view((-extent * 4 / 3, extent * 4 / 3), (-extent, extent))
        canvas.ring(0.0, 0.0, self.r_ref, _draw.GREY, width=1.5)
        canvas.circle(0.0, 0.0, self.r_min, _draw.BLUE)
        canvas.line(0.0, 0.0, 0.0, r, _draw.GREY, width=1.0)
        canvas.circle(0.0, r, 0.02 * extent + 0.1, _draw.ACCENT)

    def _picture(self, x: FloatArray) -> FloatArray:
        """The body at radius ``r`` on the vertical line (what :meth:`_draw` draws)."""
        return np.array([[0.0, float(x[0])]])

    def _measurement_picture(self, y: FloatArray) -> list[tuple[FloatArray, FloatArray | None]]:
        """The measured radius, on the same line."""
        return [(np.array([0.0, float(y[0])]), None)]

