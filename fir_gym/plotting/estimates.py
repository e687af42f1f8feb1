"""Estimates against the truth, and estimation errors against their 2σ bands, per state."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from numpy.typing import ArrayLike

from ._axes import axes_for, series, standard_deviations, state_names, trajectories


def plot_estimates(
    t: ArrayLike,
    estimate: ArrayLike,
    truth: ArrayLike | None = None,
    covariance: ArrayLike | None = None,
    *,
    measurement: ArrayLike | None = None,
    measured: Sequence[int] | None = None,
    names: Sequence[str] | None = None,
    label: str = "estimate",
    sigma: float = 2.0,
    color: Any = None,
    axes: Any = None,
) -> Any:
    """Each state's estimate (± ``sigma`` σ where a covariance is given) against the truth.

    One panel per state, time on the shared x axis: the truth (black), the estimate
    (``color``) with a shaded ``±sigma·σ`` band, and the measurements (grey dots) on
    the panels of the states they read. Call it again with ``axes=fig.axes`` to add a
    second estimator to the same panels.

    Args:
        t: times ``(T,)``.
        estimate: estimates ``(T, n)`` (``(T,)`` for one state).
        truth: true states ``(T, n)``, or ``None``.
        covariance: the estimator's covariances ``(T, n, n)`` (or variances ``(T, n)``).
        measurement: measurements ``(T, m)``; ``measured[j]`` is the state that column
            ``j`` reads (default: the first ``m`` states, as every fir-gym plant does).
        names: the states' names (y labels; default ``x1, x2, ...``).
        label: the estimate's legend entry (e.g. ``"EKF"``).
        sigma: the band's half-width in standard deviations.
        color: the estimate's matplotlib colour (default: the axes' next colour).
        axes: ``n`` Axes to draw on (default: a new figure).

    Returns:
        The :class:`matplotlib.figure.Figure` drawn on.
    """
    time, x_hat, x = trajectories(t, estimate, truth)
    n = x_hat.shape[1]
    sd = None if covariance is None else standard_deviations(covariance, len(time), n)
    fig, panels = axes_for(n, axes)
    labels = state_names(names, n)
    if measurement is not None:
        y = series("measurement", measurement, len(time))
        reads = list(range(y.shape[1])) if measured is None else [int(i) for i in measured]
        if len(reads) != y.shape[1] or not all(0 <= i < n for i in reads):
            raise ValueError(f"measured must give a state index in [0, {n}) for each of the "
                             f"{y.shape[1]} measurement columns; got {measured!r}")
        for j, i in enumerate(reads):
            panels[i].plot(time, y[:, j], ".", color="0.6", ms=2.5, label="measurement",
                           zorder=1)
    for i, ax in enumerate(panels):
        if x is not None:
            ax.plot(time, x[:, i], color="k", lw=1.4, label="truth", zorder=3)
        (line,) = ax.plot(time, x_hat[:, i], color=color, lw=1.0, label=label, zorder=4)
        if sd is not None:
            ax.fill_between(time, x_hat[:, i] - sigma * sd[:, i],
                            x_hat[:, i] + sigma * sd[:, i], color=line.get_color(),
                            alpha=0.2, lw=0, label=f"{label} ±{sigma:g}σ", zorder=2)
        ax.set_ylabel(labels[i])
    panels[-1].set_xlabel("t")
    panels[0].legend(fontsize=7, loc="best")
    return fig


def plot_errors(
    t: ArrayLike,
    estimate: ArrayLike,
    truth: ArrayLike,
    covariance: ArrayLike | None = None,
    *,
    names: Sequence[str] | None = None,
    label: str = "error",
    sigma: float = 2.0,
    color: Any = None,
    axes: Any = None,
) -> Any:
    """Each state's estimation error ``truth − estimate`` with its ``±sigma·σ`` band.

    The error is ``info["estimation_error"]``'s (``state − estimate``). For a
    consistent filter about 95 % of a 2σ band's errors lie inside it. Arguments as for
    :func:`plot_estimates`; the band is drawn about zero, from the filter's own
    covariance.

    Returns:
        The :class:`matplotlib.figure.Figure` drawn on.
    """
    time, x_hat, x = trajectories(t, estimate, truth)
    assert x is not None
    n = x.shape[1]
    error = x - x_hat
    fig, panels = axes_for(n, axes)
    labels = state_names(names, n)
    sd = None if covariance is None else standard_deviations(covariance, len(time), n)
    for i, ax in enumerate(panels):
        (line,) = ax.plot(time, error[:, i], color=color, lw=1.0, label=label, zorder=3)
        if sd is not None:
            ax.fill_between(time, -sigma * sd[:, i], sigma * sd[:, i], color=line.get_color(),
                            alpha=0.2, lw=0, label=f"±{sigma:g}σ", zorder=2)
        ax.axhline(0.0, color="k", lw=0.6, zorder=1)
        ax.set_ylabel(f"{labels[i]} error")
    panels[-1].set_xlabel("t")
    panels[0].legend(fontsize=7, loc="best")
    return fig
