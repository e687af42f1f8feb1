"""Machinery shared by the paper plants: actions, noise, parameters, the model.

Each plant subclasses :class:`PlantEnv` and supplies its transition, its
measurement function, its reward, its physical domain and a drawing, and, for the
classical controllers, its design point (:meth:`PlantEnv.design_point`: the operating
point and the weights of its reward, a :class:`~fir_gym.envs.DesignPoint`). The base
class does what must be identical everywhere:

* **Actions.** The action space is ``Box(-1, 1, (n_u,), float32)``; the plant
  scales it to physical units. A NaN/inf, wrongly shaped or non-numeric action
  (a string, a boolean, a complex number, a date: :mod:`fir_gym.envs._inputs`)
  raises ``ValueError`` naming the action. An out-of-bounds action is *clipped* to
  ``[-1, 1]`` (what stable-baselines3 does before calling ``step``);
  ``info["action"]`` is the action applied (float64, after clipping) and
  ``info["action_clipped"]`` says whether it was clipped. A size-1 action may be
  a scalar. Filters must be fed ``info["action"]``: the model's ``u`` is the
  applied action.
* **Randomness.** Every draw (initial state, process and measurement noise)
  comes from ``self.np_random``, seeded by ``reset(seed=...)`` as Gymnasium
  prescribes.
* **True versus nominal parameters.** The constructor's physical parameters
  are the truth; ``nominal={"name": value, ...}`` lists the values the filter's
  :attr:`model` believes instead (keys must be parameter names). The
  parameters actually used are in :attr:`params` and :attr:`nominal_params`.
* **Observation and info.** The observation is the noisy measurement ``y[k]``
  in float64 (filters consume it at full precision); its bounds are ±inf
  because the measurement noise is Gaussian, so Gymnasium's checker warns that
  they are "probably too low/high" — the warning is expected.
  ``info["state"]`` is a fresh copy of the true state ``x[k]``.
* **Robustness conditions** (:mod:`fir_gym.envs._conditions`, docs/robustness.md):
  ``randomize={"name": spread}`` draws the named parameters' *true* values around the
  nominal ones at every ``reset`` (from a generator of the plant's own, seeded with the
  reset's seed, so the noise of ``np_random`` is the same with and without it), and
  ``burst=((k_first, k_last, δ), ...)`` stretches the state's increment by ``1 + δ`` over
  those transitions. ``info["true_params"]`` and ``info["burst"]`` report them (only when
  set). A plant names what it can randomize in :attr:`PlantEnv.randomizable` and rebuilds
  its true dynamics in :meth:`PlantEnv._apply_params` (values: floats, or one per system
  of a native vector env).
* **Reset options.** ``reset(options={"state": x0})`` starts from a given state.
* **Frames.** ``render()`` (``render_mode="rgb_array"``) draws the true state and
  remembers the frame's view, so that :meth:`~fir_gym.envs._overlay.EstimateDrawing.draw_estimate`
  can draw an estimate, its 2σ region and the measurement over it in the plant's own
  coordinates (:mod:`fir_gym.envs._overlay`; each plant's ``_picture`` says where a
  state puts its drawing).
  ``options`` must be ``None`` or a dict (``TypeError`` otherwise) with known keys;
  ``x0`` must be real numbers of shape ``(n_x,)``, finite, within ``±state_limit``
  and inside the plant's domain (the states its episodes run in: see "Episode End"
  in each plant's docstring) — a state where the episode would end at once is
  refused with a ``ValueError`` naming ``options['state']``, not accepted and
  terminated at the first step.
* **Nothing non-finite leaves a plant.** A step whose simulation fails — the new
  state is NaN or inf (``"nonfinite_state"``) or has a component beyond the plant's
  ``±state_limit`` (``"state_overflow"``; :data:`STATE_LIMIT` = 1e150, MuJoCo's 1e10
  for the MuJoCo plant), its measurement or reward is not finite
  (``"nonfinite_observation"``, ``"nonfinite_reward"``), or MuJoCo reset its
  simulation (``"mjWARN_BADQPOS"``, ``"mjWARN_BADQVEL"``, ``"mjWARN_BADQACC"``) —
  ends the episode (``terminated=True``) with ``info["simulation_failure"]`` naming
  the cause (:data:`SIMULATION_FAILURES`). The
  plant then stays at the last valid state (``info["state"]`` and :attr:`state`),
  the observation repeats the last one, the reward is the terminal penalty (below:
  a failed step is a termination like any other, so breaking the simulation never
  pays), and per-step extras that are not finite are left out of ``info``.
  ``render()`` of a state that is not valid (set by hand) draws the finite parts of
  the scene inside a red frame.
* **Rewards and episode end (honest tasks).** Every per-step reward is a *saturated
  cost*: ``-min(cost, cost_cap)`` (a non-finite cost counts as ``cost_cap``), so it
  is finite and never below ``-cost_cap``, the plant's documented worst rate. The
  step on which a plant terminates (it left its physical domain) is paid
  ``-cost_cap * (1 + steps left to max_episode_steps)``: the terminal step and every
  step the episode would still have run, at the worst rate. Ending an episode early
  therefore never improves its return. ``max_episode_steps`` (the penalty's horizon) is
  a constructor argument defaulting to the registered time limit
  (``default_max_episode_steps``), and it follows the ``TimeLimit`` Gymnasium applies:
  ``gym.make(id, max_episode_steps=N)``, shorter or longer than the default, gives the
  plant ``N`` (its entry point reads the limit ``gymnasium.make`` applies:
  :class:`fir_gym.wrappers.factory.PlantEntryPoint`), and so do ``gym.make(env.spec)``,
  the estimator options and ``gym.make_vec`` (whose native vector env gives its plant its
  own ``max_episode_steps``). With ``max_episode_steps=-1`` (no ``TimeLimit``) the
  plant keeps its own horizon (its keyword, else the default): no finite penalty covers
  an episode without an end, so a user who ends episodes by some other rule after ``M``
  steps sets ``env.unwrapped.max_episode_steps = M``, as does one who builds a plant
  without ``gym.make`` and wraps it in a ``TimeLimit`` by hand.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from fir_gym.estimators import StateSpaceModel
from fir_gym.estimators._validation import as_covariance, as_vector, positive

from ._conditions import (
    burst_delta,
    check_burst,
    check_randomize,
    condition_generator,
    draw_params,
    stretch,
)
from ._design import DesignPoint
from ._inputs import real_array, reset_options
from ._overlay import EstimateDrawing

FloatArray = NDArray[np.float64]

#: The default largest magnitude of a state component: beyond it a simulation has
#: overflowed. Below it squares of the state stay finite (1e300), and so do every
#: plant's measurement and (quadratic) reward.
STATE_LIMIT = 1e150

#: what ``info["simulation_failure"]`` may say (the step ends the episode)
SIMULATION_FAILURES: dict[str, str] = {
    "nonfinite_state": "the transition produced NaN or inf",
    "state_overflow": "a state component beyond the plant's ±state_limit",
    "nonfinite_observation": "the measurement of the new state is not finite",
    "nonfinite_reward": "the reward of the transition is not finite",
    "mjWARN_BADQPOS": "MuJoCo found a NaN or huge position and reset its simulation",
    "mjWARN_BADQVEL": "MuJoCo found a NaN or huge velocity and reset its simulation",
    "mjWARN_BADQACC": "MuJoCo found a NaN or huge acceleration and reset its simulation",
}

#: the keys ``reset(options=...)`` understands
RESET_OPTIONS = ("state",)


class PlantEnv(EstimateDrawing, gym.Env[FloatArray, NDArray[np.float32]]):
    """Base class of the paper plants; see the module docstring for the shared rules."""

    # (gymnasium declares ``metadata`` an instance attribute: not a ClassVar, hence RUF012)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}  # noqa: RUF012

    #: names of the state components, in order (set by each plant)
    state_names: ClassVar[tuple[str, ...]] = ()
    #: names of the measurement components
    measurement_names: ClassVar[tuple[str, ...]] = ()
    #: physical meaning and unit of the single action component (documentation)
    action_names: ClassVar[tuple[str, ...]] = ()
    #: the FIR window (measurements) a wrapper uses when the user gives none
    default_horizon: ClassVar[int] = 10
    #: the registered time limit (``gym.spec(id).max_episode_steps`` mirrors it)
    default_max_episode_steps: ClassVar[int] = 1000
    #: the worst per-step cost (the reward's floor is ``-cost_cap``; set by each plant)
    cost_cap: float = math.inf
    #: beyond this magnitude a state component means the simulation failed
    state_limit: ClassVar[float] = STATE_LIMIT
    #: the parameters ``randomize`` may name (the ``mismatch`` condition draws all of them);
    #: each must be one :meth:`_apply_params` rebuilds the true dynamics from
    randomizable: ClassVar[tuple[str, ...]] = ()

    def __init__(
        self,
        *,
        params: Mapping[str, Any],
        nominal: Mapping[str, Any] | None,
        default_nominal: Mapping[str, Any] | None,
        initial_state: ArrayLike,
        initial_state_cov: ArrayLike | None,
        measurement_cov: ArrayLike,
        render_mode: str | None,
        max_episode_steps: int | None = None,
        randomize: Mapping[str, float] | None = None,
        burst: Any = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}; "
                f"got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.max_episode_steps = (self.default_max_episode_steps if max_episode_steps is None
                                  else positive("max_episode_steps", max_episode_steps,
                                                    integer=True))
        self.params: dict[str, Any] = dict(params)
        overrides = dict(default_nominal or {})
        if nominal is not None:
            if not isinstance(nominal, Mapping):
                raise TypeError(f"nominal must be a mapping of parameter names to values; "
                                f"got {type(nominal).__name__}")
            unknown = sorted(set(nominal) - set(self.params))
            if unknown:
                raise ValueError(f"nominal has unknown parameter(s) {unknown}; "
                                 f"known parameters are {sorted(self.params)}")
            overrides.update(nominal)
        self.nominal_params: dict[str, Any] = {**self.params, **overrides}
        #: relative spread of each randomized parameter (empty: none)
        self.randomize: dict[str, float] = check_randomize(randomize, self.randomizable,
                                                           type(self).__name__)
        #: the burst windows ``(k_first, k_last, δ)`` (empty: none)
        self.burst = check_burst(burst)
        #: this episode's true parameters (:attr:`params` with the randomized ones drawn)
        self.true_params: dict[str, Any] = dict(self.params)
        self._condition_rng: np.random.Generator | None = None
        n_x = len(self.state_names)
        self.initial_state = as_vector("initial_state", initial_state, n_x)
        self.initial_state_cov = (np.zeros((n_x, n_x)) if initial_state_cov is None
                                  else as_covariance("initial_state_cov", initial_state_cov, n_x))
        self._initial_sqrt = psd_sqrt(self.initial_state_cov)
        n_y = len(self.measurement_names)
        #: the covariance of the true measurement noise (the plant's, not the model's)
        self.measurement_cov = as_covariance("measurement_cov", measurement_cov, n_y)
        self._measurement_sqrt = psd_sqrt(self.measurement_cov)

        n_u = len(self.action_names)
        # float32 actions (what stable-baselines3 produces); the plant computes in float64.
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_u,), dtype=np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n_y,), dtype=np.float64)
        self.state: FloatArray = self.initial_state.copy()
        self.time_step = 0
        self._last_obs = np.zeros(n_y)
        self._last_extra: dict[str, Any] = {}
        self._model: StateSpaceModel | None = None

    # ------------------------------------------------------------------ process noise
    def _set_process_noise(self, cov: ArrayLike) -> None:
        """The true plant's additive Gaussian process noise ``w ~ N(0, cov)`` (the square
        root :meth:`_add_process_noise` draws with)."""
        self._process_sqrt = psd_sqrt(np.asarray(cov, dtype=np.float64))
        self._has_process_noise = bool(np.any(self._process_sqrt))

    def _add_process_noise(self, x_next: FloatArray, rng: np.random.Generator) -> FloatArray:
        """``x_next + w``, ``w ~ N(0, cov)`` of :meth:`_set_process_noise`, one draw per
        system of a batch (nothing is drawn without process noise)."""
        if not self._has_process_noise:
            return x_next
        return x_next + rng.standard_normal(x_next.shape) @ self._process_sqrt.T

    # ------------------------------------------------------------------ to implement
    # Every hook works on one system (x of shape (n_x,)) or on a batch (B, n_x): the
    # single env and the native vector env (fir_gym.envs._vector) share them. ``k`` is
    # the time index of ``x`` (an int, or a (B,) array), ``rng`` the generator to draw
    # from; ``extra`` carries what a step computed that its measurement needs.
    def _transition(self, x: FloatArray, a: FloatArray, k: Any, rng: np.random.Generator
                    ) -> tuple[FloatArray, dict[str, Any]]:
        """True next state from ``x`` under the normalised action ``a`` (draws the noise)."""
        raise NotImplementedError

    def _noise_free_measurement(self, x: FloatArray, extra: dict[str, Any] | None) -> FloatArray:
        """The measurement without noise (``extra`` is None for the one ``reset`` returns)."""
        raise NotImplementedError

    def _reward(self, x: FloatArray, a: FloatArray, x_next: FloatArray) -> Any:
        """The reward of the transition (a float, or a (B,) array)."""
        raise NotImplementedError

    def _in_domain(self, x: FloatArray) -> Any:
        """Whether ``x`` is inside the plant's physical domain (per row for a batch)."""
        return np.all(np.isfinite(x), axis=-1)

    def _measure(self, x: FloatArray, extra: dict[str, Any] | None,
                 rng: np.random.Generator) -> FloatArray:
        """Noisy measurement ``y = h(x) + v``, ``v ~ N(0, measurement_cov)``."""
        sqrt = self._measurement_sqrt
        noise = rng.standard_normal(x.shape[:-1] + (sqrt.shape[1],))
        diag = getattr(self, "_sqrt_diagonal", None)
        if diag is None or diag[0] is not sqrt:
            diag = self._sqrt_diagonal = (sqrt, _diagonal_of(sqrt))
        if diag[1] is not None:       # noise @ sqrt.T of a diagonal sqrt, bit for bit
            return self._noise_free_measurement(x, extra) + noise * diag[1]
        return self._noise_free_measurement(x, extra) + noise @ sqrt.T

    def _sample_initial_state(self, rng: np.random.Generator, n: int | None = None) -> FloatArray:
        """``initial_state + N(0, initial_state_cov)`` draws: one, or ``n`` of them."""
        shape = (self._initial_sqrt.shape[1],) if n is None else (n, self._initial_sqrt.shape[1])
        return self.initial_state + rng.standard_normal(shape) @ self._initial_sqrt.T

    def _restore(self, x: FloatArray) -> None:
        """Put a simulator back at the valid state ``x`` after a failed step (MuJoCo's)."""

    def _build_model(self, params: Mapping[str, Any]) -> StateSpaceModel:
        raise NotImplementedError

    def _apply_params(self, params: Mapping[str, Any]) -> None:
        """Rebuild the true dynamics from ``params`` (every parameter of :attr:`params`; the
        :attr:`randomizable` ones floats, or ``(B,)`` arrays — one value per system — in a
        native vector env). Called after a ``randomize`` draw; a plant with randomizable
        parameters implements it."""
        if self.randomizable:
            raise NotImplementedError(f"{type(self).__name__} lists randomizable parameters "
                                      "but does not implement _apply_params")

    def _perturb(self, x: FloatArray, x_next: FloatArray, extra: dict[str, Any], delta: Any
                 ) -> tuple[FloatArray, dict[str, Any]]:
        """The burst (:mod:`._conditions`): the step's increment stretched by ``1 + δ``
        (``δ`` a float, or one per row of a batch, 0 for rows outside the window). A plant
        whose measurement or simulator depends on the path overrides it."""
        return stretch(x, x_next, delta), extra

    def _draw(self, canvas: Any) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ model
    @property
    def model(self) -> StateSpaceModel:
        """The filter's belief about this plant, built from :attr:`nominal_params`."""
        if self._model is None:
            self._model = self._build_model(self.nominal_params)
        return self._model

    def make_model(self, **overrides: Any) -> StateSpaceModel:
        """A model built from the nominal parameters with some replaced.

        ``env.make_model(**env.params)`` is the model that matches the truth.
        """
        unknown = sorted(set(overrides) - set(self.params))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known parameters are "
                             f"{sorted(self.params)}")
        return self._build_model({**self.nominal_params, **overrides})

    @classmethod
    def check_vector_options(cls, options: dict[str, Any]) -> None:
        """Refuse, before anything is built, an option the plant's native vector env cannot
        honour (``options``: the keywords of ``gym.make_vec(id, n, vectorization_mode=
        "vector_entry_point", ...)``). The default refuses nothing."""

    def design_point(self) -> DesignPoint:
        """The plant's operating point, reward weights and PID tuning (a fresh record).

        What the classical controllers (:class:`~fir_gym.controllers.LQGController`,
        :class:`~fir_gym.controllers.PIDController`) design on: the LQR of
        :attr:`model` linearised at ``(x, u)`` with the weights ``M`` of the reward.
        Computed from :attr:`nominal_params`, never the truth. The base class knows
        neither a plant's operating point nor how its reward weighs the state, so a
        plant that supports the LQG baseline overrides this (each paper plant does, in
        its own file); the others raise ``NotImplementedError`` naming the plant.
        """
        name = type(self).__name__
        raise NotImplementedError(
            f"{name} publishes no design point, so the classical controllers (LQG, PID) "
            f"cannot be designed for it: implement {name}.design_point(self) -> "
            "fir_gym.envs.DesignPoint (its operating point x, u, a fixed point of the "
            "nominal model, and the quadratic weights M of its reward; "
            "docs/architecture.md#design-point)")

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[FloatArray, dict[str, Any]]:
        given = reset_options(options, RESET_OPTIONS)
        state = self._check_state("options['state']", given["state"]) \
            if "state" in given else None
        super().reset(seed=seed)
        if self.randomize:
            if seed is not None or self._condition_rng is None:
                self._condition_rng = condition_generator(seed)
            self.true_params = {**self.params, **draw_params(
                self._condition_rng, self.nominal_params, self.randomize)}
            self._apply_params(self.true_params)
        self.state = self._sample_initial_state(self.np_random) if state is None else state
        self.time_step = 0
        self._last_extra = {}
        self._last_obs = self._measure(self.state, None, self.np_random)
        return self._last_obs.copy(), self._condition_info({"state": self.state.copy()}, 0.0)

    def step(
        self, action: ArrayLike
    ) -> tuple[FloatArray, float, bool, bool, dict[str, Any]]:
        a, clipped = self._check_action(action)
        x = self.state
        x_next, extra = self._transition(x, a, self.time_step, self.np_random)
        delta = 0.0
        if self.burst:
            delta = burst_delta(self.burst, self.time_step)
            if delta:
                x_next, extra = self._perturb(x, x_next, extra, delta)
        self.time_step += 1
        failure = extra.get("simulation_failure") or state_failure(x_next, self.state_limit)
        if failure is None:
            terminated = not bool(self._in_domain(x_next))
            reward = (float(self._reward(x, a, x_next)) if not terminated
                      else float(self._terminal_reward(self.time_step)))
            obs = self._measure(x_next, extra, self.np_random)
            # a finite sum means every entry is finite (the exact test only when it is not)
            if not math.isfinite(reward + sum(obs.tolist())):
                failure = ("nonfinite_reward" if not math.isfinite(reward) else
                           None if np.isfinite(obs).all() else "nonfinite_observation")
        if failure is not None:
            return self._failed_step(x, a, clipped, extra, failure, delta)
        self.state = x_next
        self._last_extra = extra
        self._last_obs = obs
        # ``a`` is a fresh array made by _check_action: no copy needed for info
        info: dict[str, Any] = {"state": x_next.copy(), "action": a,
                                "action_clipped": clipped, **extra}
        if self.randomize or self.burst:
            info = self._condition_info(info, delta)
        return obs, reward, terminated, False, info

    def _failed_step(self, x: FloatArray, a: FloatArray, clipped: bool,
                     extra: dict[str, Any], failure: str, delta: float = 0.0
                     ) -> tuple[FloatArray, float, bool, bool, dict[str, Any]]:
        """End the episode at the last valid state ``x``: the transition failed.

        The plant stays at ``x``, the observation repeats the last one and the reward
        is the terminal penalty (a termination like any other: failing never pays).
        """
        self._restore(x)
        reward = float(self._terminal_reward(self.time_step))
        info: dict[str, Any] = {"state": x.copy(), "action": a, "action_clipped": clipped}
        info.update((key, value) for key, value in extra.items() if _all_finite(value))
        info["simulation_failure"] = failure
        return self._last_obs.copy(), reward, True, False, self._condition_info(info, delta)

    def _condition_info(self, info: dict[str, Any], delta: float) -> dict[str, Any]:
        """``info`` with the conditions' entries: ``true_params`` (the randomized parameters'
        values this episode) and ``burst`` (this step's ``δ``), each only when set."""
        if self.randomize:
            info["true_params"] = {name: self.true_params[name] for name in self.randomize}
        if self.burst:
            info["burst"] = delta
        return info

    def render_state(self, state: FloatArray, time_step: int) -> NDArray[np.uint8] | None:
        """:meth:`render` of the plant at ``state`` and ``time_step`` (without the last step's
        extras), the plant's own state, step and extras left as they were — how a native
        vector env draws each sub-env with one plant."""
        kept = self.state, self.time_step, self._last_extra
        try:
            self.state, self.time_step, self._last_extra = state, time_step, {}
            return self.render()
        finally:
            self.state, self.time_step, self._last_extra = kept

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' to "
                f"gym.make('{self.spec.id if self.spec else type(self).__name__}')."
            )
            return None
        from ._draw import ACCENT, Canvas

        canvas = Canvas(400, 300)
        with np.errstate(all="ignore"):            # a broken state's shapes are skipped
            self._draw(canvas)
        if state_failure(np.asarray(self.state, dtype=np.float64),
                         self.state_limit) is not None:
            canvas.frame(ACCENT)                    # a broken state: say so in the picture
        self._frame_view = self._plane_view(canvas)
        return canvas.image

    # ------------------------------------------------------------------ helpers
    def _terminal_reward(self, steps_taken: Any) -> Any:
        """The reward of a terminating step, after ``steps_taken`` steps (int or array):
        ``-cost_cap`` for it and for each step left to :attr:`max_episode_steps`."""
        left = np.maximum(self.max_episode_steps - np.asarray(steps_taken), 0)
        return -self.cost_cap * (1.0 + left)

    def _check_state(self, name: str, value: Any) -> FloatArray:
        """``value`` as a state of this plant: ``n_x`` real numbers, valid, in the domain."""
        names = self.state_names
        x = real_array(name, value, f"{len(names)} real numbers (the state {list(names)})")
        x = x.copy() if x is value else x                 # the plant keeps it
        if x.shape != (len(names),):
            raise ValueError(f"{name} must have shape ({len(names)},) (the state "
                             f"{list(names)}); got shape {x.shape}")
        if state_failure(x, self.state_limit) is not None:
            raise ValueError(f"{name} must be finite and within ±{self.state_limit:g}; got {x}")
        if not bool(self._in_domain(x)):
            raise ValueError(f"{name} = {x} is outside the domain of {type(self).__name__}, "
                             "where its episodes run (see 'Episode End' in its docstring): "
                             "the episode would end at once")
        return x

    def _check_action(self, action: ArrayLike) -> tuple[FloatArray, bool]:
        shape = self.action_space.shape or ()
        if shape == (1,) and type(action) is np.ndarray and action.shape == shape \
                and action.dtype.kind == "f":
            # the common case, in floats: same checks, same result as below
            v = action.item()
            if not math.isfinite(v):
                raise ValueError(f"action must be finite; got {action.astype(np.float64)}")
            c = -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)
            return np.array((c,)), c != v
        a = real_array("action", action,
                       lambda: f"{shape[0]} real number(s) in [-1, 1] (shape {shape})")
        if a.shape != shape:
            if a.size == 1 and shape == (1,) and a.ndim <= 1:
                a = a.reshape(1)
            else:
                raise ValueError(f"action must have shape {shape}; got shape {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action must be finite; got {a}")
        clipped = a.clip(-1.0, 1.0)
        return clipped, bool((clipped != a).any())


def saturated_cost(cost: Any, cap: float) -> Any:
    """``min(cost, cap)`` elementwise, with a NaN cost counted as ``cap`` (float or array):
    the per-step cost of every plant's reward, bounded by its worst rate."""
    if isinstance(cost, float):
        return cost if cost < cap else cap
    return np.where(cost < cap, cost, cap)


def state_failure(x: FloatArray, limit: float) -> str | None:
    """Why the single state ``x`` is not a valid one (see :data:`SIMULATION_FAILURES`),
    or ``None``: valid states are finite and within ``±limit``."""
    xs = x.tolist()
    # NaN fails the sum; the bounds hold for every entry when they hold for min and max
    if -limit <= min(xs) and max(xs) <= limit and math.isfinite(sum(xs)):
        return None
    return "nonfinite_state" if not np.isfinite(x).all() else "state_overflow"


def valid_states(X: FloatArray, limit: float) -> NDArray[np.bool_]:
    """Per row of a batch ``(B, n_x)``: whether the state is valid (:func:`state_failure`)."""
    return np.all(np.abs(X) <= limit, axis=-1)            # NaN compares False


def _all_finite(value: Any) -> bool:
    """Whether a per-step extra holds only finite numbers (non-numeric extras pass)."""
    try:
        return bool(np.all(np.isfinite(value)))
    except TypeError:
        return True


def _diagonal_of(M: FloatArray) -> FloatArray | None:
    """The diagonal of a square diagonal ``M``, else None.

    For diagonal ``M``, ``v @ M.T`` is ``v * diag(M)`` exactly: each sum has one
    non-zero product, and adding exact zeros changes nothing (in any order, with or
    without fused multiply-adds).
    """
    if M.ndim != 2 or M.shape[0] != M.shape[1] or np.count_nonzero(M - np.diag(np.diag(M))):
        return None
    return np.diag(M).copy()


def psd_sqrt(M: FloatArray) -> FloatArray:
    """A square root ``L`` with ``L Lᵀ = M`` for a symmetric PSD (possibly singular) ``M``."""
    w, V = np.linalg.eigh(M)
    return V * np.sqrt(np.clip(w, 0.0, None))


class FirstStateMeasured:
    """Dynamics whose measurement is the first state component: ``h(x) = x1``.

    Orbit-v0, UncertainOscillator-v0 and VanDerPol-v0 measure ``x1``; their dynamics
    classes inherit ``h`` and its Jacobian ``H = [1, 0, ...]`` (batched) from here.
    """

    n_x: ClassVar[int] = 2

    @staticmethod
    def h(x: FloatArray) -> FloatArray:
        return x[..., :1].copy()

    @classmethod
    def H(cls, x: FloatArray) -> FloatArray:
        # a fresh array filled in place: broadcasting a constant row and copying it cost
        # six times as much, a tenth of a 64-system EKF step's Python side
        J = np.zeros(x.shape[:-1] + (1, cls.n_x))
        J[..., 0, 0] = 1.0
        return J
