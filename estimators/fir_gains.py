"""Minimum-variance FIR gains over a window of time-varying matrices (pure functions).

A *window* holds ``L`` measurement instants ``j = 0..L-1`` of

    x[j+1] = A_j x[j] + B_j u[j] + w̃_j,   w̃_j ~ N(0, GQGᵀ_j)
    y[j]   = C_j x[j] + v_j,               v_j ~ N(0, R_j),  R_j > 0.

A gain ``S`` (shape ``(n, L·p)``, block ``j`` multiplies ``y_j``; block 0 is the
oldest) estimates a *target*: ``form="filter"`` → ``x[L-1]`` (window ends at the
estimate), ``"predictor"`` → ``x[L]`` (paper 000's form), ``"smoother"`` →
``x[0]`` (paper 004 §III). Without a prior the gain is the minimum-variance
*unbiased* one (``S C̃ = Φ``; the start state is a free parameter); with a prior
``Π0`` the start state is ``N(0, Π0)`` (paper 004 Theorem 2.1). Three ways:

(a) :func:`batch_gain` — the stacked formula, paper 000 Theorem 1 (eq 20),
    corrected (docs/papers.md#000-theorem-1: ``Π = G̃ Q_N G̃ᵀ + R_N``): cost O((L·p)³).
(b) :func:`riccati_gain` — paper 004: Theorem 2.1 (any prior), Corollary 2.1
    (:func:`stationary_prior`) and Corollary 2.2 (no prior, information form,
    transposes restored, "Q^k" read as Q½; needs an invertible A).
(c) :func:`two_stage_gain` — a Kalman filter from ``x = 0, P = 0`` that carries
    the sensitivity ``T = ∂x̂/∂x[0]`` and the normal equations
    ``F = Σ (C T)ᵀ Σ⁻¹ (C T)`` (Friedland's two-stage form); the gain follows by
    one adjoint sweep. O(L·n²(n+p)), no A⁻¹.

All three return :class:`GainResult` ``(S, P)`` with ``P`` the error covariance.
Inputs never enter ``S``: the gain acts on ``y - (known input response)``, see
:func:`input_gain`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from ._fir_bank import RANK_RTOL, information_is_regular
from ._validation import FloatArray, one_of
from .model import StateSpaceModel, SystemMatrices

FORMS = ("filter", "predictor", "smoother")
#: the forms a FIR filter runs in (the smoother is its own class)
WINDOW_FORMS = FORMS[:2]


class Window(NamedTuple):
    """Matrices of one window stacked over ``j = 0..L-1``; ``A_j, B_j, GQGᵀ_j`` map ``j → j+1``."""

    A: FloatArray    # (L, n, n)
    C: FloatArray    # (L, p, n)
    Qx: FloatArray   # (L, n, n)   state-noise covariance G_j Q_j G_jᵀ
    R: FloatArray    # (L, p, p)
    B: FloatArray    # (L, n, n_u)

    @property
    def horizon(self) -> int:
        return int(self.C.shape[0])


class GainResult(NamedTuple):
    """A FIR gain ``S`` ``(n, L·p)`` and the error covariance ``P`` of its estimate."""

    S: FloatArray
    P: FloatArray


def make_window(A: ArrayLike, C: ArrayLike, Qx: ArrayLike, R: ArrayLike, horizon: int,
                B: ArrayLike | None = None) -> Window:
    """Stack matrices into a :class:`Window`; a 2-D matrix is repeated ``horizon`` times.

    The stacks are fresh C-ordered arrays, never broadcast views: numpy's ``matmul`` takes a
    different loop (and so rounds differently) for a stride-0 view than for the same values
    stored, and a copy (``pickle``) stores them — a filter and its copy would drift apart in
    the last bits."""
    def stack(M: ArrayLike) -> FloatArray:
        M = np.asarray(M, dtype=np.float64)
        if M.ndim == 2:
            M = np.broadcast_to(M, (horizon, *M.shape))
        if M.ndim != 3 or M.shape[0] != horizon:
            raise ValueError(f"window matrices must be 2-D or ({horizon}, ., .); got {M.shape}")
        return M.copy(order="C")
    A_, C_ = stack(A), stack(C)
    B_ = np.zeros((horizon, A_.shape[1], 0)) if B is None else stack(B)
    return Window(A_, C_, stack(Qx), stack(R), B_)


def window_from_matrices(mats: Sequence[SystemMatrices]) -> Window:
    """A :class:`Window` from per-instant :class:`~.model.SystemMatrices` (oldest first)."""
    return Window(np.stack([m.A for m in mats]), np.stack([m.C for m in mats]),
                  np.stack([m.G @ m.Q @ m.G.T for m in mats]), np.stack([m.R for m in mats]),
                  np.stack([m.B for m in mats]))


def model_window(model: StateSpaceModel, k0: int, horizon: int) -> Window:
    """The window ``k0 .. k0+horizon-1`` of a (time-varying) linear model's ``matrices(k)``."""
    return window_from_matrices([model.matrices(k)  # type: ignore[attr-defined]
                                 for k in range(k0, k0 + horizon)])


def _target(form: str, L: int) -> int:
    one_of("form", form, FORMS)
    return {"filter": L - 1, "predictor": L, "smoother": 0}[form]


# ---------------------------------------------------------------------------- rank
def _check_information(F: FloatArray, what: str) -> None:
    if not information_is_regular(F):
        raise ValueError(
            f"the stacked observation matrix of the window is rank-deficient ({what}): the "
            "window's start state is not identifiable from its measurements; use a longer "
            "horizon (at least the observability index) or check (A, C)")


# ---------------------------------------------------------------------------- (a) batch
class StackedWindow(NamedTuple):
    """Paper 000 eqs (21)-(26): ``Y = C̃ x[0] + G̃ W + D̃ U + V``, ``x_t = Φ x[0] + M W + M_B U``."""

    Ct: FloatArray   # (L p, n)    C̃
    Gt: FloatArray   # (L p, L n)  G̃ (noise block m = w̃_m, entering x[m+1])
    Phi: FloatArray  # (n, n)      Φ (start → target)
    M: FloatArray    # (n, L n)
    Dt: FloatArray   # (L p, L n_u)
    MB: FloatArray   # (n, L n_u)
    Qbd: FloatArray  # (L n, L n)  blockdiag(GQGᵀ_m)
    Rbd: FloatArray  # (L p, L p)  blockdiag(R_j)


def stacked_window(win: Window, form: str = "filter") -> StackedWindow:
    """Build the stacked matrices of paper 000 Theorem 1 for ``form``'s target.

    The transition products ``Φ(j, m) = A_{j-1}⋯A_m`` are the blocks of
    ``𝒜 = (I - 𝒩)⁻¹`` where ``𝒩`` holds ``A_j`` on the block sub-diagonal (one
    triangular solve, no Python loop over block pairs): ``x = 𝒜 [x0; w̃_0; …]``.
    """
    L = win.horizon
    t = _target(form, L)
    n, p, nu = win.A.shape[1], win.C.shape[1], win.B.shape[2]
    A = np.array(win.A)
    if form != "predictor":
        A[L - 1] = 0.0                  # A_{L-1} is outside the window: never used
    Nsub = np.zeros(((L + 1) * n, (L + 1) * n))
    for j in range(L):
        Nsub[(j + 1) * n:(j + 2) * n, j * n:(j + 1) * n] = A[j]
    Acal = sla.solve_triangular(np.eye((L + 1) * n) - Nsub, np.eye((L + 1) * n), lower=True,
                                unit_diagonal=True)
    X = Acal.reshape(L + 1, n, L + 1, n)
    CX = np.einsum("jpn,jnmk->jpmk", win.C, X[:L]).reshape(L * p, (L + 1) * n)
    Ct, Gt = CX[:, :n], CX[:, n:]
    Phi, M = X[t, :, 0, :], X[t, :, 1:, :].reshape(n, L * n)
    Bbd = sla.block_diag(*win.B) if nu else np.zeros((L * n, 0))
    return StackedWindow(Ct, Gt, Phi, M, Gt @ Bbd, M @ Bbd, sla.block_diag(*win.Qx),
                         sla.block_diag(*win.R))


def batch_gain(win: Window, form: str = "filter", prior: ArrayLike | None = None) -> GainResult:
    """Path (a), the reference: paper 000 Theorem 1 (eq 20), corrected.

    No prior (minimum variance subject to ``S C̃ = Φ``)::

        Π = G̃ Q_N G̃ᵀ + R_N                                  (eq 23, corrected)
        S = Φ (C̃ᵀΠ⁻¹C̃)⁻¹C̃ᵀΠ⁻¹ + M Q_N G̃ᵀ Π⁻¹ [I − C̃ (C̃ᵀΠ⁻¹C̃)⁻¹ C̃ᵀΠ⁻¹]

    With prior ``x[0] ~ N(0, Π0)``: ``S = (Φ Π0 C̃ᵀ + M Q_N G̃ᵀ)(C̃ Π0 C̃ᵀ + Π)⁻¹``.
    ``P = (Φ − S C̃) Π0 (·)ᵀ + (M − S G̃) Q_N (·)ᵀ + S R_N Sᵀ``. Cost O((L·p)³).
    """
    sw = stacked_window(win, form)
    Ct, Gt, Phi, M = sw.Ct, sw.Gt, sw.Phi, sw.M
    Pi = Gt @ sw.Qbd @ Gt.T + sw.Rbd
    V = M @ sw.Qbd @ Gt.T                                   # M Q_N G̃ᵀ
    if prior is None:
        cPi = sla.cho_factor(Pi)
        U = sla.cho_solve(cPi, Ct).T                        # C̃ᵀΠ⁻¹
        F = U @ Ct
        _check_information(F, f"horizon={win.horizon}")
        FiU = sla.solve(F, U, assume_a="pos")               # (C̃ᵀΠ⁻¹C̃)⁻¹C̃ᵀΠ⁻¹
        VPi = sla.cho_solve(cPi, V.T).T
        S = Phi @ FiU + VPi - (VPi @ Ct) @ FiU
        E = np.zeros_like(Phi)
    else:
        P0 = np.asarray(prior, float)
        S = sla.solve(Ct @ P0 @ Ct.T + Pi, (Phi @ P0 @ Ct.T + V).T, assume_a="pos").T
        E = Phi - S @ Ct
    Nw = M - S @ Gt
    P = Nw @ sw.Qbd @ Nw.T + S @ sw.Rbd @ S.T
    if prior is not None:
        P = P + E @ P0 @ E.T
    return GainResult(S, 0.5 * (P + P.T))


# ---------------------------------------------------------------------------- (b) Riccati
def stationary_prior(A: ArrayLike, Qx: ArrayLike) -> FloatArray:
    """Paper 004 Cor 2.1: the stationary covariance ``P(0) = A P(0) Aᵀ + BQBᵀ`` (stable A)."""
    A_ = np.asarray(A, float)
    if np.max(np.abs(np.linalg.eigvals(A_))) >= 1.0:
        raise ValueError("a stationary prior (paper 004 Cor 2.1) needs a stable A "
                         "(all |eigenvalues| < 1)")
    P = sla.solve_discrete_lyapunov(A_, np.asarray(Qx, float))
    return 0.5 * (P + P.T)


def _psd_factor(Qx: FloatArray) -> FloatArray:
    """A factor ``Bq`` with ``Bq Bqᵀ = Qx`` (the paper's ``B Q½``), from the eigen-decomposition."""
    lam, V = np.linalg.eigh(0.5 * (Qx + Qx.T))
    return V * np.sqrt(np.clip(lam, 0.0, None))


def riccati_gain(win: Window, form: str = "filter", prior: ArrayLike | None = None
                 ) -> GainResult:
    """Path (b): paper 004's Riccati-type recursions (time-varying, ``R`` general).

    With prior (Theorem 2.1; Cor 2.1 when ``prior = stationary_prior(A, Qx)``)::

        R(n+1) = M(n) − M(n)Cᵀ[R_v + C M(n) Cᵀ]⁻¹ C M(n),  M(n) = A R(n) Aᵀ + BQBᵀ   (2.8)
        H(j; n+1) = [I − R(n+1) Cᵀ R_v⁻¹ C] A H(j; n),  H(j; j) = R(j) Cᵀ R_v⁻¹       (2.7)

    where the paper's ``M(i, −1) = A R(i,−1) Aᵀ + BQBᵀ`` is our ``prior`` on
    ``x[0]``. Products in (2.7) are accumulated backwards, ``Ψ_j = Ψ_{j+1}[I − R
    CᵀR_v⁻¹C]A_j``, so all ``L`` impulse responses cost O(L·n³), not the paper's
    O(L²). The smoother uses Theorem 3.1 (its first form for W; Cor 3.1 needs the
    missing C restored)::

        W(n+1) = W(n) Aᵀ [I − Cᵀ(R_v + C M(n) Cᵀ)⁻¹ C M(n)],  W(0) = R(0)
        H_s(j; n+1) = H_s(j; n) − W(n+1) Cᵀ R_v⁻¹ C A H(j; n),  H_s(j; j) = W(j) Cᵀ R_v⁻¹

    No prior (Cor 2.2, information form, corrected: transposes restored, Q^k → Q½)::

        Y = A'⁻¹ S(n) A⁻¹,  S(n+1) = Y + CᵀR_v⁻¹C − Y Bq [I + Bqᵀ Y Bq]⁻¹ Bqᵀ Y,  S(−1) = 0
        L(j; n+1) = [Aᵀ + S(n) A⁻¹ Bq Bqᵀ]⁻¹ L(j; n),  L(j; j) = CᵀR_v⁻¹,  H = S⁻¹(L−1) L

    (``Bq Bqᵀ = BQBᵀ``). It needs every ``A_j`` of the window invertible (a
    ValueError otherwise; path (c) has no such need). The no-prior smoother
    (Cor 3.2) needs ``[S(n+1) − CᵀC]⁻¹``, singular when ``p < n``: it is not
    offered here — use :func:`two_stage_gain` (docs/papers.md#004-cor-3-2).
    """
    L = win.horizon
    _target(form, L)
    if prior is None:
        if form == "smoother":
            raise ValueError("riccati_gain has no no-prior smoother: paper 004 Cor 3.2 needs "
                             "[S(n+1) - C'C]^-1, singular when outputs < states; use "
                             "two_stage_gain or batch_gain")
        S, P = _riccati_information(win)
    else:
        S, P = _riccati_prior(win, np.asarray(prior, float), form == "smoother")
    if form == "predictor":
        A, Qx = win.A[L - 1], win.Qx[L - 1]
        S, P = A @ S, A @ P @ A.T + Qx
    return GainResult(S, 0.5 * (P + P.T))


def _riccati_prior(win: Window, P0: FloatArray, smoother: bool) -> tuple[FloatArray, FloatArray]:
    L, n = win.horizon, win.A.shape[1]
    Rs: list[FloatArray] = []                    # R(j)
    Gam: list[FloatArray] = []                   # I − R Cᵀ R_v⁻¹ C
    Kt: list[FloatArray] = []                    # R Cᵀ R_v⁻¹
    Ws: list[FloatArray] = []                    # W(j)
    Sig: list[FloatArray] = []                   # Σ_j
    Mn = P0
    for j in range(L):
        C = win.C[j]
        Sig.append(C @ Mn @ C.T + win.R[j])
        CM = np.linalg.solve(Sig[j], C @ Mn)                      # Σ⁻¹ C M
        Rj = Mn - Mn @ C.T @ CM
        Rs.append(0.5 * (Rj + Rj.T))
        Kt.append(np.linalg.solve(win.R[j], C @ Rs[j]).T)           # R(j) Cᵀ R_v⁻¹
        Gam.append(np.eye(n) - Kt[j] @ C)
        if smoother:     # W(j) = W(j−1) Aᵀ [I − Cᵀ(R_v + C M Cᵀ)⁻¹ C M], W(0) = R(0)
            Ws.append(Rs[0] if j == 0 else Ws[j - 1] @ win.A[j - 1].T @ (np.eye(n) - C.T @ CM))
        Mn = win.A[j] @ Rs[j] @ win.A[j].T + win.Qx[j]
    blocks, Psi, Xi, Ps = [], np.eye(n), np.zeros((n, n)), Rs[0]
    if not smoother:                             # H(j; L−1) = Ψ(L−1, j) R(j) Cᵀ R_v⁻¹
        for j in range(L - 1, -1, -1):
            blocks.append(Psi @ Kt[j])
            Psi = Psi @ Gam[j] @ win.A[j - 1] if j else Psi
        return np.hstack(blocks[::-1]), Rs[L - 1]
    for j in range(1, L):                        # smoother covariance, fixed-point form
        Ks = Ws[j - 1] @ win.A[j - 1].T @ win.C[j].T
        Ps = Ps - Ks @ np.linalg.solve(Sig[j], Ks.T)
    for j in range(L - 1, -1, -1):               # Ξ_j = Σ_{m≥j} W(m+1)CᵀR_v⁻¹C A_m Ψ(m, j)
        CR = np.linalg.solve(win.R[j], win.C[j]).T                  # Cᵀ R_v⁻¹
        blocks.append((Ws[j] - Xi @ Rs[j]) @ CR)
        Xi = (Ws[j] @ CR @ win.C[j] + Xi @ Gam[j]) @ win.A[j - 1] if j else Xi
    return np.hstack(blocks[::-1]), Ps


def _riccati_information(win: Window) -> tuple[FloatArray, FloatArray]:
    L, n = win.horizon, win.A.shape[1]
    lus, CR = [], []
    for j in range(L - 1):
        if (cond := np.linalg.cond(win.A[j])) > 1.0 / RANK_RTOL:
            raise ValueError(f"gain='riccati' without a prior (paper 004 Cor 2.2) needs an "
                             f"invertible A; A at window position {j} is singular "
                             f"(cond {cond:.3g}). Use gain='two-stage'.")
        lus.append(sla.lu_factor(win.A[j]))
    S = np.zeros((n, n))
    Lam_factors = []
    for j in range(L):
        C, Rv = win.C[j], win.R[j]
        CR.append(np.linalg.solve(Rv, C).T)                        # Cᵀ R_v⁻¹
        if j == 0:
            Y = np.zeros((n, n))
        else:
            lu = lus[j - 1]
            Bq = _psd_factor(win.Qx[j - 1])
            Z = sla.lu_solve(lu, S, trans=1)                         # A'⁻¹ S
            Y = sla.lu_solve(lu, Z.T, trans=1)                       # A'⁻¹ S A⁻¹
            YB = Y @ Bq
            Y = Y - YB @ np.linalg.solve(np.eye(Bq.shape[1]) + Bq.T @ YB, YB.T)
            # L(·; j) = [A' + S(j−1) A⁻¹ Bq Bq']⁻¹ L(·; j−1)
            Lam_factors.append(win.A[j - 1].T + S @ sla.lu_solve(lu, Bq @ Bq.T))
        S = Y + CR[j] @ C
        S = 0.5 * (S + S.T)
    _check_information(S, f"horizon={L}")
    blocks, Lam = [], np.eye(n)
    for j in range(L - 1, -1, -1):
        blocks.append(Lam @ CR[j])
        if j:
            Lam = np.linalg.solve(Lam_factors[j - 1].T, Lam.T).T
    Lfull = np.hstack(blocks[::-1])
    P = sla.solve(S, np.eye(n), assume_a="pos")
    return sla.solve(S, Lfull, assume_a="pos"), P


# ---------------------------------------------------------------------------- (c) two-stage
class TwoStageForward(NamedTuple):
    """Data-free quantities of the two-stage recursion over one window."""

    K: list[FloatArray]       # Kalman gains (from x = 0, P = 0)
    W: list[FloatArray]       # (C T⁻)ᵀ Σ⁻¹
    Gam: list[FloatArray]     # I − K C
    F: FloatArray             # Σ (C T⁻)ᵀ Σ⁻¹ (C T⁻) = C̃ᵀ Π⁻¹ C̃
    T: FloatArray             # sensitivity ∂x̄_{L−1}/∂x[0] after the last update
    P: FloatArray             # covariance of x̄_{L−1} given x[0]


def two_stage_forward(win: Window) -> TwoStageForward:
    """Forward sweep of path (c): KF from ``x̄⁻ = 0, P⁻ = 0, T⁻ = I``
    (docs/papers.md#000-two-stage-form)::

        Σ = C P⁻ Cᵀ + R,  K = P⁻ Cᵀ Σ⁻¹,  Z = C T⁻,  F += Zᵀ Σ⁻¹ Z
        T = (I − K C) T⁻,  P = (I − K C) P⁻,  T⁻ ← A T,  P⁻ ← A P Aᵀ + GQGᵀ
    """
    L, n = win.horizon, win.A.shape[1]
    P, T, F = np.zeros((n, n)), np.eye(n), np.zeros((n, n))
    Ks, Ws, Gs = [], [], []
    for j in range(L):
        C = win.C[j]
        Sig = C @ P @ C.T + win.R[j]
        Z = C @ T
        KW = np.linalg.solve(Sig, np.hstack([C @ P, Z])).T
        K, W = KW[:n], KW[n:]
        Gam = np.eye(n) - K @ C
        F = F + W @ Z
        T, P = Gam @ T, Gam @ P
        P = 0.5 * (P + P.T)
        Ks.append(K)
        Ws.append(W)
        Gs.append(Gam)
        if j < L - 1:
            T, P = win.A[j] @ T, win.A[j] @ P @ win.A[j].T + win.Qx[j]
    return TwoStageForward(Ks, Ws, Gs, 0.5 * (F + F.T), T, P)


def posterior_start_covariance(F: FloatArray, prior: ArrayLike | None) -> FloatArray:
    """``V = F⁻¹`` (no prior) or ``(Π0⁻¹ + F)⁻¹ = Π0 (I + F Π0)⁻¹`` (no Π0⁻¹ formed)."""
    n = F.shape[0]
    if prior is None:
        V = sla.solve(F, np.eye(n), assume_a="pos")
    else:
        P0 = np.asarray(prior, float)
        V = sla.solve(np.eye(n) + P0 @ F, P0)
    return 0.5 * (V + V.T)


def two_stage_gain(win: Window, form: str = "filter", prior: ArrayLike | None = None
                   ) -> GainResult:
    """Path (c): the two-stage (Friedland) recursion and one adjoint sweep for ``S``.

    The estimate is ``x̂ = x̄_T + T_T V b`` with ``V = F⁻¹`` (diffuse start) or
    ``Π0 (I + F Π0)⁻¹`` (prior), ``b = Σ (C T⁻)ᵀ Σ⁻¹ (y − C x̄⁻)``; its covariance
    is ``P_T + T_T V T_Tᵀ`` (smoother: ``x̂ = V b``, covariance ``V``). Writing
    ``x̂ = L_x x̄_{L−1} + L_b b``, the blocks of ``S = ∂x̂/∂y`` follow backwards::

        μ = L_x Γ_{L−1} − L_b W_{L−1} C_{L−1},  S_{L−1} = L_x K_{L−1} + L_b W_{L−1}
        S_j = μ A_j K_j + L_b W_j,  μ ← μ A_j Γ_j − L_b W_j C_j     (j = L−2 … 0)
    """
    L, n = win.horizon, win.A.shape[1]
    _target(form, L)
    fw = two_stage_forward(win)
    if prior is None:
        _check_information(fw.F, f"horizon={L}")
    V = posterior_start_covariance(fw.F, prior)
    if form == "smoother":
        Lx, Lb, P = np.zeros((n, n)), V, V
    else:
        Lx, Lb, P = np.eye(n), fw.T @ V, fw.P + fw.T @ V @ fw.T.T
        if form == "predictor":
            A = win.A[L - 1]
            Lx, Lb, P = A, A @ Lb, A @ P @ A.T + win.Qx[L - 1]
    blocks = [Lx @ fw.K[L - 1] + Lb @ fw.W[L - 1]]
    mu = Lx @ fw.Gam[L - 1] - Lb @ fw.W[L - 1] @ win.C[L - 1]
    for j in range(L - 2, -1, -1):
        muA = mu @ win.A[j]
        blocks.append(muA @ fw.K[j] + Lb @ fw.W[j])
        mu = muA @ fw.Gam[j] - Lb @ fw.W[j] @ win.C[j]
    return GainResult(np.hstack(blocks[::-1]), 0.5 * (P + P.T))


# ---------------------------------------------------------------------------- inputs
def input_gain(win: Window, S: FloatArray, form: str = "filter") -> FloatArray:
    """Gain ``S_u = M_B − S D̃`` on the window's inputs ``u_0 … u_{L-1}`` (``(n, L·n_u)``).

    With ``x_t = Φ x0 + M W + M_B U`` and ``Y = C̃ x0 + G̃ W + D̃ U + V`` the estimate
    ``x̂ = S (Y − D̃ U) + M_B U = S Y + S_u U`` stays unbiased and keeps ``S``'s
    variance. Block ``m`` is ``(μ_m − Λ_m) B_m`` with ``μ_m = Φ(t, m+1)`` and
    ``Λ_m = Σ_{j>m} S_j C_j Φ(j, m+1)``, accumulated backwards (``Λ_m = S_{m+1}C_{m+1}
    + Λ_{m+1} A_{m+1}``): O(L·n²). Inputs after the target (``m ≥ t``) get zero gain.
    """
    L = win.horizon
    t = _target(form, L)
    n, p, nu = win.A.shape[1], win.C.shape[1], win.B.shape[2]
    out = np.zeros((n, L * nu))
    Lam, Phit = np.zeros((n, n)), np.eye(n)
    for m in range(L - 1, -1, -1):
        if m < L - 1:
            Lam = S[:, (m + 1) * p:(m + 2) * p] @ win.C[m + 1] + Lam @ win.A[m + 1]
        if m < t - 1:
            Phit = Phit @ win.A[m + 1]
        mu = Phit if m < t else np.zeros((n, n))
        out[:, m * nu:(m + 1) * nu] = (mu - Lam) @ win.B[m]
    return out
