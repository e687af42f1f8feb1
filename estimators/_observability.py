"""The one observability rule of the windowed filters (docs/architecture.md#windowed-filters).

A window of ``L`` measurements determines the window-start state exactly when the
information matrix of the stacked observation ``F_L = Σ_{j<L} (H_j Φ_j)ᵀ R⁻¹ (H_j Φ_j)``
(``Φ_j = A_{j−1} ⋯ A_0``) is regular by the :data:`~._fir_bank.RANK_RTOL` test
(:func:`~._fir_bank.information_is_regular`). The *observability index along a
nominal* is the smallest such ``L`` for the transition and output matrices along it:
``(A, C)`` of a linear model (constant or of a time-varying one from ``k = 0``), or for
the extended FIR filter ``F, H`` along its nominal trajectory from ``x0`` with zero
input (paper 000 eqs 4–10).

Every windowed filter (``fir``, ``ufir``, ``rfir``, ``fir-smoother``, ``efir``) refuses
at construction, with the same message (:func:`require_window`), a ``horizon`` shorter
than that index — such a window never determines the state, and the filter would run
on its fallback forever — and a model that no window of up to ``max(n, horizon)``
measurements makes observable along the nominal (``max(4n, horizon)`` for the
extended FIR filter, whose linearisation varies along the nominal). A filter with a prior on the
window-start state (``prior=``) needs no such index: the prior regularises the window.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike

from ._fir_bank import information_is_regular


def index_along(pairs: Iterable[tuple[ArrayLike, ArrayLike]], R: ArrayLike | None = None
                ) -> int | None:
    """Smallest number of measurements ``m`` that determines the start state, for the
    ``(A_j, C_j)`` along a nominal (``C_j`` observes the state ``j``, ``A_j`` moves it to
    ``j + 1``); ``None`` when none of the given pairs qualifies (or a matrix is not
    finite). Batched: ``A_j (B, n, n)``, ``C_j (B, p, n)`` give the largest index of the
    ``B`` nominals (``None`` if one of them has none)."""
    F = Phi = Ri = None
    found: np.ndarray | None = None
    for m, (A, C) in enumerate(pairs, start=1):
        A_, C_ = np.asarray(A, float), np.asarray(C, float)
        C_ = C_.reshape(1, 1) if C_.ndim == 0 else (C_[None] if C_.ndim == 1 else C_)
        if F is None:
            n = A_.shape[-1]
            Phi = np.eye(n)
            R_ = np.eye(C_.shape[-2]) if R is None else np.atleast_2d(np.asarray(R, float))
            Ri = np.linalg.inv(R_)
        assert Phi is not None and Ri is not None
        H = C_ @ Phi
        finite = np.asarray(np.isfinite(H).all(axis=(-2, -1)))
        H = np.where(finite[..., None, None], H, 0.0)
        F_m = H.swapaxes(-1, -2) @ Ri @ H
        F = F_m if F is None else F + F_m
        ok = np.asarray(information_is_regular(F)) & np.asarray(finite)
        found = ok if found is None else (found | ok)
        if found.all():
            return m
        Phi = A_ @ Phi
    return None


def observability_index(A: ArrayLike, C: ArrayLike, R: ArrayLike | None = None) -> int | None:
    """Smallest number ``ν`` of measurements that determines the state of ``(A, C)``.

    Uses the :data:`~._fir_bank.RANK_RTOL` test on ``Σ_{j<m} (C A^j)ᵀ R⁻¹ (C A^j)``;
    returns ``None`` when ``(A, C)`` is unobservable (no ``m ≤ n`` qualifies).
    """
    A_ = np.asarray(A, float)
    return index_along(((A_, C) for _ in range(A_.shape[0])), R)


def require_window(horizon: int, index: int | None, along: str, searched: int) -> None:
    """The rule's one refusal: ``ValueError`` when ``index`` (the observability index
    along ``along``, searched over ``searched`` measurements) is ``None`` or above
    ``horizon``."""
    if index is None:
        raise ValueError(f"horizon={horizon}: the model is not observable along {along} "
                         f"(no window of up to {searched} measurements determines the state), "
                         f"so no horizon gives an unbiased FIR estimate")
    if horizon < index:
        raise ValueError(f"horizon={horizon} is shorter than the observability index {index} "
                         f"along {along}: the window cannot determine the state; use "
                         f"horizon >= {index}")
