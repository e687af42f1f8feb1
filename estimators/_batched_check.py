"""A clear message for model callables written for one point (filterpy's ``fx(x, dt)`` habit).

fir-gym's callables take a leading batch axis (docs/architecture.md#model-contract): ``f(x
(B, n_x), u (B, n_u)) -> (B, n_x)``, ``h(x (B, n_x)) -> (B, n_y)``. A function written for
one point fails deep inside a filter with an opaque reshape or index error, or silently
returns the wrong shape. :func:`check_batched` evaluates the model once on ``n + 1`` copies of
the prior mean when a filter is built; when the batched call fails or has the wrong shape
but a single point works, it raises a ``TypeError`` that says what to change. Any other
failure is left to the filter's own first step (nothing is vectorised behind the user's
back: a Python loop over points would cost the batch its speed).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ._validation import FloatArray

__all__ = ["check_batched"]


def _shape_of(fn: Callable[..., Any], *args: FloatArray) -> tuple[int, ...] | None:
    try:
        with np.errstate(all="ignore"):
            return tuple(np.shape(fn(*args)))
    except Exception:
        return None


def check_batched(name: str, fn: Callable[..., Any], x0: FloatArray, u0: FloatArray | None,
                  size: int, filter_name: str) -> None:
    """Raise ``TypeError`` when ``fn`` works on one point but not on a batch (of ``B = n + 1``
    points, so that a one-point function indexing ``x[i]`` cannot return the right shape by
    coincidence)."""
    B = max(x0.shape[0], size) + 1
    X = np.repeat(x0[None], B, axis=0)
    args = (X,) if u0 is None else (X, np.repeat(u0[None], B, axis=0))
    if _shape_of(fn, *args) == (B, size):
        return
    one = (x0,) if u0 is None else (x0, u0)
    if _shape_of(fn, *one) not in ((size,), (size, 1)):
        return                                         # not the one-point habit: let it be
    call = "f(x, u)" if u0 is not None else "h(x)"
    raise TypeError(
        f"model.{name} must take a leading batch axis: {filter_name} calls {call} with x of "
        f"shape (B, n_x) and expects (B, {size}); {name} works on one point only. Write it "
        f"with x[..., i] instead of x[i] and stack the results on the last axis "
        f"(np.stack([...], axis=-1)), or wrap it: np.vectorize({name}, signature="
        f"{'(n),(m)->(k)' if u0 is not None else '(n)->(k)'}) (slow: a Python loop per point)")


def check_model_batched(est: Any) -> None:
    """:func:`check_batched` on the model's ``f`` and ``h`` at the filter's prior mean."""
    model = est.model
    x0 = np.asarray(est.prior[0], dtype=np.float64)
    x0 = x0[0] if x0.ndim == 2 else x0
    name = type(est).__name__
    f, _, h, _ = model.unchecked_callables()
    check_batched("f", f, x0, np.zeros(model.n_u), model.n_x, name)
    check_batched("h", h, x0, None, model.n_y, name)
