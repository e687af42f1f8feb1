"""The divergence watch of every compiled step, in place on the filter's state.

The contract is :meth:`Estimator._accept <fir_gym.estimators.base.Estimator._accept>`'s
(its numpy reference): a system's new estimate is kept only where it and its
covariance are finite (else the last finite ones stay); the system is flagged
diverged (sticky) where they are not finite, where ``trace P`` exceeds
``max_covariance_trace``, or where its NIS has been above the χ² threshold — a NaN
NIS of a usable measurement counts as above — for ``nis_patience`` steps running.

``limits`` is the record's (:mod:`~fir_gym.estimators.state`, read by the names
``NIS_THRESHOLD``, ``NIS_PATIENCE``, ``MAX_TRACE``, ``MAX_ESTIMATE``, ``GATE``); with a finite
``MAX_ESTIMATE`` (the windowed filters) a system whose new estimate has a component beyond it
in magnitude is flagged too (the growth bound of :mod:`~fir_gym.estimators._consistency`).

:func:`innovation_nis` is the twin of
:func:`~fir_gym.estimators._consistency.innovation_nis`, the windowed filters' one-step
innovation test.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..state import MAX_ESTIMATE, MAX_TRACE, NIS_PATIENCE, NIS_THRESHOLD
from . import jit

if TYPE_CHECKING:
    from ..state import FilterState

__all__ = ["Watched", "accept", "accept_into", "innovation_nis", "verdict"]


class Watched(NamedTuple):
    """The arrays of a :class:`~fir_gym.estimators.state.FilterState` a compiled step writes,
    by name. The kernels build it from the record's arrays at their entry and hand it to
    their pieces (a tuple passed between compiled functions costs nothing; at the Python
    boundary numba dispatches a tuple argument about 0.6 µs slower than its arrays, a quarter
    of a step's fixed cost, so the entry points take the record and the kernels its arrays)."""

    x: np.ndarray
    P: np.ndarray
    diverged: np.ndarray
    nis_run: np.ndarray
    nis: np.ndarray
    logdet: np.ndarray
    limits: np.ndarray


@jit
def verdict(finite: bool, trace: float, nis: float, usable: bool, has_nis: bool, run: int,
            nis_limit: float, patience: float, max_trace: float) -> tuple[int, bool]:
    """One system's booking: ``(its new NIS run, whether this step flags it)``. Its new
    estimate is stored exactly where ``finite``. The limits come as numbers (an array
    argument would cost a reference count per call)."""
    blown = not finite or trace > max_trace
    if has_nis:
        run = run + 1 if usable and not nis <= nis_limit else 0
        blown = blown or run >= patience
    return run, blown


def accept(x_new: np.ndarray, P_new: np.ndarray, nis_new: np.ndarray, valid: np.ndarray,
           has_nis: bool, state: FilterState) -> None:
    """Store ``x_new (B, n)``, ``P_new (B, n, n)`` into the record's ``x``, ``P`` where finite,
    and book every system in its watch (``nis_new`` is ignored without ``has_nis``)."""
    accept_into(x_new, P_new, nis_new, valid, has_nis, state.x, state.P, state.diverged,
                state.nis_run, state.nis, state.logdet, state.limits)


@jit
def accept_into(x_new: np.ndarray, P_new: np.ndarray, nis_new: np.ndarray, valid: np.ndarray,
                has_nis: bool, x: np.ndarray, P: np.ndarray, diverged: np.ndarray,
                nis_run: np.ndarray, nis: np.ndarray, logdet: np.ndarray, limits: np.ndarray
                ) -> None:
    """The kernel of :func:`accept`, on the record's arrays (``logdet`` is left as it is: the
    windowed filters have no innovation covariance)."""
    n_b, n = x_new.shape
    if not (P_new.shape[0] == x.shape[0] == P.shape[0] == valid.shape[0] == diverged.shape[0]
            == nis_run.shape[0] == nis.shape[0] == n_b and nis_new.shape[0] in (0, n_b)):
        raise ValueError("accept: the arrays must have a row per system")
    nis_limit, patience, max_trace = limits[NIS_THRESHOLD], limits[NIS_PATIENCE], limits[MAX_TRACE]
    max_abs = limits[MAX_ESTIMATE]
    for b in range(n_b):
        finite = True
        trace = 0.0
        grown = False
        for i in range(n):
            finite = finite and np.isfinite(x_new[b, i])
            grown = grown or not abs(x_new[b, i]) <= max_abs
            trace += P_new[b, i, i]
            for j in range(n):
                finite = finite and np.isfinite(P_new[b, i, j])
        q = nis_new[b] if has_nis else np.nan
        nis_run[b], blown = verdict(finite, trace, q, valid[b], has_nis, nis_run[b], nis_limit,
                                    patience, max_trace)
        if blown or grown:
            diverged[b] = True
        if finite:
            for i in range(n):
                x[b, i] = x_new[b, i]
                for j in range(n):
                    P[b, i, j] = P_new[b, i, j]
        nis[b] = q


@jit
def innovation_nis(P: np.ndarray, A: np.ndarray, Qx: np.ndarray, H: np.ndarray,
                   R: np.ndarray, e: np.ndarray, predict: np.ndarray, valid: np.ndarray,
                   out: np.ndarray) -> None:
    """``out[b] = eᵀ S⁻¹ e``, ``S = H P⁻ Hᵀ + R``, ``P⁻ = A P Aᵀ + Qx`` (``P`` where ``predict``
    is False) for every system; NaN where ``valid`` is False or ``S`` is not positive
    definite. Shapes as the reference's (``R`` 2-D); a leading axis of length 1 is shared.
    ``S⁻¹`` as there: closed form for ``p <= 2`` (PD test ``s11 > 0, det > 0``), else
    Cholesky. The two products are written out with plain indices: per-system views or a
    helper call cost several times the 2 x 2 algebra (700 ns against 110 ns a system)."""
    n_b, n = P.shape[0], P.shape[1]
    p = H.shape[1]
    AP, Pm, HP = np.empty((n, n)), np.empty((n, n)), np.empty((p, n))
    S, L, z = np.empty((p, p)), np.empty((p, p)), np.empty(p)
    for b in range(n_b):
        if not valid[b]:
            out[b] = np.nan
            continue
        ab = b if A.shape[0] > 1 else 0
        qb = b if Qx.shape[0] > 1 else 0
        hb = b if H.shape[0] > 1 else 0
        if predict[b]:                                  # P⁻ = (A P) Aᵀ + Qx
            for i in range(n):
                for j in range(n):
                    c = 0.0
                    for k in range(n):
                        c += A[ab, i, k] * P[b, k, j]
                    AP[i, j] = c
            for i in range(n):
                for j in range(n):
                    c = 0.0
                    for k in range(n):
                        c += AP[i, k] * A[ab, j, k]
                    Pm[i, j] = c + Qx[qb, i, j]
        else:
            for i in range(n):
                for j in range(n):
                    Pm[i, j] = P[b, i, j]
        for i in range(p):                              # S = (H P⁻) Hᵀ + R
            for j in range(n):
                c = 0.0
                for k in range(n):
                    c += H[hb, i, k] * Pm[k, j]
                HP[i, j] = c
        for i in range(p):
            for j in range(p):
                c = 0.0
                for k in range(n):
                    c += HP[i, k] * H[hb, j, k]
                S[i, j] = c + R[i, j]
        for i in range(p):                              # symmetrised
            for j in range(i):
                v = 0.5 * (S[i, j] + S[j, i])
                S[i, j] = v
                S[j, i] = v
        if p == 1:
            out[b] = e[b, 0] * (1.0 / S[0, 0]) * e[b, 0] if S[0, 0] > 0.0 else np.nan
        elif p == 2:
            a, c, d = S[0, 0], S[0, 1], S[1, 1]
            det = a * d - c * c
            if a > 0.0 and det > 0.0:
                w00, w11, w01 = d / det, a / det, -c / det
                e0, e1 = e[b, 0], e[b, 1]
                out[b] = e0 * (w00 * e0 + w01 * e1) + e1 * (w01 * e0 + w11 * e1)
            else:
                out[b] = np.nan
        else:                                           # Cholesky: NIS = |L⁻¹ e|²
            ok = True
            for j in range(p):
                d = S[j, j]
                for k in range(j):
                    d -= L[j, k] * L[j, k]
                ok = ok and d > 0.0
                L[j, j] = np.sqrt(d) if d > 0.0 else 1.0
                for i in range(j + 1, p):
                    c = S[i, j]
                    for k in range(j):
                        c -= L[i, k] * L[j, k]
                    L[i, j] = c / L[j, j]
            q = 0.0
            for i in range(p):
                c = e[b, i]
                for k in range(i):
                    c -= L[i, k] * z[k]
                z[i] = c / L[i, i]
                q += z[i] * z[i]
            out[b] = q if ok else np.nan
