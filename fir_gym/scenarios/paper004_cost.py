"""Paper 004's cost claims, measured: multiply-adds of Theorem 2.1 as printed and of the direct
solution, counted while they run.

Paper 004 states that the direct solution of (2.4) inverts a ``q(N+1) × q(N+1)``
matrix, "of order q³N³" (docs/papers.md#004-cost), and that Theorem 2.1 needs, for
each ``j``, a ``q × q``
inverse and matrix products, so that its cost "is of order q³N³" too (a slip: per
step the Riccati recursion (2.8) costs ``O(n³ + q³)``, and the impulse responses
(2.7), propagated forward for every ``j``, ``O(N² n² q)``).

:func:`theorem21_printed` runs (2.7)–(2.8) literally (each ``H(j; ·)`` forward from
``H(j; j)``) and :func:`direct_gain` the stacked solution, both through an
:class:`Ops` counter of multiply-adds (``m k n`` for a product, ``n³/3 + n² r`` for a
solve with ``r`` right-hand sides). The impulse responses they return are checked
against :func:`~fir_gym.estimators.fir_gains.riccati_gain` and ``batch_gain``, so
the counted code is the algorithm it claims to be.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fir_gym.estimators import fir_gains

#: window lengths L = N + 1 whose costs are counted
LENGTHS = (11, 21, 41, 81, 161)


class Ops:
    """Multiply-add counter: every product and solve goes through it."""

    def __init__(self) -> None:
        self.count = 0

    def mm(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a2, b2 = np.atleast_2d(a), np.atleast_2d(b)
        self.count += a2.shape[0] * a2.shape[1] * b2.shape[1]
        return a @ b

    def solve(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        n, r = a.shape[0], (1 if b.ndim == 1 else b.shape[1])
        self.count += n ** 3 // 3 + n * n * r
        return np.linalg.solve(a, b)


def theorem21_printed(win: fir_gains.Window, P0: np.ndarray, ops: Ops) -> np.ndarray:
    """Theorem 2.1 as printed (filter form, prior ``P0``): the gain ``(n, L·q)``.

        R(n+1) = M(n) − M(n)C'[R_v + C M(n) C']⁻¹ C M(n),  M(n) = A R(n) A' + BQB'   (2.8)
        H(j; n+1) = [I − R(n+1) C' R_v⁻¹ C] A H(j; n),    H(j; j) = R(j) C' R_v⁻¹  (2.7)

    each ``H(j; ·)`` propagated forward from ``j`` to the window's end, as written.
    """
    L, n = win.horizon, win.A.shape[1]
    R, G = [], []                                  # R(j), [I − R C' R_v⁻¹ C] A_{j-1}
    Mn = P0
    for j in range(L):
        C = win.C[j]
        MCt = ops.mm(Mn, C.T)
        Rj = Mn - ops.mm(MCt, ops.solve(win.R[j] + ops.mm(C, MCt), MCt.T))
        R.append(0.5 * (Rj + Rj.T))
        K = ops.solve(win.R[j], ops.mm(C, R[j])).T                   # R(j) C' R_v⁻¹
        if j:
            G.append(ops.mm(np.eye(n) - ops.mm(K, C), win.A[j - 1]))
        Mn = ops.mm(ops.mm(win.A[j], R[j]), win.A[j].T) + win.Qx[j]
    blocks = []
    for j in range(L):
        H = ops.solve(win.R[j], ops.mm(win.C[j], R[j])).T           # H(j; j)
        for m in range(j + 1, L):
            H = ops.mm(G[m - 1], H)                                   # H(j; m)
        blocks.append(H)
    return np.hstack(blocks)


def direct_gain(win: fir_gains.Window, P0: np.ndarray, ops: Ops) -> np.ndarray:
    """The direct solution of (2.4): ``S = (Φ P0 C̃ᵀ + M Q G̃ᵀ)(C̃ P0 C̃ᵀ + G̃ Q G̃ᵀ + R)⁻¹``.

    The stacked matrices are built uncounted (paper 000 eqs 21–26); the products and
    the ``L q × L q`` solve are counted.
    """
    sw = fir_gains.stacked_window(win, "filter")
    Ct, Gt = sw.Ct, sw.Gt
    big = ops.mm(ops.mm(Ct, P0), Ct.T) + ops.mm(ops.mm(Gt, sw.Qbd), Gt.T) + sw.Rbd
    rhs = ops.mm(ops.mm(sw.Phi, P0), Ct.T) + ops.mm(ops.mm(sw.M, sw.Qbd), Gt.T)
    return ops.solve(big, rhs.T).T


def count(model: Any, lengths: tuple[int, ...] = LENGTHS) -> dict[str, Any]:
    """Multiply-adds of both methods for each window length; a runner task (deterministic).

    Also returns the largest relative difference of the counted gains from
    :func:`~fir_gym.estimators.fir_gains.riccati_gain` (Theorem 2.1, ours) and
    ``batch_gain``, and the dimensions ``n``, ``q``.
    """
    A, C, R = model.A, model.C, model.R
    Qx = model.G @ model.Q @ model.G.T
    P0 = fir_gains.stationary_prior(A, Qx)
    out: dict[str, Any] = {"L": list(lengths), "thm21": [], "direct": [], "gap": 0.0,
                           "n": int(A.shape[0]), "q": int(C.shape[0])}
    for L in lengths:
        win = fir_gains.make_window(A, C, Qx, R, L)
        ref = fir_gains.riccati_gain(win, "filter", P0).S
        for key, fn, oracle in (("thm21", theorem21_printed, ref),
                                ("direct", direct_gain, fir_gains.batch_gain(win, "filter",
                                                                             P0).S)):
            ops = Ops()
            S = fn(win, P0, ops)
            out[key].append(ops.count)
            out["gap"] = max(out["gap"], float(np.max(np.abs(S - oracle)) / np.max(np.abs(oracle))),
                             float(np.max(np.abs(S - ref)) / np.max(np.abs(ref))))
    return out


def exponent(lengths: list[int], counts: list[int]) -> float:
    """The growth exponent ``d log(count) / d log(N)`` between the two longest windows."""
    (a, b), (ca, cb) = lengths[-2:], counts[-2:]
    return float(np.log(cb / ca) / np.log((b - 1) / (a - 1)))


def corrected_estimate(N: int, n: int, q: int) -> int:
    """The corrected order of Theorem 2.1's cost: ``N (n³ + q³) + N² n² q``."""
    return N * (n ** 3 + q ** 3) + N * N * n * n * q


__all__ = ["LENGTHS", "Ops", "corrected_estimate", "count", "direct_gain", "exponent",
           "theorem21_printed"]
