"""Optional compiled loops (numba) for the hot paths.

numba is a dependency of the default install, not of the estimators' contract:
without it — or with the environment variable ``FIR_GYM_NUMBA=0`` — :func:`kernel`
hands back ``None`` for every kernel and each caller takes its numpy path. That
numpy path is also the oracle the kernels are tested against (``tests/estimators/
test_compiled.py``): the kernels do the same floating-point operations in the same
order, and numba does not contract ``a * b + c`` into a fused multiply-add unless
``fastmath`` is set (it is not), so both paths give the same bits.

Kernels are compiled on first call and cached on disk (``cache=True``), so a new
process pays only the cache load (≈ 50 ms per kernel), not the compilation.
:data:`ENABLED` is read at call time; tests switch it off to run the numpy path.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

try:  # pragma: no cover - exercised by whichever of the two installs runs the tests
    import numba
except ImportError:  # pragma: no cover
    numba = None

#: whether callers use the compiled kernels (``FIR_GYM_NUMBA=0`` turns them off, and so
#: does ``NUMBA_DISABLE_JIT=1``: the loops would then run as plain Python, far slower than
#: the numpy paths)
ENABLED: bool = (numba is not None and not numba.config.DISABLE_JIT
                 and os.environ.get("FIR_GYM_NUMBA", "1").strip().lower()
                 not in ("0", "false", "no", "off"))


def kernel(fn: Callable[..., Any]) -> Callable[..., Any] | None:
    """``fn`` compiled by ``numba.njit`` (cached, no fast-math), or ``None`` without numba.

    Where numba finds no writable cache location (a read-only install without a
    writable home), the kernel is compiled in each process instead of failing the import.
    """
    if numba is None:
        return None
    try:
        return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)
    except RuntimeError:                    # "cannot cache function ...: no locator available"
        return numba.njit(cache=False, nogil=True, error_model="numpy")(fn)


def active(compiled: Callable[..., Any] | None) -> bool:
    """Whether the compiled kernel ``compiled`` is to be used now."""
    return ENABLED and compiled is not None
