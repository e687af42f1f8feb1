"""The Kalman family's step, compiled: prediction, Joseph-form update and the watch in one call.

The twin of :func:`~fir_gym.estimators.kalman.predict_covariance` followed by
:func:`~fir_gym.estimators.kalman.update_kernel` and ``Estimator._accept`` —

    P⁻ = F P Fᵀ + Q,   S = H P⁻ Hᵀ + R,   K = P⁻ Hᵀ S⁻¹,   x⁺ = x⁻ + K (y − ŷ),
    P⁺ = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ (symmetrised),   NIS = eᵀ S⁻¹ e

— on blocks of systems (:mod:`.linalg`), written in place into the filter's state and
booked by :func:`.watch.verdict`. The numpy references' rules hold: a system whose
``S`` is not positive definite gets NaN (so the watch keeps its last estimate and flags
it), a system without a usable measurement (``valid`` False) keeps ``x⁻, P⁻`` with a NaN
NIS, a system whose ``predict`` is False takes no prediction (the first step after a
(re)start: an update of its prior). The innovation gate: with a fifth entry of ``limits``
(the NIS threshold; ``inf`` or absent: no gate), a usable measurement whose NIS exceeds it
is treated as missing — the system keeps ``x⁻, P⁻`` — while its NIS is still stored and
booked by the watch (:func:`~fir_gym.estimators.kalman.keep_usable`, the reference).

Two entry points, built from the same block pieces (:func:`predict_block`,
:func:`gain_block`, :func:`finish`):

* :func:`predict_update` — the EKF's and LKF's step: the caller evaluates the model
  (``x⁻ = f(x, u)``, ``F``, ``ŷ = h(x⁻)``, ``H``), the kernel does the covariance algebra;
* :func:`linear_step` — a linear model's step with its matrices (KF, and the EKF on a
  plain :class:`~fir_gym.estimators.LinearModel`): ``x⁻ = A x + B u`` and ``ŷ = C x⁻`` in the
  kernel, and the KF's two exact shortcuts — one covariance shared by a batch started
  from one prior, and the steady state (``P``, ``K``, ``S⁻¹`` kept once the Riccati
  recursion has reached round-off).

Shapes: ``x (B, n)``, ``P (B, n, n)`` (``(1, n, n)`` shared, :func:`linear_step` only),
matrices ``(B | 1, r, c)`` (1: shared by all systems), ``y, ŷ (B, m)``, ``valid, predict
(B,)``, the watch's ``diverged, nis_run, nis (B,)`` and ``limits`` (:mod:`.watch`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..state import GATE, MAX_TRACE, NIS_PATIENCE, NIS_THRESHOLD
from . import inlined, jit
from .linalg import (
    CHUNK,
    factored_joseph,
    load,
    logdet_of_inverse,
    mul,
    spd_inverse,
    symmetrize_sum,
)
from .watch import Watched, verdict

if TYPE_CHECKING:
    from ..state import FilterState

EPS = float(np.finfo(np.float64).eps)


@jit
def scratch(n: int, m: int, c: int) -> tuple[np.ndarray, ...]:
    """The blocks of one step on ``c`` systems, carved from one allocation: ``Ps, Fs, FP, Pm,
    Qs, IKH, T, U`` (``n x n``), ``Hs`` (``m x n``), ``PHt, K, KR`` (``n x m``), ``Rs, S, W,
    L`` (``m x m``)."""
    nn, nm, mm = n * n * c, n * m * c, m * m * c
    buf = np.empty(8 * nn + 4 * nm + 4 * mm)
    o = 8 * nn + 4 * nm
    return (buf[:nn].reshape(n, n, c), buf[nn:2 * nn].reshape(n, n, c),
            buf[2 * nn:3 * nn].reshape(n, n, c), buf[3 * nn:4 * nn].reshape(n, n, c),
            buf[4 * nn:5 * nn].reshape(n, n, c), buf[5 * nn:6 * nn].reshape(n, n, c),
            buf[6 * nn:7 * nn].reshape(n, n, c), buf[7 * nn:8 * nn].reshape(n, n, c),
            buf[8 * nn:8 * nn + nm].reshape(m, n, c),
            buf[8 * nn + nm:8 * nn + 2 * nm].reshape(n, m, c),
            buf[8 * nn + 2 * nm:8 * nn + 3 * nm].reshape(n, m, c),
            buf[8 * nn + 3 * nm:o].reshape(n, m, c),
            buf[o:o + mm].reshape(m, m, c), buf[o + mm:o + 2 * mm].reshape(m, m, c),
            buf[o + 2 * mm:o + 3 * mm].reshape(m, m, c),
            buf[o + 3 * mm:o + 4 * mm].reshape(m, m, c))


@jit
def predict_block(Ps: np.ndarray, Fs: np.ndarray, Qs: np.ndarray, nb: int, FP: np.ndarray,
                  Pm: np.ndarray) -> None:
    """``P⁻ = F P Fᵀ + Q`` (symmetrised) on a block."""
    mul(Ps, Fs, FP, nb, True)                        # P Fᵀ
    mul(Fs, FP, Pm, nb, False)                       # F P Fᵀ
    symmetrize_sum(Pm, Qs, nb)                       # + Q, symmetrised


@jit
def gain_block(Pm: np.ndarray, Hs: np.ndarray, Rs: np.ndarray, nb: int, PHt: np.ndarray,
               S: np.ndarray, W: np.ndarray, L: np.ndarray, ok: np.ndarray, K: np.ndarray,
               IKH: np.ndarray, T: np.ndarray, U: np.ndarray, KR: np.ndarray) -> None:
    """The covariance half of the update on a block: ``W = S⁻¹`` (``ok`` where ``S`` is PD),
    ``K = P⁻ Hᵀ S⁻¹`` and the Joseph-form ``U = P⁺``, from factors (PSD by construction)."""
    m = Hs.shape[0]
    mul(Pm, Hs, PHt, nb, True)                       # P⁻ Hᵀ
    mul(Hs, PHt, S, nb, False)                       # H P⁻ Hᵀ
    for i in range(m):                               # S = H P⁻ Hᵀ + R
        for j in range(m):
            for t in range(nb):
                S[i, j, t] += Rs[i, j, t]
    spd_inverse(S, W, L, ok, nb)
    mul(PHt, W, K, nb, False)                        # K = P⁻ Hᵀ S⁻¹
    factored_joseph(Pm, Hs, Rs, K, nb, IKH, T, U, KR)  # Joseph form from factors: PSD


class Block(NamedTuple):
    """The covariance half of an update on a block of columns, by name: ``ok`` (``S`` positive
    definite), ``K``, ``W = S⁻¹``, ``Pm = P⁻`` and ``Pp = P⁺`` (column ``t``: one row of ``P``)."""

    ok: np.ndarray
    K: np.ndarray
    W: np.ndarray
    Pm: np.ndarray
    Pp: np.ndarray


@inlined
def finish(b0: int, nb: int, Xm: np.ndarray, E: np.ndarray, valid: np.ndarray, blk: Block,
           c0: int, shared: bool, store_P: bool, out: Watched) -> bool:
    """The state half of the update and the watch for systems ``b0 .. b0+nb``: ``x⁺ = x⁻ + K
    e`` and ``NIS = eᵀ W e`` (``W = S⁻¹``), then ``x⁺`` and ``P⁺ = blk.Pp`` (``P⁻ = blk.Pm``
    without a usable measurement) stored into ``out.x`` (and ``out.P`` with ``store_P``) where
    both are finite. Column ``t`` of the blocks ``Xm (n, ·)`` (``x⁻``) and ``E (m, ·)``
    (innovations) belongs to system ``b0 + t``; of ``blk``'s arrays column ``c0 + t`` (``0`` for
    all where ``shared``). ``out.logdet[b]`` receives ``log det S`` (NaN without a usable
    measurement), for the innovation's log-likelihood. A NIS above the gate's threshold
    (``limits[GATE]``, module docstring) keeps ``x⁻, P⁻`` as a missing measurement does; the
    watch books it all the same. Returns whether every estimate was stored."""
    ok, K, W, Pm, Pp = blk.ok, blk.K, blk.W, blk.Pm, blk.Pp
    x, P, diverged, nis_run, nis, logdet = (out.x, out.P, out.diverged, out.nis_run, out.nis,
                                            out.logdet)
    limits = out.limits
    n, m = Xm.shape[0], E.shape[0]
    nis_limit, patience, max_trace = limits[NIS_THRESHOLD], limits[NIS_PATIENCE], limits[MAX_TRACE]
    gate_limit = limits[GATE]
    xn = np.empty(n)
    every = True
    for t in range(nb):
        b, col = b0 + t, 0 if shared else c0 + t
        usable = valid[b]                            # no measurement: keep x⁻, P⁻
        update = usable                              # ... nor a rejected one
        q = np.nan
        logdet[b] = logdet_of_inverse(W, col) if usable and ok[col] else np.nan
        for i in range(n):
            xn[i] = Xm[i, t]
        if usable and ok[col]:
            q = 0.0                                  # NIS = eᵀ S⁻¹ e
            for i in range(m):
                for k in range(m):
                    q += E[i, t] * W[i, k, col] * E[k, t]
            if q > gate_limit:                       # the gate: as if missing
                update = False
            else:
                for i in range(n):                   # x⁺ = x⁻ + K e
                    v = 0.0
                    for k in range(m):
                        v += K[i, k, col] * E[k, t]
                    xn[i] += v
        elif usable:                                 # S not positive definite
            xn[0] = np.nan
        finite = True
        trace = 0.0
        for i in range(n):
            trace += Pp[i, i, col] if update else Pm[i, i, col]
            finite = finite and np.isfinite(xn[i])
            for j in range(n):
                finite = finite and np.isfinite(Pp[i, j, col] if update else Pm[i, j, col])
        nis_run[b], blown = verdict(finite, trace, q, usable, True, nis_run[b], nis_limit,
                                    patience, max_trace)
        if blown:
            diverged[b] = True
        if finite:
            for i in range(n):
                x[b, i] = xn[i]
                if store_P:
                    for j in range(n):
                        P[b, i, j] = Pp[i, j, col] if update else Pm[i, j, col]
        nis[b] = q
        every = every and finite
    return every


def predict_update(state: FilterState, xp: np.ndarray, F: np.ndarray, Q: np.ndarray,
                   y: np.ndarray, hx: np.ndarray, H: np.ndarray, R: np.ndarray,
                   valid: np.ndarray, predict: np.ndarray) -> None:
    """One step of every system of ``state`` (the filter's record), in place: ``x⁻ = xp`` (the
    caller's ``f(x, u)``; ``x`` itself where ``predict`` is False), ``P⁻ = F P Fᵀ + Q`` where
    ``predict``, the update with ``e = y − hx`` (the caller's ``h(x⁻)``), ``H`` and ``R``, then
    the watch (``state.logdet``: each system's ``log det S``)."""
    predict_update_kernel(xp, F, Q, y, hx, H, R, valid, predict, state.x, state.P,
                          state.diverged, state.nis_run, state.nis, state.logdet, state.limits)


@jit
def predict_update_kernel(xp: np.ndarray, F: np.ndarray, Q: np.ndarray, y: np.ndarray,
                          hx: np.ndarray, H: np.ndarray, R: np.ndarray, valid: np.ndarray,
                          predict: np.ndarray, x: np.ndarray, P: np.ndarray,
                          diverged: np.ndarray, nis_run: np.ndarray, nis: np.ndarray,
                          logdet: np.ndarray, limits: np.ndarray) -> None:
    """The kernel of :func:`predict_update`: the step's inputs, then the record's arrays (in
    the order of :class:`~.watch.Watched`)."""
    out = Watched(x, P, diverged, nis_run, nis, logdet, limits)
    n_b, n = x.shape
    m = y.shape[1]
    if not (P.shape[0] == xp.shape[0] == y.shape[0] == hx.shape[0] == valid.shape[0]
            == predict.shape[0] == diverged.shape[0] == nis_run.shape[0] == nis.shape[0] == n_b
            and F.shape[0] in (1, n_b) and H.shape[0] in (1, n_b) and R.shape[0] in (1, n_b)):
        raise ValueError("predict_update: the arrays must have a row per system (F, H, R: "
                         "one row for all)")
    c = min(CHUNK, n_b)
    Ps, Fs, FP, Pm, Qs, IKH, T, U, Hs, PHt, K, KR, Rs, S, W, L = scratch(n, m, c)
    ok = np.empty(c, dtype=np.bool_)
    Xm, E = np.empty((n, c)), np.empty((m, c))
    load(Q.reshape(1, n, n), 0, c, Qs)
    for b0 in range(0, n_b, c):
        nb = min(c, n_b - b0)
        load(P, b0, nb, Ps)
        load(F, b0, nb, Fs)
        load(H, b0, nb, Hs)
        load(R, b0, nb, Rs)
        predict_block(Ps, Fs, Qs, nb, FP, Pm)
        for t in range(nb):
            if not predict[b0 + t]:                  # a first step: the prior as it is
                for i in range(n):
                    for j in range(n):
                        Pm[i, j, t] = Ps[i, j, t]
        gain_block(Pm, Hs, Rs, nb, PHt, S, W, L, ok, K, IKH, T, U, KR)
        for t in range(nb):
            for i in range(n):
                Xm[i, t] = xp[b0 + t, i]
            for i in range(m):
                E[i, t] = y[b0 + t, i] - hx[b0 + t, i]
        finish(b0, nb, Xm, E, valid, Block(ok, K, W, Pm, U), 0, False, True, out)


@jit
def linear_step(A: np.ndarray, B: np.ndarray, Q: np.ndarray, C: np.ndarray, R: np.ndarray,
                u: np.ndarray, y: np.ndarray, valid: np.ndarray, predict: np.ndarray,
                gain_K: np.ndarray, gain_W: np.ndarray, regime: np.ndarray, x: np.ndarray,
                P: np.ndarray, diverged: np.ndarray, nis_run: np.ndarray, nis: np.ndarray,
                logdet: np.ndarray, limits: np.ndarray) -> bool:
    """One step of a linear model's filter, in place on its record's arrays (the last seven,
    in the order of :class:`~.watch.Watched`; :meth:`~fir_gym.estimators.kalman.LinearGains.step`
    hands them by name from the :class:`~fir_gym.estimators.state.FilterState`, with no Python
    frame between: the KF's step is the lightest of all, 4 µs): ``x⁻ = A x + B u`` (``u (B |
    1, n_u)``) and ``P⁻ = A P Aᵀ + Q`` where ``predict``, the update with ``e = y − C x⁻``, the
    watch. Returns True; False when the gate (``limits[GATE]``) rejects a measurement while
    ``P`` is shared or steady — shortcuts that cannot hold that system's own ``P⁻`` — and then
    nothing of the state (``x``, ``P``, ``regime``, the watch's arrays) has been written: the
    caller leaves the shortcut and calls again.

    ``P`` is ``(B, n, n)``, or ``(1, n, n)``: one covariance shared by every system (every
    measurement must then be usable and ``predict`` the same for all). ``gain_K (n, m, rows of
    P)`` and ``gain_W (m, m, rows)`` receive ``K`` and ``S⁻¹`` of each row of ``P`` (held as
    blocks). ``regime[0] == 1`` is the steady state: ``P`` and the gains stay, only the states
    are updated (every measurement usable, every system predicting); with ``regime[1] == 1``
    (a time-invariant model) a step enters it when ``max |P⁺ − P| <= 4 eps max |P|`` (the
    recursion then only wanders by a few ulps, often in a cycle, never settling bit for bit),
    and a repaired (non-finite) estimate leaves it.
    """
    out = Watched(x, P, diverged, nis_run, nis, logdet, limits)
    n_b, n = x.shape
    n_p, m, n_u = P.shape[0], y.shape[1], u.shape[1]
    if not (n_p in (1, n_b) and gain_K.shape[2] == gain_W.shape[2] == n_p
            and u.shape[0] in (1, n_b) and y.shape[0] == valid.shape[0] == predict.shape[0]
            == diverged.shape[0] == nis_run.shape[0] == nis.shape[0] == n_b):
        raise ValueError("linear_step: the arrays must have a row per system (P and the gains: "
                         "or one row for all; u: or one for all)")
    steady = regime[0] == 1
    Pm_all, Pp_all = np.empty((n, n, n_p)), np.empty((n, n, n_p))
    ok_all = np.ones(n_p, dtype=np.bool_)
    change, scale = 0.0, 0.0
    if steady:                                       # P⁺ = P⁻ = P
        for r in range(n_p):
            for i in range(n):
                for j in range(n):
                    Pm_all[i, j, r] = P[r, i, j]
                    Pp_all[i, j, r] = P[r, i, j]
    else:                                            # the covariance half, per row of P
        c = min(CHUNK, n_p)
        Ps, As, FP, _, Qs, IKH, T, _, Cs, PHt, _, KR, Rs, S, _, L = scratch(n, m, c)
        ok = np.empty(c, dtype=np.bool_)
        load(Q.reshape(1, n, n), 0, c, Qs)
        load(A.reshape(1, n, n), 0, c, As)
        load(C.reshape(1, m, n), 0, c, Cs)
        load(R.reshape(1, m, m), 0, c, Rs)
        for b0 in range(0, n_p, c):
            nb = min(c, n_p - b0)
            Pm, U = Pm_all[:, :, b0:b0 + nb], Pp_all[:, :, b0:b0 + nb]
            K, W = gain_K[:, :, b0:b0 + nb], gain_W[:, :, b0:b0 + nb]
            load(P, b0, nb, Ps)
            predict_block(Ps, As, Qs, nb, FP, Pm)
            for t in range(nb):
                if not predict[b0 + t]:
                    for i in range(n):
                        for j in range(n):
                            Pm[i, j, t] = Ps[i, j, t]
            gain_block(Pm, Cs, Rs, nb, PHt, S, W, L, ok, K, IKH, T, U, KR)
            for t in range(nb):
                r = b0 + t
                ok_all[r] = ok[t]
                for i in range(n):
                    for j in range(n):
                        scale = max(scale, abs(P[r, i, j]))
                        change = max(change, abs(U[i, j, t] - P[r, i, j]))
    shared = n_p < n_b
    gate_limit = limits[GATE]
    Xm, E = np.empty((n, n_b)), np.empty((m, n_b))
    settling = regime[1] == 1
    # the state half: x⁻ and e of every system, then one finish call (a call per block of
    # 64 cost the converged KF ~15 ns per system-step of its ~45)
    for b in range(n_b):
        ub = 0 if u.shape[0] == 1 else b
        settling = settling and valid[b] and predict[b]
        for i in range(n):
            if predict[b]:
                v = 0.0
                for k in range(n):
                    v += A[i, k] * x[b, k]
                for k in range(n_u):
                    v += B[i, k] * u[ub, k]
                Xm[i, b] = v
            else:
                Xm[i, b] = x[b, i]
        for i in range(m):
            v = 0.0
            for k in range(n):
                v += C[i, k] * Xm[k, b]
            E[i, b] = y[b, i] - v
    if (shared or steady) and gate_limit < np.inf:   # would the gate reject? (as finish)
        for b in range(n_b):
            col = 0 if shared else b
            if valid[b] and ok_all[col]:
                q = 0.0
                for i in range(m):
                    for k in range(m):
                        q += E[i, b] * gain_W[i, k, col] * E[k, b]
                if q > gate_limit:
                    return False
    repaired = not finish(0, n_b, Xm, E, valid, Block(ok_all, gain_K, gain_W, Pm_all, Pp_all),
                          0, shared, not (shared or steady), out)
    if settling and gate_limit < np.inf:             # a rejected measurement: as if missing
        for b in range(n_b):
            settling = settling and not nis[b] > gate_limit
    if shared and not steady:                        # one covariance, stored where finite
        finite = ok_all[0]
        for i in range(n):
            for j in range(n):
                finite = finite and np.isfinite(Pp_all[i, j, 0])
        if finite:
            for i in range(n):
                for j in range(n):
                    P[0, i, j] = Pp_all[i, j, 0]
    if steady:
        regime[0] = 0 if repaired else 1
    else:
        regime[0] = 1 if settling and not repaired and change <= 4.0 * EPS * scale else 0
    return True
