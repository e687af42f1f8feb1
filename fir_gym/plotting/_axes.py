"""Axes for the plotting helpers: the caller's, or a new figure's — never a backend change.

A helper given ``ax``/``axes`` draws on them and returns their figure; without, it makes
a figure with :func:`matplotlib.pyplot.subplots`, which uses whatever backend the session
has (inline in Jupyter, a window in a desktop session, Agg on a headless machine).
Nothing here, or anywhere in :mod:`fir_gym.plotting`, calls ``matplotlib.use``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def axes_for(n: int, axes: Any, *, height: float = 2.0, width: float = 7.0,
             sharex: bool = True) -> tuple[Any, list[Any]]:
    """``(figure, n axes)``: ``axes`` (one Axes or a sequence of ``n``), or a new column."""
    if axes is None:
        import matplotlib.pyplot as plt

        fig, grid = plt.subplots(n, 1, figsize=(width, 0.6 + height * n), sharex=sharex,
                                 squeeze=False)
        return fig, list(grid[:, 0])
    flat = list(np.ravel(np.asarray(axes, dtype=object))) if isinstance(axes, (Sequence,
                                                                               np.ndarray)) \
        else [axes]
    if len(flat) != n:
        raise ValueError(f"axes must hold {n} Axes (one per state); got {len(flat)}")
    figures = {id(ax.figure) for ax in flat}
    if len(figures) != 1:
        raise ValueError("axes must all belong to one figure")
    return flat[0].figure, flat


def series(name: str, values: ArrayLike, length: int | None = None, ndim: int = 2
           ) -> FloatArray:
    """``values`` as a float array of ``ndim`` dimensions (a 1-D series becomes one column),
    whose first axis has ``length`` entries when given; the error names the argument."""
    a = np.asarray(values, dtype=np.float64)
    if ndim == 2 and a.ndim == 1:
        a = a[:, None]
    if a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-dimensional (time first); got shape {a.shape}")
    if length is not None and a.shape[0] != length:
        raise ValueError(f"{name} must have {length} rows, one per time; got shape {a.shape}")
    return a


def trajectories(t: ArrayLike, estimate: ArrayLike, truth: ArrayLike | None
                 ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """``(t (T,), estimate (T, n), truth (T, n) or None)`` checked against each other."""
    time = series("t", t, ndim=1)
    x_hat = series("estimate", estimate, len(time))
    x = None if truth is None else series("truth", truth, len(time))
    if x is not None and x.shape != x_hat.shape:
        raise ValueError(f"truth must have the estimate's shape {x_hat.shape}; got {x.shape}")
    return time, x_hat, x


def standard_deviations(covariance: ArrayLike, length: int, n: int) -> FloatArray:
    """Per-time, per-state standard deviations ``(T, n)`` from covariances ``(T, n, n)``
    or variances ``(T, n)``; negative round-off on the diagonal reads as 0."""
    P = np.asarray(covariance, dtype=np.float64)
    if P.shape == (length, n, n):
        var = np.diagonal(P, axis1=1, axis2=2)
    elif P.shape == (length, n) or (n == 1 and P.shape == (length,)):
        var = P.reshape(length, n)
    else:
        raise ValueError(f"covariance must have shape ({length}, {n}, {n}) (or variances "
                         f"({length}, {n})); got {P.shape}")
    return np.sqrt(np.clip(var, 0.0, None))


def state_names(names: Sequence[str] | None, n: int) -> list[str]:
    if names is None:
        return [f"x{i + 1}" for i in range(n)]
    if len(names) != n:
        raise ValueError(f"names must have {n} entries (one per state); got {len(names)}")
    return [str(name) for name in names]
