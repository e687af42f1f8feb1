"""Learning curves of controllers trained with ``fir-gym train`` / ``compare-controllers``.

The curves are read from the runs' monitor files by :mod:`.monitor` (numpy only): drawing
them needs neither stable-baselines3 nor :mod:`fir_gym.training`, which draws its figures
with this function (docs/architecture.md#import-graph).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._axes import axes_for
from .monitor import learning_curve

RunDirs = str | Path | Sequence[str | Path]


def plot_learning_curves(runs: RunDirs | Mapping[str, RunDirs], *, bins: int = 20,
                         ax: Any = None) -> Any:
    """Mean training-episode return against timesteps, per run or per group of seeds.

    Args:
        runs: a run folder (what ``fir-gym train --out`` wrote), a list of them (one
            curve each), or a mapping ``label → folder(s)``: the folders of one label
            (its seeds) are averaged — a bin no episode ended in takes its neighbours'
            value — with a band of ± one standard deviation across them.
        bins: timestep bins of each curve (:func:`fir_gym.plotting.monitor.learning_curve`,
            also :func:`fir_gym.training.learning_curve`).
        ax: the Axes to draw on (default: a new figure).

    A run with no finished training episode has no curve and is listed as such in
    the legend's place. Returns the :class:`matplotlib.figure.Figure` drawn on.
    """
    groups = _groups(runs)
    fig, (panel,) = axes_for(1, ax, height=3.5)
    empty = []
    for label, folders in groups.items():
        curves = [learning_curve(folder, bins=bins) for folder in folders]
        curves = [(x, y) for x, y in curves if len(x)]
        if not curves:
            empty.append(label)
            continue
        grid = curves[0][0]
        if len(curves) == 1:                   # one run: its bins as they are (gaps stay)
            panel.plot(grid, curves[0][1], lw=1.2, label=label)
            continue
        # seeds: empty bins filled from their neighbours, each curve read on the first's grid
        ys = np.array([np.interp(grid, x, _filled(y)) for x, y in curves])
        (line,) = panel.plot(grid, ys.mean(axis=0), lw=1.2, label=label)
        if len(ys) > 1:
            panel.fill_between(grid, ys.mean(axis=0) - ys.std(axis=0),
                               ys.mean(axis=0) + ys.std(axis=0), color=line.get_color(),
                               alpha=0.2, lw=0)
    panel.set_xlabel("timesteps")
    panel.set_ylabel("training episode return")
    if empty:
        panel.text(0.5, 0.5, "no training episode finished: " + ", ".join(empty),
                   ha="center", va="center", transform=panel.transAxes, fontsize=8)
    if panel.lines:
        panel.legend(fontsize=7, loc="best")
    return fig


def _groups(runs: RunDirs | Mapping[str, RunDirs]) -> dict[str, list[Path]]:
    """``label → folders`` from any of the accepted forms of ``runs``."""
    def folders(value: RunDirs) -> list[Path]:
        return [Path(value)] if isinstance(value, (str, Path)) else [Path(v) for v in value]

    if isinstance(runs, Mapping):
        return {str(label): folders(value) for label, value in runs.items()}
    return {path.name: [path] for path in folders(runs)}


def _filled(y: np.ndarray) -> np.ndarray:
    """A curve's empty bins (NaN) filled from its neighbours, for averaging across seeds."""
    good = np.isfinite(y)
    if good.all():
        return y
    idx = np.arange(len(y))
    return np.interp(idx, idx[good], y[good])
