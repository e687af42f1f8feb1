"""The single-system fast path of :class:`~.efir.ExtendedFIRFilter` (``Estimator._make_lean``).

One system (``y`` of shape ``(n_y,)``) past start-up steps here instead of through
``ExtendedFIRFilter._advance`` + ``Estimator._accept``. A step on one small system is
a few thousand flops; the general path spends most of its ~90 µs on the glue of ~80
numpy calls on arrays with a leading batch axis of one. Here the bank's kernels act
in place on fixed 2-D views of ``WindowBank.Z`` (batch axis dropped), the model is
called once per quantity, and the bookkeeping of ``_accept`` runs on Python floats:
about a third of the calls.

**Why the numbers are the general path's, bit for bit.** Every floating-point
operation is the general path's own, on the same operands:

* products: ``np.dot`` on the operands of the general path's batched ``matmul`` with
  the batch axis of one dropped; for 2-D operands both make one call of the same BLAS
  routine (``gemm``, or the same ``gemv`` kernel where one side is a vector; ``np.dot``
  first copies a strided operand, which moves the numbers, not the arithmetic); the
  LAPACK inverse is the gufunc behind ``np.linalg.inv``;
* elementwise operations give the same result however they are broadcast, repeated
  or ordered against independent ones (``a − b`` is ``a + (−b)`` in IEEE arithmetic);
* ``Z`` holds ``M = −F`` and ``inv(−M) = −inv(M)`` exactly (LU with partial pivoting is
  sign-symmetric: the same pivots, every rounding mirrored), so ``T F⁻¹ b`` is computed
  as ``−(T M⁻¹) b`` without the negation;
* the open-loop nominal is propagated by the model's ``linearize``, ``h``, ``H`` on one
  state ``(n,)`` rather than a batch of one ``(1, n)`` — a plant's cheapest call, as in
  the EKF's fast path (:mod:`~._lean`); this assumes what batched models promise, that
  a state gives the same numbers alone as in a batch. Re-anchored nominals are
  called with the general path's ``(N, n)`` arrays.

``tests/estimators/test_efir_fast_path.py`` checks the equality bit for bit.

**Guards.** The fast step starts only when nothing unusual is pending: the first
step, the start-up (a window not yet full), a restart, a NaN or odd-shaped ``y`` or
``u`` return ``None`` before any state changes, and ``Estimator.step`` runs the general
path. Once begun, the step never hands back: a window whose information is not
regular (``rank_deficient``, a singular inverse) is read out by the general
``ExtendedFIRFilter._readout``, and a non-finite estimate or a covariance over
``max_covariance_trace`` gets ``_accept``'s treatment in :func:`commit`, on the same
state the general path reaches.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ._fir_bank import RANK_RTOL
from ._validation import FloatArray

try:        # the LAPACK gufunc of np.linalg.inv, without ~2.5 µs of wrapping
    from numpy.linalg._umath_linalg import inv as _inv  # NaN where singular (no raise)
except ImportError:                              # pragma: no cover - numpy internals moved
    def _inv(M: FloatArray) -> FloatArray:
        try:
            return np.linalg.inv(M)
        except np.linalg.LinAlgError:
            return np.full_like(M, np.nan)

#: ``spd_inverse``'s regularity test: ``‖Fs⁻¹‖²_F`` below this
_FROBENIUS_LIMIT = RANK_RTOL ** -2
#: below this, any summation order of the (non-negative) terms passes the test
_SURELY_REGULAR = _FROBENIUS_LIMIT * (1.0 - 1e-9)

#: hooks whose override disables the fast path (it computes ExtendedFIRFilter's step)
_HOOKS = ("step", "_advance", "_readout", "_nominal_of", "_accept", "_update",
          "_predict_update", "_init_batch", "_restart_systems", "_update_systems")

Lean = Callable[[Any, Any], "FloatArray | None"]


def extended_fir(flt: Any, cls: type) -> Lean | None:
    """The fast step of one system of ``flt`` (an :class:`~.efir.ExtendedFIRFilter`), or
    ``None`` where the general path must run every step (a subclass with its own hooks)."""
    if any(getattr(type(flt), h, None) is not getattr(cls, h, None) for h in _HOOKS):
        return None
    bank, m = flt._bank, flt.model
    n, p, n_u, L = m.n_x, m.n_y, m.n_u, flt.horizon
    filt, anchored = flt.form == "filter", flt.nominal != "open-loop"
    Z = bank.Z[0]                                   # (2n, L, 2n+1): the state, in place
    Z2 = Z.reshape(2 * n, -1)                       # its rows, the windows side by side
    ZP = Z[:n, :, :n].reshape(n * L, n)             # every window's P, stacked
    if bank._has_ref or not (np.shares_memory(Z2, Z) and np.shares_memory(ZP, Z)):
        return None                                 # pragma: no cover - views of Z
    Zx = Z2[:n]                                     # rows [P | T | x̄] of every window
    windows = [(Z[:, w, :], Z[n:, w, n:2 * n], Z[:n, w, n:2 * n], Z[:n, w, 2 * n],
                Z[n:, w, 2 * n], Z[:n, w, :n]) for w in range(L)]  # Z_w, M = −F, T, x̄, b, P
    AZ = np.empty((n, L * (2 * n + 1)))             # buffers: A [P | T | x̄]; residuals r
    r = np.empty((1, L * (2 * n + 1)))
    r3 = r.reshape(L, 2 * n + 1)
    r_e, r_KW, r_P = r3[:, 2 * n], r3[:, :2 * n], r3[:, :n]
    fresh, Qx = bank._fresh, flt._Qx
    Qs = None if Qx is None else np.repeat(Qx, L, axis=0)   # Qx[i] at rows i·L + w of ZP
    R, R00 = flt._R, float(flt._R[0, 0])
    linearize, h, H, f = flt._linearize, flt._h, flt._H, flt._f
    no_input, no_startup, age = flt._no_input, flt._no_startup, flt._age
    q = _frobenius_kernel(n)
    dot, inv, contiguous, subtract = np.dot, _inv, np.ascontiguousarray, np.subtract

    def predict(A: FloatArray) -> None:
        """``bank.predict(A[None], None, Qx)`` for ``A (n, n)`` shared by the windows."""
        dot(A, Zx, out=AZ)
        Zx[...] = AZ
        if Qs is not None:
            np.add(dot(ZP, contiguous(A.T)), Qs, out=ZP)

    def update(C: FloatArray, e: float) -> None:
        """``bank.update(C[None], R, y − h)`` for one measurement (``p = 1``), ``C (1, n)``
        shared by the windows, ``e = y − h``: ``Z −= g ⊗ r`` for all rows as one product."""
        dot(C, Zx, out=r)
        r_e.__isub__(e)
        S = dot(r_P, C.T)                           # C P Cᵀ of every window
        S += R00
        G = (r_KW / S).T.repeat(2 * n + 1, axis=1)  # G[i, w·(2n+1) + j] = [K; W][w, i]
        G *= r
        subtract(Z2, G, out=Z2)

    def readout(w: int, U: FloatArray, nom: FloatArray) -> tuple[FloatArray, FloatArray, bool]:
        """``ExtendedFIRFilter._readout(w, U, no start-up)``: the nominal ``nom (n,)`` plus
        ``bank.estimate(w)`` where ``spd_inverse`` finds ``F`` regular by its first (Frobenius)
        test, else the general readout with its fallback."""
        _, M, T, xb, b, Pw = windows[w]
        Mi = inv(M)                                 # −F⁻¹
        if q(Mi.tolist(), M.tolist()) < _SURELY_REGULAR or _frobenius_ok(M, Mi):
            TMi = dot(T, Mi)
            x = xb - dot(TMi, b)                    # x̄ + T F⁻¹ b
            x += nom
            P = dot(TMi, T.T)
            return x.reshape(1, n), subtract(Pw, P, out=P).reshape(1, n, n), True
        x, P, ok = flt._readout(w, U, no_startup)
        return x, P, bool(ok[0])

    def lean(y: Any, u: Any) -> FloatArray | None:
        if flt._in_startup or flt._pending is not None:
            return None
        io = inputs(y, u, p, n_u, no_input)
        if io is None:
            return None
        y, ys, U = io
        k = flt._k
        w_out, s = (k - L + filt) % L, k % L
        with np.errstate(all="ignore"):
            if anchored:                            # (L, n) nominals, one per window
                nom, A = linearize(flt._nom.reshape(-1, n), np.repeat(U, L, axis=0))
                flt._nom = nom.reshape(1, L, n)
                bank.predict(A.reshape(1, L, n, n), None, Qx)
            else:                                   # one nominal, called as one state (n,)
                nom, A = linearize(flt._nom[0], U[0])
                flt._nom = nom.reshape(1, n)
                predict(A.reshape(n, n))
            if not filt:
                x, P, ok = readout(w_out, U, nom if not anchored else flt._nom[0, w_out])
            if anchored:
                flt._nom[:, s] = x if not filt else f(flt._x, U)
            windows[s][0][...] = fresh              # bank.restart(s)
            if anchored:
                nom = flt._nom.reshape(-1, n)
                bank.update(H(nom).reshape(1, L, p, n), R, (y - h(nom)).reshape(1, L, p))
            elif p == 1:
                update(H(nom).reshape(1, n), ys[0] - h(nom).item())
            else:
                bank.update(H(nom).reshape(1, p, n), R, (y - h(nom)).reshape(1, p))
            if filt:
                x, P, ok = readout(w_out, U, nom if not anchored else flt._nom[0, w_out])
            age[0] = k + 1                          # measurements so far (+= 1, one system)
            flt._last_xP = (x, P)
            flt._info = {"startup": False, "rank_deficient": not ok}
            flt._k_last = k
            return commit(flt, x, P)
    return lean


@functools.cache
def _frobenius_kernel(n: int) -> Callable[[list[list[float]], list[list[float]]], float]:
    """``q(mi, m) = Σ_ij d_i Mi_ij² d_j`` with ``d = −diag M``: the quantity of ``spd_inverse``'s
    first regularity test (``d (Fi∘Fi) d`` for ``F = −M``, ``Fi = F⁻¹ = −Mi``), straight-line
    on the nested lists of ``Mi`` and ``M``; NaN unless every ``d_i >= 0``.

    With ``d >= 0`` every term is non-negative, so any summation order (BLAS's included)
    is within a relative ``n² ε`` of the exact sum: ``q <`` :data:`_SURELY_REGULAR` settles
    the test as the general path's own expression would. Otherwise (near or above the
    limit, a negative or non-finite ``d``) :func:`_frobenius_ok` evaluates that expression.
    """
    d = [f"d{i}" for i in range(n)]
    g = [[f"g{i}_{j}" for j in range(n)] for i in range(n)]
    rows = " + ".join(f"{d[i]} * (" + " + ".join(f"{d[j]} * {g[i][j]} * {g[i][j]}"
                                                  for j in range(n)) + ")" for i in range(n))
    src = (f"def q(mi, m):\n    {', '.join('(' + ', '.join(row) + ',)' for row in g)}, = mi\n"
           f"    {', '.join(d)}, = {', '.join(f'-m[{i}][{i}]' for i in range(n))},\n"
           f"    if not min({', '.join(d)}, 0.0) == 0.0:\n        return float('nan')\n"
           f"    return {rows}\n")
    scope: dict[str, Any] = {}
    exec(compile(src, f"<fir_gym efir frobenius {n}>", "exec"), scope)
    return scope["q"]


def _frobenius_ok(M: FloatArray, Mi: FloatArray) -> bool:
    """``spd_inverse``'s first regularity test on ``F = −M``, in its own words (``Fi∘Fi =
    Mi∘Mi``)."""
    d = (-M).diagonal()
    return bool((d[None, :] @ (Mi * Mi) @ d[:, None])[0, 0] < _FROBENIUS_LIMIT)


def inputs(y: Any, u: Any, p: int, n_u: int, no_input: FloatArray
           ) -> tuple[FloatArray, list[float], FloatArray] | None:
    """``y (p,)`` (also as floats) and ``u`` as ``(1, n_u)``, as ``Estimator.step`` takes them for
    one system (``u`` None: zeros); ``None`` for anything the general path must judge (a NaN
    or inf, another shape: it skips, raises or broadcasts as documented)."""
    if type(y) is not np.ndarray or y.dtype != np.float64:
        y = np.asarray(y, dtype=np.float64)
    ys = y.tolist()
    if y.shape != (p,) or not math.isfinite(sum(ys)):
        return None
    if u is None:
        return y, ys, no_input
    if type(u) is not np.ndarray or u.dtype != np.float64:
        u = np.asarray(u, dtype=np.float64)
    if u.shape not in ((n_u,), (1, n_u)) and not (u.ndim == 0 and n_u == 1):
        return None
    if not math.isfinite(sum(u.ravel().tolist())):
        return None
    return y, ys, u.reshape(1, n_u)


def commit(flt: Any, x: FloatArray, P: FloatArray) -> FloatArray:
    """``Estimator._accept(x, P, None, valid)`` for one system, then the step's return value.

    ``_accept`` stores ``x, P`` where both are finite and keeps the last finite ones
    otherwise; it flags divergence (sticky) where they are not finite or ``trace P``
    exceeds ``max_covariance_trace``. Here on floats: a finite sum means finite terms
    (an overflowing sum of finite terms is looked at term by term), and the trace is
    summed in numpy's own order only where ``Σ |P_ii|`` (which bounds it, summed in any
    order) comes near the limit (and never once flagged).
    """
    xs, Ps = x.tolist()[0], P.ravel().tolist()
    finite = math.isfinite(sum(xs) + sum(Ps)) or (all(map(math.isfinite, xs))
                                                  and all(map(math.isfinite, Ps)))
    if not finite:
        flt._diverged[0] = True
        x, P = flt._x, flt._P
    elif not flt._diverged[0]:
        limit = flt.max_covariance_trace
        if (sum(map(abs, Ps[::len(xs) + 1])) > limit * (1.0 - 1e-12)
                and float(np.trace(P[0])) > limit):
            flt._diverged[0] = True
    flt._x, flt._P = x, P
    flt.last_info = {"diverged": bool(flt._diverged[0]), "nis": None}
    flt._k += 1
    return x[0].copy()
