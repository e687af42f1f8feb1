"""What every plant of :mod:`fir_gym.jax` shares with the numpy plants it mirrors."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnax.environments.environment as gymnax_env
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from gymnax.environments import spaces

from ._x64 import require_x64
from .filter_model import FilterModel
from .filters import GENERIC_FILTERS, FilterKind
from .kalman import Belief, WatchLimits, ekf_predict, kf_update, watch
from .measurement_stack import stack_observation, stack_push, stack_start

#: the numpy plants' ``STATE_LIMIT`` (:data:`fir_gym.envs._base.STATE_LIMIT`; PendulumSlider-v0
#: has its own)
STATE_LIMIT = 1e150
#: what an estimator kind observes (``OBSERVATION_KINDS`` of
#: :mod:`fir_gym.wrappers.estimator_observation`)
OBSERVATIONS = ("estimate", "estimate+covariance", "estimate+measurement")
#: ``info["simulation_failure"]`` codes (0: none), the numpy plants' names in this order
SIMULATION_FAILURES = ("nonfinite_state", "state_overflow", "nonfinite_observation",
                       "nonfinite_reward")
#: the prior floor of :mod:`fir_gym.wrappers.estimator_observation` (``PRIOR_FLOOR``)
PRIOR_FLOOR = 1e-9


def psd_sqrt(M: jax.Array) -> jax.Array:
    """``V Λ₊^½`` with ``M = V Λ Vᵀ`` (:func:`fir_gym.jax.small_linalg.eigh`, no LAPACK):
    :func:`fir_gym.envs._base.psd_sqrt`, the square root that turns standard normals into a
    plant's noise increments — to round-off, not to the bit (the eigenvectors' signs and
    the rounding differ from LAPACK's; the params builders use the numpy one)."""
    from .small_linalg import eigh

    w, V = eigh(jnp.asarray(M))
    return V * jnp.sqrt(jnp.clip(w, 0.0, None))


def sqrt_of(given: Any, M: Any) -> jax.Array:
    """A noise covariance's square root: the one the params carry — their builder computed it
    host-side with the numpy plant's :func:`fir_gym.envs._base.psd_sqrt`, the same bits —
    else (params made by hand without it) :func:`psd_sqrt` of ``M`` in the trace. The
    builders precompute it because an ``eigh`` in every step is a LAPACK call, which can
    deadlock a batched program on a small CPU (docs/jax.md, "A hang, found and avoided")."""
    return psd_sqrt(jnp.asarray(M)) if given is None else given


def numpy_sqrt(M: Any) -> jax.Array:
    """:func:`fir_gym.envs._base.psd_sqrt` of ``M`` (host-side, for a params builder)."""
    from fir_gym.envs._base import psd_sqrt as plant_psd_sqrt

    return jnp.asarray(plant_psd_sqrt(np.asarray(M, dtype=np.float64)))


def filter_prior(params: Any) -> tuple[jax.Array, jax.Array]:
    """The filter's prior: the plant's initial-state mean and covariance, floored
    (:func:`fir_gym.wrappers.estimator_observation.prior_of`)."""
    x0 = jnp.asarray(params.initial_state, dtype=jnp.float64)
    return x0, jnp.asarray(params.initial_state_cov) + PRIOR_FLOOR * jnp.diag(
        jnp.maximum(1.0, x0 ** 2))


def belief_of(state: Any) -> Belief:
    """The filter's record held in an env state's ``filter_x``, ``filter_P``, ``nis``,
    ``nis_run`` and ``diverged``."""
    return Belief(state.filter_x, state.filter_P, state.nis, state.nis_run, state.diverged)


def with_belief(state: Any, b: Belief) -> Any:
    """``state`` with its filter fields replaced by the record ``b``."""
    return state.replace(filter_x=b.x, filter_P=b.P, nis=b.nis, nis_run=b.nis_run,
                         diverged=b.diverged)


def watch_limits_of(params: Any) -> WatchLimits:
    """The divergence watch's limits held in a plant's params: their ``watch`` record, or
    their ``max_covariance_trace``, ``nis_threshold`` and ``nis_patience`` fields."""
    if isinstance(getattr(params, "watch", None), WatchLimits):
        return params.watch
    return WatchLimits(params.max_covariance_trace, params.nis_threshold, params.nis_patience)


def watch_state(state: Any, x: jax.Array, P: jax.Array, nis: jax.Array,
                limits: WatchLimits, usable: jax.Array | bool = True) -> Any:
    """:meth:`fir_gym.estimators.base.Estimator._accept` (:func:`fir_gym.jax.kalman.watch`)
    on the filter record of an env state: the state afterwards (``usable``: whether the step
    had a measurement)."""
    return with_belief(state, watch(belief_of(state), x, P, nis, limits, usable))


class FilteredPlant(gymnax_env.Environment[Any, Any]):
    """What the plants of :mod:`fir_gym.jax` share: an observation ``kind`` among
    :attr:`kinds` — ``"true"``, ``"measurement"``, ``"measurement-stack"`` (the last
    ``horizon`` measurements and actions, :mod:`fir_gym.jax.measurement_stack`) and the
    filters: the plant's own (:attr:`estimator`, the default: ``"ekf"``, or ``"kf"`` on a
    linear plant; the plant runs it inside its step) and the generic ones of
    :mod:`fir_gym.jax.filters` (run here on :meth:`filter_model`) —, a filter kind's
    ``observation`` (:data:`OBSERVATIONS`), the views of the state (:meth:`get_obs`:
    ``estimate+covariance`` gives the upper triangle of ``P`` row by row) and the spaces;
    one action in ``[-1, 1]``.

    The sensor's faults (static; none by default) are those of
    :class:`~fir_gym.wrappers.SensorFaults` the JAX sensor has, checked by its own
    :func:`~fir_gym.wrappers.faulty_sensor.check_faults` and applied in its order
    (:meth:`sensor_reading`): ``bias=(k_bias, value)`` adds ``value`` to every reading from
    step ``k_bias`` on; ``outliers=(p, scale)`` adds ``scale · L z`` (``z ~ N(0, I)``, ``L Lᵀ``
    the plant's measurement noise covariance: :meth:`measurement_noise_sqrt`) with
    probability ``p``; ``every=k`` samples only at steps ``0, k, 2k, …``; ``dropout=p`` loses
    each reading — the reset's too — with probability ``p``; ``stuck=(p, mean_steps)`` (or
    ``p``) freezes a working sensor with probability ``p`` and lets a frozen one recover with
    probability ``1 / mean_steps`` (a two-state Markov chain in the state,
    ``PlantState.sensor_stuck``; a frozen sensor repeats its output exactly, which the receiver
    detects). A lost, unsampled or stuck reading is *missing*: what is observed holds the last
    delivered one (before the first, ``H`` times the plant's initial-state mean, the numpy
    sensor's ``h(initial_state)``), the filters predict only, and
    ``info["measurement_missing"]`` says so; ``info["sensor_faults"]``
    flags what acted on the step's reading (``dropped``, ``stuck``, ``outlier``, ``biased``,
    ``unsampled``). ``delay=d`` puts the readings, their flags along, on a transmission line
    (a ring of ``d + 1`` slots in the state, ``PlantState.sensor_line``; :meth:`transmit`):
    reading ``k − d`` is delivered at ``k``, nothing before ``k = d`` (``late``, missing), and
    the flags are those of the reading delivered (``late`` added). Every filter kind is told
    the delay (:meth:`lagged_step`): it runs ``d`` steps behind and its estimate is predicted
    ahead — the plant's own filter then runs there, not in the plant's step
    (:attr:`runs_own_filter`).

    ``burst=((k_first, k_last, δ), ...)`` (static; none by default) is the numpy plants'
    ``burst`` condition (:mod:`fir_gym.envs._conditions`): the transition ``x[k] → x[k+1]``
    for ``k_first <= k <= k_last`` is stretched, ``x[k+1] = x[k] + (1 + δ) (x̃[k+1] − x[k])``
    (:meth:`burst_delta`, :meth:`stretch`; each plant applies it where its numpy plant does),
    and ``info["burst"]`` is the step's ``δ``.

    ``options`` are the kind's (static): ``horizon``, the window of ``"measurement-stack"``
    and of the windowed filters (it sizes the state; :attr:`default_horizon`, the numpy
    plant's, if not given), and a generic filter's options
    (:attr:`fir_gym.jax.filters.FilterKind.options`). A subclass sets :attr:`kinds`,
    :attr:`estimator`, :attr:`n_x`, :attr:`n_y` (and :attr:`default_horizon`), implements
    :meth:`filter_model`, and ends its reset with :meth:`finish_reset` and its step with
    :meth:`finish_step`, runs its own filter where :attr:`runs_own_filter`; its state has
    ``x``, ``y``, ``terminated``, the filter fields and ``memory``.
    """

    kinds: ClassVar[tuple[str, ...]]
    estimator: ClassVar[str]
    n_x: ClassVar[int]
    n_y: ClassVar[int]
    default_horizon: ClassVar[int] = 10
    #: the parameters of the truth the ``mismatch`` condition draws per episode (the numpy
    #: plant's ``randomizable``, same names; :class:`fir_gym.jax.randomized.Randomized`)
    randomizable: ClassVar[tuple[str, ...]] = ()

    def __init__(self, kind: str | None = None, observation: str = "estimate", *,
                 dropout: float = 0.0, outliers: Any = None, bias: Any = None, every: Any = 1,
                 stuck: Any = None, delay: Any = 0, burst: Any = None, **options: Any
                 ) -> None:
        from fir_gym.envs._conditions import check_burst
        from fir_gym.wrappers.faulty_sensor import check_faults

        super().__init__()
        #: the ``burst`` windows ``(k_first, k_last, δ)`` (static; empty: none), checked by
        #: the numpy plants' :func:`~fir_gym.envs._conditions.check_burst`
        self.burst = check_burst(burst)
        #: the sensor's faults (:class:`~fir_gym.wrappers.faulty_sensor.FaultSpec`)
        self.faults = check_faults(n_y=self.n_y, episode_steps=None, dropout=dropout,
                                   outliers=outliers, bias=bias, every=every, stuck=stuck,
                                   delay=delay)
        self.dropout = self.faults.dropout
        #: the sensor's delay in steps (0: none), told to every filter kind
        self.delay = self.faults.delay
        kind = self.estimator if kind is None else kind
        if kind not in self.kinds:
            raise ValueError(f"kind must be one of {self.kinds}; got {kind!r}")
        filters = self.filter_kinds
        if observation not in OBSERVATIONS or (kind not in filters
                                               and observation != "estimate"):
            raise ValueError(f"observation must be one of {OBSERVATIONS} for the filter kinds "
                             f"{filters} (and is not an option of the others); got "
                             f"{observation!r} for {kind!r}")
        accepted = (GENERIC_FILTERS[kind].options if kind in GENERIC_FILTERS
                    else {"horizon": None} if kind == "measurement-stack" else {})
        unknown = sorted(set(options) - set(accepted))
        if unknown:
            raise ValueError(f"unknown option(s) {unknown} for kind {kind!r}; its options are "
                             f"{sorted(accepted) or 'none'}")
        options = {**accepted, **options}
        if "horizon" in options:
            horizon = options["horizon"]
            horizon = self.default_horizon if horizon is None else horizon
            if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) \
                    or horizon < 1:
                raise ValueError(f"horizon must be a positive integer; got {horizon!r}")
            options["horizon"] = int(horizon)
        if kind in GENERIC_FILTERS:
            GENERIC_FILTERS[kind].check(self.n_x, options)
        require_x64()
        self.kind, self.observation, self.options = kind, observation, options

    @property
    def horizon(self) -> int | None:
        """The window of ``"measurement-stack"`` and of the windowed filters (else None)."""
        return self.options.get("horizon")

    @property
    def filter_kinds(self) -> tuple[str, ...]:
        """The kinds of :attr:`kinds` that run a filter (the plant's own and the generic)."""
        return tuple(k for k in self.kinds if k == self.estimator or k in GENERIC_FILTERS)

    @property
    def runs_own_filter(self) -> bool:
        """Whether the plant runs its own filter inside its step: the kind is the plant's
        own filter and the sensor has no delay (with a delay every filter kind runs behind,
        in :meth:`finish_step`, :meth:`lagged_step`)."""
        return self.kind == self.estimator and not self.delay

    def filter_model(self, params: Any) -> FilterModel:
        """What the filters believe (the numpy plant's ``model``) under ``params``."""
        raise NotImplementedError(f"{type(self).__name__} has no filter_model")

    def draw_centres(self, params: Any) -> dict[str, jax.Array]:
        """The centres of the ``mismatch`` draws: the model's values of the
        :attr:`randomizable` parameters (its ``nominal_*`` fields; the numpy plant's
        ``nominal_params``, around which ``randomize`` draws the truth)."""
        return {name: jnp.asarray(getattr(params, "nominal_" + name), dtype=jnp.float64)
                for name in self.randomizable}

    def true_fields(self, params: Any, values: dict[str, Any]) -> dict[str, Any]:
        """The params fields of a truth whose :attr:`randomizable` parameters are ``values``:
        those values, and whatever the truth derives from them, rebuilt (the numpy plant's
        ``_apply_params``); the model's (``nominal_*``) are not among them. Traceable:
        ``values`` may be traced. Computed once per episode
        (:class:`fir_gym.jax.randomized.Randomized` keeps them in its state)."""
        return dict(values)

    def with_true_values(self, params: Any, values: dict[str, Any]) -> Any:
        """``params`` with the truth's :attr:`randomizable` parameters set to ``values``
        (:meth:`true_fields`)."""
        return params.replace(**self.true_fields(params, values))

    @property
    def num_actions(self) -> int:
        return 1

    # ------------------------------------------------------------- the burst condition
    def burst_delta(self, k: Any) -> jax.Array:
        """The burst's ``δ`` of the transition from ``x[k]``: ``0 + δ_1 [k ∈ w_1] + δ_2 [k ∈
        w_2] + …`` over :attr:`burst` (overlapping windows add; 0 without a burst) —
        :func:`fir_gym.envs._conditions.burst_delta`, in its order."""
        total = jnp.zeros((), dtype=jnp.float64)
        for first, last, d in self.burst:
            total = total + d * ((first <= k) & (k <= last))
        return total

    def stretch(self, x: jax.Array, x_next: jax.Array, delta: jax.Array) -> jax.Array:
        """The burst's transition: ``x + (1 + δ) (x_next − x)`` where ``δ ≠ 0``, else
        ``x_next`` untouched (:func:`fir_gym.envs._conditions.stretch`, which the numpy plant
        applies only when ``δ`` is not 0)."""
        if not self.burst:
            return x_next
        return jnp.where(delta != 0.0, x + (1.0 + delta) * (x_next - x), x_next)

    # ------------------------------------------------------------- the sensor's faults
    @property
    def can_miss(self) -> bool:
        """Whether a reading can be missing (dropout, a multi-rate, stuck or late sensor)."""
        return bool(self.dropout or self.faults.every > 1 or self.faults.stuck_probability
                    or self.delay)

    def measurement_noise_sqrt(self, params: Any) -> jax.Array:
        """A square root ``L`` (``L Lᵀ = R``, ``(n_y, n_y)``) of the true plant's measurement
        noise covariance: the outliers' scale (the numpy sensor's ``cholesky(R)``; any root
        gives the same law)."""
        raise NotImplementedError(f"{type(self).__name__} has no measurement_noise_sqrt")

    def sensor_reading(self, key: jax.Array, k: Any, params: Any,
                       stuck_before: Any = False) -> Reading:
        """What the sensor does to the reading number ``k`` (the reset's is 0) of the reset
        or step keyed ``key``, in the numpy sensor's order: the stuck chain's step from
        ``stuck_before`` (one uniform of the key's fault stream folded in 3), the bias from its
        step on, an outlier (one uniform and ``n_y`` normals, folded in 1 and 2), the
        multi-rate sampling, the dropout (:meth:`reading_missing`). Every draw comes from
        ``fold_in(key, FAULT_STREAM)``, so the plant's noise from ``key`` is the same with and
        without faults; a fault that is off draws nothing."""
        from fir_gym.wrappers.faulty_sensor import FAULT_STREAM

        f, no = self.faults, jnp.asarray(False)
        k = jnp.asarray(k)
        stream = jax.random.fold_in(key, FAULT_STREAM)
        offset = jnp.zeros(self.n_y)
        biased = outlier = unsampled = stuck = no
        if f.stuck_probability:
            u = jax.random.uniform(jax.random.fold_in(stream, 3), dtype=jnp.float64)
            stuck = jnp.where(jnp.asarray(stuck_before), u >= 1.0 / f.stuck_steps,
                              u < f.stuck_probability)
        if f.bias_step is not None and f.bias_value is not None:
            biased = k >= f.bias_step
            offset = offset + jnp.where(biased, jnp.asarray(f.bias_value, dtype=jnp.float64),
                                        0.0)
        if f.outlier_probability:
            u = jax.random.uniform(jax.random.fold_in(stream, 1), dtype=jnp.float64)
            z = jax.random.normal(jax.random.fold_in(stream, 2), (self.n_y,), jnp.float64)
            outlier = u < f.outlier_probability
            size = f.outlier_scale * (jnp.asarray(self.measurement_noise_sqrt(params)) @ z)
            offset = offset + jnp.where(outlier, size, 0.0)
        if f.every > 1:
            unsampled = k % f.every != 0
        dropped = self.reading_dropped(stream)
        return Reading(missing=dropped | unsampled | stuck, offset=offset, dropped=dropped,
                       outlier=outlier, biased=biased, unsampled=unsampled, stuck=stuck)

    def reading_missing(self, key: jax.Array) -> jax.Array:
        """Whether the reading of the reset or step keyed ``key`` is lost: one uniform of the
        key's fault stream (``fold_in(key, FAULT_STREAM)``, the numpy sensor's tag, so the
        plant's own noise from ``key`` is unchanged) below :attr:`dropout`; always False
        without dropout (no draw)."""
        from fir_gym.wrappers.faulty_sensor import FAULT_STREAM

        return self.reading_dropped(jax.random.fold_in(key, FAULT_STREAM))

    def reading_dropped(self, stream: jax.Array) -> jax.Array:
        """The dropout's draw on a key's fault stream (:meth:`reading_missing`)."""
        if not self.dropout:
            return jnp.asarray(False)
        return jax.random.uniform(stream, dtype=jnp.float64) < self.dropout

    def deliver(self, missing: Reading | jax.Array | bool, y: jax.Array, held: jax.Array
                ) -> jax.Array:
        """The reading delivered: ``y`` (plus the sensor's bias and outlier where
        ``missing`` is a :class:`Reading`), or ``held`` (the last delivered, or at a reset
        :meth:`first_hold`) where it is missing."""
        if isinstance(missing, Reading):
            if self.faults.outlier_probability or self.faults.bias_step is not None:
                y = y + missing.offset
            missing = missing.missing
        return y if not self.can_miss else jnp.where(missing, held, y)

    def first_hold(self, params: Any) -> jax.Array:
        """What is held before the first reading arrives: ``H`` times the plant's
        initial-state mean (:func:`fir_gym.wrappers.sensor_faults._sensor_setup`)."""
        return self.filter_model(params).H @ jnp.asarray(params.initial_state,
                                                          dtype=jnp.float64)

    def own_update(self, missing: Reading | jax.Array | bool, before: Any, updated: Any,
                   x_pred: jax.Array, P_pred: jax.Array, params: Any) -> Any:
        """The plant's own filter after a step: ``updated`` (the state after the update with
        the delivered reading and its watch), or where the reading is missing the
        prediction ``(x_pred, P_pred)`` alone, watched with no measurement (NaN NIS, the run
        of high NIS ended) — :meth:`fir_gym.estimators.base.Estimator.step` with ``None``.
        ``before``: the state before the update (its filter fields the previous step's)."""
        if not self.can_miss:
            return updated
        missing = lost(missing)
        predicted = watch_state(before, x_pred, P_pred, jnp.asarray(jnp.nan),
                                watch_limits_of(params), usable=False)
        return jax.tree.map(lambda a, b: jnp.where(missing, a, b), predicted, updated)

    # ------------------------------------------------------------- the sensor's delay
    def transmit(self, line: SensorLine, k: Any, reading: jax.Array, flags: jax.Array,
                 held: jax.Array) -> tuple[SensorLine, jax.Array, jax.Array,
                                           dict[str, jax.Array]]:
        """The delayed sensor's transmission line (:class:`~fir_gym.wrappers.faulty_sensor.
        FaultySensor`'s): reading number ``k`` and its ``flags`` (:func:`line_flags`) go into
        slot ``k mod (delay + 1)`` of the ring, and out comes reading ``k − delay`` from its
        slot — ``late`` for ``k < delay`` (nothing due yet). Returns the line, the reading
        delivered (``held`` where it is missing: late, or dropped, stuck or unsampled when it
        was read), whether it is missing, and its flags (``late`` added), the numpy
        sensor's ``info["sensor_faults"]``."""
        ring = self.delay + 1
        slot = k % ring
        line = SensorLine(line.values.at[slot].set(reading), line.flags.at[slot].set(flags))
        due = k - self.delay
        late = due < 0
        out = jnp.where(late, 0, due % ring)
        got = jnp.where(late, False, line.flags[out])
        named = dict(zip(LINE_FLAGS, got, strict=True))
        missing = late | named["dropped"] | named["stuck"] | named["unsampled"]
        return line, jnp.where(missing, held, line.values[out]), missing, {**named, "late": late}

    @property
    def lagged_kind(self) -> FilterKind:
        """The filter kind run behind a delayed sensor: a generic one, or for the plant's own
        filter the textbook EKF (a KF on a linear model) on :meth:`filter_model`
        (:data:`OWN_FILTER`) — the plant's own step, which it reproduces to round-off
        (tests/jax/test_kinds.py), cannot lag."""
        return GENERIC_FILTERS.get(self.kind, OWN_FILTER)

    def lagged_step(self, old: Any, new: Any, u: jax.Array, missing: Any, params: Any) -> Any:
        """A filter kind's step behind a sensor delayed ``d`` steps
        (:mod:`fir_gym.estimators.delay`, as ``gym.make(id, sensor_faults={"delay": d},
        estimator=kind)`` tells it the delay): the inputs kept (``Lagged.inputs``, the last
        ``d + 1``, oldest first) take the applied ``u[k − 1]``; at ``k = d`` the lagged filter
        consumes the delivered ``y[0]`` from its prior (an update only), after it ``y[k − d]``
        with ``u[k − d − 1]``, a prediction only where it is missing; its watch as always. Its
        estimate is then predicted ``min(k, d)`` steps ahead with the last inputs (the EKF's
        prediction on :meth:`filter_model`, :func:`fir_gym.estimators.delay.predict_ahead`):
        the state's ``filter_x``, ``filter_P`` — what is observed —, a non-finite prediction
        raising ``diverged`` and keeping the last finite one."""
        d, kind, options = self.delay, self.lagged_kind, self.options
        model, limits = self.filter_model(params), watch_limits_of(params)
        k = new.time
        lag = old.delayed
        inputs = jnp.concatenate([lag.inputs[1:], jnp.reshape(u, (1, -1))])
        # until k = d the lagged belief and memory are the reset's (the prior, the kind's
        # start): at k = d the filter's first update starts from them
        first = kind.update(old.memory, lag.x, lag.P, new.y, model, options, missing=missing)
        later = kind.predict_update(old.memory, lag.x, lag.P, new.y, inputs[0], model,
                                    options, missing=missing)
        memory, x, P, nis = jax.tree.map(lambda a, b: jnp.where(k == d, a, b), first, later)
        before = Belief(lag.x, lag.P, old.nis, old.nis_run, old.diverged)
        stepped = watch(before, x, P, nis, limits, kind.reports_nis & ~jnp.asarray(missing))
        due = k >= d
        b = jax.tree.map(lambda a, c: jnp.where(due, a, c), stepped, before)
        memory = jax.tree.map(lambda a, c: jnp.where(due, a, c), memory, old.memory)
        steps = jnp.minimum(k, d)
        x_ahead, P_ahead = b.x, b.P
        for slot in range(1, d + 1):
            xn, Pn = ekf_predict(x_ahead, P_ahead, inputs[slot], model.Q, model.f_and_F)
            active = steps >= d + 1 - slot
            x_ahead, P_ahead = jnp.where(active, xn, x_ahead), jnp.where(active, Pn, P_ahead)
        finite = jnp.all(jnp.isfinite(x_ahead)) & jnp.all(jnp.isfinite(P_ahead))
        return new.replace(memory=memory, delayed=Lagged(b.x, b.P, inputs),
                           filter_x=jnp.where(finite, x_ahead, old.filter_x),
                           filter_P=jnp.where(finite, P_ahead, old.filter_P),
                           nis=b.nis, nis_run=b.nis_run, diverged=b.diverged | ~finite)

    def get_obs(self, state: Any, params: Any = None, key: jax.Array | None = None) -> Any:
        if self.kind == "true":
            return state.x
        if self.kind == "measurement":
            return state.y
        if self.kind == "measurement-stack":
            return stack_observation(state.memory)
        if self.observation == "estimate+covariance":
            rows, cols = np.triu_indices(self.n_x)
            return {"estimate": state.filter_x, "covariance": state.filter_P[rows, cols]}
        if self.observation == "estimate+measurement":
            return {"estimate": state.filter_x, "measurement": state.y}
        return state.filter_x

    def is_terminated(self, state: Any, params: Any) -> jax.Array:
        return state.terminated

    def observation_space(self, params: Any) -> Any:
        def box(n: int) -> spaces.Box:
            return spaces.Box(-jnp.inf, jnp.inf, (n,), jnp.float64)

        n = self.n_x
        if self.kind == "measurement":
            return box(self.n_y)
        if self.kind == "measurement-stack":
            return box(self.options["horizon"] * (self.n_y + 1))
        if self.observation == "estimate+covariance":
            return spaces.Dict({"estimate": box(n), "covariance": box(n * (n + 1) // 2)})
        if self.observation == "estimate+measurement":
            return spaces.Dict({"estimate": box(n), "measurement": box(self.n_y)})
        return box(n)

    def action_space(self, params: Any = None) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, (1,), jnp.float32)

    # ------------------------------------------------------------- the kinds' shared steps
    def finish_reset(self, state: Any, params: Any, missing: Reading | jax.Array | bool = False
                     ) -> Any:
        """A reset's state after the plant's own part: the stack's windows started, or a
        generic filter's first update with ``y[0]`` from its prior (the state's filter
        fields; :meth:`fir_gym.wrappers.EstimatorObservation.reset`) — none where the reading
        is ``missing``. With a delay the reading enters the sensor's line (the one delivered,
        late, is the held :meth:`first_hold`) and a filter kind starts behind it, at its prior
        (:meth:`lagged_step`)."""
        if isinstance(missing, Reading) and self.faults.stuck_probability:
            state = state.replace(sensor_stuck=missing.stuck)
        if self.delay:               # the reading enters the line; nothing has arrived yet
            d, n_y = self.delay, self.n_y
            line = SensorLine(jnp.zeros((d + 1, n_y)), jnp.zeros((d + 1, len(LINE_FLAGS)),
                                                                 dtype=bool))
            line, y, missing, _ = self.transmit(line, jnp.asarray(0), state.y,
                                                line_flags(missing), self.first_hold(params))
            state = state.replace(y=y, sensor_line=line)
        if self.kind == "measurement-stack":
            return state.replace(memory=stack_start(state.y, self.options["horizon"]))
        if self.delay and self.kind in self.filter_kinds:
            # the filter runs d steps behind: it has not started (its prior of x[0] held),
            # and its estimate of x[0] is that prior (no input to predict with yet)
            kind = self.lagged_kind
            memory = kind.start(state.filter_x, state.filter_P, self.options)
            return state.replace(memory=memory, delayed=Lagged(
                state.filter_x, state.filter_P, jnp.zeros((self.delay + 1, self.num_actions))))
        if self.kind in GENERIC_FILTERS:
            kind = GENERIC_FILTERS[self.kind]
            missing = lost(missing)
            memory = kind.start(state.filter_x, state.filter_P, self.options)
            extra = {"missing": missing} if self.can_miss else {}
            memory, x, P, nis = kind.update(memory, state.filter_x, state.filter_P, state.y,
                                            self.filter_model(params), self.options, **extra)
            state = watch_state(state.replace(memory=memory), x, P, nis,
                                watch_limits_of(params), kind.reports_nis & ~jnp.asarray(missing))
        return state

    def finish_step(self, old: Any, new: Any, u: jax.Array, params: Any,
                    info: dict[str, Any], missing: Reading | jax.Array | bool = False
                    ) -> tuple[Any, Any, dict[str, Any]]:
        """A step's observation, state and ``info`` after the plant's own part (``new``: the
        plant moved, the reading delivered ``new.y``; the plant's own filter, if that is the
        kind, already updated): the stack pushed (a missing reading pushes the held one, as
        the numpy stack reads what the sensor delivers), or a generic filter's step with the
        applied action ``u`` (a prediction only where the reading is ``missing``) — and for
        every filter kind the ``info`` keys ``estimate``, ``estimation_error``,
        ``estimator_diverged`` and ``nis``; where a reading can be missing,
        ``measurement_missing``; with any fault, ``sensor_faults`` (:class:`Reading`'s flags).
        With a delay, ``new.y`` (the sensor's reading of the step) enters the line and the
        reading due is delivered (:meth:`transmit`; its flags, ``late`` added, are
        ``sensor_faults``), and a filter kind runs behind it (:meth:`lagged_step`)."""
        if self.burst:
            info["burst"] = self.burst_delta(old.time)
        if isinstance(missing, Reading) and self.faults.stuck_probability:
            new = new.replace(sensor_stuck=missing.stuck)
        if self.delay:               # the step's reading enters the line, y[k − d] leaves it
            line, y, missing, info["sensor_faults"] = self.transmit(
                old.sensor_line, new.time, new.y, line_flags(missing), old.y)
            new = new.replace(y=y, sensor_line=line)
        elif isinstance(missing, Reading) and self.faults.active:
            info["sensor_faults"] = missing.flags()
        missing = lost(missing)
        if self.kind == "measurement-stack":
            new = new.replace(memory=stack_push(old.memory, new.y, u))
        elif self.delay and self.kind in self.filter_kinds:
            new = self.lagged_step(old, new, u, missing, params)
        elif self.kind in GENERIC_FILTERS:
            kind = GENERIC_FILTERS[self.kind]
            extra = {"missing": missing} if self.can_miss else {}
            memory, x, P, nis = kind.predict_update(old.memory, old.filter_x, old.filter_P,
                                                    new.y, u, self.filter_model(params),
                                                    self.options, **extra)
            new = watch_state(new.replace(memory=memory), x, P, nis, watch_limits_of(params),
                              kind.reports_nis & ~jnp.asarray(missing))
        if self.can_miss:
            info["measurement_missing"] = jnp.asarray(missing)
        if self.kind in self.filter_kinds:
            info.update(estimate=new.filter_x, estimation_error=new.x - new.filter_x,
                        estimator_diverged=new.diverged, nis=new.nis)
        return self.get_obs(new, params), new, info


@struct.dataclass
class Reading:
    """What the sensor did to one reading (:meth:`FilteredPlant.sensor_reading`): whether it
    is ``missing`` (``dropped``, ``unsampled`` or ``stuck``), the ``offset`` added to the
    plant's measurement (bias and outlier, ``(n_y,)``), and the faults' flags (``stuck``: the
    stuck chain's state after this reading)."""

    missing: jax.Array
    offset: jax.Array
    dropped: jax.Array
    outlier: jax.Array
    biased: jax.Array
    unsampled: jax.Array
    stuck: jax.Array

    def flags(self) -> dict[str, jax.Array]:
        """The numpy sensor's ``info["sensor_faults"]`` flags the JAX sensor has."""
        return {"dropped": self.dropped, "stuck": self.stuck, "outlier": self.outlier,
                "biased": self.biased, "unsampled": self.unsampled}


#: the flags a reading carries along a delayed sensor's line (:class:`SensorLine`), the numpy
#: sensor's names
LINE_FLAGS = ("dropped", "stuck", "outlier", "biased", "unsampled")


def line_flags(missing: Reading | jax.Array | bool) -> jax.Array:
    """A reading's :data:`LINE_FLAGS` as one bool vector (a bare ``missing`` flag: dropped)."""
    if isinstance(missing, Reading):
        return jnp.stack([jnp.asarray(missing.dropped), jnp.asarray(missing.stuck),
                          jnp.asarray(missing.outlier), jnp.asarray(missing.biased),
                          jnp.asarray(missing.unsampled)])
    no = jnp.asarray(False)
    return jnp.stack([jnp.asarray(missing, dtype=bool), no, no, no, no])


@struct.dataclass
class SensorLine:
    """A delayed sensor's transmission line (:meth:`FilteredPlant.transmit`): a ring of
    ``delay + 1`` slots, each a reading ``values[i]`` (``n_y``) and its :data:`LINE_FLAGS`."""

    values: Any
    flags: Any


@struct.dataclass
class Lagged:
    """A filter kind behind a delayed sensor (:meth:`FilteredPlant.lagged_step`): its lagged
    mean and covariance (of ``x[k − d]``; its NIS, run and flag are the state's) and the last
    ``d + 1`` applied inputs, oldest first."""

    x: Any
    P: Any
    inputs: Any


def _own_update(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, model: FilterModel,
                options: Any, missing: jax.Array | bool = False) -> Any:
    """The textbook EKF's (a KF's) update on ``model``: the prior kept and a NaN NIS where
    the reading is ``missing``."""
    xu, Pu, nis = kf_update(x, P, y, model.H, model.R)
    missing = jnp.asarray(missing)
    return (memory, jnp.where(missing, x, xu), jnp.where(missing, P, Pu),
            jnp.where(missing, jnp.nan, nis))


def _own_step(memory: Any, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array,
              model: FilterModel, options: Any, missing: jax.Array | bool = False) -> Any:
    """The textbook EKF's step on ``model``: ``x⁻ = f(x, u)``, ``P⁻ = F P Fᵀ + Q``, then
    :func:`_own_update`."""
    xp, Pp = ekf_predict(x, P, u, model.Q, model.f_and_F)
    return _own_update(memory, xp, Pp, y, model, options, missing)


#: a plant's own filter as a filter kind (the textbook EKF on its ``filter_model``): what runs
#: behind a delayed sensor (:attr:`FilteredPlant.lagged_kind`)
OWN_FILTER = FilterKind(options={}, start=lambda x0, P0, options: (), update=_own_update,
                        predict_update=_own_step)


def lost(missing: Reading | jax.Array | bool) -> jax.Array | bool:
    """Whether a reading is missing: a :class:`Reading`'s flag, or the flag itself."""
    return missing.missing if isinstance(missing, Reading) else missing


@struct.dataclass
class PlantState(gymnax_env.EnvState):
    """A plant's state in :mod:`fir_gym.jax`: the step count, the true state ``x``, the last
    measurement ``y`` (a failed step repeats it), ``terminated``, and the filter's record
    (mean, covariance, this step's NIS, the run of high NIS, the sticky ``diverged`` flag;
    :func:`belief_of`) and the kind's ``memory`` (a pytree: the stack's windows, a windowed
    filter's bank; ``()`` for the others), and the stuck sensor's chain (``sensor_stuck``).
    Each plant subclasses it under its own name."""

    time: Any
    x: Any
    y: Any
    terminated: Any
    filter_x: Any
    filter_P: Any
    nis: Any
    nis_run: Any
    diverged: Any
    memory: Any = ()
    sensor_stuck: Any = False
    #: with a delay: the sensor's line (:class:`SensorLine`) and, for a filter kind, the
    #: lagged filter (:class:`Lagged`)
    sensor_line: Any = ()
    delayed: Any = ()

    @classmethod
    def start(cls, x: jax.Array, y: jax.Array, x0: jax.Array, P0: jax.Array) -> Any:
        """The state at a reset: step 0, the filter at its prior ``N(x0, P0)`` (no NIS yet),
        no memory (:meth:`FilteredPlant.finish_reset` gives the kind's)."""
        return cls(time=jnp.asarray(0, dtype=jnp.int64), x=x, y=y,
                   terminated=jnp.asarray(False), filter_x=x0, filter_P=P0,
                   nis=jnp.asarray(jnp.nan), nis_run=jnp.asarray(0, dtype=jnp.int64),
                   diverged=jnp.asarray(False), sensor_stuck=jnp.asarray(False))
