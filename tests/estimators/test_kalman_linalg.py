"""The batched algebra under the Kalman family (``estimators/_kalman_linalg.py``) against
per-system textbook formulas, across the batch sizes and dimensions where the helpers switch
implementation (``rmul``'s one BLAS call from 8 systems on, ``cholesky``'s LAPACK call for
``m > 3`` and fewer than 32 systems, ``cho_solve``'s for ``m > 3``).

Oracles: ``np.einsum`` for the products, ``np.linalg.cholesky`` / ``np.linalg.solve`` per
system, and the Joseph form ``(I − K H) P (I − K H)ᵀ + K R Kᵀ`` written out per system.
Found by mutation testing (docs/mutation.md): a wrong reshape in ``rmul``'s large-batch
branch and a swapped branch of ``factored_joseph`` for per-system ``H`` survived, because no
test used 8 or more systems there.
"""

from __future__ import annotations

import numpy as np
import pytest
from matrices import spd

from fir_gym.estimators._kalman_linalg import cho_solve, cholesky, factored_joseph, rmul

BATCHES = [1, 7, 8, 33]


@pytest.mark.parametrize("n_b", BATCHES)
@pytest.mark.parametrize("batched", [False, True], ids=["2-D X", "batched X"])
def test_rmul_is_the_matrix_product(n_b: int, batched: bool) -> None:
    rng = np.random.default_rng(n_b)
    X = rng.normal(size=(n_b, 4, 3) if batched else (n_b, 3))
    M = rng.normal(size=(3, 5))
    np.testing.assert_allclose(rmul(X, M), np.einsum("...ij,jk->...ik", X, M),
                               rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("n_b", [1, 31, 32, 40])
@pytest.mark.parametrize("m", [1, 2, 3, 4, 5])
def test_cholesky_is_lapacks_per_system_and_nan_where_not_positive_definite(n_b: int, m: int
                                                                          ) -> None:
    rng = np.random.default_rng(10 * m + n_b)
    S = spd(rng, (n_b,), m)
    S[-1] = -np.eye(m)                                 # the last system is not PD
    L = cholesky(S)
    for b in range(n_b - 1):
        np.testing.assert_allclose(L[b], np.linalg.cholesky(S[b]), rtol=1e-12, atol=1e-12)
    assert np.isnan(L[-1]).any()


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5])
def test_cho_solve_solves_the_system(m: int) -> None:
    rng = np.random.default_rng(m)
    S = spd(rng, (6,), m)
    Y = rng.normal(size=(6, m, 2))
    X = cho_solve(np.linalg.cholesky(S), Y)
    np.testing.assert_allclose(X, np.linalg.solve(S, Y), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("n_b", BATCHES)
@pytest.mark.parametrize("per_system", [False, True], ids=["shared H, R", "per-system H, R"])
def test_factored_joseph_is_the_joseph_form(n_b: int, per_system: bool) -> None:
    rng = np.random.default_rng(100 + n_b)
    n, p = 3, 2
    P = spd(rng, (n_b,), n)
    H = rng.normal(size=(n_b, p, n) if per_system else (p, n))
    R = spd(rng, (n_b,), p) if per_system else spd(rng, (), p)
    K = rng.normal(size=(n_b, n, p))
    out = factored_joseph(P, H, R, K)
    for b in range(n_b):
        Hb = H[b] if per_system else H
        Rb = R[b] if per_system else R
        IKH = np.eye(n) - K[b] @ Hb
        want = IKH @ P[b] @ IKH.T + K[b] @ Rb @ K[b].T
        np.testing.assert_allclose(out[b], want, rtol=1e-10, atol=1e-12)
