"""What callers hand a plant — actions and reset options — checked at the boundary.

The single plants (:class:`~fir_gym.envs._base.PlantEnv`) and the native vector envs
(:mod:`fir_gym.envs._vector`) apply the same rules:

* **Numbers are real numbers.** An action or a state is ints or floats (Python or
  numpy, a scalar, a list or an array); strings, booleans, complex numbers, dates
  and times, ``None`` and other objects are refused with a ``ValueError`` that names
  the argument and says what was expected, instead of being converted (``'0.5'``
  to 0.5, ``True`` to 1, ``0.5+1j`` to 0.5, a ``datetime64`` to its tick count).
* **Reset options** are ``None`` or a mapping (a ``TypeError`` naming ``options``
  otherwise); their keys must be known (``ValueError``).
"""

from __future__ import annotations

import reprlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: numpy dtype kinds that hold real numbers: signed and unsigned integers, floats
REAL_KINDS = frozenset("iuf")

_short = reprlib.Repr()
_short.maxstring = _short.maxother = 60


def describe(value: Any) -> str:
    """A short description of a refused value: its type and (shortened) repr."""
    if isinstance(value, np.ndarray):
        return f"an array of dtype {value.dtype} and shape {value.shape}"
    return f"{type(value).__name__} {_short.repr(value)}"


def real_array(name: str, value: Any, expected: str | Callable[[], str]) -> FloatArray:
    """``value`` as a float64 array if it holds real numbers, else ``ValueError``.

    ``expected`` completes "``name`` must be ..." in the message (e.g. "1 real number
    in [-1, 1]"; a callable is called only for the message). The result is ``value``
    itself when that is a float64 array (copy it before keeping it), else a new array.
    """
    if isinstance(value, (str, bytes)):          # numpy would make a string array
        raise _refused(name, value, expected)
    try:
        arr = value if isinstance(value, np.ndarray) else np.asarray(value)
    except (TypeError, ValueError):               # ragged lists and the like
        raise _refused(name, value, expected) from None
    if arr.dtype.kind not in REAL_KINDS:
        what = {"b": "booleans", "c": "complex numbers", "M": "dates", "m": "time deltas",
                "U": "strings", "S": "bytes", "O": "Python objects"}.get(arr.dtype.kind,
                                                                         "not numbers")
        raise _refused(name, value, expected, what)
    return arr if arr.dtype == np.float64 else arr.astype(np.float64)


def _refused(name: str, value: Any, expected: str | Callable[[], str],
             what: str | None = None) -> ValueError:
    want = expected if isinstance(expected, str) else expected()
    got = describe(value) if what is None else f"{what} ({describe(value)})"
    return ValueError(f"{name} must be {want}; got {got}")


def reset_options(options: Any, known: tuple[str, ...]) -> Mapping[str, Any]:
    """``options`` of ``reset`` as a mapping (``{}`` for ``None``), with known keys only."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"reset options must be None or a dict such as {{'state': x0}} "
                        f"(known keys: {list(known)}); got {describe(options)}")
    unknown = [key for key in options if key not in known]
    if unknown:
        raise ValueError(f"reset options {', '.join(sorted(map(repr, unknown)))} are not "
                         f"understood; known: {list(known)}")
    return options
