"""fir_gym.jax.small_linalg against numpy/LAPACK, and the absence of LAPACK custom calls
from every plant and kind's vmapped reset and step.

Tolerances are the textbook error bounds (Higham, *Accuracy and Stability of Numerical
Algorithms*, 2002; Golub & Van Loan 2013) of the two implementations compared, each
scaled by the matrix's condition number where the quantity compared is sensitive to it:
``γ_k = k ε / (1 − k ε)``; two backward-stable results differ by at most twice the bound
of one. None is tuned to the measured differences (which are printed with ``-s``: ~1e-16
relative on well-conditioned matrices).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.linalg

jax = pytest.importorskip("jax")
pytest.importorskip("gymnax")

import jax.numpy as jnp  # noqa: E402

import fir_gym.jax  # noqa: E402, F401  (float64)
from fir_gym.jax import small_linalg as sl  # noqa: E402
from fir_gym.jax.registry import PLANTS, make  # noqa: E402

EPS = float(np.finfo(np.float64).eps)
SIZES = (1, 2, 3, 4)
CONDITIONS = (1.0, 1e3, 1e8, 1e12)


def gamma(k: int) -> float:
    """Higham's ``γ_k = k ε / (1 − k ε)``."""
    return k * EPS / (1 - k * EPS)


def _orthogonal(rng: np.random.Generator, n: int) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((n, n)))
    return Q * np.sign(np.diag(R))


def spd(rng: np.random.Generator, n: int, cond: float) -> np.ndarray:
    """A symmetric positive-definite matrix with eigenvalues log-spaced over ``[1, cond]``
    (times a random scale), exactly symmetric."""
    Q = _orthogonal(rng, n)
    lam = np.logspace(0.0, np.log10(cond), n) * 10.0 ** rng.uniform(-3, 3)
    A = (Q * lam) @ Q.T
    return 0.5 * (A + A.T)


def general(rng: np.random.Generator, n: int, cond: float) -> np.ndarray:
    """A general square matrix with singular values log-spaced over ``[1, cond]``."""
    s = np.logspace(0.0, np.log10(cond), n) * 10.0 ** rng.uniform(-3, 3)
    return (_orthogonal(rng, n) * s) @ _orthogonal(rng, n)


def symmetric(rng: np.random.Generator, n: int, cond: float) -> np.ndarray:
    """A symmetric indefinite matrix, eigenvalue moduli log-spaced over ``[1, cond]``."""
    Q = _orthogonal(rng, n)
    lam = np.logspace(0.0, np.log10(cond), n) * rng.choice([-1.0, 1.0], n)
    A = (Q * lam) @ Q.T
    return 0.5 * (A + A.T)


def cases(make_matrix):
    rng = np.random.default_rng(20261205)
    return [(n, cond, make_matrix(rng, n, cond)) for n in SIZES for cond in CONDITIONS
            for _ in range(5)]


# ---------------------------------------------------------------------------- Cholesky
@pytest.mark.parametrize("n,cond,A", cases(spd))
def test_cholesky_matches_lapack(n: int, cond: float, A: np.ndarray) -> None:
    L = np.asarray(sl.cholesky(jnp.asarray(A)))
    assert np.array_equal(L, np.tril(L))
    # backward error (Higham Thm 10.3): |L Lᵀ − A| ≤ γ_{n+1} |L| |Lᵀ|, entrywise, plus
    # the rounding of the check's own product and difference (γ_{n+1} again)
    assert np.all(np.abs(L @ L.T - A) <= 2 * gamma(n + 1) * (np.abs(L) @ np.abs(L.T)))
    # forward: both factors are exact for A + ΔA, ‖ΔA‖_F ≤ n γ_{n+1} ‖A‖₂; the factor's
    # relative change is at most κ₂(A) times the data's (Sun 1991; Higham Thm 10.8)
    L_np = np.linalg.cholesky(A)
    rel = np.linalg.norm(L - L_np) / np.linalg.norm(L_np, 2)
    print(f"cholesky n={n} cond={cond:.0e}: {rel:.1e}")
    assert rel <= 2 * n * gamma(n + 1) * np.linalg.cond(A)


@pytest.mark.parametrize("A", [
    np.array([[-1.0]]), np.array([[0.0]]), np.array([[np.nan]]),
    np.array([[1.0, 2.0], [2.0, 1.0]]),                       # indefinite
    np.array([[1.0, 1.0], [1.0, 1.0]]),                       # singular PSD: zero pivot
    np.diag([1.0, 2.0, -1e-300]),
    np.diag([4.0, 3.0, 2.0, 0.0]),
    np.array([[2.0, 1.0, 0.0], [1.0, 2.0, np.inf], [0.0, np.inf, 2.0]]),
    -np.eye(4),
], ids=lambda A: f"n{A.shape[0]}")
def test_cholesky_is_nan_where_not_positive_definite(A: np.ndarray) -> None:
    L = np.asarray(sl.cholesky(jnp.asarray(A)))
    assert np.isnan(L).all()
    L_jnp = np.asarray(jnp.linalg.cholesky(jnp.asarray(A)))          # NaN lower triangle
    assert np.isnan(L_jnp[np.tril_indices(A.shape[0])]).all()


# ---------------------------------------------------------------------------- solves
@pytest.mark.parametrize("n,cond,A", cases(spd))
def test_triangular_and_cholesky_solves(n: int, cond: float, A: np.ndarray) -> None:
    rng = np.random.default_rng(n)
    L = np.linalg.cholesky(A)
    for B in (rng.standard_normal(n), rng.standard_normal((n, 3))):
        for ours, T in ((sl.solve_lower(jnp.asarray(L), jnp.asarray(B)), L),
                        (sl.solve_upper(jnp.asarray(L.T), jnp.asarray(B)), L.T)):
            x = np.asarray(ours)
            exact = scipy.linalg.solve_triangular(T, B, lower=T is L)
            # (T + ΔT) x̂ = b, |ΔT| ≤ γ_n |T| (Higham Thm 8.5): the error is bounded by
            # Skeel's condition number, and LAPACK's trsm answer carries the same bound
            skeel = np.abs(np.linalg.inv(T)) @ np.abs(T) @ np.abs(exact)
            assert np.all(np.abs(x - exact) <= 2 * gamma(n) * skeel / (1 - gamma(n)))
        x = np.asarray(sl.cho_solve(jnp.asarray(L), jnp.asarray(B)))
        exact = np.linalg.solve(A, B)
        scale = np.linalg.norm(exact) if B.ndim == 1 else np.linalg.norm(exact, axis=0)
        err = np.linalg.norm(x - exact, axis=0) / scale
        # Cholesky solve: (A + ΔA) x̂ = b, |ΔA| ≤ γ_{3n+1} |L||Lᵀ| (Higham Thm 10.4)
        assert np.all(err <= 2 * n * gamma(3 * n + 1) * np.linalg.cond(A))


@pytest.mark.parametrize("n,cond,A", cases(spd))
def test_spd_inverse(n: int, cond: float, A: np.ndarray) -> None:
    X = np.asarray(sl.spd_inverse(jnp.asarray(A)))
    rel = np.linalg.norm(X - np.linalg.inv(A)) / np.linalg.norm(np.linalg.inv(A), 2)
    print(f"spd_inverse n={n} cond={cond:.0e}: {rel:.1e}")
    assert rel <= 2 * n * gamma(3 * n + 1) * np.linalg.cond(A)
    assert np.isnan(np.asarray(sl.spd_inverse(jnp.asarray(-A)))).all()


# ---------------------------------------------------------------------------- LU
def _lu_bound(n: int, M: np.ndarray) -> float:
    """Relative forward error of an LU solve, two implementations: backward error ``γ_{3n}
    |L||U|`` (Higham Thm 9.4), ``‖|L||U|‖ ≤ n ρ ‖M‖`` with the growth factor ``ρ ≤
    2^{n−1}`` of partial pivoting (Thm 9.7), times ``κ(M)``."""
    return 2 * n * 2 ** (n - 1) * gamma(3 * n) * np.linalg.cond(M)


@pytest.mark.parametrize("n,cond,M", cases(general))
def test_solve_inv_det_match_lapack(n: int, cond: float, M: np.ndarray) -> None:
    rng = np.random.default_rng(n + 10)
    bound = _lu_bound(n, M)
    for B in (rng.standard_normal(n), rng.standard_normal((n, 2))):
        x = np.asarray(sl.solve(jnp.asarray(M), jnp.asarray(B)))
        exact = np.linalg.solve(M, B)
        assert np.linalg.norm(x - exact) <= bound * np.linalg.norm(exact)
    X = np.asarray(sl.inv(jnp.asarray(M)))
    rel = np.linalg.norm(X - np.linalg.inv(M)) / np.linalg.norm(np.linalg.inv(M))
    d, d_np = float(sl.det(jnp.asarray(M))), np.linalg.det(M)
    print(f"lu n={n} cond={cond:.0e}: inv {rel:.1e}, det {abs(d / d_np - 1):.1e}")
    assert rel <= bound
    # det(M + ΔM) / det M − 1 ≈ tr(M⁻¹ ΔM) ≤ n ‖M⁻¹‖ ‖ΔM‖
    assert abs(d / d_np - 1.0) <= bound


@pytest.mark.parametrize("M", [
    np.array([[0.0]]),
    np.array([[1.0, 2.0], [2.0, 4.0]]),
    np.array([[0.0, 0.0], [0.0, 1.0]]),
    np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [1.0, 2.0, 3.0]]),        # repeated row
    np.array([[0.3, 1.7, 0.0, 2.2], [0.1, 0.9, 0.0, -4.0],
              [5.0, -1.0, 0.0, 0.5], [1.0, 1.0, 0.0, 1.0]]),               # zero column
    np.array([[0.3, 1.7, 0.1, 2.2], [0.1, 0.9, -0.2, -4.0],
              [0.3, 1.7, 0.1, 2.2], [1.0, 1.0, 7.0, 1.0]]),                # repeated row
], ids=lambda M: f"n{M.shape[0]}")
def test_singular(M: np.ndarray) -> None:
    assert float(sl.det(jnp.asarray(M))) == 0.0
    assert not np.isfinite(np.asarray(sl.inv(jnp.asarray(M)))).all()


def test_pivoting_is_needed_and_done() -> None:
    """A zero leading entry: elimination without row exchanges divides by zero."""
    M = np.array([[0.0, 1.0, 2.0], [1.0, 0.0, 3.0], [4.0, -3.0, 8.0]])
    assert np.allclose(np.asarray(sl.inv(jnp.asarray(M))), np.linalg.inv(M), rtol=0,
                       atol=_lu_bound(3, M) * np.linalg.norm(np.linalg.inv(M)))
    assert float(sl.det(jnp.asarray(M))) == pytest.approx(np.linalg.det(M), rel=_lu_bound(3, M))
    LU, perm, sign = sl.lu(jnp.asarray(M))
    assert float(sign) == round(np.linalg.det(np.eye(3)[np.asarray(perm)]))
    Lf = np.tril(np.asarray(LU), -1) + np.eye(3)
    assert np.allclose(Lf @ np.triu(np.asarray(LU)), M[np.asarray(perm)], rtol=0,
                       atol=_lu_bound(3, np.eye(3)) * np.abs(M).max())
    assert np.all(np.abs(Lf) <= 1.0)                 # partial pivoting: |multipliers| ≤ 1


# ---------------------------------------------------------------------------- eigh
def _jacobi_bound(n: int) -> float:
    """Backward error of the Jacobi method, relative to ``‖A‖₂``: each rotation is
    backward stable with an error of a few ulps of ``‖A‖`` (GvL §8.5.5: ``O(ε)``; taken
    as ``γ_6``: the two multiply-adds of each updated entry and the rotation's own
    error, Higham §19.6), over ``sweeps · n(n−1)/2`` rotations; LAPACK's is smaller."""
    rotations = max(sl.JACOBI_SWEEPS[n] * n * (n - 1) // 2, 1)
    return 2 * n * rotations * gamma(6)


def _check_eigh(A: np.ndarray, lam: np.ndarray, V: np.ndarray) -> None:
    n = A.shape[0]
    norm = np.linalg.norm(A, 2)
    bound = _jacobi_bound(n)
    assert np.all(np.diff(lam) >= 0)
    # Weyl: eigenvalues of A + ΔA are within ‖ΔA‖₂ of A's
    assert np.abs(lam - np.linalg.eigvalsh(A)).max() <= bound * norm
    assert np.abs(A @ V - V * lam).max() <= bound * norm
    assert np.abs(V.T @ V - np.eye(n)).max() <= bound


@pytest.mark.parametrize("n,cond,A", cases(symmetric) + cases(spd))
def test_eigh_matches_lapack(n: int, cond: float, A: np.ndarray) -> None:
    lam, V = (np.asarray(a) for a in sl.eigh(jnp.asarray(A)))
    norm = np.linalg.norm(A, 2)
    err_lam = np.abs(lam - np.linalg.eigvalsh(A)).max() / norm
    print(f"eigh n={n} cond={cond:.0e}: λ {err_lam:.1e}, "
          f"AV−VΛ {np.abs(A @ V - V * lam).max() / norm:.1e}")
    _check_eigh(A, lam, V)
    assert np.array_equal(np.asarray(sl.eigvalsh(jnp.asarray(A))), lam)


def _degenerate() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    out = [np.zeros((1, 1)), np.eye(2), np.zeros((3, 3)), 3.0 * np.eye(4),
           np.diag([2.0, 1.0, 2.0, 1.0]), np.array([[1.0, 0.0], [0.0, 1.0 + 1e-15]])]
    for n, lam in ((2, [1.0, 1.0]), (3, [1.0, 1.0, 2.0]), (3, [-1.0, 5.0, 5.0]),
                   (4, [1.0, 1.0, 2.0, 2.0]), (4, [0.0, 0.0, 0.0, 1.0]),
                   (4, [1.0, 1.0 + 1e-12, 1.0 - 1e-12, 1.0]), (4, [-3.0, -3.0, -3.0, 3.0])):
        Q = _orthogonal(rng, n)
        A = (Q * np.asarray(lam)) @ Q.T
        out.append(0.5 * (A + A.T))
    return out


@pytest.mark.parametrize("A", _degenerate(), ids=lambda A: f"n{A.shape[0]}")
def test_eigh_repeated_eigenvalues(A: np.ndarray) -> None:
    lam, V = (np.asarray(a) for a in sl.eigh(jnp.asarray(A)))
    _check_eigh(A, lam, V)


def test_eigh_reads_the_lower_triangle_without_symmetrizing() -> None:
    A = np.array([[2.0, 99.0, -7.0], [1.0, 3.0, 42.0], [0.5, -1.0, 1.0]])
    lower = np.tril(A) + np.tril(A, -1).T
    lam = np.asarray(sl.eigvalsh(jnp.asarray(A), symmetrize_input=False))
    assert np.abs(lam - np.linalg.eigvalsh(lower)).max() <= _jacobi_bound(3) * np.linalg.norm(
        lower, 2)
    both = 0.5 * (A + A.T)
    lam = np.asarray(sl.eigvalsh(jnp.asarray(A)))
    assert np.abs(lam - np.linalg.eigvalsh(both)).max() <= _jacobi_bound(3) * np.linalg.norm(
        both, 2)


# ---------------------------------------------------------------------------- vmap
@pytest.mark.parametrize("n", SIZES)
def test_batches_under_vmap_and_jit(n: int) -> None:
    rng = np.random.default_rng(100 + n)
    conds = 10.0 ** rng.uniform(0, 12, 64)
    S = np.stack([spd(rng, n, c) for c in conds])
    M = np.stack([general(rng, n, c) for c in conds])
    B = rng.standard_normal((64, n, 2))
    L = np.asarray(jax.jit(jax.vmap(sl.cholesky))(S))
    Si = np.asarray(jax.jit(jax.vmap(sl.spd_inverse))(S))
    lam, V = (np.asarray(a) for a in jax.jit(jax.vmap(sl.eigh))(S))
    x = np.asarray(jax.jit(jax.vmap(sl.solve))(M, B))
    d = np.asarray(jax.jit(jax.vmap(sl.det))(M))
    for b in range(64):
        k = np.linalg.cond(S[b])
        assert (np.linalg.norm(L[b] - np.linalg.cholesky(S[b]))
                <= 2 * n * gamma(n + 1) * k * np.linalg.norm(L[b], 2))
        assert (np.linalg.norm(Si[b] - np.linalg.inv(S[b]))
                <= 2 * n * gamma(3 * n + 1) * k * np.linalg.norm(np.linalg.inv(S[b]), 2))
        _check_eigh(S[b], lam[b], V[b])
        exact = np.linalg.solve(M[b], B[b])
        assert np.linalg.norm(x[b] - exact) <= _lu_bound(n, M[b]) * np.linalg.norm(exact)
        assert abs(d[b] / np.linalg.det(M[b]) - 1.0) <= _lu_bound(n, M[b])


# ---------------------------------------------------------------------------- PSD factor
def _semidefinite(rng: np.random.Generator, n: int, cond: float) -> np.ndarray:
    """A PSD matrix of rank n − 1 (one eigenvalue exactly 0 before rounding)."""
    Q = _orthogonal(rng, n)
    lam = np.logspace(0.0, np.log10(cond), n) * 10.0 ** rng.uniform(-3, 3)
    lam[0] = 0.0
    A = (Q * lam) @ Q.T
    return 0.5 * (A + A.T)


@pytest.mark.parametrize("n,cond,A", cases(spd))
def test_psd_factor_of_a_positive_definite_matrix_is_its_cholesky_factor(
        n: int, cond: float, A: np.ndarray) -> None:
    """Positive definite: the Cholesky path, lower triangular, ``L Lᵀ = A`` to Cholesky's
    backward error bound (Higham 2002, Thm 10.3: ``|ΔA| ≤ γ_{n+1} |L||Lᵀ|``, twice for two
    results), and the numpy reference's factor to the factor's perturbation bound
    (``‖ΔL‖ ≲ κ(A) ‖ΔA‖ / ‖A‖ · ‖L‖``, Sun 1991)."""
    from fir_gym.estimators._kalman_linalg import psd_factor

    L = np.asarray(jax.jit(sl.psd_factor)(jnp.asarray(A)))
    np.testing.assert_array_equal(L, np.tril(L))
    assert (np.abs(L @ L.T - A) <= 2 * gamma(n + 1) * np.abs(L) @ np.abs(L.T)).all()
    theirs = psd_factor(A[None])[0]
    assert np.abs(L - theirs).max() <= 2 * cond * gamma(n + 1) * np.abs(theirs).max()


@pytest.mark.parametrize("n,cond,A", [c for c in cases(_semidefinite) if c[0] > 1])
def test_psd_factor_of_a_singular_psd_matrix_rebuilds_it(n: int, cond: float,
                                                         A: np.ndarray) -> None:
    """Positive semidefinite of rank n − 1, which rounding leaves a little either side of
    the cone: whichever path the pivot test takes (a zero pivot dropped, or the nearest
    PSD matrix), ``L Lᵀ`` is ``A`` and the numpy reference's ``L Lᵀ`` to both paths'
    backward error (``n ε ‖A‖`` for the eigen-decomposition, the pivots dropped at ``4 n ε
    |a_jj|``), with a factor of 2 for two results."""
    from fir_gym.estimators._kalman_linalg import psd_factor

    L = np.asarray(jax.jit(sl.psd_factor)(jnp.asarray(A)))
    theirs = psd_factor(A[None])[0]
    tol = 2 * 8 * n * EPS * np.abs(A).max()
    assert np.abs(L @ L.T - A).max() <= tol
    assert np.abs(L @ L.T - theirs @ theirs.T).max() <= tol


@pytest.mark.parametrize("n,cond,A", [c for c in cases(symmetric)
                                      if np.linalg.eigvalsh(c[2]).min() < 0])
def test_psd_factor_of_an_indefinite_matrix_is_its_nearest_psd_matrix(
        n: int, cond: float, A: np.ndarray) -> None:
    """Indefinite beyond round-off: ``L Lᵀ`` is the nearest PSD matrix in the Frobenius norm
    (Higham 1988: the negative eigenvalues of LAPACK's decomposition set to zero), to the
    eigen-solvers' accuracy (``n ε ‖A‖`` each)."""
    lam, V = np.linalg.eigh(A)
    L = np.asarray(jax.jit(sl.psd_factor)(jnp.asarray(A)))
    nearest = (V * np.maximum(lam, 0.0)) @ V.T
    norm = np.abs(lam).max()
    assert np.abs(L @ L.T - nearest).max() <= 2 * 8 * n * EPS * norm


def test_psd_factor_is_nan_where_not_finite_and_gram_is_exactly_symmetric() -> None:
    A = np.eye(3)
    A[1, 2] = A[2, 1] = np.nan
    assert np.isnan(np.asarray(sl.psd_factor(jnp.asarray(A)))).all()
    rng = np.random.default_rng(3)
    M, N = rng.normal(size=(4, 4)) * 1e3, rng.normal(size=(4, 2))
    G = np.asarray(jax.jit(sl.gram)(jnp.asarray(M), jnp.asarray(N)))
    np.testing.assert_array_equal(G, G.T)
    np.testing.assert_allclose(G, M @ M.T + N @ N.T, rtol=1e-13, atol=1e-9)


def test_no_lapack_in_the_functions_themselves() -> None:
    x = jnp.eye(4)
    for f in (sl.cholesky, sl.spd_inverse, sl.inv, sl.det, sl.eigh, sl.eigvalsh, sl.expm,
              sl.psd_factor, sl.gram,
              lambda A: sl.solve(A, A[0]), lambda A: sl.cho_solve(A, A)):
        assert "lapack" not in jax.jit(jax.vmap(f)).lower(jnp.stack([x] * 8)).as_text()


# ---------------------------------------------------------------------------- expm
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("scale", [1e-3, 0.3, 1.0, 4.0, 20.0])
def test_expm_of_a_symmetric_matrix_is_its_closed_form(n: int, scale: float) -> None:
    """``e^{V D Vᵀ} = V e^D Vᵀ`` for orthogonal ``V``: the closed form, exact up to the
    rounding of ``V`` and ``e^D``. Both sides are computed in ``float64``; a backward-stable
    result differs by ``O(n ε ‖M‖ e^{λ_max})`` (Moler & Van Loan 2003, §3: the squarings'
    error grows with ``‖M‖``), bounded here by ``γ_{8n} (1 + ‖M‖) 2^s`` relative to the
    largest entry, ``s`` the squarings."""
    rng = np.random.default_rng(n + int(scale * 1000))
    for _ in range(20):
        V = _orthogonal(rng, n)
        d = scale * rng.standard_normal(n)
        M = (V * d) @ V.T
        exact = (V * np.exp(d)) @ V.T
        got = np.asarray(jax.jit(sl.expm)(jnp.asarray(M)))
        squarings = max(0.0, np.ceil(np.log2(np.abs(M).sum(axis=1).max() / sl.EXPM_NORM)))
        bound = gamma(8 * n) * (1 + np.abs(d).max()) * 2.0 ** squarings
        assert np.abs(got - exact).max() <= bound * np.abs(exact).max()


@pytest.mark.parametrize("n", SIZES)
def test_expm_matches_scipy_and_its_properties(n: int) -> None:
    """Against :func:`scipy.linalg.expm` (Al-Mohy & Higham's Padé method) on general
    matrices of norm up to 1, where both are accurate to a few ulps (the bound: twice one
    method's ``γ_{8n}``, relative to the largest entry), and two properties that hold for
    any ``M``: ``e^M e^{−M} = I`` and ``e^{M} = (e^{M/2})²``."""
    rng = np.random.default_rng(100 + n)
    f = jax.jit(sl.expm)
    for _ in range(50):
        M = rng.standard_normal((n, n))
        M *= rng.uniform(0.0, 1.0) / np.abs(M).sum(axis=1).max()
        got, ref = np.asarray(f(jnp.asarray(M))), scipy.linalg.expm(M)
        assert np.abs(got - ref).max() <= 2 * gamma(8 * n) * np.abs(ref).max()
        back = got @ np.asarray(f(jnp.asarray(-M)))
        assert np.abs(back - np.eye(n)).max() <= 4 * gamma(8 * n)
        half = np.asarray(f(jnp.asarray(M / 2)))
        assert np.abs(half @ half - got).max() <= 4 * gamma(8 * n) * np.abs(got).max()


def test_expm_of_a_rotation_generator_and_of_nan() -> None:
    """``exp([[0, −θ], [θ, 0]])`` is the rotation by ``θ``, within ``γ_16 (1 + θ) 2¹²`` (θ =
    1000 takes 11 squarings); a non-finite matrix gives NaN."""
    for theta in (0.1, 2.0, 1000.0):
        R = np.asarray(sl.expm(jnp.array([[0.0, -theta], [theta, 0.0]])))
        c, s_ = np.cos(theta), np.sin(theta)
        assert np.abs(R - np.array([[c, -s_], [s_, c]])).max() <= gamma(16) * (1 + theta) * 4096
    assert np.all(np.isnan(np.asarray(sl.expm(jnp.array([[np.inf, 0.0], [0.0, 1.0]])))))


# ---------------------------------------------------------------------------- acceptance
LAPACK = re.compile(r"lapack_\w+")
PAIRS = [(env_id, kind) for env_id, plant in PLANTS.items() for kind in plant.kinds]


def test_the_check_sees_a_lapack_call() -> None:
    """The control: a vmapped ``eigh`` does lower to a LAPACK custom call."""
    text = jax.jit(jax.vmap(jnp.linalg.eigh)).lower(jnp.zeros((8, 3, 3))).as_text()
    assert LAPACK.search(text)


@pytest.mark.parametrize("env_id,kind", PAIRS)
def test_no_lapack_custom_call_in_a_vmapped_reset_and_step(env_id: str, kind: str) -> None:
    """Every plant × kind's reset and step, vmapped over 8 environments, lowers without a
    LAPACK custom call: the batched LAPACK kernels can deadlock XLA's CPU thread pool
    (docs/jax.md, "A known hang")."""
    env, params = make(env_id, kind)
    space = env.action_space(params)
    keys = jax.random.split(jax.random.key(0), 8)

    def reset_and_step(keys: jax.Array):
        _, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
        action = jnp.zeros((8, *space.shape), dtype=space.dtype)
        return jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, state, action, params)

    text = jax.jit(reset_and_step).lower(keys).as_text()
    assert not LAPACK.findall(text), sorted(set(LAPACK.findall(text)))
