"""Dense linear algebra for small matrices of static size, in plain ``jax.numpy``.

The estimators and plants of :mod:`fir_gym.jax` factor, invert and diagonalise matrices of
at most a few rows (``n ≤ 4`` states, ``≤ 4`` measurement channels) inside every step. The
functions here do it with the textbook algorithms written out over the static size: Python
loops over ``range(n)`` are unrolled at trace time into scalar arithmetic and ``jnp.where``
selections, with no call into ``jnp.linalg``, ``jax.scipy.linalg`` or ``lax.linalg``.

**Why.** On a CPU, jaxlib's LAPACK kernels (the ``lapack_*_ffi`` custom calls behind
Cholesky, ``eigh``, LU, QR) split a *batched* call (one under ``vmap``) into chunks, run the
chunks on XLA's intra-op thread pool and block until they finish. When the executor runs two
such calls at once on a pool with two workers, each worker waits for chunks that no free
worker can run, and the program hangs for ever (docs/jax.md, "A hang, found and
avoided"). Without the custom calls there is nothing to wait for; at these sizes the
unrolled arithmetic is also cheaper than a kernel call per step, and exact to round-off.

Each function is for one matrix (``vmap`` it for a batch) of ``float64`` entries; sizes are
read from the shapes (static), never from the data. Failures are NaN, as in ``jnp.linalg``:

* :func:`cholesky` — Cholesky–Banachiewicz (Golub & Van Loan 2013, Alg. 4.2.1), the whole
  factor NaN where ``A`` is not positive definite (:func:`jax.numpy.linalg.cholesky`).
* :func:`psd_factor` — the semidefinite Cholesky factor (Higham 2002, §10.3), the nearest
  PSD matrix's factor where ``P`` is indefinite beyond round-off; :func:`gram` — ``Σ M Mᵀ``,
  exactly symmetric (the numpy references' factored Joseph update,
  :func:`fir_gym.jax.kalman.factored_joseph`).
* :func:`solve_lower`, :func:`solve_upper` — forward and back substitution (GvL Alg. 3.1.1,
  3.1.2); :func:`cho_solve` — both with a Cholesky factor (``A⁻¹ B`` for ``A = L Lᵀ``);
  :func:`spd_inverse` — ``A⁻¹`` through them.
* :func:`lu` — Gaussian elimination with partial pivoting (GvL Alg. 3.4.1; the pivot is the
  first entry of largest modulus, LAPACK's ``idamax`` rule), pivots chosen with
  ``jnp.where``; :func:`solve`, :func:`inv`, :func:`det` from it
  (:func:`jax.numpy.linalg.solve`, ``inv``, ``det``: inf/NaN where ``M`` is singular).
* :func:`eigh` — the cyclic Jacobi method (GvL Alg. 8.5.3, the rotation of Alg. 8.5.1) with
  a fixed number of sweeps (:data:`JACOBI_SWEEPS`: enough for ``float64`` convergence at
  ``n ≤ 4``, measured), eigenvalues ascending and
  the eigenvectors as columns (:func:`jax.numpy.linalg.eigh`); :func:`eigvalsh`.
* :func:`expm` — the matrix exponential by scaling and squaring with a truncated Taylor
  series (Moler & Van Loan 2003, "Nineteen dubious ways", methods 1 and 3): ``M`` halved
  until its ∞-norm is at most :data:`EXPM_NORM`, :data:`EXPM_TERMS` terms, squared back
  (:func:`jax.scipy.linalg.expm`, which solves a Padé system with LAPACK).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

#: sweeps of the cyclic Jacobi method in :func:`eigh`, by size ``n``. Convergence is
#: quadratic once the off-diagonal is small. Measured (residual ``max|A V − V Λ| / max|A|``
#: over 15 000 symmetric matrices per size: random, graded ``10^±12``, rank one plus 1e-13,
#: repeated and 1e-15-clustered eigenvalues, condition numbers up to 1e12): one rotation is
#: exact at ``n = 2``; round-off (≤ 1e-15) after 4 sweeps at ``n = 3`` (3 leave 1e-13) and
#: after 5 at ``n = 4`` (4 leave up to 1e-6). One sweep of margin on top; a sweep past
#: convergence rotates by angles of order ε and changes nothing beyond round-off. Larger
#: sizes (not measured: outside this package's use) get 10.
JACOBI_SWEEPS: dict[int, int] = {1: 0, 2: 1, 3: 5, 4: 6}
#: :func:`expm`: the scaled matrix's ∞-norm bound and the Taylor terms. At ``‖A‖ ≤ 1/2`` the
#: remainder after the ``A¹⁸/18!`` term is below ``(1/2)¹⁹/19! · e^{1/2} < 1e-22``, far under
#: ``float64``'s unit round-off; squaring back then loses what it loses in any method.
EXPM_NORM, EXPM_TERMS = 0.5, 18


def _sqrt(x: jax.Array) -> jax.Array:
    """``√x``, kept a square root: XLA's simplifier rewrites ``y / √x`` as ``y · rsqrt(x)``,
    whose CPU kernel is not correctly rounded (1 ulp off in a quarter of the cases, measured),
    which LAPACK's ``y / √x`` is; the barrier keeps the division."""
    return jax.lax.optimization_barrier(jnp.sqrt(x))


def _entries(A: jax.Array) -> list[list[jax.Array]]:
    """The entries of a 2-D array as nested lists of scalars (rows of columns)."""
    return [[A[i, j] for j in range(A.shape[1])] for i in range(A.shape[0])]


def _matrix(a: list[list[jax.Array]]) -> jax.Array:
    return jnp.stack([jnp.stack(row) for row in a])


def _square(A: jax.Array, name: str = "A") -> int:
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"{name} must be a square matrix (n, n); got shape {A.shape} "
                         "(vmap the function for a batch)")
    return A.shape[0]


def _rows(B: jax.Array, n: int) -> tuple[list[jax.Array], bool]:
    """``B`` ``(n,)`` or ``(n, k)`` as a list of its ``n`` rows, and whether it was a vector."""
    if B.ndim not in (1, 2) or B.shape[0] != n:
        raise ValueError(f"B must have shape ({n},) or ({n}, k); got {B.shape}")
    return [B[i] for i in range(n)], B.ndim == 1


# ---------------------------------------------------------------------------- Cholesky
def cholesky(A: jax.Array) -> jax.Array:
    """The lower Cholesky factor ``L``, ``L Lᵀ = A``, of a symmetric ``A`` (its lower
    triangle is read), by Cholesky–Banachiewicz: ``l_jj = √(a_jj − Σ_{k<j} l_jk²)``, ``l_ij
    = (a_ij − Σ_{k<j} l_ik l_jk) / l_jj``. The whole factor is NaN where a pivot is not
    positive (``A`` not positive definite, or not finite), as
    :func:`jax.numpy.linalg.cholesky` returns it."""
    n = _square(A)
    a = _entries(A)
    L = [[jnp.zeros((), A.dtype)] * n for _ in range(n)]
    ok = jnp.asarray(True)
    for j in range(n):
        d = a[j][j]
        for k in range(j):
            d = d - L[j][k] * L[j][k]
        ok = ok & (d > 0.0)                            # NaN counts as not PD
        ljj = _sqrt(jnp.where(d > 0.0, d, 1.0))
        L[j][j] = ljj
        for i in range(j + 1, n):
            s = a[i][j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s / ljj
    return jnp.where(ok, _matrix(L), jnp.nan)


#: :func:`psd_factor`'s pivot tolerance per unit of ``n |P_jj|``: four units of round-off
#: (:data:`fir_gym.estimators._kalman_linalg._PIVOT_EPS`, the numpy reference's)
PIVOT_EPS = 4.0 * float(jnp.finfo(jnp.float64).eps)


def psd_factor(P: jax.Array) -> jax.Array:
    """A factor ``L``, ``L Lᵀ = P``, of a symmetric ``P`` that is positive semidefinite up
    to round-off — or, where it is not, of its nearest PSD matrix
    (:func:`fir_gym.estimators._kalman_linalg.psd_factor`, for one matrix).

    The semidefinite Cholesky factor (Higham, *Accuracy and Stability of Numerical
    Algorithms*, 2002, §10.3), lower triangle read: a pivot at or below ``4 n ε |P_jj|``
    is taken as zero, with its column. A pivot below ``−4 n ε |P_jj|`` (or NaN) means ``P``
    is indefinite beyond round-off: the factor is then ``V Λ₊^½`` of ``(P + Pᵀ)/2 = V Λ Vᵀ``
    (the Jacobi eigenpairs of :func:`eigh`, unsorted: ``L Lᵀ`` does not depend on their
    order) with the negative eigenvalues set to zero, the nearest PSD matrix in the
    Frobenius norm (Higham 1988); NaN where ``P`` is not finite. Both are computed and one
    is selected (shape-static; under ``vmap`` a branch would be computed anyway)."""
    n = _square(P, "P")
    a = _entries(P)
    zero = jnp.zeros((), P.dtype)
    L = [[zero] * n for _ in range(n)]
    indefinite = jnp.asarray(False)
    for j in range(n):
        tol = PIVOT_EPS * n * jnp.abs(a[j][j])
        d = a[j][j] - _dot(L[j][:j], L[j][:j]) if j else a[j][j]
        keep = d > tol
        indefinite = indefinite | ~(d >= -tol)         # NaN counts as indefinite
        ljj = _sqrt(jnp.where(keep, d, 1.0))
        L[j][j] = jnp.where(keep, ljj, zero)
        for i in range(j + 1, n):
            s = a[i][j] - _dot(L[i][:j], L[j][:j]) if j else a[i][j]
            L[i][j] = jnp.where(keep, s / ljj, zero)
    finite = jnp.all(jnp.isfinite(P))
    lam, V = _jacobi(jnp.where(finite, P, 0.0))
    nearest = jnp.where(finite, V * _sqrt(jnp.maximum(lam, 0.0))[None, :], jnp.nan)
    return jnp.where(indefinite, nearest, _matrix(L))


def _dot(u: list[jax.Array], v: list[jax.Array]) -> jax.Array:
    """``Σ u_k v_k`` in order: the inner product subtracted at once, as the numpy reference's
    ``einsum`` and matrix products form it."""
    total = u[0] * v[0]
    for uk, vk in zip(u[1:], v[1:], strict=True):
        total = total + uk * vk
    return total


def gram(*factors: jax.Array) -> jax.Array:
    """``Σ M Mᵀ`` over the factors ``M`` (``n × ·`` each), the upper triangle the lower one's
    mirror (:func:`fir_gym.estimators._kalman_linalg.gram`): exactly symmetric, and positive
    semidefinite up to the round-off of forming it. Each entry below the diagonal is one
    scalar placed twice: XLA's CPU matrix product rounds an entry and its mirror image
    differently (1 ulp apart, measured), and a loop fusion may recompute a value at each
    use, so a product mirrored afterwards is not symmetric to the bit."""
    n = factors[0].shape[0]
    rows = [_entries(M) for M in factors]
    g = [[jnp.zeros((), factors[0].dtype)] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            total = _dot(rows[0][i], rows[0][j])
            for m in rows[1:]:
                total = total + _dot(m[i], m[j])
            g[i][j] = g[j][i] = total
    return _matrix(g)


def solve_lower(L: jax.Array, B: jax.Array) -> jax.Array:
    """``L⁻¹ B`` for a lower-triangular ``L`` (only its lower triangle is read), ``B``
    ``(n,)`` or ``(n, k)``, by forward substitution."""
    n = _square(L, "L")
    rows, _ = _rows(B, n)
    x: list[jax.Array] = []
    for i in range(n):
        s = rows[i]
        for k in range(i):
            s = s - L[i, k] * x[k]
        x.append(s / L[i, i])
    return jnp.stack(x)


def solve_upper(U: jax.Array, B: jax.Array) -> jax.Array:
    """``U⁻¹ B`` for an upper-triangular ``U`` (only its upper triangle is read), ``B``
    ``(n,)`` or ``(n, k)``, by back substitution."""
    n = _square(U, "U")
    rows, _ = _rows(B, n)
    x: dict[int, jax.Array] = {}
    for i in reversed(range(n)):
        s = rows[i]
        for k in range(i + 1, n):
            s = s - U[i, k] * x[k]
        x[i] = s / U[i, i]
    return jnp.stack([x[i] for i in range(n)])


def cho_solve(L: jax.Array, B: jax.Array) -> jax.Array:
    """``A⁻¹ B`` for ``A = L Lᵀ`` (``L`` from :func:`cholesky`): ``L⁻ᵀ (L⁻¹ B)``, as
    :func:`jax.scipy.linalg.cho_solve` with ``(L, True)``."""
    return solve_upper(L.T, solve_lower(L, B))


def spd_inverse(S: jax.Array) -> jax.Array:
    """``S⁻¹`` of a symmetric ``S``, NaN where it is not positive definite — as
    :func:`fir_gym.estimators._kalman_linalg.spd_inverse` computes it: ``1/S`` for one
    channel, Cramer's rule with the test ``s₁₁ > 0, det > 0`` for two, Cholesky solves
    against ``I`` beyond."""
    m = S.shape[0]
    if m == 1:
        return jnp.where(S > 0.0, 1.0 / S, jnp.nan)
    if m == 2:
        a, b, d = S[0, 0], 0.5 * (S[0, 1] + S[1, 0]), S[1, 1]
        det = a * d - b * b
        det = jnp.where((a > 0.0) & (det > 0.0), det, jnp.nan)
        off = -b / det
        return jnp.array([[d / det, off], [off, a / det]])
    return cho_solve(cholesky(S), jnp.eye(m, dtype=S.dtype))


# ---------------------------------------------------------------------------- LU
def lu(M: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """``P M = L U`` by Gaussian elimination with partial pivoting: ``(LU, perm, sign)`` —
    ``L`` (unit lower, below the diagonal) and ``U`` packed in one matrix as LAPACK's
    ``getrf`` packs them, ``perm`` the row order (``M[perm] = L U``) and ``sign = det P``.
    At column ``k`` the pivot is the first entry of largest modulus on or below the
    diagonal; the row swap is a ``jnp.where`` selection. A zero pivot (singular ``M``: the
    column is zero on and below the diagonal) eliminates nothing and stays in ``U``, as in
    LAPACK's ``getf2``; :func:`det` is then 0 and the solves divide by it."""
    n = _square(M, "M")
    a = _entries(M)
    perm = [jnp.asarray(i) for i in range(n)]
    sign = jnp.asarray(1.0, M.dtype)
    for k in range(n):
        p = jnp.asarray(k)
        best = jnp.abs(a[k][k])
        for i in range(k + 1, n):
            bigger = jnp.abs(a[i][k]) > best
            p = jnp.where(bigger, i, p)
            best = jnp.where(bigger, jnp.abs(a[i][k]), best)
        if k + 1 < n:                                  # swap rows k and p
            new_k = a[k]
            new_perm_k = perm[k]
            for i in range(k + 1, n):
                here = p == i
                new_k = [jnp.where(here, a[i][j], new_k[j]) for j in range(n)]
                new_perm_k = jnp.where(here, perm[i], new_perm_k)
                a[i] = [jnp.where(here, a[k][j], a[i][j]) for j in range(n)]
                perm[i] = jnp.where(here, perm[k], perm[i])
            a[k], perm[k] = new_k, new_perm_k
            sign = jnp.where(p != k, -sign, sign)
        pivot = a[k][k]                                # 0: the column is 0 below too,
        safe = jnp.where(pivot == 0.0, 1.0, pivot)     # nothing to eliminate (getf2)
        for i in range(k + 1, n):                      # eliminate below the pivot
            m = a[i][k] / safe
            a[i] = a[i][:k] + [m] + [a[i][j] - m * a[k][j] for j in range(k + 1, n)]
    return _matrix(a), jnp.stack(perm), sign


def _lu_solve(LU: jax.Array, perm: jax.Array, B: jax.Array) -> jax.Array:
    n = LU.shape[0]
    rows, _ = _rows(B, n)
    permuted = []
    for i in range(n):                                 # rows of P B
        r = rows[0]
        for j in range(1, n):
            r = jnp.where(perm[i] == j, rows[j], r)
        permuted.append(r)
    y: list[jax.Array] = []
    for i in range(n):                                 # unit lower: L y = P B
        s = permuted[i]
        for k in range(i):
            s = s - LU[i, k] * y[k]
        y.append(s)
    return solve_upper(LU, jnp.stack(y))


def solve(M: jax.Array, B: jax.Array) -> jax.Array:
    """``M⁻¹ B`` for a general square ``M``, ``B`` ``(n,)`` or ``(n, k)``: :func:`lu`, then
    forward and back substitution (LAPACK's ``getrs`` order); inf/NaN where ``M`` is
    singular (:func:`jax.numpy.linalg.solve`)."""
    LU, perm, _ = lu(M)
    return _lu_solve(LU, perm, B)


def inv(M: jax.Array) -> jax.Array:
    """``M⁻¹`` of a general square ``M`` (:func:`solve` against ``I``); inf/NaN where ``M``
    is singular (:func:`jax.numpy.linalg.inv`)."""
    return solve(M, jnp.eye(M.shape[0], dtype=M.dtype))


def det(M: jax.Array) -> jax.Array:
    """``det M`` as ``det P · Π u_kk`` of :func:`lu` (:func:`jax.numpy.linalg.det`); 0 (or
    NaN) where ``M`` is singular."""
    LU, _, sign = lu(M)
    d = sign
    for k in range(M.shape[0]):
        d = d * LU[k, k]
    return d


# ---------------------------------------------------------------------------- eigh
def _jacobi_rotation(app: jax.Array, apq: jax.Array, aqq: jax.Array
                     ) -> tuple[jax.Array, jax.Array, jax.Array]:
    """``(c, s, t)`` of the symmetric Schur decomposition of ``[[app, apq], [apq, aqq]]``
    (GvL Alg. 8.5.1): ``t = tan θ`` the smaller root of ``t² + 2τ t − 1 = 0``, ``τ = (aqq −
    app) / (2 apq)``; ``(1, 0, 0)`` where ``apq = 0``."""
    zero = apq == 0.0
    tau = (aqq - app) / (2.0 * jnp.where(zero, 1.0, apq))
    # 1/(|τ| + √(1 + τ²)) without overflowing τ² (τ → ∞: t → 1/(2τ))
    big = jnp.abs(tau) > 1e150
    root = jnp.where(big, jnp.abs(tau), _sqrt(1.0 + tau * tau))
    t = jnp.where(tau >= 0.0, 1.0, -1.0) / (jnp.abs(tau) + root)
    t = jnp.where(zero, 0.0, t)
    c = 1.0 / _sqrt(1.0 + t * t)
    return c, t * c, t


def _jacobi(A: jax.Array, *, symmetrize_input: bool = True) -> tuple[jax.Array, jax.Array]:
    """The eigenpairs of a symmetric ``A``, in no particular order (:func:`eigh` sorts them;
    :func:`psd_factor` needs no order, and a sort is an expensive operation in an XLA CPU
    program).

    The cyclic Jacobi method: :data:`JACOBI_SWEEPS` sweeps over the pairs ``p < q`` in row
    order, each rotation ``A ← Jᵀ A J`` zeroing ``a_pq`` and accumulating ``V ← V J``;
    eigenvalues are the final diagonal (one rotation is the closed form at ``n = 2``;
    ``n = 1`` is the identity). One sweep is unrolled, the sweeps are a
    :func:`jax.lax.fori_loop`: unrolled, the six sweeps of a 4 × 4 matrix were 181 kB of
    the 194 kB of :func:`psd_factor`'s program, and the four factorisations of an EKF step
    with auto-reset most of PendulumSlider-v0's step; looped, its training program compiles
    in less than half the time and steps faster (docs/jax.md, "Compilation")."""
    n = _square(A)
    As = 0.5 * (A + A.T) if symmetrize_input else jnp.tril(A) + jnp.tril(A, -1).T
    one, zero = jnp.ones((), A.dtype), jnp.zeros((), A.dtype)

    def sweep(_: Any, carry: tuple[list[list[jax.Array]], list[list[jax.Array]]]
              ) -> tuple[list[list[jax.Array]], list[list[jax.Array]]]:
        a, v = [list(row) for row in carry[0]], [list(row) for row in carry[1]]
        for p in range(n - 1):
            for q in range(p + 1, n):
                c, s, t = _jacobi_rotation(a[p][p], a[p][q], a[q][q])
                apq = a[p][q]
                for k in range(n):                     # the other rows/columns
                    if k in (p, q):
                        continue
                    akp, akq = a[k][p], a[k][q]
                    a[k][p] = a[p][k] = c * akp - s * akq
                    a[k][q] = a[q][k] = s * akp + c * akq
                a[p][p] = a[p][p] - t * apq
                a[q][q] = a[q][q] + t * apq
                a[p][q] = a[q][p] = zero
                for k in range(n):
                    vkp, vkq = v[k][p], v[k][q]
                    v[k][p] = c * vkp - s * vkq
                    v[k][q] = s * vkp + c * vkq
        return a, v

    identity = [[one if i == j else zero for j in range(n)] for i in range(n)]
    a, v = jax.lax.fori_loop(0, JACOBI_SWEEPS.get(n, 10), sweep, (_entries(As), identity))
    return jnp.stack([a[i][i] for i in range(n)]), _matrix(v)


def eigh(A: jax.Array, *, symmetrize_input: bool = True) -> tuple[jax.Array, jax.Array]:
    """Eigenvalues (ascending) and eigenvectors (columns, orthonormal) of a symmetric ``A``:
    ``A V = V diag(λ)`` (:func:`jax.numpy.linalg.eigh`). ``symmetrize_input`` takes ``(A +
    Aᵀ)/2``, else the lower triangle is read (LAPACK's ``UPLO='L'``): :func:`_jacobi`'s
    eigenpairs, sorted."""
    lam, V = _jacobi(A, symmetrize_input=symmetrize_input)
    order = jnp.argsort(lam)
    return lam[order], V[:, order]


def eigvalsh(A: jax.Array, *, symmetrize_input: bool = True) -> jax.Array:
    """The eigenvalues (ascending) of a symmetric ``A`` (:func:`eigh`'s first output)."""
    return eigh(A, symmetrize_input=symmetrize_input)[0]


# ---------------------------------------------------------------------------- expm
def expm(M: jax.Array) -> jax.Array:
    """``e^M`` of a square ``M`` (:func:`jax.scipy.linalg.expm`, without its LAPACK solve).

    Scaling and squaring (Moler & Van Loan 2003, methods 1 and 3): ``s = ⌈log₂(‖M‖∞ /
    EXPM_NORM)⌉₊`` halvings bring ``A = M / 2ˢ`` to ``‖A‖∞ ≤`` :data:`EXPM_NORM`; the Taylor
    series ``Σₖ Aᵏ/k!`` to :data:`EXPM_TERMS` terms, summed by Horner's rule, gives ``e^A`` to
    round-off; ``s`` squarings give ``e^M = (e^A)^{2ˢ}`` (a :func:`jax.lax.fori_loop` of
    data-dependent length: ``jit``- and ``vmap``-able). A non-finite ``M`` gives NaN."""
    n = _square(M, "M")
    norm = jnp.max(jnp.sum(jnp.abs(M), axis=1))
    finite = jnp.isfinite(norm)
    halvings = jnp.where(finite & (norm > EXPM_NORM),
                         jnp.ceil(jnp.log2(jnp.where(finite, norm, 1.0) / EXPM_NORM)), 0.0)
    A = M / jnp.exp2(halvings)
    eye = jnp.eye(n, dtype=M.dtype)
    E = eye
    for k in range(EXPM_TERMS, 0, -1):           # I + A/1 (I + A/2 (I + ... (I + A/K)))
        E = eye + (A @ E) / k
    E = jax.lax.fori_loop(0, halvings.astype(jnp.int32), lambda _, X: X @ X, E)
    return jnp.where(finite, E, jnp.nan)
