"""The attributes of an estimator that a user may assign, and what assigning them does.

Every public attribute either takes effect at the next step or refuses the assignment
with an error that says what to do (no silent traps): ``model`` on the Kalman family
(``model_reassignable``; the filter rebuilds what it derived from it in
``_model_changed``), refused on the filters that precompute gains from it;
``nan_policy``, ``nis_patience``, ``max_covariance_trace`` and ``gate`` validated and live
(the last three are entries of the state record's ``limits``, :mod:`.state`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import scipy.stats

from ._validation import one_of, open_probability, positive
from .model import StateSpaceModel
from .state import GATE, MAX_TRACE, NIS_PATIENCE

__all__ = ["NAN_POLICIES", "LiveAttributes"]

NAN_POLICIES = ("raise", "skip")


class LiveAttributes:
    """Mixin of :class:`~fir_gym.estimators.base.Estimator`: its assignable attributes."""

    #: whether ``est.model = new_model`` takes effect (the class rebuilds what it derived from
    #: the model in :meth:`_model_changed`); otherwise assignment is refused
    model_reassignable: ClassVar[bool] = False

    #: whether the step can reject a measurement by its NIS (``gate=``, the innovation gate)
    can_gate: ClassVar[bool] = False
    #: why a class that cannot gate refuses ``gate`` (its error message)
    no_gate_reason: ClassVar[str] = "its step has no innovation gate"

    if TYPE_CHECKING:
        _limits: np.ndarray
        _nan_policy: str
        _n_y: int
        reports_nis: ClassVar[bool]

    @property
    def model(self) -> StateSpaceModel:
        """The filter's model. Assigning a new one of the same sizes (``n_x, n_y, n_u``) takes
        effect at the next step on the Kalman family (``model_reassignable``), the state and
        covariance kept — e.g. ``kf.model = kf.model.replace(R=2 * kf.model.R)``; the other
        filters, which precompute gains from their model, refuse it with an error."""
        return self._filter_model

    @model.setter
    def model(self, model: StateSpaceModel) -> None:
        if "_filter_model" not in self.__dict__ or model is self._filter_model:
            self._filter_model: StateSpaceModel = model    # the constructor's assignment
            return
        name = type(self).__name__
        if not self.model_reassignable:
            raise AttributeError(f"{name}.model cannot be reassigned: the filter precomputes "
                                 f"its gains from the model. Build a new {name} from the new "
                                 f"model instead")
        if not isinstance(model, StateSpaceModel):
            raise TypeError(f"model must be a StateSpaceModel; got {type(model).__name__}")
        old = self._filter_model
        sizes = ("n_x", "n_y", "n_u")
        if any(getattr(model, a) != getattr(old, a) for a in sizes):
            raise ValueError(f"model must keep the sizes of {name}'s model "
                             f"(n_x, n_y, n_u = {tuple(getattr(old, a) for a in sizes)}); "
                             f"got {tuple(getattr(model, a) for a in sizes)}: build a new filter")
        self._filter_model = model
        try:
            self._model_changed()
        except Exception:
            self._filter_model = old
            self._model_changed()
            raise

    @contextmanager
    def _stepping_with(self, model: StateSpaceModel | None) -> Iterator[None]:
        """Step with ``model`` (of the same sizes, e.g. this call's ``R`` or ``H``) inside the
        block, and with the filter's own model again after it, whatever happens (``None``:
        the filter's own model throughout). The public ``update(y, R=..., H=...)`` of the
        Kalman family (:mod:`.public_steps`)."""
        if model is None:
            yield
            return
        own = self._filter_model
        self._filter_model = model
        self._model_changed()
        try:
            yield
        finally:
            self._filter_model = own
            self._model_changed()

    def _model_changed(self) -> None:
        """Hook: rebuild what the filter derived from ``self.model`` (a new one was assigned)."""

    @property
    def max_covariance_trace(self) -> float:
        """Divergence limit on ``trace(P)`` (assignable)."""
        return float(self._limits[MAX_TRACE])

    @max_covariance_trace.setter
    def max_covariance_trace(self, value: float) -> None:
        self._limits[MAX_TRACE] = positive("max_covariance_trace", value)

    @property
    def nis_patience(self) -> int:
        """Consecutive high-NIS steps that flag divergence (assignable)."""
        return int(self._limits[NIS_PATIENCE])

    @nis_patience.setter
    def nis_patience(self, value: int) -> None:
        self._limits[NIS_PATIENCE] = float(positive("nis_patience", value, integer=True))

    @property
    def gate(self) -> float | None:
        """The innovation gate: ``None`` (no gate) or a probability ``0 < gate < 1``
        (assignable; docs/architecture.md#nonfinite-and-divergence).

        A usable measurement whose normalised innovation squared exceeds
        ``scipy.stats.chi2.ppf(gate, n_y)`` is treated as missing for its system (the
        estimate, covariance and all other state end exactly as with that measurement
        missing); ``last_info["nis"]`` still reports its NIS, and the divergence watch still
        counts it. A class that cannot gate (``can_gate`` False) refuses any value but ``None``
        with a ``ValueError``.
        """
        return self._gate

    @gate.setter
    def gate(self, value: float | None) -> None:
        if value is None:
            self._gate: float | None = None
            self._gate_threshold: float | None = None
            self._limits[GATE] = np.inf
            return
        gate = open_probability("gate", value)
        if not self.can_gate:
            reason = (self.no_gate_reason if self.reports_nis
                      else "it computes no normalised innovation squared to gate on")
            raise ValueError(f"gate: {type(self).__name__} cannot gate its measurements "
                             f"({reason}); leave gate=None")
        self._gate = gate
        #: the NIS above which a measurement is rejected: χ²(n_y)'s ``gate`` quantile
        self._gate_threshold = float(scipy.stats.chi2.ppf(gate, self._n_y))
        self._limits[GATE] = self._gate_threshold

    @property
    def nan_policy(self) -> str:
        """``"raise"`` or ``"skip"`` for non-finite measurements (assignable)."""
        return self._nan_policy

    @nan_policy.setter
    def nan_policy(self, value: str) -> None:
        self._nan_policy = one_of("nan_policy", value, NAN_POLICIES)

