"""Estimation metrics: RMSE, NEES, NIS and Monte Carlo averages with χ² confidence bands.

Consistency tests follow Bar-Shalom, Li & Kirubarajan, *Estimation with
Applications to Tracking and Navigation* (2001), §5.4: for a consistent filter
the normalised estimation error squared ``NEES = (x − x̂)ᵀ P⁻¹ (x − x̂)`` is χ²
with ``n_x`` degrees of freedom, and the NIS ``eᵀ S⁻¹ e`` is χ² with ``n_y``. The
average over ``M`` independent Monte Carlo runs, times ``M``, is χ² with ``M·n``
degrees of freedom, which gives the two-sided band of :func:`chi2_band`.

The mean alone is a fragile summary of a sample of per-step NEES values: one step with
a nearly singular ``P`` can carry it by orders of magnitude while almost every other
step is consistent. :func:`nees_summary` reports it beside the median, the 95th
percentile and the fraction of values inside the single-value χ² band
(docs/estimators/metrics.md#nees-summary).

Arrays follow the estimators' layout: a leading run axis ``M`` and/or a time
axis ``T`` before the state axis, e.g. errors ``(M, T, n)``, covariances
``(M, T, n, n)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike

from ._validation import FloatArray

__all__ = ["NEESSummary", "anees", "chi2_band", "mean_nis", "nees", "nees_summary", "nis", "rmse",
           "within_band"]


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


@dataclass(frozen=True)
class NEESSummary:
    """A sample of NEES (or NIS) values summarised against χ²(``dof``); see :func:`nees_summary`.

    Attributes:
        mean: the sample mean (the ANEES, *not* divided by ``dof``; χ² expects ``dof``).
        median: the sample median (χ² expects :attr:`expected_median`, e.g. 1.386 for
            ``dof = 2``).
        p95: the sample's 95th percentile (χ² expects :attr:`expected_p95`).
        in_band: the fraction of values inside :attr:`band` (χ² expects ``confidence``).
        band: the two-sided ``confidence`` band of one χ²(``dof``) value,
            :func:`chi2_band` ``(dof, 1, confidence)``.
        count: the number of values; ``dof``, ``confidence`` as given.
    """

    mean: float
    median: float
    p95: float
    in_band: float
    band: tuple[float, float]
    count: int
    dof: int
    confidence: float

    @property
    def expected_median(self) -> float:
        """The median of χ²(``dof``)."""
        return float(scipy.stats.chi2.median(self.dof))

    @property
    def expected_p95(self) -> float:
        """The 95th percentile of χ²(``dof``)."""
        return float(scipy.stats.chi2.ppf(0.95, self.dof))


def nees_summary(values: ArrayLike, dof: int, confidence: float = 0.95) -> NEESSummary:
    """Summarise a sample of per-step NEES values ``(x − x̂)ᵀ P⁻¹ (x − x̂)`` against χ²(``dof``).

    For a consistent filter each value is χ² with ``dof = n_x`` degrees of freedom
    (Bar-Shalom et al. 2001, §5.4; for the NIS, ``dof = n_y``). Returns a
    :class:`NEESSummary`: the mean (ANEES), the median, the 95th percentile and the
    fraction of values inside the two-sided ``confidence`` band of a single χ²(``dof``)
    value (``scipy.stats.chi2``). Values from different steps and runs of one filter
    are pooled; they need not be independent, but then the in-band fraction's
    sampling spread is wider than the binomial one.

    The median and the in-band fraction do not move when a handful of steps explode
    (a nearly singular ``P``), which the mean does by orders of magnitude — report
    them beside it (docs/estimators/metrics.md#nees-summary).

    Args:
        values: NEES values, any shape (flattened); ``+inf`` is allowed (outside the
            band), NaN is not.
        dof: degrees of freedom (``n_x`` for the NEES), ≥ 1.
        confidence: the band's coverage, in (0, 1).
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("nees_summary needs at least one value")
    if np.any(np.isnan(v)) or np.any(v < 0):
        raise ValueError("NEES values must be non-negative numbers (NaN is not a NEES)")
    band = chi2_band(dof, 1, confidence)
    return NEESSummary(
        mean=float(np.mean(v)), median=_quantile(v, 0.5), p95=_quantile(v, 0.95),
        in_band=float(np.mean(within_band(v, dof, 1, confidence))),
        band=band, count=int(v.size), dof=int(dof), confidence=float(confidence))


def _quantile(v: FloatArray, q: float) -> float:
    """numpy's default (linear) quantile, and ``inf`` where it would interpolate to an ``inf``
    (numpy gives NaN there)."""
    if np.all(np.isfinite(v)):
        return float(np.quantile(v, q))
    s = np.sort(v)
    pos = q * (s.size - 1)
    lo, hi = int(np.floor(pos)), int(np.ceil(pos))
    if np.isinf(s[lo]) or (hi > lo and np.isinf(s[hi])):
        return float("inf")
    return float(s[lo] + (pos - lo) * (s[hi] - s[lo]))
