"""Straight-line float kernels for one small system: the single-system fast path.

A filter step on one system with ``n ≲ 4`` states is a few hundred flops; numpy
spends about a microsecond on each call whatever the size, so the batched
kernels cost tens of microseconds there. For one system the filters instead run
these kernels: Python functions generated once per shape (and cached), with every
matrix entry in a local variable and every product written out, on plain floats.
They compute the *same formulas in the same order* as the batched kernels of
:mod:`~._kalman_linalg`, :mod:`~.kalman` and :mod:`~.unscented` (Joseph form,
symmetrisation, ``S⁻¹`` by the same closed form or Cholesky factor), so results
agree with the general path to round-off (BLAS may fuse multiply-adds); the
tests check 1e-12. Constant matrices may be baked in as literals, in which case
products with an exact ``0.0`` or ``1.0`` are folded (exact for finite values).

A kernel returns ``None`` where the general path would produce NaN (a
non-positive-definite ``S``, a failed Cholesky factor): the caller then runs the
general path, which handles those cases.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: largest state / measurement size that gets a generated kernel
MAX_SIZE = 4

Entry = Any          # a variable name (str) or a constant (float)
Matrix = list[list[Entry]]


class _Code:
    """A function body under construction: named temporaries and folded constants."""

    def __init__(self, name: str, args: Sequence[str]) -> None:
        self.name, self.args, self.lines, self.count = name, list(args), [], 0

    def let(self, expr: Entry) -> Entry:
        if not isinstance(expr, str) or expr.isidentifier():
            return expr
        var = f"t{self.count}"
        self.count += 1
        self.lines.append(f"{var} = {expr}")
        return var

    def line(self, text: str) -> None:
        self.lines.append(text)

    def vec(self, arg: str, n: int) -> list[Entry]:
        names = [f"{arg}{i}" for i in range(n)]
        self.lines.append(f"{', '.join(names)}, = {arg}")
        return names

    def mat(self, arg: str, r: int, c: int) -> Matrix:
        flat = self.vec(arg, r * c)
        return [flat[i * c:(i + 1) * c] for i in range(r)]

    def compile(self, consts: dict[str, Any] | None = None) -> Callable[..., Any]:
        body = "\n".join("    " + ln for ln in self.lines)
        src = f"def {self.name}({', '.join(self.args)}):\n{body}\n"
        scope: dict[str, Any] = {"_sqrt": __import__("math").sqrt, **(consts or {})}
        exec(compile(src, f"<fir_gym small kernel {self.name}>", "exec"), scope)
        fn = scope[self.name]
        fn.source = src
        return fn


def same_hooks(flt: Any, cls: type) -> bool:
    """Whether ``flt`` steps as ``cls`` does: a subclass that overrides a step hook gets no
    fast path (the fast path computes ``cls``'s step, which would bypass the override)."""
    hooks = ("_update", "_predict_update", "_accept", "_correct", "_draw")
    return all(getattr(type(flt), h, None) is getattr(cls, h, None) for h in hooks)


def const(M: Any) -> Matrix:
    """A numpy matrix (or vector) as constant entries."""
    a = np.asarray(M, dtype=np.float64)
    return a.tolist() if a.ndim == 2 else [[v] for v in a.tolist()]


# ---------------------------------------------------------------------------- expressions
def _lit(v: float) -> str:
    return repr(float(v)) if v >= 0 else f"({float(v)!r})"


def _term(a: Entry, b: Entry) -> Entry | None:
    """``a*b`` with exact folding of constants 0 and 1; None for an exact zero."""
    if isinstance(a, float) and isinstance(b, float):
        return a * b if a * b != 0.0 else None
    for p, q in ((a, b), (b, a)):
        if isinstance(p, float):
            if p == 0.0:
                return None
            if p == 1.0:
                return q
            if p == -1.0:
                return f"(-{q})"
            return f"{_lit(p)}*{q}"
    return f"{a}*{b}"


def _sum(terms: Sequence[Entry | None]) -> Entry:
    """Left-to-right sum (``+`` of the non-zero terms); 0.0 when none."""
    parts = [t for t in terms if t is not None]
    if not parts:
        return 0.0
    if all(isinstance(t, float) for t in parts):
        s = 0.0
        for t in parts:
            s += t
        return s
    out = [p if isinstance(p, str) else _lit(p) for p in parts]
    return " + ".join(out) if len(out) > 1 else out[0]


def _add(a: Entry, b: Entry, sign: str = "+") -> Entry:
    if isinstance(b, float) and b == 0.0:
        return a
    if isinstance(a, float) and isinstance(b, float):
        return a + b if sign == "+" else a - b
    if isinstance(a, float) and a == 0.0 and sign == "+":
        return b
    sa = a if isinstance(a, str) else _lit(a)
    sb = b if isinstance(b, str) else _lit(b)
    return f"{sa} {sign} ({sb})" if sign == "-" else f"{sa} + {sb}"


def matmul(c: _Code, A: Matrix, B: Matrix) -> Matrix:
    """``A B`` entry by entry (sum over the inner index in order)."""
    return [[c.let(_sum([_term(A[i][k], B[k][j]) for k in range(len(B))]))
             for j in range(len(B[0]))] for i in range(len(A))]


def transpose(A: Matrix) -> Matrix:
    return [list(r) for r in zip(*A, strict=True)]


def madd(c: _Code, A: Matrix, B: Matrix, sign: str = "+") -> Matrix:
    return [[c.let(_add(a, b, sign)) for a, b in zip(ra, rb, strict=True)]
            for ra, rb in zip(A, B, strict=True)]


def symmetrize(c: _Code, A: Matrix) -> Matrix:
    """``(A + Aᵀ) * 0.5`` as the batched kernel computes it (diagonal unchanged)."""
    n = len(A)
    out = [[A[i][i] if i == j else None for j in range(n)] for i in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            v = c.let(f"({_add(A[i][j], A[j][i])}) * 0.5")
            out[i][j] = out[j][i] = v
    return out  # type: ignore[return-value]


def flat(A: Matrix) -> list[Entry]:
    return [v for row in A for v in row]


def spd_inverse(c: _Code, S: Matrix) -> Matrix:
    """``S⁻¹`` as :func:`~._kalman_linalg.spd_inverse`; ``return None`` where it gives NaN."""
    m = len(S)
    if m == 1:
        c.line(f"if not {S[0][0]} > 0.0: return None")
        return [[c.let(f"1.0 / {S[0][0]}")]]
    if m == 2:
        a, d = S[0][0], S[1][1]
        b = c.let(f"0.5 * ({S[0][1]} + {S[1][0]})")
        det = c.let(f"{a} * {d} - {b} * {b}")
        c.line(f"if not ({a} > 0.0 and {det} > 0.0): return None")
        w01 = c.let(f"-{b} / {det}")
        return [[c.let(f"{d} / {det}"), w01], [w01, c.let(f"{a} / {det}")]]
    L = cholesky(c, S)
    eye = [[1.0 if i == j else 0.0 for j in range(m)] for i in range(m)]
    return cho_solve(c, L, eye)


def cholesky(c: _Code, S: Matrix) -> Matrix:
    """Lower factor, column by column as :func:`~._kalman_linalg.cholesky` (reads the lower
    triangle); ``return None`` on a non-positive pivot."""
    m = len(S)
    L: Matrix = [[0.0] * m for _ in range(m)]
    for j in range(m):
        d = S[j][j] if not j else c.let(
            f"{S[j][j]} - ({_sum([_term(L[j][k], L[j][k]) for k in range(j)])})")
        c.line(f"if not {d} > 0.0: return None")
        L[j][j] = c.let(f"_sqrt({d})")
        for i in range(j + 1, m):
            col = S[i][j] if not j else c.let(
                f"{S[i][j]} - ({_sum([_term(L[i][k], L[j][k]) for k in range(j)])})")
            L[i][j] = c.let(f"{col} / {L[j][j]}")
    return L


def cho_solve(c: _Code, L: Matrix, Y: Matrix) -> Matrix:
    """``(L Lᵀ)⁻¹ Y`` by forward and backward substitution, as the batched kernel."""
    m, k = len(L), len(Y[0])
    Z: Matrix = [[0.0] * k for _ in range(m)]
    for i in range(m):
        for col in range(k):
            acc = Y[i][col] if not i else _add(
                Y[i][col], _sum([_term(L[i][j], Z[j][col]) for j in range(i)]), "-")
            Z[i][col] = c.let(f"({acc if isinstance(acc, str) else _lit(acc)}) / {L[i][i]}")
    X: Matrix = [[0.0] * k for _ in range(m)]
    for i in range(m - 1, -1, -1):
        for col in range(k):
            acc = Z[i][col] if i == m - 1 else _add(
                Z[i][col], _sum([_term(L[j][i], X[j][col]) for j in range(i + 1, m)]), "-")
            X[i][col] = c.let(f"({acc if isinstance(acc, str) else _lit(acc)}) / {L[i][i]}")
    return X


# ---------------------------------------------------------------------------- KF kernels
def _joseph(c: _Code, x: list[Entry], P: Matrix, e: list[Entry], H: Matrix, R: Matrix
            ) -> tuple[list[Entry], Matrix, Entry, Matrix, Matrix]:
    """:func:`~.kalman.gain_kernel` and :func:`~.kalman.correct` on entries."""
    n, m = len(P), len(H)
    PHt = matmul(c, P, transpose(H))                     # P Hᵀ
    S = madd(c, matmul(c, transpose(PHt), transpose(H)), R)   # (P Hᵀ)ᵀ Hᵀ + R
    W = spd_inverse(c, S)
    K = matmul(c, PHt, W)
    KH = matmul(c, K, H)
    IKH = [[c.let(_add(1.0 if i == j else 0.0, KH[i][j], "-")) for j in range(n)]
           for i in range(n)]
    KR = matmul(c, K, R)
    Pn = madd(c, matmul(c, matmul(c, IKH, P), transpose(IKH)), matmul(c, KR, transpose(K)))
    Pn = symmetrize(c, Pn)
    Ke = [c.let(_sum([_term(K[i][j], e[j]) for j in range(m)])) for i in range(n)]
    xn = [c.let(_add(x[i], Ke[i])) for i in range(n)]
    We = [c.let(_sum([_term(e[j], W[j][i]) for j in range(m)])) for i in range(m)]
    nis = c.let(_sum([_term(We[i], e[i]) for i in range(m)]))
    return xn, Pn, nis, K, W


def _predict_cov(c: _Code, P: Matrix, F: Matrix, Q: Matrix) -> Matrix:
    """:func:`~.kalman.predict_covariance`: ``(F (P Fᵀ)ᵀ… )`` = F P Fᵀ + Q, symmetrised."""
    FP = transpose(matmul(c, P, transpose(F)))          # rmul(P, Fᵀ).mT
    return symmetrize(c, madd(c, matmul(c, FP, transpose(F)), Q))


@functools.lru_cache(maxsize=64)
def ekf_kernel(n: int, m: int) -> Callable[..., Any]:
    """``(x, P, F, Q, hx, y, H, R) -> (x⁺, P⁺, nis)`` (flat tuples) or None.

    ``x`` is the predicted mean ``f(x, u)``; ``P⁻ = F P Fᵀ + Q``; then the Joseph update
    with the innovation ``y − hx``. ``F is None`` skips the prediction (first step).
    """
    c = _Code("ekf_step", ["x", "P", "F", "Q", "hx", "y", "H", "R"])
    x = c.vec("x", n)
    P = c.mat("P", n, n)
    c.line("if F is not None:")
    inner = _Code("", [])
    inner.count = 100000                                 # its own temporaries
    Fm, Qm = inner.mat("F", n, n), inner.mat("Q", n, n)
    Pp = _predict_cov(inner, P, Fm, Qm)
    for ln in inner.lines:
        c.line("    " + ln)
    for i in range(n):
        c.line("    " + ", ".join(f"P{i * n + j}" for j in range(n)) + ", = "
               + ", ".join(str(v) for v in Pp[i]) + ",")
    hx, y = c.vec("hx", m), c.vec("y", m)
    e = [c.let(f"{yi} - {hi}") for yi, hi in zip(y, hx, strict=True)]
    xn, Pn, nis, _, _ = _joseph(c, x, P, e, c.mat("H", m, n), c.mat("R", m, m))
    c.line(f"return ({', '.join(map(str, xn))},), ({', '.join(map(str, flat(Pn)))},), {nis}")
    return c.compile()


def kf_kernel(A: np.ndarray, B: np.ndarray, C: np.ndarray, Qd: np.ndarray, R: np.ndarray,
              predict: bool = True) -> Callable[..., Any]:
    """A linear time-invariant model's full step with its matrices baked in.

    ``(x, P, u, y) -> (x⁺, P⁺, nis, K, W)`` (flat tuples), or None; ``predict=False``:
    the first step (update only, ``u`` ignored).
    """
    n, m, nu = A.shape[0], C.shape[0], B.shape[1]
    c = _Code("kf_step", ["x", "P", "u", "y"])
    x, P = c.vec("x", n), c.mat("P", n, n)
    if predict:
        u = c.vec("u", nu) if nu else []
        Am, Bm = const(A), const(B)
        xa = [c.let(_sum([_term(x[k], Am[i][k]) for k in range(n)])) for i in range(n)]
        if nu:
            xa = [c.let(_add(xa[i], _sum([_term(u[k], Bm[i][k]) for k in range(nu)])))
                  for i in range(n)]
        x, P = xa, _predict_cov(c, P, Am, const(Qd))
    y = c.vec("y", m)
    Cm = const(C)
    e = [c.let(_add(y[i], _sum([_term(x[k], Cm[i][k]) for k in range(n)]), "-"))
         for i in range(m)]
    xn, Pn, nis, K, W = _joseph(c, x, P, e, Cm, const(R))
    c.line(f"return ({', '.join(map(str, xn))},), ({', '.join(map(str, flat(Pn)))},), {nis}, "
           f"({', '.join(map(str, flat(K)))},), ({', '.join(map(str, flat(W)))},)")
    return c.compile()


def kf_steady_kernel(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> Callable[..., Any]:
    """The steady-state step of :class:`~.kalman.KalmanFilter`: ``(x, u, y, K, W) -> (x⁺, nis)``."""
    n, m, nu = A.shape[0], C.shape[0], B.shape[1]
    c = _Code("kf_steady", ["x", "u", "y", "K", "W"])
    x = c.vec("x", n)
    u = c.vec("u", nu) if nu else []
    Am, Bm, Cm = const(A), const(B), const(C)
    x = [c.let(_sum([_term(x[k], Am[i][k]) for k in range(n)])) for i in range(n)]
    if nu:
        x = [c.let(_add(x[i], _sum([_term(u[k], Bm[i][k]) for k in range(nu)])))
             for i in range(n)]
    y = c.vec("y", m)
    e = [c.let(_add(y[i], _sum([_term(x[k], Cm[i][k]) for k in range(n)]), "-"))
         for i in range(m)]
    K, W = c.mat("K", n, m), c.mat("W", m, m)
    xn = [c.let(_add(x[i], _sum([_term(e[j], K[i][j]) for j in range(m)]))) for i in range(n)]
    We = [c.let(_sum([_term(e[j], W[j][i]) for j in range(m)])) for i in range(m)]
    nis = c.let(_sum([_term(We[i], e[i]) for i in range(m)]))
    c.line(f"return ({', '.join(map(str, xn))},), {nis}")
    return c.compile()


# ---------------------------------------------------------------------------- UKF kernels
def ukf_kernels(xi: np.ndarray, Wm: np.ndarray, Wc: np.ndarray, same_tail: bool,
                sum_Wc: float, m: int) -> tuple[Callable[..., Any], Callable[..., Any],
                                                Callable[..., Any]]:
    """Kernels of :class:`~.unscented.UnscentedKalmanFilter` for one sigma-point scheme.

    * ``draw(x, P) -> points`` (flat ``N·n``) or None: lower Cholesky factor ``S`` of
      ``P`` and ``χⱼ = x + S ξⱼ``;
    * ``moments(Z, Q) -> (mean, P)``: the deviation form of the unscented transform,
      ``P = sym(Σ Wᶜ DDᵀ …) + Q``;
    * ``correct(x, P, X, Z, y, R) -> (x⁺, P⁺, nis)`` or None.
    """
    return (_ukf_draw(xi.tobytes(), xi.shape), _ukf_moments(*_key(Wm, Wc, same_tail, sum_Wc),
                                                            xi.shape[1]),
            _ukf_correct(*_key(Wm, Wc, same_tail, sum_Wc), xi.shape[1], m))


def _key(Wm: np.ndarray, Wc: np.ndarray, same_tail: bool, sum_Wc: float) -> tuple[Any, ...]:
    return tuple(Wm.tolist()), tuple(Wc.tolist()), bool(same_tail), float(sum_Wc)


@functools.lru_cache(maxsize=32)
def _ukf_draw(xi_bytes: bytes, shape: tuple[int, int]) -> Callable[..., Any]:
    N, n = shape
    xi = np.frombuffer(xi_bytes, dtype=np.float64).reshape(shape).tolist()
    c = _Code("ukf_draw", ["x", "P"])
    x, P = c.vec("x", n), c.mat("P", n, n)
    S = cholesky(c, P)
    pts = []
    for j in range(N):
        for i in range(n):
            # rmul(S, ξᵀ): (S ξⱼ)ᵢ = Σ_k S_ik ξ_jk, then x + that
            pts.append(c.let(_add(x[i], _sum([_term(S[i][k], xi[j][k]) for k in range(n)]))))
    c.line(f"return ({', '.join(map(str, pts))},)")
    return c.compile()


def _moments_code(c: _Code, Z: list[list[Entry]], Wm: tuple[float, ...], Wc: tuple[float, ...],
                  same_tail: bool) -> tuple[list[Entry], list[list[Entry]], list[Entry],
                                            list[Entry]]:
    """:func:`~.unscented._moments` on entries: mean, deviations, d and c."""
    N, k = len(Z), len(Z[0])
    D = [[0.0] * k] + [[c.let(f"{Z[j][i]} - {Z[0][i]}") for i in range(k)] for j in range(1, N)]
    d = [c.let(_sum([_term(Wm[j], D[j][i]) for j in range(N)])) for i in range(k)]
    cc = d if same_tail else [c.let(_sum([_term(Wc[j], D[j][i]) for j in range(N)]))
                              for i in range(k)]
    mean = [c.let(_add(Z[0][i], d[i])) for i in range(k)]
    return mean, D, d, cc


def _cross_code(c: _Code, Da: list[list[Entry]], da: list[Entry], ca: list[Entry],
                Db: list[list[Entry]], db: list[Entry], cb: list[Entry], Wc: tuple[float, ...],
                same_tail: bool, sum_Wc: float) -> Matrix:
    """:func:`~.unscented._cross` on entries."""
    N, ka, kb = len(Da), len(da), len(db)
    WD = [[c.let(_term(Da[j][i], Wc[j]) or 0.0) for i in range(ka)] for j in range(N)]
    out = []
    for i in range(ka):
        row = []
        for j in range(kb):
            v = _sum([_term(WD[t][i], Db[t][j]) for t in range(N)])
            if same_tail:
                v = _add(v, _term(sum_Wc - 2.0, c.let(f"{da[i]} * {db[j]}")) or 0.0)
            else:
                v = _add(v, c.let(f"{da[i]} * {cb[j]}"), "-")
                v = _add(c.let(v), c.let(f"{ca[i]} * {db[j]}"), "-")
                v = _add(c.let(v), _term(sum_Wc, c.let(f"{da[i]} * {db[j]}")) or 0.0)
            row.append(c.let(v))
        out.append(row)
    return out


@functools.lru_cache(maxsize=32)
def _ukf_moments(Wm: tuple[float, ...], Wc: tuple[float, ...], same_tail: bool, sum_Wc: float,
                 n: int) -> Callable[..., Any]:
    N = len(Wm)
    c = _Code("ukf_moments", ["Z", "Q"])
    Zf = c.vec("Z", N * n)
    Z = [Zf[j * n:(j + 1) * n] for j in range(N)]
    mean, D, d, cc = _moments_code(c, Z, Wm, Wc, same_tail)
    P = symmetrize(c, _cross_code(c, D, d, cc, D, d, cc, Wc, same_tail, sum_Wc))
    P = madd(c, P, c.mat("Q", n, n))
    c.line(f"return ({', '.join(map(str, mean))},), ({', '.join(map(str, flat(P)))},)")
    return c.compile()


@functools.lru_cache(maxsize=32)
def _ukf_correct(Wm: tuple[float, ...], Wc: tuple[float, ...], same_tail: bool, sum_Wc: float,
                 n: int, m: int) -> Callable[..., Any]:
    N = len(Wm)
    c = _Code("ukf_correct", ["x", "P", "X", "Z", "y", "R"])
    x, P = c.vec("x", n), c.mat("P", n, n)
    Xf, Zf = c.vec("X", N * n), c.vec("Z", N * m)
    X = [Xf[j * n:(j + 1) * n] for j in range(N)]
    Z = [Zf[j * m:(j + 1) * m] for j in range(N)]
    y_hat, DZ, dz, cz = _moments_code(c, Z, Wm, Wc, same_tail)
    _, DX, dx, cx = _moments_code(c, X, Wm, Wc, same_tail)
    S = madd(c, symmetrize(c, _cross_code(c, DZ, dz, cz, DZ, dz, cz, Wc, same_tail, sum_Wc)),
             c.mat("R", m, m))
    Pxz = _cross_code(c, DX, dx, cx, DZ, dz, cz, Wc, same_tail, sum_Wc)
    W = spd_inverse(c, S)
    K = matmul(c, Pxz, W)
    y = c.vec("y", m)
    e = [c.let(f"{y[i]} - {y_hat[i]}") for i in range(m)]
    xn = [c.let(_add(x[i], _sum([_term(K[i][j], e[j]) for j in range(m)]))) for i in range(n)]
    Pn = symmetrize(c, madd(c, P, matmul(c, K, transpose(Pxz)), "-"))
    We = [c.let(_sum([_term(W[i][j], e[j]) for j in range(m)])) for i in range(m)]
    nis = c.let(_sum([_term(We[i], e[i]) for i in range(m)]))
    c.line(f"return ({', '.join(map(str, xn))},), ({', '.join(map(str, flat(Pn)))},), {nis}")
    return c.compile()
