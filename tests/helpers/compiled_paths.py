"""Run filters on the numpy reference or on the compiled twins (importable: pytest's
``pythonpath`` has this folder)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from fir_gym.estimators import compiled

#: the compiled twins are on in this run (numba importable, FIR_GYM_NUMBA not 0)
TWINS = compiled.ENABLED

#: marks a test that compares the compiled twins with the numpy references
needs_twins = pytest.mark.skipif(not TWINS, reason="the compiled twins are off in this run "
                                                   "(no numba, or FIR_GYM_NUMBA=0)")


@contextmanager
def numpy_path() -> Iterator[None]:
    """A block in which every step takes the numpy reference."""
    saved = compiled.ENABLED
    compiled.ENABLED = False
    try:
        yield
    finally:
        compiled.ENABLED = saved


def step_on(flt: Any, twin: bool, y: Any, u: Any = None) -> Any:
    """``flt.step(y, u)`` on the compiled twin (``twin``) or on the numpy reference."""
    if twin:
        return flt.step(y, u)
    with numpy_path():
        return flt.step(y, u)


def on_path(path: str) -> Any:
    """A block on ``path``: ``"numpy"`` (the references) or ``"compiled"`` (the dispatch rule
    as it is)."""
    return numpy_path() if path == "numpy" else contextlib.nullcontext()
