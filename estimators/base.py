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
  broadcast. A batch of one is not a special code path.
* ``x``, ``P`` (where defined), ``diverged`` and ``last_info`` are readable;
  returned arrays are fresh copies.
* ``restart(systems)`` sends some systems of a batch back to their prior: their
  next ``step`` consumes a first measurement (update only) while the others
  predict and update as usual — what a vector env's autoreset needs.

**Non-finite measurements** follow ``nan_policy``: ``"raise"`` (default) raises
``ValueError`` naming ``y``; ``"skip"`` treats the measurement of a system whose
``y`` has any NaN as missing (that system predicts only).

**Divergence.** After every step a system is flagged as diverged when its
estimate or covariance is non-finite, when ``trace(P)`` exceeds
``max_covariance_trace``, or when its normalised innovation squared has stayed
above the ``1 - nis_tail`` χ² quantile for ``nis_patience`` consecutive steps.
The flag is sticky until ``reset``. A system whose estimate became non-finite
keeps its last finite estimate (and covariance), so NaN never reaches a caller.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_batch, as_covariance, one_of, positive
from .model import StateSpaceModel

NAN_POLICIES = ("raise", "skip")


class Estimator(ABC):
    """Base class of all filters: prior handling, batching, validation, divergence.

    Subclasses implement :meth:`_update` (the first step) and
    :meth:`_predict_update` (later steps) on batched arrays ``x (B, n_x)``,
    ``P (B, n_x, n_x)``, ``y (B, n_y)``, ``u (B, n_u)`` and a boolean mask
    ``valid (B,)`` of systems whose measurement is usable. They return the new
    ``x``, ``P`` (or ``None`` for filters without one) and the normalised
    innovation squared per system (or ``None``).
    """

    #: short registry name (``"kf"``, ``"efir"``, ...)
    name: ClassVar[str] = ""
    #: whether the filter needs and uses the prior (x0, P0); FIR filters do not
    uses_prior: ClassVar[bool] = True
    #: whether the filter reports an error covariance ``P`` (a controller may observe it)
    provides_covariance: ClassVar[bool] = True
    #: the plant attribute holding the model this filter is built from
    model_attribute: ClassVar[str] = "model"

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
    ) -> None:
        if not isinstance(model, StateSpaceModel):
            raise TypeError(f"model must be a StateSpaceModel; got {type(model).__name__}")
        one_of("nan_policy", nan_policy, NAN_POLICIES)
        self.model = model
        self._n_y = model.n_y
        self.nan_policy = nan_policy
        self.max_covariance_trace = positive("max_covariance_trace", max_covariance_trace)
        tail = positive("nis_tail", nis_tail)
        if tail >= 1:
            raise ValueError(f"nis_tail must be in (0, 1); got {nis_tail!r}")
        self.nis_patience = positive("nis_patience", nis_patience, integer=True)
        self._nis_threshold = float(scipy.stats.chi2.isf(tail, model.n_y))
        self.reset(x0, P0)

    # ------------------------------------------------------------------ public API
    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None) -> None:
        """Set the prior of ``x[0]``: mean ``x0`` (default 0) and covariance ``P0`` (default I).

        ``x0`` may be ``(n_x,)`` or ``(B, n_x)``; ``P0`` may be ``(n_x, n_x)`` or
        ``(B, n_x, n_x)``, symmetric positive semi-definite.
        """
        n = self.model.n_x
        x0_ = np.zeros(n) if x0 is None else as_batch("x0", x0, n)
        if not np.all(np.isfinite(x0_)):
            raise ValueError("x0 must be finite")
        if P0 is None:
            P0_ = np.eye(n)
        else:
            P0_ = np.asarray(P0, dtype=np.float64)
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
        self._x: FloatArray | None = None
        self._P: FloatArray | None = None
        self._k = 0
        self._diverged: np.ndarray | None = None
        self._nis_run: np.ndarray | None = None
        self._fresh: np.ndarray | None = None
        self._restarting = False
        self._lean: Any = None
        self._lean_cache: tuple[Any, ...] = (None, None, (), ())
        self.last_info: dict[str, Any] = {}
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
        if self._x is None:
            return
        n_b = self._x.shape[0]
        mask = np.zeros(n_b, bool)
        try:
            mask[np.asarray(systems)] = True
        except (IndexError, ValueError, TypeError):
            raise ValueError(f"systems must be a boolean mask of length {n_b} or indices below "
                             f"{n_b}; got {systems!r}") from None
        if np.asarray(systems).dtype == bool and np.asarray(systems).shape != (n_b,):
            raise ValueError(f"systems must be a boolean mask of length {n_b}; got shape "
                             f"{np.asarray(systems).shape}")
        if not mask.any():
            return
        if mask.all():
            self.reset(self._x0, self._P0)
            return
        n = self.model.n_x
        self._x = np.array(self._x)
        self._x[mask] = np.broadcast_to(self._x0, (n_b, n))[mask]
        if self._P is not None:
            self._P = np.array(self._P)
            self._P[mask] = np.broadcast_to(self._P0, (n_b, n, n))[mask]
        self._diverged[mask] = False
        self._nis_run[mask] = 0
        self._nis_running = bool(self._nis_run.any())
        self._fresh |= mask
        self._restarting = True
        self._restart_systems(mask)

    def step(self, y: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """Consume ``y[k]`` (and ``u[k-1]``) and return the estimate of ``x[k]``.

        The hot path is kept lean (a filter step on a small system costs a few
        microseconds): shapes are checked with attribute look-ups, finiteness
        with one reduction, and the exact per-system bookkeeping of
        :meth:`_accept` runs only when something is off. Floating-point
        warnings are silenced inside the hooks: a diverging filter is reported
        through :attr:`diverged`, not through ``RuntimeWarning``.
        """
        lean = self._lean
        if lean is not None and self._k:
            out = lean(y, u)
            if out is not None:
                return out
        n_y = self._n_y
        Y = np.asarray(y, dtype=np.float64)
        if Y.ndim == 2 and Y.shape[1] == n_y:
            single = False
        elif Y.ndim == 1 and Y.shape[0] == n_y:
            Y, single = Y.reshape(1, n_y), True
        else:
            Y = as_batch("y", Y, n_y)       # raises on a wrong shape, or
            single = Y.ndim == 1           # accepts a scalar when n_y == 1
            Y = Y.reshape(1, n_y) if single else Y
        if self._x is None or Y.shape[0] != self._x.shape[0] or single != self._single:
            self._ensure_batch(Y.shape[0], single)
        valid = self._all_valid
        if not math.isfinite(Y.sum()):
            valid = np.all(np.isfinite(Y), axis=1)
            if valid.all():             # the sum overflowed; every value is finite
                valid = self._all_valid
        if valid is not self._all_valid:
            if self.nan_policy == "raise":
                raise ValueError(
                    "y must be finite (nan_policy='raise'); got NaN or inf in the measurement. "
                    "Pass nan_policy='skip' to treat it as missing."
                )
            Y = np.where(valid[:, None], Y, 0.0)
        U = self._no_input if u is None else self._check_u(u, Y.shape[0])
        with np.errstate(all="ignore"):
            if self._k == 0:
                x, P, nis = self._update(self._x, self._P, Y, valid)
            else:
                x_prior, P_prior = self._x, self._P
                x, P, nis = self._predict_update(x_prior, P_prior, Y, U, valid)
                if self._restarting:
                    x, P, nis = self._first_steps(x, P, nis, x_prior, P_prior, Y, valid)
            self._accept(x, P, nis, valid)
        self._k += 1
        return self._x[0].copy() if self._single else self._x.copy()

    @property
    def x(self) -> FloatArray:
        """The current estimate (the prior mean before the first step); a copy."""
        if self._x is None:
            return self._x0.copy()
        return self._out(self._x)

    @property
    def P(self) -> FloatArray | None:
        """The current error covariance (or ``None`` where the filter has none); a copy."""
        if self._x is None:
            return self._P0.copy()
        return None if self._P is None else self._out(self._P)

    @property
    def diverged(self) -> bool | np.ndarray:
        """Sticky divergence flag: a bool, or a ``(B,)`` array for a batch."""
        if self._diverged is None:
            return False if not self._batched_prior else np.zeros(self._batch or 0, bool)
        return bool(self._diverged[0]) if self._single else self._diverged.copy()

    @property
    def time_step(self) -> int:
        """Number of measurements consumed since ``reset``."""
        return self._k

    # ------------------------------------------------------------------ to implement
    def _reset_state(self) -> None:  # noqa: B027 (optional hook)
        """Hook for subclasses to clear their own state on ``reset``."""

    def _restart_systems(self, mask: np.ndarray) -> None:  # noqa: B027 (optional hook)
        """Hook: clear the per-system state of the systems in ``mask`` (see :meth:`restart`)."""

    def _update_systems(self, idx: np.ndarray, x: FloatArray, P: FloatArray | None,
                        y: FloatArray, valid: np.ndarray
                        ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """First step of the restarted systems ``idx`` (their prior rows ``x``, ``P``).

        The default calls :meth:`_update` on the sub-batch, which is right for filters
        whose first step depends only on its arguments; filters with more per-system
        state override it.
        """
        return self._update(x, P, y, valid)

    @abstractmethod
    def _update(
        self, x: FloatArray, P: FloatArray | None, y: FloatArray, valid: np.ndarray
    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """First step: measurement update of the prior with ``y[0]``."""

    @abstractmethod
    def _predict_update(
        self, x: FloatArray, P: FloatArray | None, y: FloatArray, u: FloatArray,
        valid: np.ndarray,
    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """Later steps: predict with ``u[k-1]``, then update with ``y[k]``."""

    # ------------------------------------------------------------------ helpers
    def _ensure_batch(self, n_batch: int, single: bool) -> None:
        if self._x is not None:
            if n_batch != self._x.shape[0] or single != self._single:
                n_y = self.model.n_y
                want = f"({n_y},)" if self._single else f"({self._x.shape[0]}, {n_y})"
                raise ValueError(f"y must have shape {want} like the earlier measurements; "
                                 f"got a batch of {n_batch}")
            return
        if self._batch is not None and (single or n_batch != self._batch):
            raise ValueError(f"y must have shape ({self._batch}, {self.model.n_y}) to match the "
                             f"batched prior; got {'a single measurement' if single else n_batch}")
        self._single = single and self._batch is None
        n = self.model.n_x
        self._x = np.array(np.broadcast_to(self._x0, (n_batch, n)))
        self._P = np.array(np.broadcast_to(self._P0, (n_batch, n, n)))
        self._diverged = np.zeros(n_batch, bool)
        self._fresh = np.zeros(n_batch, bool)
        self._nis_run = np.zeros(n_batch, int)
        self._nis_running = False
        self._all_valid = np.ones(n_batch, bool)
        self._all_valid.setflags(write=False)
        self._no_input = np.zeros((n_batch, self.model.n_u))
        self._no_input.setflags(write=False)
        self._lean_u0 = [0.0] * self.model.n_u
        self._init_batch(n_batch)
        self._lean = self._make_lean() if self._single else None

    def _init_batch(self, n_batch: int) -> None:  # noqa: B027 (optional hook)
        """Hook: allocate per-system state once the batch size is known."""

    # ------------------------------------------------------------------ single-system fast path
    def _make_lean(self) -> Callable[[Any, Any], FloatArray | None] | None:
        """Hook: a fast step for one system, ``(y, u) -> x̂`` or ``None`` (general path).

        Called once the batch is known to be a single system. The returned function
        must compute what :meth:`_predict_update` + :meth:`_accept` would, to
        round-off (the tests check 1e-12), and must not change any state before it
        commits (:func:`~._lean.commit`); returning ``None`` hands the step to the
        general path (a NaN measurement, an unusual shape, a covariance that is not
        positive definite, a divergence test that fails, ...). It runs only after
        the first step (the first step is an update only, on the general path).
        """
        return None

    def _check_u(self, u: ArrayLike, n_batch: int) -> FloatArray:
        n_u = self.model.n_u
        u_ = np.asarray(u, dtype=np.float64)
        if u_.shape == (n_batch, n_u):
            pass
        elif u_.shape == (n_u,) or (u_.ndim == 0 and n_u == 1):
            u_ = u_.reshape(1, n_u)
            if n_batch > 1:
                u_ = np.broadcast_to(u_, (n_batch, n_u))
        else:
            raise ValueError(f"u must have shape ({n_u},) or ({n_batch}, {n_u}); got {u_.shape}")
        if not np.isfinite(u_).all():
            raise ValueError("u must be finite")
        return u_

    def _accept(self, x: FloatArray, P: FloatArray | None, nis: FloatArray | None,
                valid: np.ndarray) -> None:
        """Store the new estimate, keeping the last finite one where the new is not.

        Fast path: one finiteness reduction over ``x``, ``max |P|`` (``trace P <=
        n max|P|``, so ``n max|P| <= max_covariance_trace`` clears every system)
        and ``max nis``. Only when one of them fails are the exact per-system
        masks computed.
        """
        n = x.shape[1]
        fine = math.isfinite(x.sum())
        if fine and P is not None:
            fine = bool(abs(P).max() * n <= self.max_covariance_trace)
        if fine and nis is not None and (self._nis_running or not nis.max() <= self._nis_threshold):
            fine = False
        if fine:
            self._x = x
            self._P = P
            if self._single:
                self.last_info = {"diverged": bool(self._diverged[0]),
                                  "nis": None if nis is None else float(nis[0])}
            else:
                self.last_info = {"diverged": self._diverged.copy(),
                                  "nis": None if nis is None else nis.copy()}
            return
        finite = np.all(np.isfinite(x), axis=1)
        if P is not None:
            finite &= np.all(np.isfinite(P), axis=(1, 2))
            trace = np.trace(P, axis1=1, axis2=2)
            blown = ~finite | (np.where(finite, trace, 0.0) > self.max_covariance_trace)
        else:
            blown = ~finite
        if nis is not None:
            high = valid & (np.nan_to_num(nis, nan=np.inf) > self._nis_threshold)
            self._nis_run = np.where(high, self._nis_run + 1, 0)
            self._nis_running = bool(self._nis_run.any())
            blown |= self._nis_run >= self.nis_patience
        self._diverged |= blown
        self._x = np.where(finite[:, None], x, self._x)
        if P is not None:
            self._P = P if self._P is None else np.where(finite[:, None, None], P, self._P)
        else:
            self._P = None
        self.last_info = {"diverged": self.diverged, "nis": None if nis is None else
                          (float(nis[0]) if self._single else nis.copy())}

    def _first_steps(self, x: FloatArray, P: FloatArray | None, nis: FloatArray | None,
                     x_prior: FloatArray, P_prior: FloatArray | None, Y: FloatArray,
                     valid: np.ndarray) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """Replace the rows of restarted systems by their first step (an update only)."""
        idx = np.flatnonzero(self._fresh)
        xs, Ps, ns = self._update_systems(idx, x_prior[idx],
                                          None if P_prior is None else P_prior[idx],
                                          Y[idx], valid[idx])
        x = np.array(x)
        x[idx] = xs
        if P is not None and Ps is not None:
            P = np.array(np.broadcast_to(P, (x.shape[0], *P.shape[1:])))
            P[idx] = Ps
        if nis is not None:
            nis = np.array(nis)
            nis[idx] = np.nan if ns is None else ns
        self._fresh[:] = False
        self._restarting = False
        return x, P, nis

    def _out(self, a: FloatArray) -> FloatArray:
        return a[0].copy() if self._single else a.copy()
