"""Figures of estimators and controllers: estimates against the truth, errors, NEES/NIS, learning.

Every helper takes the data as arrays (time first), draws on the ``ax``/``axes`` it is
given or on a new figure, and returns the :class:`matplotlib.figure.Figure`. None of
them changes matplotlib's backend, so they draw inline in a notebook, in a window on a
desktop, and to files on a headless machine alike (``fig.savefig(...)``).

* :func:`plot_estimates` — each state's estimate ± 2σ against the truth (and the
  measurements);
* :func:`plot_errors` — the estimation error ``truth − estimate`` with its 2σ band;
* :func:`plot_nees`, :func:`plot_nis` — NEES and NIS against their χ² bands;
* :func:`plot_learning_curves` — training return against timesteps from runs'
  monitor files.
"""

from .consistency import plot_nees, plot_nis
from .estimates import plot_errors, plot_estimates
from .learning import plot_learning_curves

__all__ = ["plot_errors", "plot_estimates", "plot_learning_curves", "plot_nees", "plot_nis"]
