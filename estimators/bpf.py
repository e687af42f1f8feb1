"""Kalman filter for a nonlinear stochastic system via block-pulse functions (paper 002).

**Adaptive piecewise linearisation** (paper 002, §2). The drift is written
``a(x) = A(x) x`` (eq 2.2) and ``A`` is frozen on each block-pulse interval
``[t_k, t_k + h)`` at its value at the interval's start (eqs 2.5–2.8, 2.10),
here at the current estimate: ``A_k = A(x̂(t_k))``. An input enters as the
frozen term ``b_k = a(x̂_k, u) − A_k x̂_k`` (zero when ``u = 0``).

**Block-pulse integration** of ``ẋ = M x + b`` with ``M, b`` constant on the
interval (eqs 2.11–2.16, with the eq 2.14 erratum, docs/papers.md#002-errata): the interval
coefficient (average) is ``X = (I − h/2 M)⁻¹ (x(t_k) + h/2 b)`` (eq 2.14, first
line) and the end value ``x(t_k + h) = 2 X − x(t_k)`` (eq 2.16), i.e.

    x(t_k + h) = (I − h/2 M)⁻¹ [(I + h/2 M) x(t_k) + h b]      (trapezoid / Tustin).

The recursion is restarted from ``x̂(t_k)`` on every interval. With ``A``
frozen at the interval's start, as the adaptive scheme prescribes, the method is
first order in ``h`` along a time-varying ``A`` (the Riccati solution is about
12 % off at m = 100 on the Van der Pol path); with block-pulse coefficients
(interval averages) of a known ``A(t)`` the recursion is second order (tests).

**Kalman–Bucy filter** ``dx̂ = A x̂ dt + K (dz − H x̂ dt)`` (eq 3.3) with
``K = P Hᵀ R⁻¹`` (eq 3.7) and the Riccati equation (eq 3.6) solved through the
Hamiltonian system (eq 3.8)

    d/dt [U; V] = M [U; V],   M = [[−Aᵀ, Hᵀ R⁻¹ H], [G Q Gᵀ, A]],   P = V U⁻¹,

with ``P = [Φ21 + Φ22 P0][Φ11 + Φ12 P0]⁻¹`` (eq 3.11, erratum). The block-pulse
recursion for the backward transition ``Φ(t0, t)`` (eqs 3.24–3.26; "1" in 3.24
is ``I``) is ``φ_0 = (I + h/2 M_0)⁻¹``, ``φ_{k+1} = φ_k (I − h/2 M_k)(I + h/2
M_{k+1})⁻¹``, and ``Φ(t, t0) = φ⁻¹`` (eq 3.27). Its interval coefficients give
the gain (eq 3.28, ``r_kᵀ`` read ``r_k⁻¹``); its end values give ``P(t_k)``.

* ``riccati="restart"`` (default) restarts that recursion on every interval
  from ``[I; P(t_k)]`` (:func:`bpf_riccati_step`): exact algebra, and stable
  because only one interval's transition is ever inverted. The end value is the
  Cayley transform ``(I − h/2 M)⁻¹ (I + h/2 M) [I; P]`` (Padé (1,1) of
  ``e^{M h}``, local error O(h³), global O(h²)); the gain uses the interval
  coefficient ``(I + h/2 M) [I; P(t_k)]`` (eqs 3.25, 3.27 restarted).
* ``riccati="global"`` is the paper-literal recursion from ``t0``
  (:func:`bpf_riccati_global_step`). It is the same numbers in exact arithmetic,
  but ``Φ(t0, t)`` of a Hamiltonian system has modes ``e^{±λt}``: its condition
  number grows like ``e^{2λt}`` and the inversions of eq 3.27 lose all accuracy
  within seconds. The condition number of every matrix inverted is monitored;
  when it exceeds ``max_condition`` (or a result is not finite) the system is
  flagged diverged (``diverged``, ``last_info["riccati_breakdown"]``) and
  continues with the restarted recursion from its last well-conditioned
  ``P(t_k)``. It never returns NaN.

**Measurements.** Step ``k ≥ 1`` consumes ``ȳ[k]``, the block-pulse coefficient
(interval average) of ``z`` over ``[t_{k-1}, t_k]``, whose noise covariance is
``R/h``; one block-pulse interval of the filter (predict and update are fused:
the measurement acts throughout the interval) returns ``x̂(t_k)``. The first
step is the Kalman update of the prior with the point measurement ``y[0]`` of
``h(x(t0))``, covariance ``R/h`` (the Gymnasium plant's convention). A nonlinear
``h`` is linearised at ``x̂(t_k)`` like ``A``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from ._kalman_linalg import psd_rebuild
from ._validation import FloatArray, one_of, positive
from .continuous import ContinuousModel
from .continuous_estimator import ContinuousEstimator
from .errors import IncompatibleModelError
from .registry import register_estimator

__all__ = ["BlockPulseKalmanFilter", "RiccatiPath", "RiccatiStep", "bpf_riccati",
           "bpf_riccati_global_step", "bpf_riccati_step", "bpf_state_step", "hamiltonian"]

RICCATI_FORMS = ("restart", "global")


class RiccatiStep(NamedTuple):
    """One block-pulse interval of the Riccati equation (batched like ``P``).

    Attributes:
        P_next: ``P`` at the end of the interval.
        P_bar: ``P`` from the interval coefficient (the value the gain uses).
        condition: the largest 2-norm condition number of the matrices inverted.
    """

    P_next: FloatArray
    P_bar: FloatArray
    condition: FloatArray


class RiccatiPath(NamedTuple):
    """The block-pulse Riccati solution over ``m`` intervals.

    ``P``: end values ``P(t_0..t_m)``, shape ``(m + 1, ..., n, n)``; ``P_bar``:
    interval values ``(m, ..., n, n)``; ``condition``: per interval ``(m, ...)``.
    """

    P: FloatArray
    P_bar: FloatArray
    condition: FloatArray


def hamiltonian(A: ArrayLike, S: ArrayLike, W: ArrayLike) -> FloatArray:
    """``M = [[−Aᵀ, S], [W, A]]`` with ``S = Hᵀ R⁻¹ H``, ``W = G Q Gᵀ`` (eqs 3.8, 3.14).

    Batched over leading axes (``A``, ``S``, ``W`` broadcast against each other).
    """
    A, S, W = np.broadcast_arrays(*(np.asarray(m, dtype=np.float64) for m in (A, S, W)))
    top = np.concatenate([-np.swapaxes(A, -1, -2), S], axis=-1)
    return np.concatenate([top, np.concatenate([W, A], axis=-1)], axis=-2)


def bpf_riccati_step(P: ArrayLike, M: ArrayLike, h: float) -> RiccatiStep:
    """One interval of the block-pulse Riccati recursion restarted from ``[I; P]``.

    With ``ξ = [I; P]`` (eq 3.9 at ``t_k``), ``E± = I ± h/2 M``:

        end value             ξ⁺ = E₋⁻¹ E₊ ξ  = 2 E₋⁻¹ ξ − ξ   (eqs 3.25–3.27 restarted; 2.14, 2.16)
        interval coefficient  Ξ  = E₊ ξ                      (eq 3.25 inverted, eq 3.27)

    and ``P = V U⁻¹`` of each (eq 3.11). ``P`` is ``(n, n)`` or ``(B, n, n)``;
    ``M`` is ``(2n, 2n)`` or ``(B, 2n, 2n)``.
    """
    P = np.asarray(P, dtype=np.float64)
    M = np.asarray(M, dtype=np.float64)
    n = P.shape[-1]
    xi = _stack_identity(P)
    half = 0.5 * h * M
    E_minus = np.eye(2 * n) - half
    coef = xi + half @ xi
    end = _solve(E_minus, coef)
    P_next, c_end = _ratio(end)
    P_bar, c_bar = _ratio(coef)
    condition = np.maximum(_cond(E_minus), np.maximum(c_end, c_bar))
    return RiccatiStep(P_next, P_bar, condition)


def bpf_riccati_global_step(
    psi: ArrayLike, M: ArrayLike, xi0: ArrayLike, h: float
) -> tuple[FloatArray, RiccatiStep]:
    """One interval of the paper-literal global recursion (eqs 3.25–3.28).

    ``psi = Φ(t0, t_k)`` is the backward transition at the interval's start
    (the identity at ``t0``), ``xi0 = [I; P(t0)]``. Then

        φ_k     = ψ_k (I + h/2 M_k)⁻¹          coefficient of Φ(t0, t) (eqs 3.25, 3.26)
        Ξ_k     = φ_k⁻¹ ξ0                      interval value, gain (eqs 3.27, 3.28)
        ψ_{k+1} = φ_k (I − h/2 M_k)             = 2 φ_k − ψ_k (eq 2.16)
        ξ_{k+1} = ψ_{k+1}⁻¹ ξ0                  end value (eqs 3.10, 3.27)

    Returns ``(ψ_{k+1}, RiccatiStep)``; ``condition`` covers ``φ_k``, ``ψ_{k+1}``
    and the two ``U`` of eq 3.11 — it grows like ``e^{2λ(t − t0)}``.
    """
    psi = np.asarray(psi, dtype=np.float64)
    M = np.asarray(M, dtype=np.float64)
    xi0 = np.asarray(xi0, dtype=np.float64)
    half = 0.5 * h * M
    I2 = np.eye(M.shape[-1])
    phi = np.swapaxes(_solve(np.swapaxes(I2 + half, -1, -2), np.swapaxes(psi, -1, -2)), -1, -2)
    psi_next = phi - phi @ half
    P_bar, c_bar = _ratio(_solve(phi, xi0))
    P_next, c_end = _ratio(_solve(psi_next, xi0))
    condition = np.maximum(np.maximum(_cond(phi), _cond(psi_next)),
                           np.maximum(c_bar, c_end))
    return psi_next, RiccatiStep(P_next, P_bar, condition)


def bpf_riccati(P0: ArrayLike, M: ArrayLike, h: float, *, form: str = "restart") -> RiccatiPath:
    """The block-pulse Riccati solution over the intervals whose Hamiltonians are ``M``.

    ``M`` has shape ``(m, 2n, 2n)`` (or ``(m, B, 2n, 2n)``): ``M[k]`` is the block-pulse
    coefficient of ``M(t)`` on interval ``k``; ``P0`` is ``P(t0)``. ``form`` is
    ``"restart"`` (:func:`bpf_riccati_step`) or ``"global"``
    (:func:`bpf_riccati_global_step`). Nothing is checked or repaired: the
    global form's loss of accuracy shows in ``condition``.
    """
    one_of("form", form, RICCATI_FORMS)
    P = np.asarray(P0, dtype=np.float64)
    M = np.asarray(M, dtype=np.float64)
    Ps, Pbars, conds = [P], [], []
    xi0 = _stack_identity(P)
    psi = np.broadcast_to(np.eye(M.shape[-1]), M.shape[1:]).copy()
    with np.errstate(all="ignore"):
        for M_k in M:
            if form == "restart":
                step = bpf_riccati_step(Ps[-1], M_k, h)
            else:
                psi, step = bpf_riccati_global_step(psi, M_k, xi0, h)
            Ps.append(step.P_next)
            Pbars.append(step.P_bar)
            conds.append(step.condition)
    return RiccatiPath(np.stack(Ps), np.stack(Pbars), np.stack(conds))


def bpf_state_step(x: ArrayLike, M: ArrayLike, b: ArrayLike, h: float) -> FloatArray:
    """``x(t + h) = (I − h/2 M)⁻¹ [(I + h/2 M) x + h b]`` (eqs 2.14 and 2.16, restarted).

    Block-pulse integration of ``ẋ = M x + b`` over one interval with ``M``
    and ``b`` frozen; ``x`` is ``(n,)`` or ``(B, n)``, ``M`` ``(n, n)`` or
    ``(B, n, n)``, ``b`` like ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    M = np.asarray(M, dtype=np.float64)
    half = 0.5 * h * M
    rhs = x + (half @ x[..., None])[..., 0] + h * np.asarray(b, dtype=np.float64)
    return np.linalg.solve(np.eye(M.shape[-1]) - half, rhs[..., None])[..., 0]


def _solve(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a⁻¹ b`` for stacks; a system whose ``a`` is exactly singular gets NaN (flagged later)."""
    try:
        return np.linalg.solve(a, b).astype(np.float64, copy=False)
    except np.linalg.LinAlgError:
        shape = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
        a = np.broadcast_to(a, shape + a.shape[-2:])
        b = np.broadcast_to(b, shape + b.shape[-2:])
        out = np.full(shape + b.shape[-2:], np.nan)
        for idx in np.ndindex(shape):
            try:
                out[idx] = np.linalg.solve(a[idx], b[idx])
            except np.linalg.LinAlgError:
                pass
        return out


def _cond(a: FloatArray) -> FloatArray:
    """2-norm condition numbers of a stack; ``inf`` for a non-finite matrix."""
    finite = np.all(np.isfinite(a), axis=(-2, -1))
    cond = np.linalg.cond(np.where(finite[..., None, None], a, 1.0))
    return np.where(finite, cond, np.inf)


def _stack_identity(P: FloatArray) -> FloatArray:
    """``[I; P]`` (eq 3.9), batched."""
    I = np.broadcast_to(np.eye(P.shape[-1]), P.shape)
    return np.concatenate([I, P], axis=-2)


def _ratio(xi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``P = V U⁻¹`` of ``ξ = [U; V]`` (eq 3.11), symmetrised, and the condition of ``U``."""
    n = xi.shape[-1]
    U, V = xi[..., :n, :], xi[..., n:, :]
    P = np.swapaxes(_solve(np.swapaxes(U, -1, -2), np.swapaxes(V, -1, -2)), -1, -2)
    return 0.5 * (P + np.swapaxes(P, -1, -2)), _cond(U)


class BlockPulseKalmanFilter(ContinuousEstimator):
    """The block-pulse Kalman filter of paper 002 on a :class:`ContinuousModel` (batched).

    Args:
        model: a continuous model with a factorisation ``A(x)``
            (:attr:`ContinuousModel.has_factorisation`); its ``dt`` is the
            block-pulse interval ``h``.
        x0, P0: prior of ``x(t0)``.
        riccati: ``"restart"`` (stable, default) or ``"global"`` (paper-literal,
            breaks down; see the module docstring).
        max_condition: the condition number above which the global recursion is
            declared broken down (its relative accuracy is about
            ``condition · 2e-16``).
        **options: those of :class:`~fir_gym.estimators.base.Estimator`.

    ``model`` (the attribute) is the sampled discrete view
    (:meth:`ContinuousModel.sampled`) the base class reads; the continuous model
    is :attr:`continuous_model`. ``last_info`` adds ``riccati_condition`` and
    ``riccati_breakdown`` (per system); its ``nis`` is a diagnostic: the interval
    average against its open-loop prediction, with variance ``H P(t_k) Hᵀ + R/h``.

    The innovation gate (``gate=``, :class:`~fir_gym.estimators.base.Estimator`) decides on
    that diagnostic, computed before the interval: a rejected measurement enters the interval
    as a missing one (no measurement term in the Hamiltonian nor in the state's recursion).
    Its variance leaves out the process noise inside the interval, so its law is χ²(n_y)
    only approximately (well for ``h`` short against the dynamics): the rate of rejected
    good measurements is about ``1 − gate``, not exactly. The first step gates the Kalman
    update of the prior (its NIS is exact).
    """

    name = "bpf-kf"

    def __init__(self, model: ContinuousModel, *, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, riccati: str = "restart",
                 max_condition: float = 1e12, **options: Any) -> None:
        self.riccati = one_of("riccati", riccati, RICCATI_FORMS)
        self.max_condition = positive("max_condition", max_condition)
        if isinstance(model, ContinuousModel) and not model.has_factorisation:
            raise IncompatibleModelError(
                f"model {model.name!r} has no factorisation A(x); the block-pulse filter "
                "freezes A(x) on each interval (paper 002, eq 2.2): use 'cd-ekf'")
        super().__init__(model, x0=x0, P0=P0, **options)

    def _reset_state(self) -> None:
        self._psi: FloatArray | None = None
        self._xi0: FloatArray | None = None
        self._broken: np.ndarray | None = None
        self._condition: FloatArray | None = None

    def step(self, y: ArrayLike | None, u: ArrayLike | None = None) -> FloatArray:
        """As :meth:`Estimator.step`; a global-recursion breakdown also sets ``diverged``."""
        x = super().step(y, u)
        if self._broken is not None and self._broken.any():
            self._state.diverged |= self._broken
        return x

    def _step_info(self) -> dict[str, Any]:
        if self._broken is None or self._condition is None:
            return {}
        if self._state.single:
            return {"riccati_breakdown": bool(self._broken[0]),
                    "riccati_condition": float(self._condition[0])}
        return {"riccati_breakdown": self._broken.copy(),
                "riccati_condition": self._condition.copy()}

    # ------------------------------------------------------------------ hooks
    def _update(self, x: FloatArray, P: FloatArray, y: FloatArray, valid: np.ndarray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        cm = self.continuous_model
        x, P, nis = super()._update(x, P, y, valid)
        n_b = x.shape[0]
        self._broken = np.zeros(n_b, bool)
        self._condition = np.ones(n_b)
        if self.riccati == "global":
            self._xi0 = _stack_identity(P)
            self._psi = np.broadcast_to(np.eye(2 * cm.n_x), (n_b, 2 * cm.n_x, 2 * cm.n_x)).copy()
        return x, P, nis

    def _predict_update(self, x: FloatArray, P: FloatArray, y: FloatArray, u: FloatArray,
                        valid: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray]:
        cm, h = self.continuous_model, self.continuous_model.dt
        A = cm.A_of_x(x)                                          # frozen A_k (eq 2.10)
        b = cm.a(x, u) - (A @ x[:, :, None])[:, :, 0]             # input term (0 for u = 0)
        Hm = cm.H(x)
        d = cm.h(x) - (Hm @ x[:, :, None])[:, :, 0]               # 0 for a linear h
        # innovation of the interval average against the open-loop prediction (diagnostic),
        # before the interval: the gate decides on it which measurements enter
        x_bar = np.linalg.solve(np.eye(cm.n_x) - 0.5 * h * A, (x + 0.5 * h * b)[:, :, None])
        e = y - (Hm @ x_bar)[:, :, 0] - d
        S = Hm @ P @ np.swapaxes(Hm, 1, 2) + cm.R / h
        nis = np.einsum("bi,bi->b", e, np.linalg.solve(S, e[:, :, None])[:, :, 0])
        nis = np.where(valid, nis, np.nan)
        if self._gate_threshold is not None:                     # rejected: as if missing
            rejected = nis > self._gate_threshold
            if rejected.any():
                y, valid = np.where(rejected[:, None], 0.0, y), valid & ~rejected
        HtRinv = np.swapaxes(Hm, 1, 2) @ cm.R_inv * valid[:, None, None]
        M = hamiltonian(A, HtRinv @ Hm, cm.GQGT)                  # eq 3.14
        step = bpf_riccati_step(P, M, h)
        if self.riccati == "global":
            step = self._global(step, M, h)
        self._condition = step.condition
        K = step.P_bar @ HtRinv                                   # eqs 3.7, 3.28
        x_next = bpf_state_step(x, A - K @ Hm, b + (K @ (y - d)[:, :, None])[:, :, 0], h)
        # P = V U⁻¹ is no Gram matrix: rebuilt from its semidefinite factor, it is symmetric
        # PSD by construction (docs/architecture.md#covariance-updates)
        return x_next, psd_rebuild(step.P_next), nis

    def _global(self, restarted: RiccatiStep, M: FloatArray, h: float) -> RiccatiStep:
        """The global recursion where it is still well conditioned; the restart elsewhere."""
        assert self._psi is not None and self._xi0 is not None and self._broken is not None
        psi, step = bpf_riccati_global_step(self._psi, M, self._xi0, h)
        fine = ~self._broken & (step.condition <= self.max_condition)
        for arr in (step.P_next, step.P_bar):
            fine &= np.all(np.isfinite(arr), axis=(1, 2))
        self._broken |= ~fine
        self._psi = np.where(fine[:, None, None], psi, self._psi)
        keep = fine[:, None, None]
        return RiccatiStep(np.where(keep, step.P_next, restarted.P_next),
                           np.where(keep, step.P_bar, restarted.P_bar),
                           np.where(fine, step.condition, restarted.condition))


register_estimator("bpf-kf", BlockPulseKalmanFilter)
