"""The divergence watch of every compiled step, in place on the filter's state.

The contract is :meth:`Estimator._accept <fir_gym.estimators.base.Estimator._accept>`'s
(its numpy reference): a system's new estimate is kept only where it and its
covariance are finite (else the last finite ones stay); the system is flagged
diverged (sticky) where they are not finite, where ``trace P`` exceeds
``max_covariance_trace``, or where its NIS has been above the χ² threshold — a NaN
NIS of a usable measurement counts as above — for ``nis_patience`` steps running.

``limits = [nis_threshold, nis_patience, max_covariance_trace]`` (float64).
"""

from __future__ import annotations

import numpy as np

from . import jit


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


@jit
def accept(x_new: np.ndarray, P_new: np.ndarray, nis_new: np.ndarray, valid: np.ndarray,
           has_nis: bool, x: np.ndarray, P: np.ndarray, diverged: np.ndarray,
           nis_run: np.ndarray, nis: np.ndarray, limits: np.ndarray) -> None:
    """Store ``x_new (B, n)``, ``P_new (B, n, n)`` into ``x``, ``P`` where finite, and book every
    system (``nis_new`` is ignored without ``has_nis``)."""
    n_b, n = x_new.shape
    if not (P_new.shape[0] == x.shape[0] == P.shape[0] == valid.shape[0] == diverged.shape[0]
            == nis_run.shape[0] == nis.shape[0] == n_b and nis_new.shape[0] in (0, n_b)):
        raise ValueError("accept: the arrays must have a row per system")
    nis_limit, patience, max_trace = limits[0], limits[1], limits[2]
    for b in range(n_b):
        finite = True
        trace = 0.0
        for i in range(n):
            finite = finite and np.isfinite(x_new[b, i])
            trace += P_new[b, i, i]
            for j in range(n):
                finite = finite and np.isfinite(P_new[b, i, j])
        q = nis_new[b] if has_nis else np.nan
        nis_run[b], blown = verdict(finite, trace, q, valid[b], has_nis, nis_run[b], nis_limit,
                                    patience, max_trace)
        if blown:
            diverged[b] = True
        if finite:
            for i in range(n):
                x[b, i] = x_new[b, i]
                for j in range(n):
                    P[b, i, j] = P_new[b, i, j]
        nis[b] = q
