"""NEES and NIS against their χ² confidence bands (Bar-Shalom et al. 2001, §5.4).

For a consistent filter the NEES ``(x − x̂)ᵀ P⁻¹ (x − x̂)`` is χ²(n_x) and the NIS
``eᵀ S⁻¹ e`` is χ²(n_y); the average of ``M`` Monte Carlo runs lies, with probability
``confidence``, in :func:`fir_gym.estimators.chi2_band` ``(dof, M, confidence)``.
Compute the values with :func:`fir_gym.estimators.nees` / :func:`~fir_gym.estimators.nis`
(or read ``info["estimator_info"]["nis"]``); these helpers draw them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fir_gym.estimators import chi2_band

from ._axes import axes_for, series


def plot_nees(t: ArrayLike, nees: ArrayLike, *, dof: int, runs: int | None = None,
              confidence: float = 0.95, label: str = "NEES", color: Any = None,
              log: bool = True, ax: Any = None) -> Any:
    """The NEES over time with the χ²(``dof``) band of its average over ``runs`` runs.

    Args:
        t: times ``(T,)``.
        nees: NEES values ``(T,)`` (one run, or already averaged over ``runs``), or
            ``(M, T)``: ``M`` runs, averaged here (``runs`` is then ``M``).
        dof: the state dimension ``n_x`` (the NEES's degrees of freedom).
        runs: how many runs ``nees`` averages (default 1, or ``M``).
        confidence: the band's two-sided probability.
        label, color: the line's legend entry and colour.
        log: a logarithmic y axis (NEES spans decades when a filter is overconfident).
        ax: the Axes to draw on (default: a new figure).

    Returns:
        The :class:`matplotlib.figure.Figure` drawn on.
    """
    return _consistency(t, nees, "NEES", dof, runs, confidence, label, color, log, ax)


def plot_nis(t: ArrayLike, nis: ArrayLike, *, dof: int, runs: int | None = None,
             confidence: float = 0.95, label: str = "NIS", color: Any = None,
             log: bool = True, ax: Any = None) -> Any:
    """The NIS over time with the χ²(``dof`` = ``n_y``) band; as :func:`plot_nees`."""
    return _consistency(t, nis, "NIS", dof, runs, confidence, label, color, log, ax)


def _consistency(t: ArrayLike, values: ArrayLike, what: str, dof: int, runs: int | None,
                 confidence: float, label: str, color: Any, log: bool, ax: Any) -> Any:
    time = series("t", t, ndim=1)
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 2:
        if runs is not None and runs != v.shape[0]:
            raise ValueError(f"runs={runs} but {what.lower()} holds {v.shape[0]} runs")
        runs, v = v.shape[0], v.mean(axis=0)
    v = series(what.lower(), v, len(time), ndim=1)
    runs = 1 if runs is None else runs
    lo, hi = chi2_band(dof, runs, confidence)
    fig, (panel,) = axes_for(1, ax, height=3.0)
    average = f" (average of {runs} runs)" if runs > 1 else ""
    panel.axhspan(lo, hi, color="0.85", lw=0, zorder=1,
                  label=f"{confidence:.0%} χ²({dof}) band{average}")
    panel.axhline(dof, color="0.5", ls="--", lw=0.8, zorder=2, label=f"expected ({dof})")
    panel.plot(time, v, color=color, lw=1.0, label=label, zorder=3)
    if log:
        panel.set_yscale("log")
    panel.set_xlabel("t")
    panel.set_ylabel(what + average)
    panel.legend(fontsize=7, loc="best")
    return fig
