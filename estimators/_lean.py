"""The single-system fast path of the Kalman family (``Estimator._make_lean``).

For one system (``y`` of shape ``(n_y,)``) with ``n_x, n_y <= 4`` a filter step runs
the generated float kernels of :mod:`~._small` instead of the batched numpy kernels:
the same formulas in the same order, to round-off (the tests check 1e-12 against the
general path). :func:`inputs`, :func:`state` and :func:`commit` do what
``Estimator.step`` and ``Estimator._accept`` do around a step; anything unusual (a NaN
measurement, another shape, a covariance that is not positive definite, a NIS above
its threshold, a divergence) returns ``None`` before any state changes, and the
general path then redoes the step with its exact bookkeeping.

The fast path is off where round-off is amplified, since then only the general
path's own operation order reproduces its numbers to 1e-12: finite-difference
Jacobians (step ``eps^(1/3)``: ~1e5 times the last bits) and sigma-point weights
above :data:`MAX_WEIGHT` (``1/α²``: 1e6 at the UKF's default α = 1e-3).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from . import _small
from ._validation import FloatArray

#: Largest sigma-point weight of the UKF's fast path. The weighted sums lose about
#: ``max |W|`` ulps (``1/α²``: 1e6 at the default α = 1e-3), so with large weights the
#: estimate depends on the last bits of every operation; such schemes stay on the
#: general path.
MAX_WEIGHT = 10.0

#: machine epsilon (the KF's steady-state test, as ``kalman._converged``)
_EPS = float(np.finfo(np.float64).eps)


def inputs(flt: Any, y: Any, u: Any) -> tuple[list[float], list[float], Any] | None:
    """``y`` and ``u`` of one system as float lists, plus ``u`` as a ``(1, n_u)`` array.

    ``None`` when the general path must decide (NaN or inf, another shape).
    """
    if type(y) is not np.ndarray or y.dtype != np.float64:
        y = np.asarray(y, dtype=np.float64)
    if y.shape != (flt._n_y,):
        return None
    ys = y.tolist()
    if not math.isfinite(sum(ys)):
        return None
    if u is None:
        U = flt._no_input
        return ys, flt._lean_u0, U
    if type(u) is not np.ndarray or u.dtype != np.float64:
        u = np.asarray(u, dtype=np.float64)
    n_u = flt._no_input.shape[1]
    if u.shape != (n_u,):
        if u.shape == (1, n_u):
            u = u[0]
        else:
            return None
    us = u.tolist()
    if not math.isfinite(sum(us)):
        return None
    return ys, us, u.reshape(1, n_u)

def state(flt: Any) -> tuple[list[float], list[float]]:
    """The current ``x`` and ``P`` of the single system as flat float sequences."""
    cache = flt._lean_cache
    if cache[0] is flt._x and cache[1] is flt._P:
        return cache[2], cache[3]
    xs = flt._x.ravel().tolist()
    Ps = () if flt._P is None else flt._P.ravel().tolist()
    flt._lean_cache = (flt._x, flt._P, xs, Ps)
    return xs, Ps

def commit(flt: Any, x: Sequence[float], P: Sequence[float] | None, nis: float | None,
                 keep_P: bool = False) -> FloatArray | None:
    """Store a fast step's result if :meth:`Estimator._accept` would take it as it is.

    ``Estimator._accept``'s fast test passes exactly when ``x`` and ``P`` are finite, the
    trace of ``P`` is within ``max_covariance_trace`` and the NIS is below its
    threshold with no NIS run going on; otherwise nothing is stored and ``None``
    returned (the general path redoes the step with its exact bookkeeping).
    ``keep_P``: ``P`` is the stored covariance, unchanged.
    """
    if not math.isfinite(sum(x)):
        return None
    n = len(x)
    if P is not None and not keep_P:
        if not math.isfinite(sum(P)) or not sum(P[::n + 1]) <= flt.max_covariance_trace:
            return None
    if nis is not None and (flt._nis_running or not nis <= flt._nis_threshold):
        return None
    X = np.array(x)
    flt._x = X.reshape(1, n)
    if P is None:
        flt._P = None
    elif not keep_P:
        flt._P = np.array(P).reshape(1, n, n)
    flt._lean_cache = (flt._x, flt._P, x, flt._lean_cache[3] if keep_P else P)
    flt.last_info = {"diverged": bool(flt._diverged[0]), "nis": nis}
    flt._k += 1
    return X.copy()


def kalman(flt: Any) -> Any:
    """One system of a time-invariant model with ``n_x, n_y <= 4``: generated float kernels
    (:mod:`~._small`) with the matrices baked in, and the same steady-state shortcut."""
    m = flt.model
    if not flt._constant or max(m.n_x, m.n_y) > _small.MAX_SIZE:
        return None
    kernels = getattr(flt, "_lean_kernels", None)
    if kernels is None:
        A, B, C, _, _, R = m.matrices(0)
        kernels = flt._lean_kernels = (_small.kf_kernel(A, B, C, flt._mats[4], R),
                                        _small.kf_steady_kernel(A, B, C))
    full, steady_step = kernels

    def lean(y: Any, u: Any) -> FloatArray | None:
        io = inputs(flt, y, u)
        if io is None:
            return None
        ys, us, _ = io
        x, P = state(flt)
        st = flt._lean_steady
        if st is not None and flt._P is st[0]:
            x_new, nis = steady_step(x, us, ys, st[1], st[2])
            return commit(flt, x_new, P, nis, keep_P=True)
        try:
            r = full(x, P, us, ys)
        except ArithmeticError:
            r = None
        if r is None:
            return None
        x_new, P_new, nis, K, W = r
        out = commit(flt, x_new, P_new, nis)
        if out is not None:
            # _converged's test: max|ΔP| <= 4 eps max|P|
            change = max(abs(a - b) for a, b in zip(P_new, P, strict=True))
            steady = change <= 4.0 * _EPS * max(map(abs, P))
            flt._lean_steady = (flt._P, K, W) if steady else None
        return out
    return lean


def extended(flt: Any, plain_linear: bool) -> Any:
    """One system with ``n_x, n_y <= 4`` and analytic Jacobians: the model's ``f, F, h, H``
    on the ``(n,)`` state (a plant's cheapest call; every model callable accepts it),
    the covariance algebra in a generated float kernel (:mod:`~._small`); on a
    :class:`LinearModel` the matrices are baked in and the model is not called
    (``f = A x + B u``, ``F = A``, ``h = C x``, ``H = C``)."""
    m = flt.model
    n, n_y = m.n_x, m.n_y
    if max(n, n_y) > _small.MAX_SIZE or not all(m.has_analytic_jacobians):
        # finite-difference Jacobians amplify round-off by 1/step ~ 1e5: only the general
        # path's own operation order reproduces its numbers to 1e-12
        return None
    if plain_linear:
        full = _small.kf_kernel(m.A, m.B, m.C, flt._GQGt, m.R)

        def lean_linear(y: Any, u: Any) -> FloatArray | None:
            io = inputs(flt, y, u)
            if io is None:
                return None
            x, P = state(flt)
            try:
                r = full(x, P, io[1], io[0])
            except ArithmeticError:
                return None
            return None if r is None else commit(flt, r[0], r[1], r[2])
        return lean_linear
    kernel = _small.ekf_kernel(n, n_y)
    Q, R = flt._GQGt.ravel().tolist(), m.R.ravel().tolist()
    linearize, h, H = flt._linearize, flt._h, flt._H

    def lean(y: Any, u: Any) -> FloatArray | None:
        io = inputs(flt, y, u)
        if io is None:
            return None
        ys, _, U = io
        P = state(flt)[1]
        with np.errstate(all="ignore"):           # one system as (n,): the model's
            xp, F = linearize(flt._x[0], U[0])   # cheapest call (no batch axis)
            hx, Hx = h(xp), H(xp)
        try:
            r = kernel(xp.ravel().tolist(), P, F.ravel().tolist(), Q, hx.ravel().tolist(),
                       ys, Hx.ravel().tolist(), R)
        except (ArithmeticError, ValueError):
            return None
        return None if r is None else commit(flt, r[0], r[1], r[2])
    return lean


def unscented(flt: Any) -> Any:
    """One system with ``n_x, n_y <= 4`` and no jitter: the model's ``f`` and ``h`` on the
    ``(N, n)`` sigma points (exactly the general path's calls), everything else in
    generated float kernels (:mod:`~._small`)."""
    m, sp = flt.model, flt.points
    n, n_y = m.n_x, m.n_y
    if max(n, n_y) > _small.MAX_SIZE or flt.jitter or max(
            np.abs(sp.Wm).max(), np.abs(sp.Wc).max()) > MAX_WEIGHT:
        return None
    draw, moments, correct = _small.ukf_kernels(np.ascontiguousarray(sp.xi), sp.Wm, sp.Wc,
                                                sp.same_tail, sp.sum_Wc, n_y)
    N, redraw = sp.num_points, flt.redraw
    Q, R = flt._GQGt.ravel().tolist(), m.R.ravel().tolist()
    f, h = flt._f, flt._h

    def lean(y: Any, u: Any) -> FloatArray | None:
        io = inputs(flt, y, u)
        if io is None:
            return None
        ys, _, U = io
        x, P = state(flt)
        try:
            X = draw(x, P)
            if X is None:
                return None
            with np.errstate(all="ignore"):
                Xf = f(np.array(X).reshape(N, n), np.repeat(U, N, axis=0)).ravel().tolist()
                x_pred, P_pred = moments(Xf, Q)
                Xp = draw(x_pred, P_pred) if redraw else Xf
                if Xp is None:
                    return None
                Z = h(np.array(Xp).reshape(N, n)).ravel().tolist()
            r = correct(x_pred, P_pred, Xp, Z, ys, R)
        except (ArithmeticError, ValueError):
            return None
        return None if r is None else commit(flt, r[0], r[1], r[2])
    return lean
