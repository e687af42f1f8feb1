"""Kalman filter over batched pure functions (the linearised one: :mod:`.linearized`).

The two pure functions are the textbook recursion (e.g. Simon, *Optimal State
Estimation*, 2006, eqs 5.17–5.19), batched over a leading axis:

    predict   x⁻ = F x + B u,                 P⁻ = F P Fᵀ + Q
    update    e = y − H x⁻,  S = H P⁻ Hᵀ + R,  K = P⁻ Hᵀ S⁻¹,
              x⁺ = x⁻ + K e,
              P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ          (Joseph form)

``S⁻¹`` is never formed by ``inv``: ``K`` and the normalised innovation squared
``NIS = eᵀ S⁻¹ e`` come from a Cholesky factorisation of ``S`` (closed form for
``n_y <= 3``, vectorised over the batch). The Joseph form is evaluated from
factors (:func:`~._kalman_linalg.factored_joseph`), which keeps ``P⁺`` symmetric
positive semidefinite in floating point for any gain and any valid input
(docs/architecture.md#covariance-updates).

:class:`KalmanFilter` reads ``model.matrices(k)``; the pure functions also serve
:class:`~.linearized.LinearizedKalmanFilter` and :class:`~.extended.ExtendedKalmanFilter`.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol, cast

import numpy as np
from numpy.typing import ArrayLike

from ._kalman_linalg import (
    constant_or_batch,
    factored_joseph,
    logdet_of_inverse,
    mul_t,
    rmul,
    spd_inverse,
    symmetrize,
)
from ._validation import FloatArray
from .base import Estimator
from .compiled import kalman as compiled_kalman
from .errors import needs_linear
from .model import StateSpaceModel, SystemMatrices
from .public_steps import PublicSteps
from .registry import register_estimator
from .sequences import SmootherResult
from .smoothers import smooth_sequence
from .state import FilterState

__all__ = ["Innovation", "KalmanFilter", "kf_predict", "kf_update"]


class Innovation(NamedTuple):
    """Innovation statistics of one measurement update (batched like the state).

    Attributes:
        e: innovation ``y − ŷ`` (``(n_y,)`` or ``(B, n_y)``).
        S: innovation covariance ``H P⁻ Hᵀ + R``.
        nis: normalised innovation squared ``eᵀ S⁻¹ e`` (a float or ``(B,)``),
            χ²-distributed with ``n_y`` degrees of freedom for a consistent filter.
    """

    e: FloatArray
    S: FloatArray
    nis: FloatArray


# ---------------------------------------------------------------------------- kernels
def predict_covariance(P: FloatArray, F: FloatArray, Q: FloatArray) -> FloatArray:
    """Batched ``P⁻ = F P Fᵀ + Q`` (symmetrised); ``F`` 2-D (shared) or batched."""
    F = constant_or_batch(F)
    if F.ndim == 2:
        Ft = F.T
        P = rmul(rmul(P, Ft).mT, Ft) + Q      # (F (F P)ᵀ)ᵀ = F P Fᵀ for symmetric P
    else:
        P = mul_t(F @ P, F) + Q
    return symmetrize(P)


def predict_kernel(x: FloatArray, P: FloatArray, F: FloatArray, Q: FloatArray,
                   Bu: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Batched ``x⁻ = F x (+ B u)``, ``P⁻ = F P Fᵀ + Q``; no validation. ``F`` 2-D or 3-D."""
    F = constant_or_batch(F)
    x = rmul(x, F.T) if F.ndim == 2 else (F @ x[:, :, None])[:, :, 0]
    if Bu is not None:
        x = x + Bu
    return x, predict_covariance(P, F, Q)


def gain_kernel(P: FloatArray, H: FloatArray, R: FloatArray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Covariance half of the update: ``K = P Hᵀ S⁻¹`` and the Joseph-form ``P⁺``.

    Returns ``(K, W, P⁺)`` with ``W = S⁻¹`` (for the NIS). ``H`` and ``R`` are
    2-D (shared) or batched; ``P`` may be a batch of one shared by many systems.
    ``P⁺`` is the Joseph form computed from factors (:func:`~._kalman_linalg.factored_joseph`):
    symmetric positive semidefinite by construction.
    """
    if H.ndim == 2:
        PHt = rmul(P, H.T)                              # (B, n, m)
        S = rmul(PHt.mT, H.T) + R                       # H P Hᵀ + R (P symmetric)
    else:
        PHt = mul_t(P, H)
        S = H @ PHt + R
    W = spd_inverse(S)
    K = PHt @ W
    return K, W, factored_joseph(P, H, R, K)           # PSD by construction


def correct(x: FloatArray, e: FloatArray, K: FloatArray, W: FloatArray
            ) -> tuple[FloatArray, FloatArray]:
    """State half of the update: ``x⁺ = x + K e``, ``NIS = eᵀ W e`` (``K, W`` shared or not)."""
    if K.shape[0] == 1:
        x_new = x + np.dot(e, K[0].T)
        We = np.dot(e, W[0])
    else:
        x_new = x + (K @ e[:, :, None])[:, :, 0]
        We = (W @ e[:, :, None])[:, :, 0]
    return x_new, (We * e).sum(axis=1)


def update_kernel(x: FloatArray, P: FloatArray, e: FloatArray, H: FloatArray, R: FloatArray,
                  valid: np.ndarray | None = None, gate: float | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Batched Joseph-form update given the innovation ``e``; returns ``x⁺, P⁺, S⁻¹, nis``.

    ``H`` is ``(m, n)`` or ``(B, m, n)``; ``R`` is ``(m, m)`` or ``(B, m, m)``.
    A system whose ``S`` is not positive definite gets NaN (its caller flags it).
    Systems with ``valid`` False keep ``x, P`` (their ``nis`` is NaN); so do, with a
    ``gate`` (a NIS threshold, the innovation gate's), those whose NIS exceeds it (their
    ``nis`` is kept).
    """
    K, W, P_new = gain_kernel(P, constant_or_batch(H), constant_or_batch(R))
    x_new, nis = correct(x, e, K, W)
    x_new, P_new, nis = keep_usable(x_new, P_new, nis, x, P, valid, gate)
    return x_new, P_new, W, nis


def keep_usable(x_new: FloatArray, P_new: FloatArray, nis: FloatArray, x: FloatArray,
                P: FloatArray, valid: np.ndarray | None, gate: float | None
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The update where its measurement counts: a system without a usable measurement
    (``valid`` False) keeps its prior ``x, P`` and gets a NaN NIS; with ``gate``, one whose
    NIS exceeds it (the innovation gate; NaN compares False) keeps ``x, P`` too, exactly as
    if its measurement were missing, and its NIS."""
    keep = valid
    if gate is not None:
        rejected = nis > gate
        if rejected.any():
            keep = ~rejected if valid is None else valid & ~rejected
    if keep is not None and not keep.all():
        x_new = np.where(keep[:, None], x_new, x)
        P_new = np.where(keep[:, None, None], P_new, P)
    if valid is not None and not valid.all():
        nis = np.where(valid, nis, np.nan)
    return x_new, P_new, nis


# ---------------------------------------------------------------------------- pure functions
def _batch_args(x: ArrayLike, P: ArrayLike) -> tuple[FloatArray, FloatArray, bool]:
    x_ = np.asarray(x, dtype=np.float64)
    P_ = np.asarray(P, dtype=np.float64)
    if x_.ndim not in (1, 2):
        raise ValueError(f"x must have shape (n,) or (B, n); got shape {x_.shape}")
    n = x_.shape[-1]
    if P_.shape[-2:] != (n, n) or P_.ndim not in (2, 3) or P_.ndim - x_.ndim != 1 or (
            P_.ndim == 3 and P_.shape[0] != x_.shape[0]):
        want = f"({n}, {n})" if x_.ndim == 1 else f"({x_.shape[0]}, {n}, {n})"
        raise ValueError(f"P must have shape {want} to match x; got shape {P_.shape}")
    single = x_.ndim == 1
    return (x_[None], P_[None], True) if single else (x_, P_, False)


def _matrix_arg(name: str, M: ArrayLike | None, shape: tuple[int, int], n_b: int,
                single: bool) -> FloatArray:
    M_ = np.asarray(M, dtype=np.float64)
    if M_.ndim == 0 and shape == (1, 1):
        M_ = M_.reshape(1, 1)
    if M_.shape == shape or (not single and M_.shape == (n_b, *shape)):
        return M_
    batched = "" if single else f" or ({n_b}, {shape[0]}, {shape[1]})"
    raise ValueError(f"{name} must have shape {shape}{batched}; got shape {M_.shape}")


def kf_predict(x: ArrayLike, P: ArrayLike, F: ArrayLike, Q: ArrayLike,
               B: ArrayLike | None = None, u: ArrayLike | None = None
               ) -> tuple[FloatArray, FloatArray]:
    """Kalman prediction ``x⁻ = F x + B u``, ``P⁻ = F P Fᵀ + Q`` (symmetrised).

    Args:
        x: ``(n,)`` or ``(B, n)``. P: ``(n, n)`` or ``(B, n, n)``.
        F: ``(n, n)``, or ``(B, n, n)`` for a batch. Q: the state noise
            covariance ``G Q Gᵀ`` as an ``(n, n)`` (or batched) matrix.
        B, u: optional input matrix ``(n, n_u)`` and input ``(n_u,)``/``(B, n_u)``.

    Returns:
        ``(x⁻, P⁻)`` with the shapes of ``x`` and ``P``.
    """
    x_, P_, single = _batch_args(x, P)
    n_b, n = x_.shape
    F_ = _matrix_arg("F", F, (n, n), n_b, single)
    Q_ = _matrix_arg("Q", Q, (n, n), n_b, single)
    Bu = None
    if (B is None) != (u is None):
        raise ValueError("B and u must be given together")
    if B is not None:
        B_ = np.asarray(B, dtype=np.float64).reshape(n, -1)
        u_ = np.asarray(u, dtype=np.float64).reshape(-1, B_.shape[1])
        Bu = rmul(u_, B_.T)
    x_new, P_new = predict_kernel(x_, P_, F_, Q_, Bu)
    return (x_new[0], P_new[0]) if single else (x_new, P_new)


def kf_update(x: ArrayLike, P: ArrayLike, y: ArrayLike, H: ArrayLike, R: ArrayLike
              ) -> tuple[FloatArray, FloatArray, Innovation]:
    """Joseph-form Kalman measurement update; returns ``(x⁺, P⁺, Innovation(e, S, nis))``.

    Args:
        x: prior mean ``(n,)`` or ``(B, n)``. P: prior covariance.
        y: measurement ``(m,)`` or ``(B, m)``.
        H: ``(m, n)`` or ``(B, m, n)``. R: ``(m, m)`` or ``(B, m, m)``. For a one-state,
            one-output system ``H`` and ``R`` may be numbers (so may ``F`` and ``Q`` of
            :func:`kf_predict`).

    Raises:
        ValueError: on a shape mismatch, or when ``S = H P Hᵀ + R`` is not
            positive definite for some system.
    """
    x_, P_, single = _batch_args(x, P)
    n_b, n = x_.shape
    y_ = np.asarray(y, dtype=np.float64)
    H_ = np.asarray(H, dtype=np.float64)
    if H_.ndim == 0 and n == 1:                  # a scalar H of a one-state system: 1 x 1
        H_ = H_.reshape(1, 1)
    if H_.ndim < 2:
        raise ValueError(f"H must have shape (m, {n})" + ("" if single else f" or ({n_b}, m, {n})")
                         + f"; got shape {H_.shape}")
    m = H_.shape[-2]
    if y_.shape != ((m,) if single else (n_b, m)):
        raise ValueError(f"y must have shape ({m},) to match H; got {y_.shape}" if single else
                         f"y must have shape ({n_b}, {m}) to match x and H; got {y_.shape}")
    H_ = _matrix_arg("H", H_, (m, n), n_b, single)
    R_ = _matrix_arg("R", R, (m, m), n_b, single)
    Y = y_[None] if single else y_
    e = Y - (rmul(x_, H_.T) if H_.ndim == 2 else (H_ @ x_[:, :, None])[:, :, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        x_new, P_new, _, nis = update_kernel(x_, P_, e, H_, R_)
    S = (H_ @ P_ @ H_.mT if H_.ndim == 3 else H_ @ P_ @ H_.T) + R_
    bad = ~np.isfinite(nis)
    if bad.any():
        raise ValueError(f"S = H P Hᵀ + R is not positive definite for system(s) "
                         f"{np.flatnonzero(bad).tolist()}")
    if single:
        return x_new[0], P_new[0], Innovation(e[0], S[0], nis[0])
    return x_new, P_new, Innovation(e, S, nis)


# ---------------------------------------------------------------------------- filters
class KalmanFilter(PublicSteps, Estimator):
    """Linear Kalman filter on a :class:`LinearModel` or :class:`TimeVaryingLinearModel`.

    Convention for time-varying models (docs/architecture.md#time-varying-models): the prediction
    ``x[k-1] → x[k]`` uses ``A, B, G, Q`` of ``model.matrices(k-1)``; the update
    at ``k`` uses ``C, R`` of ``model.matrices(k)``. Options are those of
    :class:`~fir_gym.estimators.base.Estimator` (``nan_policy``, divergence limits).

    Two exact shortcuts, both because the covariance recursion of a linear
    model does not depend on the data:

    * **shared covariance** — systems of a batch started from one unbatched
      ``P0`` and always updated together have the same ``P``; it is held once
      (``(1, n, n)``) and computed once per step, so a batch costs one covariance
      update plus the state updates. A skipped measurement or a restart gives every
      system its own ``P`` from then on;
    * **steady state** — for a time-invariant model, once a step maps ``P`` to
      itself up to round-off (``max|ΔP| <= 4 eps max|P|``; the recursion then only
      wanders by a few ulps, often in a cycle, never settling bit for bit), ``P`` and
      that step's ``K`` and ``S⁻¹`` are kept and only the state is updated.
      Estimates differ from the full recursion at the round-off level (about 1e-16
      relative). A skipped measurement, a repaired (non-finite) estimate, a restart
      or ``reset`` leaves that regime.

    **The innovation gate** (``gate=``, :class:`~fir_gym.estimators.base.Estimator`) keeps
    both shortcuts while it rejects nothing. A rejected measurement gives its system
    ``x⁻, P⁻`` — its own covariance, which neither shortcut can hold — so a step in which the
    gate fires under a shortcut is computed again without it, as a step with a missing
    measurement is: first out of the steady state (the full recursion, on a shared ``P``
    still), then, if the gate fires there too, with a covariance per system; the gate decides
    on the pass that is kept (whose NIS ``last_info`` reports). The step then ends exactly
    as the same step with the rejected measurements missing would, and it leaves both
    shortcuts as that step does. A step costs twice or three times its usual cost only when
    the gate fires; giving up the shortcuts for a gated filter would cost a batch its shared
    covariance on every step.

    The compiled twin (:func:`~.compiled.kalman.linear_step`) does the same step, both
    shortcuts and the gate included (it hands back, writing nothing, when the gate fires
    under a shortcut).
    """

    name = "kf"
    has_compiled_step = True
    can_gate = True
    reports_likelihood = True
    model_reassignable = True
    per_call_H = "C"
    twin_replaces = (*Estimator.twin_replaces, "_correct", "_matrices")

    def __init__(self, model: StateSpaceModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, **options: Any) -> None:
        self._bind(model)
        super().__init__(model, x0=x0, P0=P0, **options)

    def _bind(self, model: StateSpaceModel) -> None:
        if not getattr(model, "is_linear", False) or not hasattr(model, "matrices"):
            raise needs_linear(type(self).__name__, model,
                               "'ekf' (ExtendedKalmanFilter) or 'ukf' (UnscentedKalmanFilter)")
        self._constant = bool(getattr(model, "time_invariant", True))
        if self._constant:
            self._mats = self._prepare(model.matrices(0))

    def _model_changed(self) -> None:
        self._bind(self.model)
        self._gains = LinearGains(self.model.n_x, self.model.n_y, self._constant)

    @staticmethod
    def _prepare(mats: Any) -> StepMatrices:
        A, B, C, G, Q, R = mats
        return StepMatrices(np.ascontiguousarray(A), np.ascontiguousarray(B),
                            np.ascontiguousarray(C), np.ascontiguousarray(G @ Q @ G.T),
                            np.ascontiguousarray(R))

    def _matrices(self, k: int) -> StepMatrices:
        if self._constant:
            return self._mats
        return self._prepare(cast(_Scheduled, self.model).matrices(k))

    def _reset_state(self) -> None:
        self._gains = LinearGains(self.model.n_x, self.model.n_y, self._constant)

    def _init_batch(self, n_batch: int) -> None:
        if self._P0.ndim == 2:                         # one covariance for the whole batch
            self._state.P = self._P0[None].copy()

    def _restart_systems(self, mask: np.ndarray) -> None:
        self._gains.regime[0] = 0

    @property
    def steady_state(self) -> bool:
        """Whether the filter is in the steady-state regime (``P``, ``K``, ``S⁻¹`` kept)."""
        return bool(self._gains.regime[0])

    # ------------------------------------------------------------------ numpy reference
    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        x, P, nis, _, W = self._correct(x, P, y, valid, self._matrices(self._state.k))
        return x, P, nis, logdet_of_inverse(W, x.shape[0])

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray
                        ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        s = self._state
        A, B, _, Qd, _ = self._matrices(s.k - 1)
        x = x @ A.T + u @ B.T                          # x⁻ = A x + B u
        every = s.every_usable and not s.restarting
        gains = self._gains
        if gains.regime[0] and every:                  # steady state: P, K, S⁻¹ kept
            K, W = gains.K.transpose(2, 0, 1), gains.W.transpose(2, 0, 1)
            x_new, nis = correct(x, y - x @ self._mats.C.T, K, W)
            if not _fires(nis, self._gate_threshold):
                gains.regime[0] = int(bool(np.isfinite(x_new).all()))
                return x_new, P, nis, logdet_of_inverse(W, x.shape[0])
            # the gate rejects a measurement: its system needs its own P⁻, which the steady
            # state does not hold — the step again in full (class docstring)
        gains.regime[0] = 0
        mats = self._matrices(s.k)
        x_new, P_new, nis, K, W = self._correct(x, predict_covariance(P, A, Qd), y, valid,
                                                mats)
        if (gains.regime[1] and every and K is not None and _converged(P_new, P)
                and np.isfinite(x_new).all() and np.isfinite(P_new).all()):
            gains.regime[0] = 1
            gains.K = np.ascontiguousarray(K.transpose(1, 2, 0))
            gains.W = np.ascontiguousarray(W.transpose(1, 2, 0))
        return x_new, P_new, nis, logdet_of_inverse(W, x.shape[0])

    def _correct(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray,
                 mats: StepMatrices) -> tuple[Any, ...]:
        """The update ``(x⁺, P⁺, nis, K, S⁻¹)``; a shared ``P`` is split where some system has
        no usable measurement or the gate rejects one (``K`` is then not returned)."""
        C, R = mats.C, mats.R
        e = y - x @ C.T
        gate = self._gate_threshold
        if self._state.every_usable:
            K, W, P_new = gain_kernel(P, C, R)
            x_new, nis = correct(x, e, K, W)
            if not _fires(nis, gate):
                return x_new, P_new, nis, K, W
            # a rejected measurement: the update again as with it missing (a P per system)
        if P.shape[0] != x.shape[0]:
            P = np.repeat(P, x.shape[0], axis=0)
        x_new, P_new, W, nis = update_kernel(x, P, e, C, R, valid, gate)
        return x_new, P_new, nis, None, W

    # ------------------------------------------------------------------ smoother
    def smooth(self, ys: ArrayLike, us: ArrayLike | None = None) -> SmootherResult:
        """Rauch–Tung–Striebel smoother over a whole sequence (:mod:`.smoothers`): a
        forward :meth:`filter` (same arguments and alignment), then the backward pass with
        ``A, B, G Q Gᵀ`` of ``model.matrices(k)``. Returns a
        :class:`~fir_gym.estimators.sequences.SmootherResult` (``x``, ``P``, ``filtered``)."""
        return smooth_sequence(self, ys, us, self._smoother_prediction)

    def _smoother_prediction(self, k: int, x: FloatArray, P: FloatArray, u: FloatArray
                             ) -> tuple[FloatArray, FloatArray, FloatArray]:
        A, B, _, Qd, _ = self._matrices(k)
        return x @ A.T + u @ B.T, predict_covariance(P, A, Qd), P @ A.T

    # ------------------------------------------------------------------ compiled twin
    def _compiled_update(self, y: FloatArray, valid: np.ndarray) -> None:
        mats = self._matrices(self._state.k)
        self._gains.step(self._state, self._predicting(), mats, mats, self._no_input, y, valid)

    def _compiled_predict_update(self, y: FloatArray, u: FloatArray, valid: np.ndarray
                                 ) -> None:
        s = self._state
        if self._constant:                             # (two calls of _matrices: 0.1 µs)
            prediction = update = self._mats
        else:
            prediction, update = self._matrices(s.k - 1), self._matrices(s.k)
        self._gains.step(s, self._predicting(), prediction, update, u, y, valid)


class LinearGains:
    """The compiled step of a filter on a linear model's matrices, and what it keeps.

    Used by :class:`KalmanFilter` and by the EKF on a plain :class:`LinearModel`:
    :func:`~.compiled.kalman.linear_step` on the filter's state, with ``K`` and ``S⁻¹`` of
    each row of ``P`` held as blocks (``K (n, m, rows)``, ``W (m, m, rows)``) and the
    ``regime`` ``[steady now, may settle]`` (a time-invariant model's KF may settle).
    A missing measurement gives every system its own covariance and leaves the regime;
    so does a measurement the gate rejects (the kernel hands back when it would under a
    shortcut, and the step runs again without it: :class:`KalmanFilter`).
    """

    def __init__(self, n: int, m: int, may_settle: bool) -> None:
        self.K, self.W = np.zeros((n, m, 0)), np.zeros((m, m, 0))
        self.regime = np.array([0, int(may_settle)], dtype=np.int64)

    def step(self, state: FilterState, predict: np.ndarray, prediction: StepMatrices,
             update: StepMatrices, u: FloatArray, y: FloatArray, valid: np.ndarray) -> None:
        """One step of the filter whose record is ``state``: predict the systems ``predict``
        with ``prediction``'s matrices, update with ``update``'s."""
        if not state.every_usable:                     # a missing measurement: no shortcuts
            self.regime[0] = 0
            if state.P.shape[0] < state.batch:
                state.P = np.repeat(state.P, state.batch, axis=0)
        while True:
            rows = state.P.shape[0]
            if self.K.shape[2] != rows:
                self.regime[0] = 0
                self.K = np.zeros((*self.K.shape[:2], rows))
                self.W = np.zeros((*self.W.shape[:2], rows))
            s = state                                  # the record's arrays, by name
            if compiled_kalman.linear_step(prediction.A, prediction.B, prediction.Qd, update.C,
                                           update.R, u, y, valid, predict, self.K, self.W,
                                           self.regime, s.x, s.P, s.diverged, s.nis_run, s.nis,
                                           s.logdet, s.limits):
                return
            # the gate fired under a shortcut and nothing was written: the step again without
            # it, in the numpy reference's order (out of the steady state, then a P per system)
            if self.regime[0]:
                self.regime[0] = 0
            else:
                state.P = np.repeat(state.P, state.batch, axis=0)


class _Scheduled(Protocol):
    """A linear model with matrices at each time (``LinearModel``, ``TimeVaryingLinearModel``)."""

    def matrices(self, k: int = 0) -> SystemMatrices: ...


class StepMatrices(NamedTuple):
    """A linear model's matrices as a filter step uses them: ``A, B, C``, ``Qd = G Q Gᵀ``, ``R``."""

    A: FloatArray
    B: FloatArray
    C: FloatArray
    Qd: FloatArray
    R: FloatArray


def _fires(nis: FloatArray, gate: float | None) -> bool:
    """Whether the innovation gate (a NIS threshold, ``None``: none) rejects some system's
    measurement (NaN compares False)."""
    return gate is not None and bool((nis > gate).any())


def _converged(P_new: FloatArray, P: FloatArray) -> bool:
    """Whether the Riccati recursion has reached round-off: ``max|ΔP| <= 4 eps max|P|``."""
    scale = float(np.abs(P).max())
    return float(np.abs(P_new - P).max()) <= 4.0 * _EPS * scale


_EPS = float(np.finfo(np.float64).eps)


register_estimator("kf", KalmanFilter)
