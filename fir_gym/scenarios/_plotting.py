"""Saving the scenarios' figures as PNGs recorded in the report, without touching matplotlib's
backend.

A figure here is a :class:`matplotlib.figure.Figure` on its own
:class:`~matplotlib.backends.backend_agg.FigureCanvasAgg`: it is never registered with
pyplot and no backend is selected (no ``matplotlib.use``), so running the reproduction in
a notebook leaves its backend and inline plots as they were, and the figures render the
same headless or not. Where a panel is an estimate against the truth, an error or a NEES,
the scenarios draw it with :mod:`fir_gym.plotting` on these axes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import offset_copy
from numpy.typing import ArrayLike

from .report import Report

FIGURE_DIR = "figures"
#: two curves coincide (one hides the other) when their largest relative difference is below
#: this: 1 % is about a pixel on a decade of a log axis at the figures' size, less than a line
COINCIDE_RTOL = 1e-2
#: markers for curves drawn one over another: each smaller than the one before, so all show
MARKERS = ("o", "s", "^", "d", "v", "P", "X", "*")
#: how far under its axes a legend ``below`` them starts (points: the tick labels and the
#: x label take about 30 at the default font size, whatever the axes' height)
BELOW_POINTS = 40.0


def new_figure(rows: int = 1, cols: int = 1, *, width: float = 8.0, height: float = 3.0,
               sharex: bool = False) -> tuple[Figure, Any]:
    """A figure of ``rows × cols`` panels, ``height`` inches per row; axes always a flat array."""
    fig = Figure(figsize=(width, height * rows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, sharex=sharex, squeeze=False)
    return fig, np.asarray(axes).ravel()


def save(report: Report, out_dir: str | Path, name: str, fig: Figure, caption: str) -> Path:
    """Write ``fig`` to ``out_dir/figures/paper<id>_<name>.png`` and record it in ``report.images``.

    A report whose id is not a paper number (``"sweeps"``) uses the id as the prefix.

    ``caption`` becomes the image's alt text in REPORT.md; the path is relative to ``out_dir``.
    """
    folder = Path(out_dir) / FIGURE_DIR
    folder.mkdir(parents=True, exist_ok=True)
    prefix = f"paper{report.paper}" if report.paper.isdigit() else report.paper
    file = folder / f"{prefix}_{name}.png"
    fig.tight_layout()
    fig.savefig(file, dpi=110, bbox_inches="tight")   # the legends outside the axes included
    report.images[caption] = f"{FIGURE_DIR}/{file.name}"
    return file


def legend_outside(ax: Any, *, below: bool = False, ncol: int = 1, fontsize: float = 7) -> Any:
    """``ax``'s legend outside its data: to the right of the axes, or ``below`` them (for
    panels side by side) in ``ncol`` columns."""
    if below:    # anchored a fixed distance under the axes, clear of the ticks and x label
        under = offset_copy(ax.transAxes, fig=ax.figure, y=-BELOW_POINTS, units="points")
        return ax.legend(fontsize=fontsize, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                         bbox_transform=under, ncol=ncol, frameon=False)
    return ax.legend(fontsize=fontsize, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                     borderaxespad=0.0, frameon=False)


def coincident(curves: Mapping[str, ArrayLike], rtol: float = COINCIDE_RTOL) -> dict[str, str]:
    """Which curves would hide one another: label -> the label of the first earlier curve it
    coincides with (same length, largest relative difference below ``rtol``)."""
    arrays = {name: np.asarray(values, dtype=float) for name, values in curves.items()}
    out: dict[str, str] = {}
    names = list(arrays)
    for i, name in enumerate(names):
        for earlier in names[:i]:
            a, b = arrays[name], arrays[earlier]
            if a.shape != b.shape or earlier in out:
                continue
            scale = np.maximum(np.abs(a), np.abs(b))
            with np.errstate(divide="ignore", invalid="ignore"):
                rel = np.where(scale > 0, np.abs(a - b) / scale, 0.0)
            if np.all(np.isfinite(rel)) and float(np.max(rel, initial=0.0)) < rtol:
                out[name] = earlier
                break
    return out


def coincidence_note(label: str, same: Mapping[str, str]) -> str:
    """``label``, with ``" (coincides with X)"`` when :func:`coincident` found it under X."""
    return f"{label} (coincides with {same[label]})" if label in same else label


def unlabelled_axes(fig: Figure) -> list[str]:
    """The panels of ``fig`` that lack a y label, or an x label (a panel sharing its x axis
    with a labelled one, as in a column of panels, needs none of its own): their titles."""
    missing = []
    for ax in fig.get_axes():
        shared = ax.get_shared_x_axes().get_siblings(ax)
        has_x = any(other.get_xlabel().strip() for other in shared)
        if not (ax.get_ylabel().strip() and has_x):
            missing.append(ax.get_title() or f"axes {fig.get_axes().index(ax)}")
    return missing
