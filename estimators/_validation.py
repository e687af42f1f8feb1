"""Argument checks shared by models and filters.

Every public constructor, ``reset`` and ``step`` in this package validates its
inputs here, so a bad argument fails at the boundary with a message that names
the argument and says what was expected (docs/architecture.md#validation).
Numbers must be real: :func:`real_array` refuses booleans, complex numbers, dates and
anything non-numeric (strings, ``None``) instead of letting numpy convert or drop them.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Relative tolerance for symmetry and for the smallest admissible eigenvalue.
SYMMETRY_RTOL = 1e-9

#: dtype kinds read as real numbers: floats, signed and unsigned integers
REAL_KINDS = "fiu"
#: scalar types numpy counts as numbers that are not real numbers here
_NOT_REAL = (bool, np.bool_, np.datetime64, np.timedelta64)


def real_array(name: str, value: ArrayLike) -> FloatArray:
    """``value`` as a float64 array, refusing what is not real numbers.

    Floats and integers (numpy arrays, scalars, nested sequences) are accepted;
    booleans, complex numbers, ``datetime64``/``timedelta64``, strings and other
    objects raise ``TypeError`` naming ``name`` (numpy would otherwise turn ``True`` into
    1, ``"0.5"`` into 0.5, or drop an imaginary part). A ragged sequence raises
    ``ValueError``.
    """
    if type(value) is np.ndarray and value.dtype.kind in REAL_KINDS:
        return value.astype(np.float64, copy=False)
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        raise ValueError(f"{name} must be an array of real numbers; got a ragged or "
                         f"malformed {type(value).__name__}") from None
    kind = arr.dtype.kind
    if kind == "O" and all(isinstance(v, numbers.Real) and not isinstance(v, _NOT_REAL)
                           for v in arr.flat):
        kind = "f"                              # e.g. Fractions or Decimals mixed with floats
    elif kind in REAL_KINDS and _holds_bool(value):
        kind = "b"                              # numpy reads [True, 0.5] as [1.0, 0.5]
    if kind not in REAL_KINDS:
        what = {"b": "booleans", "c": "complex numbers", "M": "dates (datetime64)",
                "m": "time spans (timedelta64)", "U": "strings", "S": "bytes"}.get(
                    kind, f"{type(value).__name__} of dtype {arr.dtype}")
        raise TypeError(f"{name} must be real numbers (floats or integers); got {what}")
    return arr.astype(np.float64, copy=False)


def _holds_bool(value: Any) -> bool:
    """Whether a (nested) list or tuple holds a boolean anywhere."""
    if isinstance(value, (list, tuple)):
        return any(isinstance(v, (bool, np.bool_)) or _holds_bool(v) for v in value)
    return False


def as_matrix(name: str, value: ArrayLike, shape: tuple[int | None, int | None]) -> FloatArray:
    """Return ``value`` as a finite float64 2-D array of the given shape.

    ``None`` in ``shape`` accepts any size on that axis. A scalar is accepted
    for a 1x1 matrix.
    """
    arr = real_array(name, value)
    if arr.ndim == 0 and shape in ((1, 1), (None, None), (1, None), (None, 1)):
        arr = arr.reshape(1, 1)
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be a 2-D matrix of shape {_fmt(shape)}; got shape {arr.shape}")
    for axis, want in enumerate(shape):
        if want is not None and arr.shape[axis] != want:
            raise ValueError(f"{name} must have shape {_fmt(shape)}; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; it contains NaN or inf")
    return arr


def as_covariance(
    name: str,
    value: ArrayLike,
    size: int | None = None,
    *,
    definite: bool = False,
) -> FloatArray:
    """Return ``value`` as a symmetric positive semi-definite matrix.

    A scalar is a 1x1 covariance; a 1-D array is read as a diagonal. The
    matrix must be symmetric to a relative ``SYMMETRY_RTOL`` (it is then
    symmetrised exactly) and its smallest eigenvalue must not be below
    ``-SYMMETRY_RTOL * max|eig|`` (or must be positive when ``definite``).
    """
    arr = real_array(name, value)
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = np.diag(arr)
    want = (size, size)
    arr = as_matrix(name, arr, want)
    if arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be square; got shape {arr.shape}")
    scale = max(float(np.max(np.abs(arr))), np.finfo(float).tiny)
    if np.max(np.abs(arr - arr.T)) > SYMMETRY_RTOL * scale:
        raise ValueError(f"{name} must be symmetric; max |{name} - {name}ᵀ| = "
                         f"{np.max(np.abs(arr - arr.T)):.3g}")
    arr = 0.5 * (arr + arr.T)
    eig = np.linalg.eigvalsh(arr)
    if definite and eig[0] <= SYMMETRY_RTOL * scale:
        raise ValueError(f"{name} must be positive definite; smallest eigenvalue is {eig[0]:.3g}")
    if eig[0] < -SYMMETRY_RTOL * scale:
        raise ValueError(
            f"{name} must be positive semi-definite; smallest eigenvalue is {eig[0]:.3g}"
        )
    return arr


def as_vector(name: str, value: ArrayLike, size: int) -> FloatArray:
    """Return ``value`` as a finite float64 vector of length ``size``."""
    arr = real_array(name, value)
    if arr.ndim == 0 and size == 1:
        arr = arr.reshape(1)
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},); got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {arr}")
    return arr


def as_batch(name: str, value: ArrayLike, size: int) -> FloatArray:
    """Return ``value`` as float64 of shape ``(size,)`` or ``(B, size)``.

    Finiteness is not checked here: filters decide what a non-finite
    measurement means (see their ``nan_policy``).
    """
    arr = real_array(name, value)
    if arr.ndim == 0 and size == 1:
        arr = arr.reshape(1)
    if arr.ndim not in (1, 2) or arr.shape[-1] != size:
        raise ValueError(f"{name} must have shape ({size},) or (B, {size}); got shape {arr.shape}")
    return arr


def input_batch(u: ArrayLike | None, x: FloatArray, n_u: int) -> FloatArray:
    """The input for states ``x`` (``(n_x,)`` or ``(B, n_x)``): zeros when ``u`` is None.

    ``u`` may be ``(n_u,)``, ``(B, n_u)``, or a scalar when ``n_u == 1``.
    """
    if u is None:
        return np.zeros(x.shape[:-1] + (n_u,))
    return as_batch("u", u, n_u)


def one_of(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """Check that ``value`` is one of ``choices``; returns it."""
    choices = tuple(choices)
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}; got {value!r}")
    return value


def positive(name: str, value: Any, *, integer: bool = False) -> Any:
    """Check that ``value`` is a finite positive number (an int if ``integer``)."""
    if integer:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
            raise ValueError(f"{name} must be a positive integer; got {value!r}")
        return int(value)
    try:
        val = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number; got {value!r}") from None
    if not np.isfinite(val) or val <= 0:
        raise ValueError(f"{name} must be a positive finite number; got {value!r}")
    return val


def open_probability(name: str, value: Any) -> float:
    """Check that ``value`` is a real number strictly between 0 and 1; returns it as a float.

    A bool, a string or another non-number raises ``TypeError``; NaN, ``<= 0`` or ``>= 1``
    raises ``ValueError`` (both naming ``name``)."""
    if isinstance(value, _NOT_REAL) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a probability strictly between 0 and 1 (e.g. 0.999) "
                        f"or None; got {value!r} ({type(value).__name__})")
    val = float(value)
    if not 0.0 < val < 1.0:                     # NaN fails too
        raise ValueError(f"{name} must be a probability strictly between 0 and 1 (e.g. "
                         f"0.999) or None; got {value!r}")
    return val


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
