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

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .report import Report

FIGURE_DIR = "figures"


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
    fig.savefig(file, dpi=110)
    report.images[caption] = f"{FIGURE_DIR}/{file.name}"
    return file
