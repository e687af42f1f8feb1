"""Aircraft-carrier motion at sea: paper 001's plant, discretised exactly."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from fir_gym.estimators import LinearModel, discretize_lti
from fir_gym.estimators._validation import FloatArray, positive
from fir_gym.estimators.continuous import ContinuousModel

from . import _draw
from ._base import PlantEnv, psd_sqrt, saturated_cost
from ._design import DesignPoint

PAPER_A21 = -0.36
PAPER_A22 = -0.06
PAPER_NOISE_INPUT = (0.6, -0.036)


def carrier_continuous(params: Mapping[str, Any]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Continuous matrices ``(A, G, C)`` of paper 001 §V for the given parameters.

    ``ẋ = [[0, 1], [a21, a22 + Δ22]] x + g w``, ``z = [1 + Δc, 0] x + v``.
    """
    A = np.array([[0.0, 1.0], [params["a21"], params["a22"] + params["delta22"]]])
    G = np.asarray(params["noise_input"], dtype=np.float64).reshape(2, 1)
    C = np.array([[1.0 + params["delta_c"], 0.0]])
    return A, G, C


def carrier_discrete(params: Mapping[str, Any]) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Exact sampling ``(A_d, Q_d, C, R_d)`` at ``sample_period`` (Van Loan for ``Q_d``).

    ``R_d = v / T_s``: a continuous measurement of intensity ``v`` read through an
    integrate-and-dump of length ``T_s`` has that variance; it is applied to the
    point sample ``C x[k]``, the standard discrete equivalent (exact as ``T_s → 0``).
    """
    A, G, C = carrier_continuous(params)
    T = params["sample_period"]
    A_d, _, Q_d = discretize_lti(A, T, G=G, Q=params["q"])
    return A_d, Q_d, C, params["v"] / T


class CarrierMotionEnv(PlantEnv):
    """
    ## Description

    The motion of an aircraft carrier's deck at sea (Sidar & Doolin, NASA TM X-62,
    1975), the example of paper 001 (performance bounds of the continuous-time
    optimal FIR filter, §V). The continuous model

        ẋ = [[0, 1], [-0.36, -0.06 + Δ22]] x + [0.6, -0.036]ᵀ w,   E[w wᵀ] = q δ(t), q = 0.035
        z = [1 + Δc, 0] x + v,                                      E[v vᵀ] = V δ(t), V = 1

    is sampled exactly at ``sample_period`` (default 0.1 s, about 1/100 of the
    10.5 s motion period): ``A_d = e^{A T}``, ``Q_d`` by Van Loan's method, and the
    measurement noise variance ``R_d = V / T`` (an integrate-and-dump of the
    continuous measurement, applied to the point sample). The true uncertainties
    Δ22 (|Δ22| ≤ 0.006 in the paper) and Δc (|Δc| ≤ 0.1) default to 0; the
    filter's :attr:`model` believes Δ22 = Δc = 0 (paper 001's nominal system)
    whatever the truth, unless ``nominal`` says otherwise; every other model
    parameter defaults to the truth.

    **Task: deck-motion compensation.** A compensating platform (for instance a
    landing aid or a motion-compensated gangway) is set at the start of each
    interval to an offset ``c_k = action * c_max`` and held; the reward penalises
    the residual deck motion it leaves at the end of the interval,
    ``x1[k+1] - c_k``. Doing well requires predicting ``x1`` one interval ahead
    from noisy measurements, which is what the estimators do; the action does not
    move the carrier (the model's input matrix is zero).

    ## Action Space

    | Num | Action                                   | Min | Max |
    |-----|------------------------------------------|-----|-----|
    | 0   | compensator offset, in units of `c_max`  | -1  | 1   |

    ## Observation Space

    | Num | Observation                    | Min  | Max |
    |-----|--------------------------------|------|-----|
    | 0   | (1 + Δc) x1 + v, v ~ N(0, V/T) | -Inf | Inf |

    (±inf bounds: the measurement noise is Gaussian; Gymnasium's checker warns.)

    ## State (``info["state"]``)

    ``[x1, x2]``: deck displacement and its rate.

    ## Rewards

    ``-min(((x1[k+1] - c_k) / σ1)², cost_cap)`` with ``σ1`` the stationary standard
    deviation of ``x1`` (≈ 0.32 with the paper's values; 1 for a calm sea, ``q = 0``):
    0 is perfect compensation, about -1 is doing nothing; ``cost_cap = 100`` (a
    residual of 10 σ1, never reached from the stationary distribution) keeps every
    reward finite, e.g. after ``reset(options={"state": ...})`` with a huge state.

    ## Starting State

    Drawn from the stationary distribution ``N(0, P∞)`` of the true system
    (``P∞`` from the continuous Lyapunov equation), as paper 001 assumes for the
    window start; ``initial_state`` / ``initial_state_cov`` override it.

    ## Episode End

    No termination (the plant is stable and linear) unless the state stops being
    finite, which is paid ``-cost_cap * (1 + steps left to max_episode_steps)``;
    truncation at ``max_episode_steps`` = 1000 steps (100 s) by the registered
    ``TimeLimit``.

    ## Arguments

    ``gym.make("fir_gym/CarrierMotion-v0", sample_period=0.1, q=0.035, v=1.0,
    delta22=0.0, delta_c=0.0, a21=-0.36, a22=-0.06, noise_input=(0.6, -0.036),
    c_max=1.0, nominal=None, initial_state=(0, 0), initial_state_cov="stationary",
    max_episode_steps=1000, randomize=None, burst=None, render_mode=None)``. ``nominal``
    may change any of ``q, v, delta22, delta_c, a21, a22, noise_input, sample_period``
    for the model. ``randomize`` draws the true ``a21`` and ``a22`` (the sea's stiffness
    and damping terms) around the nominal ones every episode; ``burst`` stretches the
    increments over a window of steps (docs/robustness.md#plant-conditions).

    ## Version History

    * v0: initial version.
    """

    state_names: ClassVar[tuple[str, ...]] = ("deck", "deck_rate")
    measurement_names: ClassVar[tuple[str, ...]] = ("deck_measured",)
    action_names: ClassVar[tuple[str, ...]] = ("compensator_offset",)
    #: default FIR window (5 s: a long window against the heavy measurement noise)
    default_horizon: ClassVar[int] = 50
    #: the legend's name and mark for what the drawing shows of the true state
    truth_label: ClassVar[str] = "truth (deck)"
    truth_color: ClassVar[tuple[int, int, int]] = _draw.GREY
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012
    default_max_episode_steps: ClassVar[int] = 1000
    cost_cap: float = 100.0
    #: the motion's stiffness and damping terms (a fraction below 1 keeps them stable)
    randomizable: ClassVar[tuple[str, ...]] = ("a21", "a22")

    def __init__(
        self,
        *,
        sample_period: float = 0.1,
        q: float = 0.035,
        v: float = 1.0,
        delta22: float = 0.0,
        delta_c: float = 0.0,
        a21: float = PAPER_A21,
        a22: float = PAPER_A22,
        noise_input: ArrayLike = PAPER_NOISE_INPUT,
        c_max: float = 1.0,
        nominal: Mapping[str, Any] | None = None,
        initial_state: ArrayLike = (0.0, 0.0),
        initial_state_cov: ArrayLike | str | None = "stationary",
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
    ) -> None:
        noise_input_ = np.asarray(noise_input, dtype=np.float64)
        if noise_input_.shape != (2,) or not np.all(np.isfinite(noise_input_)):
            raise ValueError(f"noise_input must be 2 finite numbers; got {noise_input!r}")
        params = {
            "sample_period": positive("sample_period", sample_period),
            "q": _non_negative("q", q),
            "v": positive("v", v),
            "delta22": float(delta22),
            "delta_c": float(delta_c),
            "a21": float(a21),
            "a22": float(a22),
            "noise_input": tuple(noise_input_),
        }
        A, G, _ = carrier_continuous(params)
        if np.max(np.linalg.eigvals(A).real) >= 0:
            raise ValueError("a21, a22 + delta22 must give a stable carrier model (the stationary "
                             f"distribution must exist); eigenvalues {np.linalg.eigvals(A)}")
        self.stationary_cov = scipy.linalg.solve_continuous_lyapunov(A, -params["q"] * G @ G.T)
        self.c_max = positive("c_max", c_max)
        if isinstance(initial_state_cov, str):
            if initial_state_cov != "stationary":
                raise ValueError("initial_state_cov must be 'stationary', None or a 2x2 "
                                 f"covariance; got {initial_state_cov!r}")
            initial_state_cov = self.stationary_cov
        _, _, C, R_d = carrier_discrete(params)
        super().__init__(params=params, nominal=nominal,
                         default_nominal={"delta22": 0.0, "delta_c": 0.0},
                         initial_state=initial_state, initial_state_cov=initial_state_cov,
                         measurement_cov=R_d, render_mode=render_mode,
                         max_episode_steps=max_episode_steps, randomize=randomize, burst=burst)
        self._C = C
        self._apply_params(self.params)
        # reward normaliser; a calm sea (q = 0) has no stationary spread, use 1
        self._sigma1 = float(np.sqrt(self.stationary_cov[0, 0])) or 1.0

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        """``A_d`` and the square root of ``Q_d`` of the true system: one pair, or one per
        system where ``a21``/``a22`` hold one value per system."""
        if not any(isinstance(params[name], np.ndarray) for name in self.randomizable):
            A_d, Q_d, _, _ = carrier_discrete(params)
            self._A_d, self._process_sqrt = A_d, psd_sqrt(Q_d)
            return
        n = max(np.size(params[name]) for name in self.randomizable)
        columns = {name: np.broadcast_to(np.asarray(params[name], dtype=np.float64), (n,))
                   for name in self.randomizable}
        rows = [carrier_discrete({**params, **{name: float(c[i]) for name, c in columns.items()}})
                for i in range(n)]
        self._A_d = np.stack([r[0] for r in rows])
        self._process_sqrt = np.stack([psd_sqrt(r[1]) for r in rows])

    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        noise = rng.standard_normal(x.shape)
        if self._A_d.ndim == 2:
            x_next = x @ self._A_d.T + noise @ self._process_sqrt.T
        else:           # one true system per row (randomized): each row as one system's
            x_next = ((x[:, None, :] @ self._A_d.mT)[:, 0, :]
                      + (noise[:, None, :] @ self._process_sqrt.mT)[:, 0, :])
        return x_next, {"compensator_offset": a[..., 0] * self.c_max}

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        with np.errstate(over="ignore", invalid="ignore"):   # a non-finite reading is a
            return x @ self._C.T                             # simulation failure, reported

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        if x_next.ndim == 1:   # in Python floats: a huge finite state overflows to inf quietly
            d = (x_next.item(0) - a.item(0) * self.c_max) / self._sigma1
        else:
            d = (x_next[:, 0] - a[:, 0] * self.c_max) / self._sigma1
        return -saturated_cost(d * d, self.cost_cap)

    @property
    def continuous_model(self) -> ContinuousModel:
        """Paper 001's continuous model with the nominal parameters (for continuous filters).

        ``z`` has intensity ``v``; the plant's discrete measurement is the point sample
        with variance ``v / T`` (see the class docstring), which continuous filters
        read as an interval average — a small mismatch at T = 0.1 s.
        """
        p = self.nominal_params
        A, G, C = carrier_continuous(p)
        return ContinuousModel.linear(A=A, C=C, G=G, Q=p["q"], R=p["v"], dt=p["sample_period"],
                                      B=np.zeros((2, 1)), name="CarrierMotion (continuous)")

    def _build_model(self, params: Mapping[str, Any]) -> LinearModel:
        A_d, Q_d, C, R_d = carrier_discrete(params)
        return LinearModel(A=A_d, C=C, Q=Q_d, R=R_d, B=np.zeros((2, 1)),
                           dt=params["sample_period"], name="CarrierMotion")

    def design_point(self) -> DesignPoint:
        """``x = 0``, ``c = 0``: compensation, where the action predicts the deck.

        The action does not move the deck (the model's input matrix is zero), so the
        operating point is the sea's rest with the platform centred, and the cost is the
        reward's, ``((x1[k+1] − c_max a) / σ1)²``: its cross term between ``x1[k+1]`` and
        ``a`` is all the LQR sees, and its gain is the certainty-equivalent one-step
        predictor ``c = C A x̂ / c_max`` of paper 001's nominal model. No measured
        quantity is held (``output=None``): PID does not apply.
        """
        c = self.c_max / self._sigma1
        w = np.array([1.0 / self._sigma1, 0.0, -c])       # z -> (x1[k+1] - c_max a) / σ1
        return DesignPoint(x=np.zeros(2), u=np.zeros(1), M=np.outer(w, w), states=(0, 1),
                           note="compensation: the action predicts the deck, it does not "
                                "move it")

    def _draw(self, canvas: _draw.Canvas) -> None:
        s = 3.0 * self._sigma1
        canvas.set_view((-2.0 * s, 2.0 * s), (-1.5 * s, 1.5 * s))
        heave = float(np.clip(self.state[0], -1.4 * s, 1.4 * s))
        canvas.rect(-2.0 * s, -1.5 * s, 2.0 * s, 0.0, (205, 225, 240))       # sea
        hull_x = [-1.4 * s, 1.4 * s, 1.1 * s, -1.1 * s]
        hull_y = [heave, heave, heave - 0.35 * s, heave - 0.35 * s]
        canvas.polygon(hull_x, hull_y, _draw.INK)                             # hull
        canvas.rect(-1.4 * s, heave, 1.4 * s, heave + 0.06 * s, _draw.GREY)   # deck
        offset = float(self._last_extra.get("compensator_offset", 0.0))
        c = float(np.clip(offset, -1.4 * s, 1.4 * s))
        canvas.line(1.6 * s, c, 1.9 * s, c, _draw.ACCENT, width=4.0)          # compensator

    def _picture(self, x: FloatArray) -> FloatArray:
        """The middle of the deck at heave ``x1`` (the grey strip :meth:`_draw` draws)."""
        return np.array([[0.0, float(x[0]) + 0.09 * self._sigma1]])

    def _measurement_picture(self, y: FloatArray) -> list[tuple[FloatArray, FloatArray | None]]:
        """The deck position the measurement reads (through the true sensor gain)."""
        deck = float(y[0]) / float(self._C[0, 0])
        return [(np.array([0.0, deck + 0.09 * self._sigma1]), None)]


def _non_negative(name: str, value: Any) -> float:
    val = float(value)
    if not np.isfinite(val) or val < 0:
        raise ValueError(f"{name} must be a non-negative finite number; got {value!r}")
    return val
