"""The numpy window bank's small algebra (``estimators/_fir_bank.py``) against definitions:
``spd_inverse`` against ``np.linalg.inv`` on both of its paths (LAPACK below 32 systems or
above 3 states; the adjugate over the determinant for large batches of 1 to 3 states), its
regularity flag against the smallest eigenvalue of the unit-diagonal matrix, and
``information_is_regular`` against that definition, scale-free.

Found by mutation testing (docs/mutation.md): every FIR test ran small batches, so the
closed-form inverses (a wrong cofactor table, a wrong 2 x 2 determinant) went unseen.
"""

from __future__ import annotations

import numpy as np
import pytest
from matrices import unit_diagonal

from fir_gym.estimators._fir_bank import RANK_RTOL, information_is_regular, spd_inverse


def regular_by_definition(F: np.ndarray) -> np.ndarray:
    """``λ_min(D⁻¹ F D⁻¹) > RANK_RTOL`` with ``D = diag(√F_ii)`` (the docstring's rule)."""
    return np.linalg.eigvalsh(unit_diagonal(F))[:, 0] > RANK_RTOL


def information_matrices(rng: np.random.Generator, nb: int, n: int) -> np.ndarray:
    """Symmetric PD matrices of very different scales per state, and two singular ones."""
    G = rng.normal(size=(nb, n, n))
    F = G @ G.mT + 0.1 * np.eye(n)
    scale = 10.0 ** rng.uniform(-6, 6, size=(nb, n))
    F = F * scale[:, :, None] * scale[:, None, :]      # D F D: the scale test's point
    v = rng.normal(size=(2, n))
    F[0] = np.outer(v[0], v[0]) * (n > 1) if n > 1 else 0.0   # rank one (n > 1) or zero
    F[1] = 0.0
    return F


@pytest.mark.parametrize("nb", [5, 40])
@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_spd_inverse_is_the_inverse_and_flags_the_singular(nb: int, n: int) -> None:
    rng = np.random.default_rng(10 * n + nb)
    F = information_matrices(rng, nb, n)
    Fi, ok = spd_inverse(F)
    want_ok = regular_by_definition(F)
    np.testing.assert_array_equal(ok, want_ok)
    assert not ok[:2].any() and ok[2:].all()
    for b in np.flatnonzero(ok):
        # compared unit-free: D F⁻¹ D, D = diag(√F_ii) (the entries span 24 decades)
        D = np.diag(np.sqrt(np.diag(F[b])))
        want = D @ np.linalg.inv(F[b]) @ D
        np.testing.assert_allclose(D @ Fi[b] @ D, want, rtol=0,
                                   atol=1e-9 * np.abs(want).max())
    for b in np.flatnonzero(~ok):
        np.testing.assert_array_equal(Fi[b], np.eye(n))       # the identity's inverse


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_information_is_regular_is_the_scale_free_eigenvalue_rule(n: int) -> None:
    rng = np.random.default_rng(n)
    F = information_matrices(rng, 12, n)
    np.testing.assert_array_equal(information_is_regular(F), regular_by_definition(F))
    # a diagonal matrix is regular at any scale of its entries, small ones included
    tiny = np.diag(10.0 ** -np.arange(1, n + 1) * 1e-3)[None]
    assert information_is_regular(tiny).all()


@pytest.mark.parametrize("first", [True, False], ids=["first reference", "later reference"])
def test_a_window_restarted_at_a_reference_starts_there(first: bool) -> None:
    """``restart(w, x_ref)`` starts window ``w`` at ``x̄ = x_ref``: with no data since, its
    estimate under a prior is ``x_ref`` itself (``b = 0``); the bank's first reference
    counts as much as a later one (mutation testing found the first one droppable)."""
    from fir_gym.estimators._fir_bank import WindowBank
    rng = np.random.default_rng(0)
    B, W, n = 3, 2, 2
    bank = WindowBank(B, W, n)
    if not first:
        bank.restart(1, x_ref=np.zeros((B, n)))
    X = rng.normal(size=(B, n))
    bank.restart(0, x_ref=X)
    x, _, ok = bank.estimate(0, prior=np.eye(n))
    assert ok.all()
    np.testing.assert_allclose(x, X, rtol=0, atol=1e-15)
