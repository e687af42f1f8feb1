"""A plant built from a model: the user's own system as a fir-gym environment.

:class:`ModelPlant` turns a :class:`~fir_gym.estimators.StateSpaceModel` or a
:class:`~fir_gym.estimators.ContinuousModel` (or a function building one from named
parameters) plus a quadratic cost, a domain, an initial-state distribution and an
operating point into a :class:`~fir_gym.envs._base.PlantEnv`. Everything the base class
does generically comes with it: estimators in the loop (``gym.make(id, estimator="ekf")``),
the native vector env, :func:`fir_gym.training.make_sb3_vec_env`, the LQG baseline (its
:meth:`ModelPlant.design_point`), the ``nominal`` / ``randomize`` / ``burst`` conditions,
the honest saturated reward, copies, seeding and a generic ``rgb_array`` frame.
docs/tutorials/your-own-plant.md is the walk-through; :func:`fir_gym.register_plant`
registers one under the user's own id.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from fir_gym.estimators import ContinuousModel, StateSpaceModel
from fir_gym.estimators._validation import FloatArray, as_covariance, as_vector, positive

from . import _draw
from ._base import PlantEnv, saturated_cost
from ._design import DesignPoint

Model = StateSpaceModel | ContinuousModel
#: corners of the domain box enumerated for the default ``cost_cap`` (2**n_x of them)
MAX_CORNER_STATES = 16


class ScaledInput:
    """``fn(x, u * scale)``: a model callable fed the normalised action (picklable)."""

    def __init__(self, fn: Callable[..., Any], scale: FloatArray) -> None:
        self.fn, self.scale = fn, scale

    def __call__(self, x: FloatArray, u: FloatArray) -> Any:
        return self.fn(x, np.asarray(u, dtype=np.float64) * self.scale)


def _scaled(model: Model, scale: FloatArray | None) -> Model:
    """``model`` taking the action in ``[-1, 1]`` (physical input ``u * scale``)."""
    if scale is None:
        return model
    if isinstance(model, ContinuousModel):
        return ContinuousModel(
            a=ScaledInput(model.a, scale), J=ScaledInput(model.J, scale), h=model.h, H=model.H,
            A_of_x=model.A_of_x if model.has_factorisation else None, Q=model.Q, R=model.R,
            G=model.G, dt=model.dt, n_u=model.n_u, name=model.name)
    return StateSpaceModel(f=ScaledInput(model.f, scale), F=ScaledInput(model.F, scale),
                           h=model.h, H=model.H, Q=model.Q, R=model.R, G=model.G, dt=model.dt,
                           n_u=model.n_u, name=model.name)


class ModelPlant(PlantEnv):
    """
    ## Description

    The system of a user's model, simulated as the model says: a
    :class:`~fir_gym.estimators.StateSpaceModel` steps ``x[k+1] = f(x[k], a[k]) + G w[k]``,
    ``w ~ N(0, Q)``, and measures ``y = h(x) + v``, ``v ~ N(0, R)``; a
    :class:`~fir_gym.estimators.ContinuousModel` is simulated through its sampled view
    (:meth:`~fir_gym.estimators.ContinuousModel.sampled`: RK4 over ``dt`` with the input
    held, the integrated process noise, the measurement ``h(x[k]) + N(0, R/dt)``), and
    publishes itself as :attr:`continuous_model` for the continuous filters. The filters'
    :attr:`model` is the same model built from the *nominal* parameters.

    ## Arguments

    * ``model`` — the model, or a function ``model(**params) -> model`` with ``params``
      its named parameters (then ``nominal={...}`` gives the filter different values
      from the truth's, and ``randomize={...}`` draws the truth's around them every
      episode). The model's ``u`` is the physical input ``a * action_scale``.
    * ``action_scale`` — ``(n_u,)`` (or a number): the action space is always
      ``Box(-1, 1)``; the plant and the published :attr:`model` apply ``u = a * scale``
      (default 1: the model takes the action as it is).
    * ``operating_point``, ``operating_input`` — ``x*`` and ``a*`` (the latter in action
      units, ``[-1, 1]``), a fixed point of the nominal model (checked). The cost and
      the LQG baseline are centred there (default: zeros).
    * ``state_weight``, ``action_weight`` — the cost
      ``(x[k+1] − x*)ᵀ W_x (x[k+1] − x*) + (a − a*)ᵀ W_u (a − a*)`` (defaults: ``I`` and
      ``0.01 I``); or ``cost(x, a, x_next) -> cost`` (batched over a leading axis), in
      which case the LQG designs on the weights only when they are given too.
    * ``cost_cap`` — the worst per-step cost. Default: the quadratic cost's maximum over
      the domain box and the action box (their corners), which needs finite
      ``state_bounds`` for every weighted state.
    * ``state_bounds`` — ``(low, high)`` (±inf allowed) and/or ``domain(x) -> bool``
      (batched): the states the episode runs in.
    * ``initial_state``, ``initial_state_cov`` — the start's mean (default ``x*``) and
      covariance (default 0).
    * ``process_cov``, ``measurement_cov`` — the truth's ``G Q Gᵀ`` and ``R`` when they
      differ from the model's (default: the true model's).
    * ``substeps`` — RK4 steps per ``dt`` of a continuous model (default 10).
    * ``state_names``, ``measurement_names``, ``action_names``, ``state_scale`` — labels
      and the half-width of each state's gauge in the frame.
    * ``max_episode_steps``, ``nominal``, ``randomize``, ``burst``, ``render_mode`` —
      as for every plant (docs/robustness.md).

    ## Rewards

    ``-min(cost, cost_cap)``; leaving the domain pays ``-cost_cap`` for the step and for
    every step left to ``max_episode_steps``, so ending early never pays.

    ## Episode End

    Termination when the state leaves ``state_bounds`` (strictly inside) or ``domain``;
    truncation at ``max_episode_steps`` by the registered ``TimeLimit``.

    ## Frames

    ``render()`` draws one gauge per state: the truth's position between
    ``centre ± state_scale`` (``state_bounds`` where finite); an estimator wrapper draws
    the estimate and its ±2σ bar on the same gauges.
    """

    default_max_episode_steps: ClassVar[int] = 1000

    def __init__(
        self,
        *,
        model: Model | Callable[..., Model],
        params: Mapping[str, Any] | None = None,
        action_scale: ArrayLike | None = None,
        operating_point: ArrayLike | None = None,
        operating_input: ArrayLike | None = None,
        state_weight: ArrayLike | None = None,
        action_weight: ArrayLike | None = None,
        cost: Callable[[FloatArray, FloatArray, FloatArray], Any] | None = None,
        cost_cap: float | None = None,
        state_bounds: tuple[ArrayLike, ArrayLike] | None = None,
        domain: Callable[[FloatArray], Any] | None = None,
        initial_state: ArrayLike | None = None,
        initial_state_cov: ArrayLike | None = None,
        process_cov: ArrayLike | None = None,
        measurement_cov: ArrayLike | None = None,
        substeps: int = 10,
        state_names: Sequence[str] | None = None,
        measurement_names: Sequence[str] | None = None,
        action_names: Sequence[str] | None = None,
        state_scale: ArrayLike | None = None,
        max_episode_steps: int | None = None,
        nominal: Mapping[str, Any] | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(model, (StateSpaceModel, ContinuousModel)):
            if params:
                raise ValueError("params name the arguments of a model-building function; "
                                 "model is a model already")
            self._given: Model | None = model
            self._builder: Callable[..., Model] | None = None
        elif callable(model):
            self._given, self._builder = None, model
        else:
            raise TypeError("model must be a StateSpaceModel, a ContinuousModel or a function "
                            f"building one from params; got {type(model).__name__}")
        self.substeps = positive("substeps", substeps, integer=True)
        params = dict(params or {})
        raw = self._raw(params)
        n_x, n_y, n_u = raw.n_x, raw.n_y, raw.n_u
        if n_u < 1:
            raise ValueError("the model has no input (n_u = 0); a plant needs an action")
        self.action_scale = None if action_scale is None else as_vector(
            "action_scale", np.broadcast_to(np.asarray(action_scale, dtype=np.float64),
                                            (n_u,)), n_u)
        self.x_op = np.zeros(n_x) if operating_point is None else \
            as_vector("operating_point", operating_point, n_x)
        self.u_op = np.zeros(n_u) if operating_input is None else \
            as_vector("operating_input", operating_input, n_u)
        # state_names & co. are class attributes of the paper plants; here, the instance's
        self.__dict__.update(
            state_names=_names(state_names, "x", n_x, "state_names"),
            measurement_names=_names(measurement_names, "y", n_y, "measurement_names"),
            action_names=_names(action_names, "u", n_u, "action_names"),
            randomizable=tuple(name for name, value in params.items()
                               if isinstance(value, (int, float, np.integer, np.floating))
                               and not isinstance(value, bool)))
        self.cost = cost
        self.weights_given = cost is None or state_weight is not None or \
            action_weight is not None
        self.state_weight = as_covariance(
            "state_weight", np.eye(n_x) if state_weight is None else state_weight, n_x)
        self.action_weight = as_covariance(
            "action_weight", 0.01 * np.eye(n_u) if action_weight is None else action_weight,
            n_u)
        lo, hi = (np.full(n_x, -np.inf), np.full(n_x, np.inf)) if state_bounds is None else (
            _bound("state_bounds[0]", state_bounds[0], n_x),
            _bound("state_bounds[1]", state_bounds[1], n_x))
        if not np.all(lo < hi):
            raise ValueError(f"state_bounds must have low < high; got {lo}, {hi}")
        self.state_low, self.state_high, self.domain = lo, hi, domain
        self.cost_cap = self._default_cap() if cost_cap is None else positive("cost_cap",
                                                                             cost_cap)
        scale = None if state_scale is None else as_vector(
            "state_scale", np.broadcast_to(np.asarray(state_scale, dtype=np.float64), (n_x,)),
            n_x)
        self._process_override = None if process_cov is None else as_covariance(
            "process_cov", process_cov, n_x)
        true_model = self._discrete(raw)
        super().__init__(params=params, nominal=nominal, default_nominal=None,
                         initial_state=self.x_op if initial_state is None else initial_state,
                         initial_state_cov=initial_state_cov,
                         measurement_cov=true_model.R if measurement_cov is None
                         else measurement_cov,
                         render_mode=render_mode, max_episode_steps=max_episode_steps,
                         randomize=randomize, burst=burst)
        self._gauge(scale)
        self._set_truth(true_model)
        if operating_point is not None or operating_input is not None:
            self._check_fixed_point()

    # ------------------------------------------------------------------ the model
    def _raw(self, params: Mapping[str, Any]) -> Model:
        if self._builder is None:
            assert self._given is not None
            return self._given
        built = self._builder(**params)
        if not isinstance(built, (StateSpaceModel, ContinuousModel)):
            raise TypeError(f"model(**params) must return a StateSpaceModel or a "
                            f"ContinuousModel; got {type(built).__name__}")
        return built

    def _discrete(self, raw: Model) -> StateSpaceModel:
        scaled = _scaled(raw, self.action_scale)
        if isinstance(scaled, ContinuousModel):
            return scaled.sampled(self.substeps, at=self.x_op)
        return scaled

    def _build_model(self, params: Mapping[str, Any]) -> StateSpaceModel:
        return self._discrete(self._raw(params))

    @property
    def continuous_model(self) -> ContinuousModel:
        """The nominal continuous-time model (a plant built from a ``ContinuousModel``)."""
        raw = _scaled(self._raw(self.nominal_params), self.action_scale)
        if not isinstance(raw, ContinuousModel):
            raise AttributeError("this ModelPlant was built from a discrete-time model and "
                                 "has no continuous_model")
        return raw

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        if any(np.ndim(params[name]) for name in self.randomizable):
            raise NotImplementedError(
                "ModelPlant builds one model per parameter set, so its native vector env "
                "cannot randomize parameters per sub-env; use single envs (e.g. "
                "make_sb3_vec_env(..., vec_env='dummy')) with randomize")
        self._set_truth(self._build_model(params))

    def _set_truth(self, true_model: StateSpaceModel) -> None:
        self._true = true_model
        self._set_process_noise(true_model.GQGT if self._process_override is None
                                else self._process_override)

    def _check_fixed_point(self) -> None:
        drift = self.model.f(self.x_op, self.u_op) - self.x_op
        if not np.all(np.abs(drift) <= 1e-8 * (1.0 + np.abs(self.x_op))):
            raise ValueError(f"operating_point {self.x_op} with operating_input {self.u_op} is "
                             f"not a fixed point of the nominal model: f(x*, a*) - x* = {drift}")

    def _default_cap(self) -> float:
        """The quadratic cost's maximum over the domain box and the action box."""
        weighted = np.flatnonzero(np.diag(self.state_weight))
        lo, hi = self.state_low[weighted], self.state_high[weighted]
        if self.cost is not None or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) \
                or weighted.size > MAX_CORNER_STATES:
            raise ValueError("give cost_cap (the worst per-step cost): it has a default only "
                             "for the quadratic cost with finite state_bounds on every "
                             "weighted state")
        W = self.state_weight[np.ix_(weighted, weighted)]
        x_op = self.x_op[weighted]
        worst_x = max(float(e @ W @ e) for e in
                      (np.array(c) - x_op for c in itertools.product(*zip(lo, hi, strict=True))))
        worst_u = max(float(e @ self.action_weight @ e) for e in
                      (np.array(c) - self.u_op
                       for c in itertools.product((-1.0, 1.0), repeat=len(self.u_op))))
        return worst_x + worst_u

    def design_point(self) -> DesignPoint:
        """The declared operating point ``(x*, a*)`` and the cost's weights.

        The LQG baseline is the LQR of :attr:`model` linearised there, with
        ``M = diag(W_x, W_u)``: the reward's own quadratic cost. A plant with a ``cost``
        function and no weights has no design point.
        """
        if not self.weights_given:
            raise NotImplementedError(
                "this ModelPlant's reward is a cost function without quadratic weights: give "
                "state_weight and action_weight (the design's M) for the LQG baseline")
        self._check_fixed_point()
        n_x, n_u = self.x_op.size, self.u_op.size
        M = np.zeros((n_x + n_u, n_x + n_u))
        M[:n_x, :n_x], M[n_x:, n_x:] = self.state_weight, self.action_weight
        return DesignPoint(x=self.x_op.copy(), u=self.u_op.copy(), M=M,
                           states=tuple(range(n_x)), note="the declared operating point")

    # ------------------------------------------------------------------ the hooks
    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        return self._add_process_noise(self._true.f(x, a), rng), {}

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        return self._true.h(x)

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        if self.cost is not None:
            c = self.cost(x, a, x_next)
            c = float(c) if np.ndim(c) == 0 else np.asarray(c, dtype=np.float64)
        else:
            e, d = x_next - self.x_op, a - self.u_op
            c = np.einsum("...i,ij,...j->...", e, self.state_weight, e) + \
                np.einsum("...i,ij,...j->...", d, self.action_weight, d)
            c = float(c) if np.ndim(c) == 0 else c
        return -saturated_cost(c, self.cost_cap)

    def _in_domain(self, x: FloatArray) -> Any:
        inside = np.isfinite(x).all(axis=-1) & np.all(
            (self.state_low < x) & (x < self.state_high), axis=-1)
        if self.domain is not None:
            with np.errstate(all="ignore"):
                inside = inside & np.asarray(self.domain(x), dtype=bool)
        return inside

    # ------------------------------------------------------------------ the frame
    def _gauge(self, scale: FloatArray | None) -> None:
        """Each state's gauge: its centre and half-width in the frame."""
        finite = np.isfinite(self.state_low) & np.isfinite(self.state_high)
        centre = np.where(finite, 0.5 * (self.state_low + self.state_high), self.x_op)
        if scale is None:
            spread = 3.0 * np.sqrt(np.diag(self.initial_state_cov)) + np.abs(
                self.initial_state - self.x_op)
            scale = np.where(finite, 0.5 * (self.state_high - self.state_low),
                             np.maximum(spread, 1.0))
        self._gauge_centre, self._gauge_scale = centre, np.asarray(scale, dtype=np.float64)

    def _picture(self, x: FloatArray) -> FloatArray:
        """State ``i`` on gauge ``i``: ``((x_i − centre_i) / scale_i, −i)``."""
        x = np.asarray(x, dtype=np.float64)
        lanes = -np.arange(x.shape[-1], dtype=np.float64)
        return np.stack([(x - self._gauge_centre) / self._gauge_scale, lanes], axis=-1)

    def _draw(self, canvas: _draw.Canvas) -> None:
        n = len(self.state_names)
        canvas.set_view((-1.6, 1.4), (-n + 0.4, 0.9))
        op = (self.x_op - self._gauge_centre) / self._gauge_scale
        for i, name in enumerate(self.state_names):
            canvas.line(-1.0, -i, 1.0, -i, _draw.GREY, width=1.0)
            for end in (-1.0, 1.0):
                canvas.line(end, -i - 0.12, end, -i + 0.12, _draw.GREY, width=1.0)
            if math.isfinite(op[i]):
                canvas.line(op[i], -i - 0.2, op[i], -i + 0.2, _draw.GREEN, width=1.5)
            column, row = canvas.to_pixels(-1.55, -i + 0.1)
            canvas.text(column, row - 9, name[:8], _draw.INK)
        points = self._picture(np.asarray(self.state, dtype=np.float64))
        for px, py in points.tolist():
            if math.isfinite(px):
                canvas.circle(min(max(px, -1.3), 1.3), py, 0.06, self.truth_color)


def _names(names: Sequence[str] | None, prefix: str, n: int, what: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{i}" for i in range(n))
    out = tuple(str(name) for name in names)
    if len(out) != n:
        raise ValueError(f"{what} must name {n} components; got {len(out)}")
    return out


def _bound(name: str, value: ArrayLike, n: int) -> FloatArray:
    b = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
    if np.isnan(b).any():
        raise ValueError(f"{name} must not be NaN; got {b}")
    return b
