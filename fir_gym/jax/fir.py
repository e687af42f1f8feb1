"""The extended FIR filter (paper 000) and the linear FIR filter as pure JAX steps, for one
system.

The JAX twin of :class:`fir_gym.estimators.efir.ExtendedFIRFilter` (the numpy reference)
as :func:`fir_gym.wrappers.estimator_observation.build_estimator` configures it for a
plant: the plant's ``model``, ``x0``/``P0`` its initial-state distribution
(:func:`fir_gym.wrappers.estimator_observation.prior_of`), ``startup="prior"``, and the
defaults ``form="filter"`` (window ``y[k−L+1..k]``) and ``nominal="open-loop"``.

**The filter** (paper 000, eqs 3–13): a nominal trajectory runs open loop from ``x0``
under the applied inputs, ``x̄[k] = f(x̄[k−1], u[k−1])`` (eq 4); the perturbation ``δx``
obeys the model linearised along it, ``F[k−1] = ∂f/∂x`` at ``x̄[k−1]`` (eqs 5–6), and is
measured through ``δy[k] = y[k] − H x̄[k]`` (eqs 7–10); the estimate is ``x̂[k] = x̄[k] +
δx̂[k]`` (eq 11) with ``δx̂`` the minimum-variance unbiased FIR estimate over the window
(eqs 12–13, the gain of Theorem 1). The gain is never formed: a bank of ``L = horizon``
staggered windows runs the two-stage recursion (docs/papers.md#000-two-stage-form,
:class:`fir_gym.estimators._fir_bank.WindowBank`) — one window starts at every step and
the oldest, full one is read out (:func:`bank_predict`, :func:`bank_restart`,
:func:`bank_update`, :func:`bank_estimate`). Window ``w``'s block ``Z[w] = [[P | T | x̄],
[· | −𝓕 | b]]`` (``2n × (2n+1)``) holds a Kalman filter started at ``x̄ = 0, P = 0``, its
sensitivity ``T = ∂x̄/∂δx_start``, and the normal equations ``𝓕 = Σ (C T⁻)ᵀ Σ⁻¹ (C T⁻)``,
``b = Σ (C T⁻)ᵀ Σ⁻¹ e``; its estimate is ``x̄ + T V b`` with covariance ``P + T V Tᵀ``,
``V = 𝓕⁻¹``. With ``Q = 0`` (Orbit-v0) ``P`` stays 0 and the estimate is the weighted
least-squares fit of the window start.

**Start-up** (``startup="prior"``): while the window is not yet full (``k < L − 1``) the
window that began at ``x0`` takes ``N(x0, P0)`` as the prior of its start state, ``V =
(P0⁻¹ + 𝓕)⁻¹ = (I + P0 𝓕)⁻¹ P0`` — the Kalman filter's estimate from that prior on the
linearised model. **Rank-deficient fallback**: a full window whose ``𝓕`` is not regular
(:func:`information_is_regular`, the smallest eigenvalue of its unit-diagonal version
below :data:`RANK_RTOL`) gives the previous estimate predicted, ``f(x̂, u)``, ``F P Fᵀ +
Q`` (``F`` at ``x̂``); selected with ``jnp.where``, never a Python branch on data.

**Consistency** (:mod:`fir_gym.estimators._consistency`, the NIS that
:meth:`fir_gym.estimators._windowed.WindowedEstimator._accept` hands the watch): the new
measurement against the filter's one-step prediction from its previous estimate, ``x⁻ =
f(x̂, u)``, ``P⁻ = F P Fᵀ + Q``, ``S = H P⁻ Hᵀ + R``, ``NIS = eᵀ S⁻¹ e`` (at a reset the
prior ``(x0, P0)`` in place of ``(x⁻, P⁻)``); NaN where ``S`` is not positive definite.

**Interface** (:class:`fir_gym.jax.filters.FilterKind`): :func:`efir_start` builds the
memory (:class:`EFIRMemory`: the bank, the nominal, the step count, the prior covariance
and the last step's flags — fixed shapes, ``horizon`` static), :func:`efir_update` is the
reset's update with ``y[0]`` (:meth:`fir_gym.wrappers.EstimatorObservation.reset`) and
:func:`efir_predict_update` one env step under the applied action. Both take the filter's
current estimate ``(x, P)`` — the record the divergence watch keeps
(:func:`fir_gym.jax.kalman.watch`, which is the numpy filter's ``state.x``, ``state.P``) —
and return ``(memory, x, P, nis)``. The watch is the numpy one; the windowed filters' growth
bound (a component of ``x̂`` beyond ``max_estimate``, which the numpy watch flags while it
still stores that estimate) is handed to :func:`~fir_gym.jax.kalman.watch` as NaN in ``x``
and ``P``: the flag is the same, the record keeps the previous estimate instead.

**The linear FIR filter** (:func:`fir_start`, :func:`fir_update`,
:func:`fir_predict_update`, :class:`FIRMemory`): :class:`fir_gym.estimators.fir.FIRFilter`
as the envs build it (``estimator="fir"``: no ``startup`` option, no prior on the window) on
a time-invariant linear model (``f(x, u) = A x + B u``: ``A`` from ``f_and_F``, ``B u =
f(0, u)``). The numpy filter applies the window's fixed gain (computed once, paper 000
Theorem 1 by the two-stage path) to a ring buffer of ``[y, u]``; here the same staggered bank
runs on the data with ``x̄ ← A x̄ + B u`` — the same estimator, computed in another order
(they agree to ~1e-14 on the models of ``tests/jax/test_fir.py``). Its start-up is the
numpy filter's: the growing window (the bank's window 0) without a prior, and, before it
determines the state, the prior propagated open loop (``A x + B u``, ``A P Aᵀ + Q`` from
``x0, P0``); its covariances are symmetrised as there.

**Missing measurements** (``missing=``, a traced bool; the numpy ``step(None)`` — what
:class:`fir_gym.wrappers.EstimatorObservation` does where ``info["measurement_missing"]``,
the reset's reading included): the sample stays in the window as a gap. Every window skips
it (:meth:`WindowBank.update` with ``valid`` False leaves ``Z`` as it is), everything else
moves on as at any step (the nominal, the windows' time update, the window that starts, the
step count), the oldest window is read out from its remaining data, and the NIS is NaN. So a
missing ``y[0]`` gives the prior ``(x0, P0)`` back; a full window whose data no longer
determine the state — a run of misses as long as the window, or the few steps after it —
takes the rank-deficient fallback; the linear FIR's full window with a gap is its two-stage
estimate over the rest (:func:`fir_gym.estimators.fir.masked_window_estimate`), without one
its fixed gain (:class:`FIRMemory` keeps the step of the newest miss to tell). ``missing``
left at its default ``False`` traces no select at all: the program is the one without it.

**The unbiased FIR filter** (:func:`ufir_update`, :func:`ufir_predict_update`; memory
:func:`fir_start`'s): :class:`fir_gym.estimators.ufir.UFIRFilter` as the envs build it
(``method="batch"``) — Shmaliy's filter, which needs no noise statistics, is the linear FIR
filter of the model with ``Q = 0`` and ``R = I`` (:func:`unbiased_model`; the numpy class
is built that way, ``UFIRFilter._fir_model``), its covariance reported as the noise power
gain times ``r̄``, the mean of the model's own ``diag R`` (``noise_scale``), except where the
window fell back (rank deficient: the fallback's ``P`` as it is), and no NIS (NaN: the numpy
filter hands its watch none, so no run of high NIS can flag it; the kind says so,
:attr:`fir_gym.jax.filters.FilterKind.reports_nis`).

**Not here** (options the envs do not use): gated measurements, restarts of some systems
of a batch, ``form="predictor"``, ``nominal="reanchor"``, ``startup="diffuse"``
for the EFIR, a time-varying model or a prior on the window for the FIR; nor the numpy
constructors' host-side check that the horizon reaches the observability index (a JAX
filter with too short a window just falls back every step).

The numpy reference runs with ``numba`` absent (:data:`fir_gym.estimators.compiled.ENABLED`
false) on its numpy path, whose operations these follow in its order (its compiled twin
agrees with it to round-off), except that a ``2 × 2`` information matrix is inverted, and its
determinant and smallest eigenvalue taken, in closed form rather than by LAPACK (under
``vmap`` on a CPU the batched LAPACK calls cost as much as the rest of a step; the results
agree to round-off, the regularity decisions exactly on the tests' cases), and larger ones
by :mod:`fir_gym.jax.small_linalg`'s unrolled LU, Jacobi and Cholesky (no LAPACK custom
call in a step: see there why). Every function is pure and shape-static: ``jit``- and
``vmap``-able.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from . import small_linalg
from .filter_model import FilterModel
from .kalman import symmetrize

#: :data:`fir_gym.estimators._fir_bank.RANK_RTOL`: an information matrix counts as singular
#: when the smallest eigenvalue of its unit-diagonal version is below this
RANK_RTOL = 1e-12
#: :data:`fir_gym.estimators._consistency.MAX_ESTIMATE`: the growth bound's default
MAX_ESTIMATE = 1e12


def unless_missing(missing: jax.Array | bool, kept: jax.Array | float, new: jax.Array
                   ) -> jax.Array:
    """``kept`` where this step's measurement is ``missing``, else ``new``: a ``jnp.where``
    on the traced flag, and ``new`` itself (no select in the trace) when ``missing`` is the
    literal ``False`` — the default, so a caller without missing measurements gets the very
    program it got before."""
    if missing is False:
        return new
    return jnp.where(missing, kept, new)


# ---------------------------------------------------------------------------- the window bank
def _times_rows(M: jax.Array, X: jax.Array) -> jax.Array:
    """``M X_w`` for every window ``w`` of ``X`` ``(W, k, m)``: ``Σ_j M[:, j] X_w[j, :]``,
    summed in ``j`` order as a loop of products over the few rows (XLA fuses it; a batched
    ``dot`` of such small matrices costs several times more on a CPU)."""
    out = M[None, :, 0, None] * X[:, None, 0, :]
    for j in range(1, M.shape[1]):
        out = out + M[None, :, j, None] * X[:, None, j, :]
    return out


def bank_blank(n: int) -> jax.Array:
    """A window as it starts: ``x̄ = 0, P = 0, T = I, 𝓕 = b = 0`` (``2n × (2n+1)``)."""
    return jnp.zeros((2 * n, 2 * n + 1)).at[:n, n:2 * n].set(jnp.eye(n))


def bank_start(n_windows: int, n: int) -> jax.Array:
    """``n_windows`` blank windows, ``Z`` of shape ``(n_windows, 2n, 2n+1)`` (window first;
    :class:`fir_gym.estimators._fir_bank.WindowBank`'s ``Z[b, :, w, :]``)."""
    return jnp.broadcast_to(bank_blank(n), (n_windows, 2 * n, 2 * n + 1))


def bank_restart(Z: jax.Array, w: jax.Array) -> jax.Array:
    """Window ``w`` afresh (:meth:`WindowBank.restart`, no reference state)."""
    n = Z.shape[1] // 2
    chosen = (jnp.arange(Z.shape[0]) == w)[:, None, None]   # a select, not a scatter: fuses
    return jnp.where(chosen, bank_blank(n), Z)


def bank_predict(Z: jax.Array, A: jax.Array, Q: jax.Array | None,
                 Bu: jax.Array | None = None) -> jax.Array:
    """The time update of every window (:meth:`WindowBank.predict`, one matrix ``A`` shared):
    ``[P | T | x̄] ← A [P | T | x̄]``, then ``P ← (A P) Aᵀ + Q`` (skipped with ``Q = None``,
    where ``P`` stays 0) and ``x̄ ← x̄ + B u``."""
    n = Z.shape[1] // 2
    top = _times_rows(A, Z[:, :n])
    if Q is not None:
        P = _times_rows(A, top[:, :, :n].swapaxes(1, 2)).swapaxes(1, 2) + Q
        top = jnp.concatenate([P, top[:, :, n:]], axis=2)
    if Bu is not None:
        top = top.at[:, :, 2 * n].add(Bu)
    return jnp.concatenate([top, Z[:, n:]], axis=1)


def bank_update(Z: jax.Array, C: jax.Array, R: jax.Array, y: jax.Array) -> jax.Array:
    """The measurement update of every window with ``y = C x + v``, ``v ~ N(0, R)``
    (:meth:`WindowBank.update`): ``r = C [P | T | x̄] − [0 | 0 | y] = [C P | C T | −e]``,
    ``Σ = C P Cᵀ + R``, ``Z −= [K; W] ⊗ r`` with ``[K; W] = [P Cᵀ; (C T)ᵀ] Σ⁻¹`` (one
    channel: a division; more: a solve, channel by channel as the reference)."""
    n, p = Z.shape[1] // 2, C.shape[0]
    r = _times_rows(C, Z[:, :n])                                   # (W, p, 2n+1)
    r = r.at[:, :, 2 * n].add(-y)
    if p == 1:
        CPC = _times_rows(C, r[:, 0, None, :n].swapaxes(1, 2))[:, 0, 0]   # (W,)
        g = (r[:, 0, :2 * n] / (CPC + R[0, 0])[:, None])[:, None]  # (W, 1, 2n)
    else:
        Sig = _times_rows(C, r[:, :, :n].swapaxes(1, 2)).swapaxes(1, 2) + R
        g = jax.vmap(small_linalg.solve)(Sig, r[:, :, :2 * n])     # (W, p, 2n)
    for q in range(p):
        Z = Z - g[:, q, :, None] * r[:, q, None, :]
    return Z


def _det(M: jax.Array) -> jax.Array:
    """``det M``: in closed form for ``2 × 2``, else by LU with partial pivoting
    (:func:`fir_gym.jax.small_linalg.det`, as :func:`jax.numpy.linalg.det`)."""
    if M.shape[0] == 2:
        return M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    return small_linalg.det(M)


def _inv(M: jax.Array) -> jax.Array:
    """``M⁻¹``: the adjugate over the determinant for ``2 × 2`` (inf/NaN where singular, as
    the reference's LAPACK inverse raises or overflows), else by LU
    (:func:`fir_gym.jax.small_linalg.inv`)."""
    if M.shape[0] == 2:
        adjugate = jnp.array([[M[1, 1], -M[0, 1]], [-M[1, 0], M[0, 0]]])
        return adjugate / _det(M)
    return small_linalg.inv(M)


def _smallest_eigenvalue(S: jax.Array) -> jax.Array:
    """``λ_min`` of the symmetric matrix whose lower triangle is ``S``'s
    (:func:`numpy.linalg.eigvalsh`): ``(a + d)/2 − √(((a − d)/2)² + c²)`` for ``2 × 2``, else
    by Jacobi rotations (:func:`fir_gym.jax.small_linalg.eigvalsh`)."""
    if S.shape[0] == 2:
        a, c, d = S[0, 0], S[1, 0], S[1, 1]
        return 0.5 * (a + d) - jnp.sqrt((0.5 * (a - d)) ** 2 + c * c)
    return small_linalg.eigvalsh(S, symmetrize_input=False)[0]


def information_is_regular(F: jax.Array) -> jax.Array:
    """Whether the information matrix ``F`` is numerically invertible: the tests of
    :func:`fir_gym.estimators._fir_bank.spd_inverse` for one system (LAPACK path), in its
    order of sufficiency — ``‖Fs⁻¹‖²_F < RANK_RTOL⁻²``, else ``det Fs > RANK_RTOL
    n^(n−1)``, else ``λ_min(Fs) > RANK_RTOL``, ``Fs = D^(-1/2) F D^(-1/2)`` the
    unit-diagonal version (:func:`fir_gym.estimators._fir_bank.information_is_regular`)."""
    n = F.shape[0]
    Fi = _inv(F)
    d = jnp.diagonal(F)
    frobenius = d @ (Fi * Fi) @ d < RANK_RTOL ** -2
    s = jnp.sqrt(jnp.abs(d))
    s = jnp.where(s > 0, s, 1.0)
    Fs = F / (s[:, None] * s[None, :])
    by_det = _det(Fs) > RANK_RTOL * n ** (n - 1)
    finite = jnp.all(jnp.isfinite(Fs))
    by_eig = finite & (_smallest_eigenvalue(jnp.where(finite, Fs, 0.0)) > RANK_RTOL)
    return frobenius | by_det | by_eig


def bank_estimate(Z: jax.Array, w: jax.Array, prior: jax.Array | None = None
                  ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Window ``w``'s estimate ``x̄ + T V b`` and covariance ``P + T V Tᵀ``
    (:meth:`WindowBank.estimate`), and whether it is regular: ``V = 𝓕⁻¹`` (meaningless
    where ``𝓕`` is singular: the caller falls back) or, with the ``prior`` covariance
    ``Π0`` of the window start, ``V = (I + Π0 𝓕)⁻¹ Π0`` (always regular)."""
    n = Z.shape[1] // 2
    Zs = Z[w]
    if prior is None:
        F = -Zs[n:, n:2 * n]
        regular = information_is_regular(F)
        V = _inv(jnp.where(regular, F, jnp.eye(n)))
    else:
        M = jnp.eye(n) - prior @ Zs[n:, n:2 * n]
        V = _inv(M) @ prior if n == 2 else small_linalg.solve(M, prior)
        regular = jnp.asarray(True)
    T = Zs[:n, n:2 * n]
    TV = T @ V
    return Zs[:n, 2 * n] + TV @ Zs[n:, 2 * n], Zs[:n, :n] + TV @ T.T, regular


# ---------------------------------------------------------------------------- the NIS
def innovation_nis(P_pred: jax.Array, e: jax.Array, H: jax.Array, R: jax.Array) -> jax.Array:
    """``eᵀ S⁻¹ e``, ``S = H P⁻ Hᵀ + R`` symmetrised
    (:func:`fir_gym.estimators._consistency.innovation_nis`); NaN where ``S`` is not PD."""
    S = symmetrize(H @ P_pred @ H.T + R)
    return jnp.einsum("i,ij,j->", e, small_linalg.spd_inverse(S), e)


# ---------------------------------------------------------------------------- the filter
@struct.dataclass
class EFIRMemory:
    """What the extended FIR filter keeps beyond its estimate: the bank ``Z`` (``horizon``
    windows, ``(horizon, 2n, 2n+1)``), the open-loop ``nominal`` ``x̄`` (n,), the number
    ``k`` of measurements consumed, the prior covariance ``P0`` of the start-up window, and
    the last step's ``startup`` and ``rank_deficient`` flags (the numpy filter's
    ``last_info``)."""

    Z: Any
    nominal: Any
    k: Any
    P0: Any
    startup: Any
    rank_deficient: Any


def efir_start(x0: jax.Array, P0: jax.Array, horizon: int, model: FilterModel | None = None
               ) -> EFIRMemory:
    """The memory right after construction or ``reset`` with the prior ``N(x0, P0)``: blank
    windows, the nominal at ``x0``, no measurement yet (``horizon`` is static: the bank's
    length; ``model`` is not needed, the signature is the generic filters')."""
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    return EFIRMemory(Z=bank_start(int(horizon), x0.shape[0]), nominal=x0,
                      k=jnp.asarray(0, dtype=jnp.int64),
                      P0=jnp.asarray(P0, dtype=jnp.float64), startup=jnp.asarray(True),
                      rank_deficient=jnp.asarray(False))


def _advance(memory: EFIRMemory, x: jax.Array, P: jax.Array, y: jax.Array, u: jax.Array | None,
             model: FilterModel, max_estimate: float, missing: jax.Array | bool = False
             ) -> tuple[EFIRMemory, jax.Array, jax.Array, jax.Array]:
    """One pass of :meth:`ExtendedFIRFilter._advance` (preceded by the NIS of
    :meth:`WindowedEstimator._numpy_pass`); ``u`` is ``None`` at the reset's update. A
    ``missing`` measurement (the numpy ``step(None)``: ``valid`` False) is skipped by every
    window (:meth:`WindowBank.update` with ``valid``: ``Z`` unchanged) and its NIS is NaN
    (:func:`fir_gym.estimators._consistency.innovation_nis`); the step is otherwise the same
    — the nominal and the windows move on, a window starts, the oldest is read out."""
    L = memory.Z.shape[0]
    k, Z, nominal = memory.k, memory.Z, memory.nominal
    H, R, Q = jnp.asarray(model.H), jnp.asarray(model.R), jnp.asarray(model.Q)
    # the filter's one-step prediction: the NIS's (x⁻, P⁻) and the rank-deficient fallback
    if u is None:                                     # the prior (x0, P0)
        x_pred, P_pred = x, P
    else:
        x_pred, F_hat = model.f_and_F(x, u)
        P_pred = F_hat @ P @ F_hat.T + Q
    nis = unless_missing(missing, jnp.nan, innovation_nis(P_pred, y - H @ x_pred, H, R))
    start = k < L - 1                                 # the window is not yet full
    w_out = jnp.maximum(0, k - L + 1) % L             # the oldest window: read out now
    if u is not None:                                 # nominal and perturbation time update
        nominal, A = model.f_and_F(nominal, u)
        Z = bank_predict(Z, A, Q)
    Z = bank_restart(Z, k % L)
    Z = unless_missing(missing, Z, bank_update(Z, H, R, y - H @ nominal))
    dx, P_new, regular = bank_estimate(Z, w_out)
    dx_prior, P_prior, _ = bank_estimate(Z, w_out, memory.P0)
    dx = jnp.where(start, dx_prior, dx)
    P_new = jnp.where(start, P_prior, P_new)
    ok = regular | start
    # rank deficient: the previous estimate predicted (at the reset: the prior itself)
    x_new = jnp.where(ok, nominal + dx, x_pred)
    P_new = jnp.where(ok, P_new, P_pred)
    grown = ~(jnp.max(jnp.abs(x_new)) <= max_estimate)
    x_out = jnp.where(grown, jnp.nan, x_new)
    P_out = jnp.where(grown, jnp.nan, P_new)
    memory = EFIRMemory(Z=Z, nominal=nominal, k=k + 1, P0=memory.P0, startup=start,
                        rank_deficient=~ok)
    return memory, x_out, P_out, nis


def efir_update(memory: EFIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                model: FilterModel, max_estimate: float = MAX_ESTIMATE, *,
                missing: jax.Array | bool = False
                ) -> tuple[EFIRMemory, jax.Array, jax.Array, jax.Array]:
    """The first step from the prior ``(x, P) = (x0, P0)`` with ``y[0]`` (the numpy
    filter's ``_update``, as :meth:`fir_gym.wrappers.EstimatorObservation.reset` calls it
    on a fresh memory): ``(memory, x, P, nis)``, NaN in ``x`` and ``P`` where the numpy
    watch would flag the estimate (non-finite, or a component beyond ``max_estimate``).
    ``missing`` (a traced bool): ``y`` did not arrive (the numpy ``step(None)``; ``y`` is
    then ignored, whatever it holds): the window that began at ``x0`` holds no data, so the
    estimate is the prior itself, ``(x0, P0)``, and the NIS NaN."""
    return _advance(memory, x, P, y, None, model, max_estimate, missing)


def efir_predict_update(memory: EFIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                        u: jax.Array, model: FilterModel, max_estimate: float = MAX_ESTIMATE,
                        *, missing: jax.Array | bool = False
                        ) -> tuple[EFIRMemory, jax.Array, jax.Array, jax.Array]:
    """One env step: the previous estimate ``(x, P)`` (the watch's record), the new
    measurement ``y`` and the applied action ``u`` (``_predict_update``):
    ``(memory, x, P, nis)`` as :func:`efir_update`. ``missing`` (a traced bool): no ``y``
    this step (the numpy ``step(None, u)``): the windows skip it and the oldest is read out
    as ever — from the rest of its data (the prior's window through start-up; a full window
    whose data no longer determine the state falls back to the prediction ``f(x̂, u)``,
    ``F P Fᵀ + Q``) — and the NIS is NaN."""
    return _advance(memory, x, P, y, u, model, max_estimate, missing)


# ---------------------------------------------------------------------------- the linear FIR
@struct.dataclass
class FIRMemory:
    """What the linear FIR filter keeps beyond its estimate: the bank ``Z`` (``horizon``
    windows), the number ``k`` of measurements consumed, the prior ``x_open``, ``P_open``
    propagated open loop through the start-up, the last step's ``startup`` and
    ``rank_deficient`` flags, and ``last_missing``, the step of the newest missing
    measurement (−1: none yet) — whether the window has a gap (the numpy filter's ring of
    validity flags, ``FIRFilter._vbuf``)."""

    Z: Any
    k: Any
    x_open: Any
    P_open: Any
    startup: Any
    rank_deficient: Any
    last_missing: Any


def fir_start(x0: jax.Array, P0: jax.Array, horizon: int, model: FilterModel | None = None
              ) -> FIRMemory:
    """The linear FIR filter's memory right after construction or ``reset`` with the prior
    ``N(x0, P0)`` (``horizon`` static; ``model`` unused, the generic filters' signature)."""
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    return FIRMemory(Z=bank_start(int(horizon), x0.shape[0]), k=jnp.asarray(0, dtype=jnp.int64),
                     x_open=x0, P_open=jnp.asarray(P0, dtype=jnp.float64),
                     startup=jnp.asarray(True), rank_deficient=jnp.asarray(False),
                     last_missing=jnp.asarray(-1, dtype=jnp.int64))


def _fir_advance(memory: FIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                 u: jax.Array | None, model: FilterModel, max_estimate: float,
                 missing: jax.Array | bool = False
                 ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """One pass of :meth:`fir_gym.estimators.fir.FIRFilter._advance` for a time-invariant
    linear model (preceded by its NIS); ``u`` is ``None`` at the reset's update.

    A ``missing`` measurement (the numpy ``step(None)``, ``valid`` False) is skipped by
    every window (the numpy growing window's :meth:`WindowBank.update` with ``valid``; the
    ring buffer's slot marked invalid, ``FIRFilter._push``) and its NIS is NaN. A full
    window is the numpy filter's fixed gain where it has no gap — always regular — and,
    where it has one, the two-stage estimate over its remaining data
    (:func:`fir_gym.estimators.fir.masked_window_estimate`), whose information may be
    singular: then, as through the start-up, the rank-deficient fallback."""
    L = memory.Z.shape[0]
    k, Z = memory.k, memory.Z
    H, R, Q = jnp.asarray(model.H), jnp.asarray(model.R), jnp.asarray(model.Q)
    x_open, P_open = memory.x_open, memory.P_open
    start = k < L - 1                                 # the window is not yet full
    if u is None:
        x_pred, P_pred = x, P
    else:
        x_pred, A = model.f_and_F(x, u)               # A x̂ + B u (linear: A anywhere)
        P_pred = A @ P @ A.T + Q
        Bu = model.f(jnp.zeros_like(x), u)            # B u
        x_open = jnp.where(start, A @ x_open + Bu, x_open)
        P_open = jnp.where(start, A @ P_open @ A.T + Q, P_open)
        Z = bank_predict(Z, A, Q, Bu)
    nis = unless_missing(missing, jnp.nan, innovation_nis(P_pred, y - H @ x_pred, H, R))
    Z = bank_restart(Z, k % L)
    Z = unless_missing(missing, Z, bank_update(Z, H, R, y))
    x_new, P_new, regular = bank_estimate(Z, jnp.maximum(0, k - L + 1) % L)
    last_missing = memory.last_missing if missing is False else jnp.where(
        missing, k, memory.last_missing)
    gap = last_missing > k - L                        # a missing one in y[k−L+1..k]
    ok = regular | (~start & ~gap)                    # a full window: the fixed gain's
    x_fall = jnp.where(start, x_open, x_pred)
    P_fall = jnp.where(start, P_open, P_pred)
    x_new = jnp.where(ok, x_new, x_fall)
    P_new = symmetrize(jnp.where(ok, P_new, P_fall))
    grown = ~(jnp.max(jnp.abs(x_new)) <= max_estimate)
    memory = FIRMemory(Z=Z, k=k + 1, x_open=x_open, P_open=P_open, startup=start,
                       rank_deficient=~ok, last_missing=last_missing)
    return memory, jnp.where(grown, jnp.nan, x_new), jnp.where(grown, jnp.nan, P_new), nis


def fir_update(memory: FIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
               model: FilterModel, max_estimate: float = MAX_ESTIMATE, *,
               missing: jax.Array | bool = False
               ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """The linear FIR filter's first step from the prior with ``y[0]`` (as
    :func:`efir_update`; a ``missing`` ``y[0]`` leaves the growing window empty: the
    estimate is the prior ``(x0, P0)``, the NIS NaN)."""
    return _fir_advance(memory, x, P, y, None, model, max_estimate, missing)


def fir_predict_update(memory: FIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                       u: jax.Array, model: FilterModel, max_estimate: float = MAX_ESTIMATE,
                       *, missing: jax.Array | bool = False
                       ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """One env step of the linear FIR filter (as :func:`efir_predict_update`, ``missing``
    included: :func:`_fir_advance` says what a missing measurement does)."""
    return _fir_advance(memory, x, P, y, u, model, max_estimate, missing)


# ---------------------------------------------------------------------------- the UFIR
def unbiased_model(model: FilterModel) -> FilterModel:
    """``model`` with ``Q = 0`` and ``R = I``: the model whose linear FIR filter is the
    unbiased FIR filter (:meth:`fir_gym.estimators.ufir.UFIRFilter._fir_model`)."""
    n, p = jnp.asarray(model.Q).shape[0], jnp.asarray(model.R).shape[0]
    return FilterModel(model.f, model.f_and_F, model.H, jnp.zeros((n, n)), jnp.eye(p))


def _unbiased(memory: FIRMemory, x: jax.Array, P: jax.Array, model: FilterModel
              ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """The UFIR's output from the FIR step on :func:`unbiased_model`: ``P`` scaled by
    ``r̄ = mean diag R`` where the window's estimate stands (:meth:`fir_gym.estimators.ufir.
    UFIRFilter._advance`), no NIS."""
    r_bar = jnp.mean(jnp.diag(jnp.asarray(model.R)))
    return memory, x, jnp.where(memory.rank_deficient, P, r_bar * P), jnp.asarray(jnp.nan)


def ufir_update(memory: FIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                model: FilterModel, max_estimate: float = MAX_ESTIMATE, *,
                missing: jax.Array | bool = False
                ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """The unbiased FIR filter's first step from the prior with ``y[0]`` (:func:`fir_update`
    on :func:`unbiased_model`)."""
    memory, x, P, _ = _fir_advance(memory, x, P, y, None, unbiased_model(model), max_estimate,
                                   missing)
    return _unbiased(memory, x, P, model)


def ufir_predict_update(memory: FIRMemory, x: jax.Array, P: jax.Array, y: jax.Array,
                        u: jax.Array, model: FilterModel, max_estimate: float = MAX_ESTIMATE,
                        *, missing: jax.Array | bool = False
                        ) -> tuple[FIRMemory, jax.Array, jax.Array, jax.Array]:
    """One env step of the unbiased FIR filter (:func:`fir_predict_update` on
    :func:`unbiased_model`)."""
    memory, x, P, _ = _fir_advance(memory, x, P, y, u, unbiased_model(model), max_estimate,
                                   missing)
    return _unbiased(memory, x, P, model)
