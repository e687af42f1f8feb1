"""Estimation metrics: RMSE, NEES, NIS and Monte Carlo averages with χ² confidence bands.

Consistency tests follow Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation* (2001), §5.4: for a consistent filter
the normalised estimation error squared ``NEES = (x − x̂)ᵀ P⁻¹ (x − x̂)`` is χ²
with ``n_x`` degrees of freedom, and the NIS ``eᵀ S⁻¹ e`` is χ² with ``n_y``. The
average over ``M`` independent Monte Carlo runs, times ``M``, is χ² with ``M·n``
degrees of freedom, which gives the two-sided band of :func:`chi2_band`.

Arrays follow the estimators' layout: a leading run axis ``M`` and/or a time
axis ``T`` before the state axis, e.g. errors ``(M, T, n)``, covariances
``(M, T, n, n)``.
"""

from __future__ import annotations

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike

from ._validation import FloatArray

__all__ = ["anees", "chi2_band", "mean_nis", "nees", "nis", "rmse", "within_band"]


def rmse(x_true: ArrayLike, x_est: ArrayLike, axis: int | tuple[int, ...] | None = 0
         ) -> FloatArray:
    """Root-mean-square error ``sqrt(mean((x_est − x_true)²))`` over ``axis``.

    ``axis=0`` (default) averages over the first axis (runs or time) per component;
    ``axis=None`` returns one number. Non-finite estimates propagate (NaN in,
    NaN out): an RMSE over a diverged run is not silently finite.
    """
    err = np.asarray(x_est, dtype=np.float64) - np.asarray(x_true, dtype=np.float64)
    return np.sqrt(np.mean(err * err, axis=axis))


def _quadratic(e: FloatArray, P: FloatArray, name: str) -> FloatArray:
    if P.shape[-2:] != (e.shape[-1], e.shape[-1]) or P.shape[:-2] != e.shape[:-1]:
        raise ValueError(f"{name} must have shape {e.shape + (e.shape[-1],)} to match the "
                         f"errors; got {P.shape}")
    L = np.linalg.cholesky(P)                 # raises LinAlgError if not PD
    w = np.linalg.solve(L, e[..., None])[..., 0]
    return np.einsum("...i,...i->...", w, w)


def nees(x_true: ArrayLike, x_est: ArrayLike, P: ArrayLike) -> FloatArray:
    """Normalised estimation error squared ``(x − x̂)ᵀ P⁻¹ (x − x̂)`` for each leading index.

    ``x_true, x_est``: ``(..., n)``; ``P``: ``(..., n, n)`` positive definite.
    Computed with a Cholesky solve. Raises ``ValueError`` if ``P`` is not PD.
    """
    e = np.asarray(x_est, dtype=np.float64) - np.asarray(x_true, dtype=np.float64)
    try:
        return _quadratic(e, np.asarray(P, dtype=np.float64), "P")
    except np.linalg.LinAlgError:
        raise ValueError("P must be positive definite to compute the NEES") from None


def nis(innovation: ArrayLike, S: ArrayLike) -> FloatArray:
    """Normalised innovation squared ``eᵀ S⁻¹ e`` for each leading index (``S`` PD)."""
    try:
        return _quadratic(np.asarray(innovation, dtype=np.float64),
                          np.asarray(S, dtype=np.float64), "S")
    except np.linalg.LinAlgError:
        raise ValueError("S must be positive definite to compute the NIS") from None


def chi2_band(dof: int, runs: int = 1, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided ``confidence`` band of the average of ``runs`` χ²(``dof``) variables.

    ``[χ²_{(1−c)/2}(runs·dof), χ²_{(1+c)/2}(runs·dof)] / runs`` (Bar-Shalom et al.,
    eq 5.4.2-8). For ``runs = 1`` it is the band of a single NEES/NIS value.
    """
    if dof < 1 or runs < 1 or not 0 < confidence < 1:
        raise ValueError(f"need dof >= 1, runs >= 1, 0 < confidence < 1; got {dof}, {runs}, "
                         f"{confidence}")
    tail = 0.5 * (1.0 - confidence)
    k = runs * dof
    return (float(scipy.stats.chi2.ppf(tail, k)) / runs,
            float(scipy.stats.chi2.isf(tail, k)) / runs)


def anees(x_true: ArrayLike, x_est: ArrayLike, P: ArrayLike) -> FloatArray:
    """Average NEES over Monte Carlo runs (axis 0): ``(M, ..., n)`` → ``(...)``.

    Compare with :func:`chi2_band` ``(n, M)`` at each time; dividing by ``n``
    gives the "ANEES" normalised to 1.
    """
    return np.mean(nees(x_true, x_est, P), axis=0)


def mean_nis(innovations: ArrayLike, S: ArrayLike) -> FloatArray:
    """Average NIS over Monte Carlo runs (axis 0); compare with ``chi2_band(n_y, M)``."""
    return np.mean(nis(innovations, S), axis=0)


def within_band(values: ArrayLike, dof: int, runs: int = 1, confidence: float = 0.95
                ) -> np.ndarray:
    """Which run-averaged values lie in :func:`chi2_band` ``(dof, runs, confidence)``."""
    lo, hi = chi2_band(dof, runs, confidence)
    v = np.asarray(values, dtype=np.float64)
    return (v >= lo) & (v <= hi)
