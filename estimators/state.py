"""The state record of a filter: one object that holds everything a step reads and writes.

Every :class:`~fir_gym.estimators.base.Estimator` owns one :class:`FilterState` (its
:attr:`~fir_gym.estimators.base.Estimator.state`) and passes it whole — to its numpy
reference step, to its compiled twin (:mod:`~fir_gym.estimators.compiled`, which reads the
arrays by name and writes them in place) and to the public ``predict``/``update`` steps
(:meth:`FilterState.branch`). No module reaches into another object's private attributes
for them (docs/architecture.md#filter-state).

The record holds the state every filter shares: the estimate ``x (B, n)``, the covariance
``P (B, n, n)`` (``(1, n, n)`` when one covariance is shared by the batch), the divergence
watch per system (``diverged``, ``nis_run``, ``nis``, ``logdet``), the innovation gate's
bookkeeping (``gated``, ``gated_count``), the step flags (``k``, ``update_next``,
``restarting``, ``fresh``, ``every_usable``) and the watch's limits. A filter's own state
(a FIR window bank, a UKF's sigma points, a KF's steady-state gains) stays with the filter
and goes to its twin as the filter's own record.

``limits`` is a float64 array indexed by the names below (the compiled kernels read it in
one argument; an array costs a numba dispatch 40 ns, a tuple of numbers several times that).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ._validation import FloatArray

__all__ = ["GATE", "MAX_ESTIMATE", "MAX_TRACE", "NIS_PATIENCE", "NIS_THRESHOLD",
           "FilterState", "new_limits"]

#: index of ``limits``: the χ² threshold of the NIS watch (``n_y`` degrees of freedom)
NIS_THRESHOLD = 0
#: index of ``limits``: consecutive high-NIS steps that flag divergence
NIS_PATIENCE = 1
#: index of ``limits``: the divergence limit on ``trace P``
MAX_TRACE = 2
#: index of ``limits``: the windowed filters' growth bound on ``|x|`` (inf: none)
MAX_ESTIMATE = 3
#: index of ``limits``: the innovation gate's NIS threshold (inf: no gate)
GATE = 4


def new_limits(nis_threshold: float, nis_patience: int, max_trace: float) -> FloatArray:
    """A ``limits`` array: the watch's three limits, no growth bound, no gate."""
    limits = np.full(5, np.inf)
    limits[NIS_THRESHOLD] = nis_threshold
    limits[NIS_PATIENCE] = float(nis_patience)
    limits[MAX_TRACE] = max_trace
    return limits


def _empty(n: int) -> FloatArray:
    return np.empty((0, n))


@dataclass(eq=False, slots=True)
class FilterState:
    """The state of one filter over a batch of ``batch`` systems (``0`` before the first step).

    Attributes:
        x: the estimate of every system ``(B, n)``.
        P: the error covariance ``(B, n, n)``, or ``(1, n, n)`` shared by the batch.
        diverged: the sticky divergence flag per system ``(B,)``.
        nis_run: consecutive steps with the NIS above its threshold ``(B,)``.
        nis: the last normalised innovation squared ``(B,)`` (NaN: none).
        logdet: ``log det S`` of the last innovation ``(B,)`` (NaN: none).
        limits: the watch's and the gate's limits (indices :data:`NIS_THRESHOLD` ...).
        gated: whether the gate rejected this step's measurement ``(B,)``.
        gated_count: rejections since the system's (re)start ``(B,)``.
        fresh: the systems restarted since the last step ``(B,)``.
        k: measurements consumed since ``reset``.
        update_next: whether the next step is an update only (the first after ``reset``,
            or one after ``predict``).
        restarting: whether some system restarted since the last step (``fresh`` has one).
        every_usable: whether every system's measurement of this step is usable (the
            shortcuts of a shared or steady covariance hold only then): written by the
            measurement's check at each step, read only within that step.
        single: whether the caller steps one system (shapes ``(n,)``), not a batch.
    """

    n: int
    limits: FloatArray
    batch: int = 0
    x: FloatArray = field(default_factory=lambda: _empty(0))
    P: FloatArray = field(default_factory=lambda: np.empty((0, 0, 0)))
    diverged: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    nis_run: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    nis: FloatArray = field(default_factory=lambda: np.zeros(0))
    logdet: FloatArray = field(default_factory=lambda: np.zeros(0))
    gated: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gated_count: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fresh: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    k: int = 0
    update_next: bool = True
    restarting: bool = False
    every_usable: bool = True
    single: bool = False

    def __post_init__(self) -> None:
        if self.x.shape != (self.batch, self.n):
            self.x = np.empty((self.batch, self.n))
        if self.P.shape[1:] != (self.n, self.n):
            self.P = np.empty((self.batch, self.n, self.n))

    @classmethod
    def of_batch(cls, x: FloatArray, P: FloatArray, limits: FloatArray) -> FilterState:
        """The state of ``len(x)`` systems starting at ``x (B, n)``, ``P (B | 1, n, n)``."""
        state = cls(n=x.shape[1], limits=limits)
        state.allocate(x, P)
        return state

    def allocate(self, x: FloatArray, P: FloatArray) -> None:
        """Hold ``len(x)`` systems from ``x (B, n)`` and ``P (B | 1, n, n)`` (copied, C order),
        every watch entry cleared (the first step fixes the batch). The record stays the same
        object: whoever holds it sees the new arrays."""
        n_b = x.shape[0]
        self.batch = n_b
        self.x = np.array(x, dtype=np.float64, order="C")
        self.P = np.array(P, dtype=np.float64, order="C")
        self.diverged = np.zeros(n_b, bool)
        self.nis_run = np.zeros(n_b, np.int64)
        self.nis = np.full(n_b, np.nan)
        self.logdet = np.full(n_b, np.nan)
        self.gated = np.zeros(n_b, bool)
        self.gated_count = np.zeros(n_b, np.int64)
        self.fresh = np.zeros(n_b, bool)

    @contextmanager
    def branch(self, *, update_only: bool, keep_nis_run: bool = False) -> Iterator[None]:
        """Take the next step on a chosen branch: an update only (``update_only``), or a
        prediction (then ``k`` counts at least one step, so a time-varying model's ``A(k-1)``
        exists) — the public ``predict``/``update`` steps (:mod:`.public_steps`).

        With ``keep_nis_run`` the NIS run of the watch is left as it was (a prediction is not
        an innovation). After a prediction the next step is an update only; a step that
        raises leaves the branch flag as it found it.
        """
        k, pending = self.k, self.update_next
        run = self.nis_run.copy() if keep_nis_run else None
        self.update_next = update_only
        if not update_only:
            self.k = max(k, 1)
        try:
            yield
        except BaseException:
            self.update_next = pending
            raise
        finally:
            if not update_only:
                self.k = k
            if run is not None and self.nis_run.shape == run.shape:
                self.nis_run[:] = run
        if not update_only:
            self.update_next = True
