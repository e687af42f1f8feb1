"""Whole sequences: :meth:`Estimator.filter <fir_gym.estimators.base.Estimator.filter>`.

One loop over the filter's own :meth:`~fir_gym.estimators.base.Estimator.step` serves every
filter, on whichever path :data:`compiled.ENABLED <fir_gym.estimators.compiled.ENABLED>`
selects — so a sequence run equals the env loop step for step, bit for bit.

**Alignment** (the env loop's, and :meth:`step`'s): ``ys[0]`` is the first measurement
(the one ``env.reset`` returns), ``us[k]`` the input applied between ``ys[k]`` and
``ys[k+1]`` (the action chosen after observing ``ys[k]``); ``us`` has ``T − 1`` or ``T``
rows (the last one is then unused). A filter that has already stepped continues from its
current state (its prediction into ``ys[0]`` then takes no input); call ``reset`` first for
a fresh run.

**Missing measurements**: NaN entries and the masked entries of a ``numpy.ma`` array,
whatever ``nan_policy`` says; a system with any missing entry at step ``k`` predicts only
(its ``log_likelihoods`` term is 0, its ``nis`` NaN). A measurement the innovation gate
rejects (``gate=``) is treated as missing too, with its ``nis`` kept and ``gated`` True.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, real_array

if TYPE_CHECKING:
    from .base import Estimator

__all__ = ["FilterResult", "SmootherResult", "filter_sequence", "input_sequence",
           "measurement_sequence"]


@dataclass(frozen=True)
class FilterResult:
    """A filter's run over a sequence (:meth:`Estimator.filter`).

    Attributes:
        x: estimates ``x̂[k|k]``, ``(T, n_x)`` or ``(T, B, n_x)`` for a batch.
        P: their error covariances ``(T, n_x, n_x)`` / ``(T, B, n_x, n_x)``; ``None`` for
            a filter without one (``provides_covariance`` False).
        log_likelihoods: the Gaussian log-likelihood of each innovation, ``(T,)`` /
            ``(T, B)`` (0 where the measurement was missing); ``None`` for a filter without
            an innovation covariance (``reports_likelihood`` False).
        log_likelihood: their sum over time (a float, or ``(B,)``), pykalman's
            ``loglikelihood``; ``None`` with ``log_likelihoods``.
        nis: normalised innovation squared ``(T,)`` / ``(T, B)`` (NaN where missing);
            ``None`` for a filter without one.
        diverged: the sticky divergence flag after each step, ``(T,)`` / ``(T, B)``.
        gated: whether the innovation gate rejected each step's measurement, ``(T,)`` /
            ``(T, B)``; ``None`` for a filter without a gate (``gate=None``).
    """

    x: FloatArray
    P: FloatArray | None
    log_likelihoods: FloatArray | None
    log_likelihood: Any
    nis: FloatArray | None
    diverged: np.ndarray
    gated: np.ndarray | None = None


@dataclass(frozen=True)
class SmootherResult:
    """A fixed-interval smoother's run (:meth:`smooth`): ``x̂[k|T−1]`` and its covariance.

    Attributes:
        x: smoothed estimates, ``(T, n_x)`` or ``(T, B, n_x)``.
        P: their error covariances, ``(T, n_x, n_x)`` or ``(T, B, n_x, n_x)``.
        filtered: the forward pass the smoother ran on (:class:`FilterResult`).
    """

    x: FloatArray
    P: FloatArray
    filtered: FilterResult


def measurement_sequence(ys: ArrayLike, n_y: int) -> np.ma.MaskedArray:
    """``ys`` as a masked ``(T, n_y)`` or ``(T, B, n_y)`` float array, NaN entries masked.

    ``(T,)`` is accepted for ``n_y = 1``. Raises ``ValueError`` naming ``ys`` otherwise.
    """
    mask = np.ma.getmaskarray(ys) if isinstance(ys, np.ma.MaskedArray) else None
    data = real_array("ys", np.ma.getdata(ys) if mask is not None else ys)
    if data.ndim == 1 and n_y == 1:
        data = data[:, None]
        mask = None if mask is None else mask[:, None]
    if data.ndim not in (2, 3) or data.shape[-1] != n_y or data.shape[0] < 1:
        raise ValueError(f"ys must have shape (T, {n_y}) or (T, B, {n_y}) with T >= 1 (one "
                         f"measurement per row); got shape {data.shape}")
    missing = np.isnan(data) if mask is None else (mask | np.isnan(data))
    return np.ma.MaskedArray(np.where(missing, 0.0, data), mask=missing)


def input_sequence(us: ArrayLike | None, T: int, n_u: int) -> FloatArray | None:
    """``us`` as ``(T − 1 | T, n_u)`` or ``(T − 1 | T, B, n_u)`` floats (``(L,)`` for ``n_u =
    1``), or ``None``. Raises ``ValueError`` naming ``us`` on a wrong length or shape."""
    if us is None:
        return None
    u = real_array("us", us)
    if u.ndim == 1 and n_u == 1:
        u = u[:, None]
    if u.ndim not in (2, 3) or u.shape[-1] != n_u:
        raise ValueError(f"us must have shape (T - 1, {n_u}) or (T - 1, B, {n_u}) (or T rows, "
                         f"the last unused); got shape {u.shape}")
    if u.shape[0] not in (T - 1, T):
        raise ValueError(f"us must have T - 1 = {T - 1} or T = {T} rows (us[k] drives the plant "
                         f"from ys[k] to ys[k+1]); got {u.shape[0]}")
    if not np.isfinite(u).all():
        raise ValueError("us must be finite")
    return u


def filter_sequence(est: Estimator, ys: ArrayLike, us: ArrayLike | None = None
                    ) -> FilterResult:
    """Run ``est`` over ``ys`` (and ``us``) from its current state; see the module docstring."""
    Y = measurement_sequence(ys, est.model.n_y)
    T = Y.shape[0]
    U = input_sequence(us, T, est.model.n_u)
    batch = Y.shape[1] if Y.ndim == 3 else None
    if U is not None and U.ndim == 3 and U.shape[1] != batch:
        raise ValueError(f"us must have shape (T - 1, {est.model.n_u}) or (T - 1, B, "
                         f"{est.model.n_u}) with the B = {batch} systems of ys; got {U.shape}")
    state = est.state
    seen = state.batch and (None if state.single else state.batch)
    if state.batch and seen != batch:
        raise ValueError(f"ys must be {'unbatched' if seen is None else f'a batch of {seen}'} "
                         f"like the measurements this filter has seen (it continues from its "
                         f"state); got {'unbatched' if batch is None else f'a batch of {batch}'}"
                         f" — call reset() first for a fresh run")
    xs: list[FloatArray] = []
    Ps: list[Any] = []
    lls: list[Any] = []
    nis: list[Any] = []
    div: list[Any] = []
    gated: list[Any] = []
    gaps = np.isnan(np.ma.filled(Y, np.nan)).reshape(T, -1).any(axis=1)
    for k in range(T):
        y = Y[k] if gaps[k] else Y.data[k]
        u = None if (k == 0 or U is None) else U[k - 1]
        xs.append(est.step(y, u))
        info = est.last_info
        Ps.append(est.P)
        lls.append(info.get("log_likelihood"))
        nis.append(info.get("nis"))
        div.append(info["diverged"])
        gated.append(info.get("gated"))
    x = np.stack(xs)
    lh = None if lls[0] is None else np.asarray(lls, dtype=np.float64)
    total = None if lh is None else (float(lh.sum()) if lh.ndim == 1 else lh.sum(axis=0))
    return FilterResult(
        x=x, P=None if Ps[0] is None else np.stack(Ps), log_likelihoods=lh,
        log_likelihood=total, nis=None if nis[0] is None else np.asarray(nis, np.float64),
        diverged=np.asarray(div, dtype=bool),
        gated=None if gated[0] is None else np.asarray(gated, dtype=bool))
