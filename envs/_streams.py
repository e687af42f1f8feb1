"""One random stream per system, drawn a block at a time: per-system generators at batch speed.

A native vector env with ``generators="per_env"`` (and the sensor faults' per-system
generators) gives every system a generator of its own, so that system ``i`` draws exactly
the numbers a single env with that generator draws. Calling ``B`` generators one by one
at every step costs about a microsecond each — for 100 systems more than the plant and
the filter together. :class:`RowStreams` keeps, per system, a buffer of the generator's
next numbers and serves every draw from it with one fancy-indexing gather; a system's
buffer is refilled (one vectorised call of its generator) when it runs low.

Exact, not approximate: a generator's ``standard_normal(n)`` (or ``random(n)``) is the same
``n`` numbers as ``n`` scalar draws, in order, and each stream serves only numbers of one
kind, in the order they were asked for. So a system consuming its stream ``k`` numbers at
a time gets, bit for bit, what a single env drawing ``k`` at a time from the same
generator gets (``tests/envs/test_streams.py``). The generator itself runs ahead of what
has been served; nothing else may draw from it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
KINDS = ("normal", "uniform")
#: numbers fetched from a generator at a time
BLOCK = 512


class RowStreams:
    """``B`` buffered streams of one kind (``"normal"``: standard normal; ``"uniform"``:
    ``random()`` in [0, 1)), one per generator. Plain arrays and generators: copies and
    pickles continue exactly."""

    def __init__(self, generators: Sequence[np.random.Generator], kind: str = "normal",
                 block: int = BLOCK) -> None:
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}; got {kind!r}")
        self.generators = list(generators)
        self.kind, self.block = kind, int(block)
        n = len(self.generators)
        self.buffer = np.zeros((n, 0))
        #: per row: the next unread entry and the end of its numbers in ``buffer``
        self.position = np.zeros(n, dtype=np.int64)
        self.end = np.zeros(n, dtype=np.int64)

    def replace(self, i: int, generator: np.random.Generator) -> None:
        """Give row ``i`` a new generator (a reseeded system): its buffered numbers go."""
        self.generators[i] = generator
        self.end[i] = self.position[i]

    def draw(self, rows: NDArray[np.bool_] | None, k: int) -> FloatArray:
        """The next ``k`` numbers of each selected row (all rows for ``None``): ``(n, k)``."""
        idx = np.arange(len(self.generators)) if rows is None else np.flatnonzero(rows)
        if k == 0 or len(idx) == 0:
            return np.zeros((len(idx), k))
        short = idx[self.position[idx] + k > self.end[idx]]
        if len(short):
            self._refill(short, k)
        columns = self.position[idx][:, None] + np.arange(k)
        out = self.buffer[idx[:, None], columns]
        self.position[idx] += k
        return out

    def _refill(self, rows: NDArray[np.intp], k: int) -> None:
        """Move every row's unread numbers to the front, and top up ``rows`` with ``max(block,
        k)`` fresh numbers each from their generators."""
        fresh = max(self.block, k)
        unread = self.end - self.position
        need = unread.copy()
        need[rows] += fresh
        buffer = np.zeros((len(self.generators), int(need.max())))
        for i in np.flatnonzero(unread).tolist():
            buffer[i, :unread[i]] = self.buffer[i, self.position[i]:self.end[i]]
        for i in rows.tolist():
            buffer[i, unread[i]:need[i]] = self._fetch(self.generators[i], fresh)
        self.buffer, self.position, self.end = buffer, np.zeros_like(self.position), need

    def _fetch(self, generator: np.random.Generator, n: int) -> FloatArray:
        if self.kind == "normal":
            return generator.standard_normal(n)
        return generator.random(n)
