"""The Estimator contract shared by every filter (docs/architecture.md#estimator-contract).

An estimator is one object per filter, batched by design:

* ``SomeFilter(model, *, x0=None, P0=None, **options)``; ``reset(x0=None, P0=None)``
  sets the prior of ``x[0]`` (default ``x0 = 0``, ``P0 = I``).
* ``step(y, u=None) -> x_hat`` consumes ``y[k]`` (and ``u[k-1]``, the input that
  drove the plant into ``x[k]``) and returns the estimate of ``x[k]``. The first
  ``step`` after ``reset`` is a measurement update only (it consumes ``y[0]``,
  the measurement ``env.reset`` returns); every later ``step`` predicts, then
  updates.
* Shapes: ``(n_x,)`` for one system, ``(B, n_x)`` for ``B`` systems in lock-step.
  The batch size is fixed by the prior (a batched ``x0`` or ``P0``) or, when the
  prior is unbatched, by the first batched measurement, to which the prior is
  broadcast. One system is held as a batch of one: it takes the same code.
* ``x``, ``P`` (where defined), ``diverged`` and ``last_info`` are readable; returned
  arrays are fresh copies.
* ``restart(systems)`` sends some systems of a batch back to their prior: their
  next ``step`` consumes a first measurement (update only) while the others
  predict and update as usual — what a vector env's autoreset needs.

**Input.** ``y``, ``u``, ``x0`` and ``P0`` must be real numbers (floats or integers):
booleans, complex numbers, dates and strings raise ``TypeError`` naming the argument
(:func:`~._validation.real_array`); a wrong shape raises ``ValueError``.
**Non-finite measurements** follow ``nan_policy``: ``"raise"`` (default) raises
``ValueError`` naming ``y``; ``"skip"`` treats the measurement of a system whose
``y`` has any NaN as missing (that system predicts only). ``u`` must be finite.

**Divergence.** After every step a system is flagged as diverged when its
estimate or covariance is non-finite, when ``trace(P)`` exceeds
``max_covariance_trace``, or when its normalised innovation squared has stayed
above the ``1 - nis_tail`` χ² quantile for ``nis_patience`` consecutive steps (a
NaN NIS of a usable measurement counts as above). The flag is sticky until
``reset``. A system whose estimate became non-finite keeps its last finite
estimate (and covariance), so NaN never reaches a caller.

**Innovation gate.** ``gate=None`` (default) uses every usable measurement. ``gate=p``,
a probability strictly between 0 and 1 (e.g. 0.999), rejects the measurement of a
system whose normalised innovation squared — the number ``last_info["nis"]`` reports —
exceeds ``scipy.stats.chi2.ppf(p, n_y)``: that system's estimate, covariance and every
other state (windows, ages, regimes) end the step exactly as with that measurement
missing, the other systems are unaffected. ``last_info["nis"]`` still reports the
rejected NIS, the divergence watch counts it as it would an accepted one, and the step's
log-likelihood is 0 there (as for a missing measurement). With a gate ``last_info`` adds
``gated`` (this step's measurement was rejected: a bool or ``(B,)``) and ``gated_count``
(rejections since ``reset``; ``restart`` zeroes the restarted systems'); without one the
two keys are absent. A class that cannot gate (``can_gate`` False) refuses ``gate``.

**A known sensor delay.** ``delay=d`` (default 0) says the measurement handed to
:meth:`step` at ``k`` is ``y[k − d]``: the filter runs ``d`` steps behind on it and the
model predicts the current state ``d`` steps ahead (:mod:`.delay`); ``x``, ``P`` and the
returned estimate are that prediction, ``last_info["delayed_estimate"]`` the lagged one.

**One step, two implementations.** The hooks :meth:`_update` and :meth:`_predict_update`
(returning new arrays) with :meth:`_accept` (the watch above) are the numpy reference.
A class that sets ``has_compiled_step`` also implements :meth:`_compiled_update` and
:meth:`_compiled_predict_update`: the same step with the compiled twins of
:mod:`~fir_gym.estimators.compiled`, written in place into the same state arrays,
watch included. :meth:`step` takes the compiled one exactly when
:data:`compiled.ENABLED <fir_gym.estimators.compiled.ENABLED>` (the package's one dispatch
rule). A subclass that overrides a numpy hook the twin replaces (``twin_replaces``)
without overriding the twins steps on numpy.

**Copies are copies.** The state is plain arrays and numbers — no closures, no views
of other arrays — so ``copy.deepcopy`` and ``pickle`` work at any point and the copy's
future equals the original's bit for bit.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike

from . import compiled
from ._attributes import LiveAttributes
from ._validation import FloatArray, as_batch, as_covariance, positive, real_array
from .delay import DelayLine, check_delay, predict_ahead
from .model import StateSpaceModel
from .sequences import FilterResult, filter_sequence
from .state import FilterState, new_limits

#: what a numpy hook returns: ``(x, P, nis)``, or ``(x, P, nis, log det S)`` for a filter
#: with a Gaussian innovation (its log-likelihood, :attr:`Estimator.last_info`)
StepResult = tuple[Any, ...]

_F64 = np.dtype(np.float64)
_LOG_2PI = math.log(2.0 * math.pi)


def _all_finite(a: np.ndarray) -> bool:
    """Whether every value of ``a`` is finite. A few values are summed as Python floats
    (faster than any numpy call; a sum that is not finite, from a NaN, an inf or an
    overflow, is looked at value by value); more go to ``np.isfinite`` (a numpy sum
    would warn when it overflows)."""
    if a.size <= 16 and math.isfinite(sum(a.ravel().tolist())):
        return True
    return bool(np.isfinite(a).all())


class Estimator(LiveAttributes, ABC):
    """Base class of all filters: prior handling, batching, validation, divergence.

    Subclasses implement :meth:`_update` (the first step) and
    :meth:`_predict_update` (later steps) on batched arrays ``x (B, n_x)``,
    ``P (B, n_x, n_x)``, ``y (B, n_y)``, ``u (B, n_u)`` and a boolean mask
    ``valid (B,)`` of systems whose measurement is usable. They return the new
    ``x``, ``P`` (``None`` for a filter without covariance, ``provides_covariance``
    False) and the normalised innovation squared per system (or ``None``). A class
    that sets ``can_gate`` treats a usable measurement whose returned NIS exceeds
    ``_gate_threshold`` (when not ``None``) as missing, in both hooks and its twins.
    """

    #: short registry name (``"kf"``, ``"efir"``, ...)
    name: ClassVar[str] = ""
    #: whether the filter needs and uses the prior (x0, P0); FIR filters do not
    uses_prior: ClassVar[bool] = True
    #: whether the filter reports an error covariance ``P`` (a controller may observe it)
    provides_covariance: ClassVar[bool] = True
    #: the plant attribute holding the model this filter is built from
    model_attribute: ClassVar[str] = "model"
    #: whether a step may go without a measurement (``step(None)``, a masked or NaN row);
    #: a filter that cannot refuses it with a ValueError that says why
    accepts_missing: ClassVar[bool] = True
    #: whether the step computes a normalised innovation squared (``last_info["nis"]``)
    reports_nis: ClassVar[bool] = True
    #: whether the step computes the Gaussian log-likelihood of its innovation (the
    #: Kalman family; ``log det S`` comes from the step)
    reports_likelihood: ClassVar[bool] = False
    #: whether the class has compiled twins of its step (:meth:`_compiled_update`,
    #: :meth:`_compiled_predict_update`)
    has_compiled_step: ClassVar[bool] = False
    #: numpy hooks the compiled twins compute in their own way
    twin_replaces: ClassVar[tuple[str, ...]] = ("_update", "_predict_update", "_accept",
                                                "_update_systems")

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = cls.__dict__
        if ("_compiled_update" not in own and "_compiled_predict_update" not in own
                and any(hook in own for hook in cls.twin_replaces)):
            cls.has_compiled_step = False      # the twins would bypass the override

    def __init__(
        self,
        model: StateSpaceModel,
        *,
        x0: ArrayLike | None = None,
        P0: ArrayLike | None = None,
        nan_policy: str = "raise",
        max_covariance_trace: float = 1e12,
        nis_tail: float = 1e-9,
        nis_patience: int = 10,
        gate: float | None = None,
        delay: int = 0,
    ) -> None:
        if not isinstance(model, StateSpaceModel):
            raise TypeError(f"model must be a StateSpaceModel; got {type(model).__name__}")
        self.model = model
        self._n_y = model.n_y
        self.nan_policy = nan_policy
        max_trace = positive("max_covariance_trace", max_covariance_trace)
        tail = positive("nis_tail", nis_tail)
        if tail >= 1:
            raise ValueError(f"nis_tail must be in (0, 1); got {nis_tail!r}")
        patience = positive("nis_patience", nis_patience, integer=True)
        self._nis_threshold = float(scipy.stats.chi2.isf(tail, model.n_y))
        #: the limits as the compiled twins read them (:mod:`.compiled.watch`): the watch's
        #: three, the windowed filters' ``max_estimate`` and the gate's NIS threshold (inf:
        #: none); the properties ``nis_patience``, ``max_covariance_trace`` and ``gate`` write them
        self._limits = new_limits(self._nis_threshold, patience, max_trace)
        self.gate = gate
        self._delay = check_delay(delay, model)
        self.reset(x0, P0)

    @property
    def state(self) -> FilterState:
        """The filter's state record (:class:`~fir_gym.estimators.state.FilterState`), live: the
        arrays and flags the next step reads and writes, passed whole to the numpy reference,
        the compiled twin and ``predict``/``update``. Read it; change the estimate through
        :meth:`reset` and :meth:`restart` (``copy.deepcopy(est.state)`` is a snapshot)."""
        return self._state

    @property
    def prior(self) -> tuple[FloatArray, FloatArray]:
        """The prior ``(x0, P0)`` that :meth:`reset` set (copies; batched where it was given
        batched) — what a restarted system returns to."""
        return self._x0.copy(), self._P0.copy()

    @property
    def delay(self) -> int:
        """The known sensor delay in steps (0: none; :mod:`.delay`), fixed at construction."""
        return self._delay

    # ------------------------------------------------------------------ public API
    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None) -> None:
        """Set the prior of ``x[0]``: mean ``x0`` (default 0) and covariance ``P0`` (default I).

        ``x0`` may be ``(n_x,)`` or ``(B, n_x)``; ``P0`` may be ``(n_x, n_x)`` or
        ``(B, n_x, n_x)``, symmetric positive semi-definite.
        """
        n = self.model.n_x
        x0_ = np.zeros(n) if x0 is None else np.array(as_batch("x0", x0, n))
        if not np.all(np.isfinite(x0_)):
            raise ValueError("x0 must be finite")
        if P0 is None:
            P0_ = np.eye(n)
        else:
            P0_ = real_array("P0", P0)
            if P0_.ndim == 3:
                P0_ = np.stack([as_covariance(f"P0[{i}]", p, n) for i, p in enumerate(P0_)])
            else:
                P0_ = as_covariance("P0", P0_, n)
        sizes = {a.shape[0] for a, d in ((x0_, 2), (P0_, 3)) if a.ndim == d}
        if len(sizes) > 1:
            raise ValueError(f"x0 and P0 have different batch sizes {sorted(sizes)}")
        self._batch: int | None = sizes.pop() if sizes else None
        self._batched_prior = self._batch is not None
        self._x0, self._P0 = x0_, P0_
        #: the state record (:mod:`.state`): empty until the first step fixes the batch size
        self._state = FilterState(n=n, limits=self._limits)
        #: with a delay: the inputs kept and each system's age, and the estimate predicted
        #: to the current step (:mod:`.delay`)
        self._line: DelayLine | None = None
        self._ahead: tuple[FloatArray, FloatArray] = (np.empty((0, n)), np.empty((0, n, n)))
        self._y_shape: tuple[int, ...] | None = None
        self._reset_state()

    def restart(self, systems: ArrayLike) -> None:
        """Send some systems of a batch back to the prior (e.g. their episode ended).

        ``systems`` is a boolean mask ``(B,)`` or an array of indices. Their estimate
        and covariance return to ``x0``/``P0`` (their rows, for a batched prior),
        their divergence flag clears, and their next :meth:`step` consumes a *first*
        measurement (an update only) while the other systems predict and update.
        Before the first step, or when every system restarts, this is :meth:`reset`
        with the same prior.
        """
        s = self._state
        if not s.batch:
            return
        n_b = s.batch
        chosen = np.asarray(systems)
        mask = np.zeros(n_b, bool)
        try:
            mask[chosen] = True
        except (IndexError, ValueError, TypeError):
            raise ValueError(f"systems must be a boolean mask of length {n_b} or indices below "
                             f"{n_b}; got {systems!r}") from None
        if chosen.dtype == bool and chosen.shape != (n_b,):
            raise ValueError(f"systems must be a boolean mask of length {n_b}; got shape "
                             f"{chosen.shape}")
        if not mask.any():
            return
        if mask.all():
            self.reset(self._x0, self._P0)
            return
        self._restart_rows(mask)
        if self._line is not None:
            self._line.restart(mask)
            x_ahead, P_ahead = self._ahead
            x_ahead[mask] = s.x[mask]
            P_ahead[mask] = s.P[mask]

    def _restart_rows(self, mask: np.ndarray) -> None:
        """Send the systems ``mask`` (some, not all) back to the prior: their next step is a
        first step."""
        s = self._state
        n_b, n = s.batch, self.model.n_x
        s.x[mask] = np.broadcast_to(self._x0, (n_b, n))[mask]
        if s.P.shape[0] < n_b:                     # a shared covariance parts ways
            s.P = np.repeat(s.P, n_b, axis=0)
        s.P[mask] = np.broadcast_to(self._P0, (n_b, n, n))[mask]
        s.diverged[mask] = False
        s.nis_run[mask] = 0
        s.gated_count[mask] = 0
        s.fresh |= mask
        s.restarting = True
        self._restart_systems(mask)

    def step(self, y: ArrayLike | None, u: ArrayLike | None = None) -> FloatArray:
        """Consume ``y[k]`` (and ``u[k-1]``) and return the estimate of ``x[k]``.

        ``y = None`` means no measurement this step (every system predicts only), and so
        do the masked entries of a ``numpy.ma`` array (a system with any masked entry
        predicts only), whatever ``nan_policy`` says.

        The boundary checks are cheap (a type test, a shape comparison, a finiteness
        test: a Python sum of up to 16 values, else ``np.isfinite``); the step is then
        the compiled twin or the numpy reference (see the module docstring).
        Floating-point warnings are silenced inside the numpy hooks: a diverging filter
        is reported through :attr:`diverged`, not through ``RuntimeWarning``.
        """
        if self._delay:
            return self._delayed_step(y, u)
        Y, valid = self._measurement(y)
        U = self._no_input if u is None else self._input(u)
        self._take_step(Y, U, valid)
        s = self._state
        return s.x[0].copy() if s.single else s.x.copy()

    def _take_step(self, Y: FloatArray, U: FloatArray, valid: np.ndarray) -> None:
        """One step on checked arrays, compiled or numpy (the module docstring's rule)."""
        s = self._state
        self._last_valid: np.ndarray = valid
        if compiled.ENABLED and self.has_compiled_step:
            if s.update_next:
                self._compiled_update(Y, valid)
            else:
                self._compiled_predict_update(Y, U, valid)
        else:
            self._numpy_step(Y, U, valid)
        if self._gate_threshold is not None:
            self._book_gate(valid, self._gate_threshold)
        if s.restarting:
            s.fresh[:] = False
            s.restarting = False
        s.k += 1
        s.update_next = False

    def _delayed_step(self, y: ArrayLike | None, u: ArrayLike | None) -> FloatArray:
        """:meth:`step` with a known delay (:mod:`.delay`): the lagged filter consumes
        ``y[k − d]`` with ``u[k − d − 1]`` where it has started, then every system's estimate
        is predicted to the current step."""
        s = self._state
        Y, valid = self._measurement(y)
        U = self._no_input if u is None else self._input(u)
        line = self._line
        assert line is not None                        # made with the batch
        lagged_input = line.push(U)
        due = line.age >= line.delay                   # their y[k − d] exists
        early = valid & ~due
        if early.any():
            raise ValueError(f"y: with delay={line.delay}, the first {line.delay} steps after a "
                             "(re)start carry no measurement (y[k - delay] does not exist yet); "
                             f"got one for system(s) {np.flatnonzero(early).tolist()}")
        if due.any():
            self._take_step(Y, lagged_input, valid)
            if not due.all():                          # the others have not started yet
                self._restart_rows(~due)
        line.age += 1
        steps = np.minimum(line.age - 1, line.delay)
        P_lagged = None if not self.provides_covariance else np.broadcast_to(
            s.P, (s.batch, *s.P.shape[1:]))
        x_new, P_new = predict_ahead(self.model, s.x, P_lagged, line.window, steps)
        x_old, P_old = self._ahead
        finite = np.all(np.isfinite(x_new), axis=1)
        if P_new is not None:
            finite &= np.all(np.isfinite(P_new), axis=(1, 2))
        s.diverged |= ~finite                      # a prediction that left the numbers
        x_ahead = np.where(finite[:, None], x_new, x_old)
        P_ahead = P_old if P_new is None else np.where(finite[:, None, None], P_new, P_old)
        self._ahead = (x_ahead, P_ahead)
        return self._out(x_ahead)

    def filter(self, ys: ArrayLike, us: ArrayLike | None = None) -> FilterResult:
        """Run the filter over a whole sequence: ``step(ys[k], us[k-1])`` for every ``k``.

        Args:
            ys: measurements ``(T, n_y)``, or ``(T, B, n_y)`` for a batch (``(T,)`` when
                ``n_y = 1``); ``ys[0]`` is the first (the one ``env.reset`` returns). NaN and
                masked (``numpy.ma``) entries are missing measurements.
            us: inputs ``(T − 1, n_u)`` or ``(T − 1, B, n_u)`` (``T`` rows accepted, the
                last unused): ``us[k]`` is the input applied between ``ys[k]`` and
                ``ys[k+1]``, as in an env loop. ``None``: no input.

        Returns:
            A :class:`~fir_gym.estimators.sequences.FilterResult` (estimates, covariances,
            log-likelihoods, NIS and divergence flags per step). The filter continues from
            its current state and ends where the sequence ends: call :meth:`reset` first
            for a fresh run. The loop is :meth:`step` itself (compiled or numpy path alike),
            so the result equals a step-by-step run exactly.

        Raises:
            ValueError: naming ``ys`` or ``us`` on a wrong shape or length.
        """
        return filter_sequence(self, ys, us)

    @property
    def x(self) -> FloatArray:
        """The current estimate (the prior mean before the first step); a copy."""
        if not self._state.batch:
            return self._x0.copy()
        if self._line is not None:
            return self._out(self._ahead[0])
        return self._out(self._state.x)

    @property
    def P(self) -> FloatArray | None:
        """The current error covariance (the prior's before the first step; ``None`` for a
        filter without one, ``provides_covariance`` False); a copy."""
        s = self._state
        if not s.batch:
            return self._P0.copy()
        if not self.provides_covariance:
            return None
        if self._line is not None:
            return self._out(self._ahead[1])
        P = s.P if s.P.shape[0] == s.batch else np.broadcast_to(
            s.P, (s.batch,) + s.P.shape[1:])
        return self._out(P)

    @property
    def diverged(self) -> bool | np.ndarray:
        """Sticky divergence flag: a bool, or a ``(B,)`` array for a batch."""
        s = self._state
        if not s.batch:
            return False if not self._batched_prior else np.zeros(self._batch or 0, bool)
        return bool(s.diverged[0]) if s.single else s.diverged.copy()

    @property
    def last_info(self) -> dict[str, Any]:
        """Diagnostics of the last step (fresh copies; empty before the first step).

        ``diverged`` (as :attr:`diverged`), ``nis`` (the normalised innovation squared:
        a float or ``(B,)``, NaN where a measurement was skipped; ``None`` for filters
        without one), ``log_likelihood`` (the Gaussian log-density of the innovation,
        ``−½ (eᵀ S⁻¹ e + log det 2π S)``: pykalman's ``loglikelihood`` term; 0 where a
        measurement was skipped or rejected by the gate, ``None`` for filters without an
        innovation covariance), with a gate ``gated`` and ``gated_count`` (module
        docstring, *Innovation gate*), and the filter's own keys (e.g. the windowed
        filters' ``startup`` and ``rank_deficient``).
        """
        s = self._state
        if not s.batch or s.k == 0:
            return {}
        nis: Any = None
        ll: Any = None
        if self.reports_nis:
            nis = float(s.nis[0]) if s.single else s.nis.copy()
        if self.reports_likelihood:
            lls = self._log_likelihoods()
            ll = float(lls[0]) if s.single else lls
        info = {"diverged": self.diverged, "nis": nis, "log_likelihood": ll,
                **self._step_info()}
        if self._line is not None:
            info["delayed_estimate"] = self._out(s.x)
        if self._gate is not None:
            info["gated"] = bool(s.gated[0]) if s.single else s.gated.copy()
            info["gated_count"] = (int(s.gated_count[0]) if s.single
                                   else s.gated_count.copy())
        return info

    def _book_gate(self, valid: np.ndarray, threshold: float) -> None:
        """The gate's bookkeeping after a step: the systems whose NIS is above the threshold
        — the ones the step rejected: every path decides on that very comparison, and the NIS
        is NaN where no measurement was usable — are counted, and their log-likelihood is 0.
        One system takes no array operation (a few µs of a step of a few µs)."""
        s = self._state
        if s.batch == 1:
            gated = bool(s.nis[0] > threshold)
            s.gated[0] = gated
            if gated:
                s.gated_count[0] += 1
                self._last_valid = np.zeros(1, bool)
            return
        s.gated = s.nis > threshold
        if s.gated.any():
            s.gated_count += s.gated
            self._last_valid = valid & ~s.gated

    def _log_likelihoods(self) -> FloatArray:
        """``(B,)`` Gaussian log-likelihood of the last innovation of every system: 0 where
        the measurement was missing, ``-inf`` where it was usable but ``S`` was not positive
        definite (module docstring, *Divergence*)."""
        m = self._n_y
        with np.errstate(invalid="ignore"):
            ll = -0.5 * (self._state.nis + self._state.logdet + m * _LOG_2PI)
        return np.where(self._last_valid, np.where(np.isfinite(ll), ll, -np.inf), 0.0)

    @property
    def time_step(self) -> int:
        """Number of measurements consumed since ``reset``."""
        return self._state.k

    # ------------------------------------------------------------------ to implement
    def _reset_state(self) -> None:
        """Hook for subclasses to clear their own state on ``reset``."""

    def _restart_systems(self, mask: np.ndarray) -> None:
        """Hook: clear the per-system state of the systems in ``mask`` (see :meth:`restart`)."""

    def _init_batch(self, n_batch: int) -> None:
        """Hook: allocate per-system state once the batch size is known."""

    def _step_info(self) -> dict[str, Any]:
        """Hook: the filter's own entries of :attr:`last_info` (fresh copies)."""
        return {}

    def _update_systems(self, idx: np.ndarray, x: FloatArray, P: FloatArray, y: FloatArray,
                        valid: np.ndarray) -> StepResult:
        """First step of the restarted systems ``idx`` (their prior rows ``x``, ``P``).

        The default calls :meth:`_update` on the sub-batch, which is right for filters
        whose first step depends only on its arguments; filters with more per-system
        state override it.
        """
        return self._update(x, P, y, valid)

    @abstractmethod
    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> StepResult:
        """First step: measurement update of the prior with ``y[0]`` (numpy reference)."""

    @abstractmethod
    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> StepResult:
        """Later steps: predict with ``u[k-1]``, then update with ``y[k]`` (numpy reference)."""

    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        """The compiled twin of :meth:`_update` + :meth:`_accept`, in place on the state."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled step")

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        """The compiled twin of :meth:`_predict_update` + :meth:`_accept`, in place. Systems
        restarted since the last step (``_fresh``) take an update of their prior only."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled step")

    # ------------------------------------------------------------------ the numpy step
    def _numpy_step(self, Y: FloatArray, U: FloatArray, valid: np.ndarray) -> None:
        s = self._state
        with np.errstate(all="ignore"):
            if s.update_next:
                out = self._update(s.x, s.P, Y, valid)
            else:
                x_prior, P_prior = s.x, s.P
                out = self._predict_update(x_prior, P_prior, Y, U, valid)
                if s.restarting:
                    out = self._first_steps(*_four(out), x_prior, P_prior, Y, valid)
            x, P, nis, logdet = _four(out)
            self._accept(x, P, nis, valid)
            s.logdet[:] = np.nan if logdet is None else logdet

    def _accept(self, x: FloatArray, P: FloatArray | None, nis: FloatArray | None,
                valid: np.ndarray) -> None:
        """The divergence watch (module docstring): store the new estimate where it is
        finite, keep the last finite one elsewhere, and book every system.

        Shortcut: one finiteness reduction over ``x``, ``max |P|`` (``trace P <= n
        max|P|``, so ``n max|P| <= max_covariance_trace`` clears every system) and ``max
        nis``; only when one of them fails are the exact per-system masks computed. A
        covariance shared by the batch (``P`` of one row) is stored where it is finite.
        """
        s = self._state
        n = x.shape[1]
        fine = math.isfinite(x.sum()) and (
            P is None or bool(abs(P).max() * n <= self.max_covariance_trace))
        if fine and nis is not None:
            fine = bool(nis.max() <= self._nis_threshold) and not s.nis_run.any()
        if fine:
            s.x = _owned(x)
            if P is not None:
                s.P = _owned(P)
            s.nis[:] = np.nan if nis is None else nis
            return
        finite = np.all(np.isfinite(x), axis=1)
        blown = ~finite
        if P is not None:                              # (a filter without covariance: None)
            finite_P = np.all(np.isfinite(P), axis=(1, 2))
            finite &= finite_P
            trace = np.trace(P, axis1=1, axis2=2)
            blown = ~finite | (np.where(finite, trace, 0.0) > self.max_covariance_trace)
        if nis is not None:
            high = valid & ~(nis <= self._nis_threshold)      # NaN counts as above
            s.nis_run = np.where(high, s.nis_run + 1, 0)
            blown |= s.nis_run >= self.nis_patience
        s.diverged |= blown
        s.x = np.where(finite[:, None], x, s.x)
        if P is not None:
            keep = finite_P if P.shape[0] < x.shape[0] else finite
            s.P = np.where(keep[:, None, None], P, s.P)
        s.nis[:] = np.nan if nis is None else nis

    def _first_steps(self, x: FloatArray, P: FloatArray | None, nis: FloatArray | None,
                     logdet: FloatArray | None, x_prior: FloatArray, P_prior: FloatArray,
                     Y: FloatArray, valid: np.ndarray) -> StepResult:
        """Replace the rows of restarted systems by their first step (an update only)."""
        idx = np.flatnonzero(self._state.fresh)
        xs, Ps, ns, lds = _four(self._update_systems(idx, x_prior[idx], P_prior[idx], Y[idx],
                                                     valid[idx]))
        x = np.array(x)
        x[idx] = xs
        if P is not None and Ps is not None:
            P = np.array(np.broadcast_to(P, (x.shape[0], *P.shape[1:])))
            P[idx] = Ps
        if nis is not None:
            nis = np.array(nis)
            nis[idx] = np.nan if ns is None else ns
        if logdet is not None:
            logdet = np.array(logdet)
            logdet[idx] = np.nan if lds is None else lds
        return x, P, nis, logdet

    # ------------------------------------------------------------------ the boundary
    def _measurement(self, y: ArrayLike | None) -> tuple[FloatArray, np.ndarray]:
        """``y`` as ``(B, n_y)`` float64 and the mask of usable rows (``nan_policy``; ``None``
        and masked entries are missing whatever the policy)."""
        s = self._state
        if type(y) is not np.ndarray or y.dtype is not _F64:
            if y is None:
                return self._no_measurement()
            if isinstance(y, np.ma.MaskedArray):
                return self._masked_measurement(y)
            y = real_array("y", y)
        if y.shape == self._y_shape:
            Y = y[None] if s.single else y
        else:
            Y = self._first_measurement(y)
        if _all_finite(Y):
            s.every_usable = True
            return Y, self._all_valid
        s.every_usable = False
        valid = np.all(np.isfinite(Y), axis=1)
        if self.nan_policy == "raise":
            raise ValueError("y must be finite (nan_policy='raise'); got NaN or inf in the "
                             "measurement. Pass nan_policy='skip' to treat it as missing.")
        return np.where(valid[:, None], Y, 0.0), valid

    def _no_measurement(self) -> tuple[FloatArray, np.ndarray]:
        """``step(None)``: no system has a measurement (before the first step: one system, or
        the batched prior's batch)."""
        s = self._state
        if not s.batch:
            self._ensure_batch(self._batch or 1, self._batch is None)
        s.every_usable = False
        return np.zeros((s.batch, self._n_y)), np.zeros(s.batch, bool)

    def _masked_measurement(self, y: np.ma.MaskedArray) -> tuple[FloatArray, np.ndarray]:
        """A masked array: a system with any masked entry has no measurement this step."""
        mask = np.ma.getmaskarray(y)
        data = np.array(real_array("y", np.ma.getdata(y)), dtype=np.float64)
        data[mask] = 0.0
        Y, valid = self._measurement(data)
        if not mask.any():
            return Y, valid
        missing = mask.reshape(Y.shape).any(axis=1)
        self._state.every_usable = False
        return Y, valid & ~missing

    def _first_measurement(self, y: FloatArray) -> FloatArray:
        """A measurement of a shape not yet seen: the first one (which fixes the batch), a
        scalar for ``n_y = 1``, or an error."""
        s = self._state
        n_y = self._n_y
        Y = as_batch("y", y, n_y)                      # raises on a wrong shape
        single = Y.ndim == 1
        Y = Y.reshape(1, n_y) if single else Y
        if not s.batch:
            self._ensure_batch(Y.shape[0], single)
        elif Y.shape[0] != s.batch or single != s.single:
            want = f"({n_y},)" if s.single else f"({s.batch}, {n_y})"
            raise ValueError(f"y must have shape {want} like the earlier measurements; got "
                             f"{'a single measurement' if single else f'a batch of {len(Y)}'}")
        return Y

    def _input(self, u: ArrayLike) -> FloatArray:
        """``u`` as ``(B, n_u)`` float64 (one ``(n_u,)`` input serves every system)."""
        if type(u) is not np.ndarray or u.dtype is not _F64:
            u = real_array("u", u)
        U = self._no_input
        n_b, n_u = U.shape
        if u.shape == U.shape:
            U = u
        elif u.shape == (n_u,) or (u.ndim == 0 and n_u == 1):
            U = u.reshape(1, n_u) if n_b == 1 else np.broadcast_to(u.reshape(1, n_u), U.shape)
        else:
            raise ValueError(f"u must have shape ({n_u},) or ({n_b}, {n_u}); got {u.shape}")
        if n_u and not _all_finite(u):
            raise ValueError("u must be finite")
        return U

    def _ensure_batch(self, n_batch: int, single: bool) -> None:
        s = self._state
        if self._batch is not None and (single or n_batch != self._batch):
            raise ValueError(f"y must have shape ({self._batch}, {self.model.n_y}) to match the "
                             f"batched prior; got {'a single measurement' if single else n_batch}")
        s.single = single and self._batch is None
        s.batch = n_batch
        self._y_shape = (self._n_y,) if s.single else (n_batch, self._n_y)
        n = self.model.n_x
        s.allocate(np.broadcast_to(self._x0, (n_batch, n)),
                             np.broadcast_to(self._P0, (n_batch, n, n)))
        self._all_valid = np.ones(n_batch, bool)
        self._last_valid = self._all_valid
        #: ``predict`` masks of the compiled twins: every system, none (the first step)
        self._all_predict = np.ones(n_batch, bool)
        self._none_predict = np.zeros(n_batch, bool)
        self._no_input = np.zeros((n_batch, self.model.n_u))
        self._init_batch(n_batch)
        if self._delay:
            self._line = DelayLine(self._delay, n_batch, self.model.n_u)
            self._ahead = (s.x.copy(), np.array(np.broadcast_to(
                s.P, (n_batch, n, n)), order="C"))

    def _predicting(self) -> np.ndarray:
        """The systems that predict this step (the compiled twins' ``predict`` mask)."""
        s = self._state
        if s.update_next:
            return self._none_predict
        return ~s.fresh if s.restarting else self._all_predict

    def _out(self, a: FloatArray) -> FloatArray:
        return a[0].copy() if self._state.single else a.copy()


def _four(out: StepResult) -> tuple[Any, Any, Any, Any]:
    """A numpy hook's ``(x, P, nis)`` or ``(x, P, nis, log det S)`` as four items."""
    return (out[0], out[1], out[2], out[3] if len(out) > 3 else None)


def _owned(a: FloatArray) -> FloatArray:
    """``a`` if it owns its (writable, C-contiguous) data, else a copy: the state must never be
    a view of another array, or of a broadcast (the compiled twins write it in place)."""
    if a.base is None and a.flags.writeable and a.flags.c_contiguous:
        return a
    return np.array(a, order="C")
