"""Learning curves of runs, from their monitor files: the figure file of a comparison.

The curve of a run (:func:`learning_curve`, re-exported) is read by
:mod:`fir_gym.plotting.monitor` and drawn by :func:`fir_gym.plotting.plot_learning_curves`:
training imports plotting, never the other way round (docs/architecture.md#import-graph).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from fir_gym.plotting.monitor import learning_curve

__all__ = ["learning_curve", "plot_learning_curves"]


def plot_learning_curves(runs: Mapping[str, Sequence[str | Path]], path: str | Path,
                         title: str = "") -> Path | None:
    """Save one learning curve per kind (mean over its runs, ± one std); ``None`` — and no
    file — without matplotlib or when no run has a finished training episode (an empty
    figure would say nothing: :func:`kinds_with_curves` tells the caller why).

    ``runs`` maps a label (a kind) to its run folders; kinds without a finished training
    episode are named on the figure. Drawn by :func:`fir_gym.plotting.plot_learning_curves`
    on a :class:`matplotlib.figure.Figure` of its own (an Agg canvas, never registered
    with pyplot): the session's matplotlib backend is not touched.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    from fir_gym.plotting import plot_learning_curves as draw

    if not kinds_with_curves(runs):
        return None
    fig = Figure(figsize=(7, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw(dict(runs), ax=ax)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return Path(path)


def kinds_with_curves(runs: Mapping[str, Sequence[str | Path]]) -> list[str]:
    """The labels of ``runs`` with at least one finished training episode (a curve to draw)."""
    from fir_gym.plotting.monitor import learning_curve

    return [label for label, folders in runs.items()
            if any(len(learning_curve(folder)[0]) for folder in folders)]
