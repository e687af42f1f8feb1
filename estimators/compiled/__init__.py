"""The compiled twins (numba) of the numpy steps, and the one rule that picks them.

Every filter step has a numpy implementation that reads like the textbook — the
reference, the fallback without numba and the oracle of the tests — and at most one
compiled twin, here: one loop over the systems of a batch, so a single system is a
batch of one and takes the same code. The twins are built from per-system (or
per-chunk) pieces — a covariance prediction, a measurement update, the divergence
watch — composed into one call per step, so a step costs one dispatch:

* :mod:`.kalman` — the Kalman family's prediction and Joseph-form update (KF, EKF, LKF);
* :mod:`.unscented` — sigma points, unscented moments and the UKF update;
* :mod:`.window_bank` — the FIR engine's time update, measurement update and read-out;
* :mod:`.watch` — the divergence watch (keep the last finite estimate, trace limit, NIS
  run) that every compiled step applies in place;
* :mod:`.linalg` — the small dense algebra on blocks of systems the others share.

**The dispatch rule.** A compiled twin runs exactly when :data:`ENABLED` is true: numba
is importable, ``FIR_GYM_NUMBA`` is not ``0``/``false``/``no``/``off`` and
``NUMBA_DISABLE_JIT`` is not set. It is read at call time, at the boundary of each
component that has twins — :meth:`Estimator.step <fir_gym.estimators.base.Estimator.step>`
for a filter's step (a class opts in with ``has_compiled_step``), each operation of
:class:`~fir_gym.estimators._fir_bank.WindowBank`, and each plant's interval map in
``fir_gym.envs`` — and nowhere below: a numpy path calls no compiled code, a compiled
step no numpy reference. Both paths read and write the same state arrays, so the
switch may flip between two steps (the tests run a filter on both, step by step).

Without numba, :func:`jit` returns the function unchanged (a Python loop with the
same signature that is never called while :data:`ENABLED` is false), so a twin is
always a callable — never ``None`` — and type checkers see one signature.

Kernels compile on first call and are cached on disk (``cache=True``; where no
cache folder is writable they compile in each process). ``fastmath`` is off, so
numba does not reorder or contract floating-point operations; the twins agree with
the numpy references to round-off (BLAS sums in other orders), which the tests in
``tests/estimators/test_compiled.py`` bound.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

numba: Any
try:  # pragma: no cover - exercised by whichever of the two installs runs the tests
    import numba
except ImportError:  # pragma: no cover
    numba = None

__all__ = ["ENABLED", "inlined", "jit"]

#: whether the compiled twins run (``FIR_GYM_NUMBA=0`` turns them off, and so does
#: ``NUMBA_DISABLE_JIT=1``: the loops would then run as plain Python, far slower than
#: the numpy references)
ENABLED: bool = (numba is not None and not numba.config.DISABLE_JIT
                 and os.environ.get("FIR_GYM_NUMBA", "1").strip().lower()
                 not in ("0", "false", "no", "off"))

Function = TypeVar("Function", bound=Callable[..., Any])


def jit(fn: Function) -> Function:
    """``fn`` compiled by ``numba.njit`` (cached, ``nogil``, no fast-math), or ``fn`` itself
    without numba.

    Where numba finds no writable cache location (a read-only install without a
    writable home), the kernel is compiled in each process instead of failing the import.
    """
    if numba is None:
        return fn
    try:
        return cast("Function", numba.njit(cache=True, nogil=True, error_model="numpy")(fn))
    except RuntimeError:                    # "cannot cache function ...: no locator available"
        return cast("Function", numba.njit(cache=False, nogil=True, error_model="numpy")(fn))


def inlined(fn: Function) -> Function:
    """:func:`jit` for a piece that is always inlined into the kernels that call it (numba's
    ``inline="always"``): a piece taking named tuples of arrays (:class:`.watch.Watched`,
    :class:`.kalman.Block`) then costs what it would with the arrays one by one — called
    through numba's calling convention, each array of a tuple is reference-counted in and out,
    0.26 µs a KF step (measured)."""
    if numba is None:
        return fn
    options = {"nogil": True, "error_model": "numpy", "inline": "always"}
    try:
        return cast("Function", numba.njit(cache=True, **options)(fn))
    except RuntimeError:                    # no writable cache location
        return cast("Function", numba.njit(cache=False, **options)(fn))
