"""A run's learning curve, read from the monitor files of its folder.

``fir-gym train --out RUN`` (stable-baselines3's ``VecMonitor``) writes one line per finished
training episode; the curve is the mean episode return in bins of timesteps. Reading the
files needs numpy only, so the curve is drawn (:func:`fir_gym.plotting.plot_learning_curves`)
without stable-baselines3 or PyTorch; :mod:`fir_gym.training` re-exports
:func:`learning_curve` where it has always been.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["learning_curve"]


def learning_curve(run_dir: str | Path, bins: int = 20
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean training-episode return against timesteps, from the run's monitor files.

    A run's ``VecMonitor`` writes one file, ``RUN/monitor.monitor.csv``, with a line per
    finished episode of any sub-env in the order they finish (``r``, ``l``, ``t``): the
    lengths finished so far add up to (about) the timesteps taken. Runs of fir-gym ≤ 0.1
    wrote one file per sub-env in ``RUN/monitor/``: there an episode's timestep is its
    file's cumulative length times the number of files. Empty bins are NaN.
    """
    folder = Path(run_dir)
    per_env = sorted((folder / "monitor").glob("*.monitor.csv"))
    rows: list[tuple[float, float]] = []                    # (timestep, return)
    if per_env:
        for path in per_env:
            done = 0.0
            for _, r, length in _episodes(path):
                done += length
                rows.append((done * len(per_env), r))
    else:
        episodes = sorted(e for path in folder.glob("*monitor.csv") for e in _episodes(path))
        done = 0.0
        for _, r, length in episodes:                       # by wall time: finish order
            done += length
            rows.append((done, r))
    if not rows:
        return np.zeros(0), np.zeros(0)
    data = np.array(sorted(rows))
    steps = data[:, 0]
    edges = np.linspace(0, steps[-1], bins + 1)
    idx = np.clip(np.digitize(steps, edges) - 1, 0, bins - 1)
    centers = 0.5 * (edges[1:] + edges[:-1])
    means = np.array([data[idx == b, 1].mean() if np.any(idx == b) else np.nan
                      for b in range(bins)])
    return centers, means


def _episodes(path: Path) -> list[tuple[float, float, float]]:
    """``(t, r, l)`` of each episode in an SB3 monitor file (a JSON line, a header, rows)."""
    out = []
    for line in path.read_text().splitlines()[2:]:
        r, length, t = line.split(",")[:3]
        out.append((float(t), float(r), float(length)))
    return out
