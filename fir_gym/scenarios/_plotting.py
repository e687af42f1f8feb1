"""Saving the scenarios' figures: matplotlib without a display, PNGs recorded in the report."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from .report import Report

FIGURE_DIR = "figures"


def new_figure(rows: int = 1, cols: int = 1, *, width: float = 8.0, height: float = 3.0,
               sharex: bool = False) -> tuple[Any, Any]:
    """A figure of ``rows × cols`` panels, ``height`` inches per row; axes always a flat array."""
    import numpy as np

    fig, axes = plt.subplots(rows, cols, figsize=(width, height * rows), sharex=sharex,
                             squeeze=False)
    return fig, np.asarray(axes).ravel()


def save(report: Report, out_dir: str | Path, name: str, fig: Any, caption: str) -> Path:
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
    plt.close(fig)
    report.images[caption] = f"{FIGURE_DIR}/{file.name}"
    return file
