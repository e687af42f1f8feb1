"""Performance bounds of the continuous-time optimal FIR filter under model uncertainty (paper 001).

A *true* system ``ẋ = A x + G w``, ``z = C x + v`` (``Q``, ``V``; paper 001's ``B`` is
``G``, ``V`` is the model's ``R``) produces the data; the optimal FIR filter of
:mod:`~fir_gym.estimators.continuous_fir` designed from a *nominal* system
(``A_M = A + ΔA``, ``C_M = C + ΔC``, ``Q_M``, ``V_M``) processes it. Which of paper
001's two systems is which is ambiguous; every function takes both explicitly
(``fir_gym.scenarios.paper001`` states which reading reproduces Table 1).
``horizon=None`` selects the steady-state Kalman–Bucy filters instead of FIR ones.

**True error covariance** ``R_r`` (Theorem 2.1). :func:`error_covariance`
propagates the joint covariance of ``[x; x̂]`` (``ẋ = A x + G w``,
``dx̂/dσ = F_M x̂ + K_M (C x + v)``, ``x(0) ~ N(0, Π)``, ``x̂(0) = 0``) and returns
``R_r = [I, −I] Σ [I, −I]ᵀ``. :func:`theorem21` integrates the paper's
``R_r = R + U`` (eqs 2.11–2.14), which re-derivation confirms with ``ΔA = A_M − A``,
``ΔC = C_M − C``, ``ΔK = K_M − K``, ``T = R − E[e xᵀ]`` (``e = x − x̂``) and the noise
term ``ΔK V ΔKᵀ`` (the paper's ``ΔK ΔKᵀ`` is the case ``V = I``).

**Δπ₁** (Theorem 3.1, ``ΔA = ΔC = 0``): ``R_r − R = ∫_0^T Φ_F ΔK V ΔKᵀ Φ_Fᵀ dτ``
(3.7, ``Φ_F = Φ_F(T, τ)`` of the nominal filter). Eq 3.2 read as
``∫ ‖Φ_F ΔK ΔKᵀ Φ_Fᵀ‖_F dτ`` (docs/papers.md#001-eq-3-2) is *not* an upper bound in general: for a
PSD matrix ``‖X‖_F ≤ tr X``, so it is ≤ ``tr(R_r − R)`` when ``V = I``, with equality
when the integrand has rank one (one output, as in Table 1) — there it is the
exact difference, not a bound. The step 3.9 → 3.10 misapplies Lemma 1 (eq 1.5),
which gives the valid ``|tr(Φ Y Φᵀ)| ≤ ‖ΦᵀΦ‖_F ‖Y‖_F``. :func:`delta_pi1` returns
the paper's reading, that Lemma-1 bound and the exact trace.

**Which transition Φ_F** (docs/papers.md#001-eq-3-3-transition). Eq 3.7 (the
solution of 3.6) and the bound built on it use ``Φ_F(T, τ)``, from ``τ`` to the
window's end. Eqs 3.2–3.4 as printed write
``Φ_F(t, τ)`` but define it by ``d/dt Φ_F(t, τ) = [A_M − K_M(t, σ) C_M] Φ_F(t, τ)``,
mixing the time ``t`` with the window time ``σ``; integrated in ``σ`` from the window
start it is ``Φ_F(τ, 0)``, the transition from ``σ = 0`` to ``τ``.
:func:`delta_pi1_from_start` evaluates eq 3.2 under that reading (it is no bound
of ``tr(R_r − R)``; for the steady-state filter both readings are ``e^{F τ}`` and
coincide).

**Δπ₂** (Theorem 4.1, eqs 4.2–4.19): reconstructed in :func:`delta_pi2`.
:func:`worst_case` evaluates the exact ``tr(R_r − R)`` on the corners of an
uncertainty box.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import scipy.linalg
from scipy.integrate import simpson

from ._validation import FloatArray, positive
from .continuous import ContinuousModel
from .continuous_fir import (
    FIRSolution,
    fir_riccati,
    grid_steps,
    kalman_bucy,
    linear_matrices,
    stationary_covariance,
)

__all__ = ["ErrorCovariance", "ModelBound", "NoiseBound", "Theorem21", "WorstCase",
           "corners", "delta_pi1", "delta_pi1_from_start", "delta_pi2", "error_covariance",
           "theorem21", "worst_case"]


class NoiseBound(NamedTuple):
    """Theorem 3.1: ``paper`` (eq 3.2 with the Frobenius norm — reproduces Table 1, not a
    valid bound in general), ``lemma1`` (a valid upper bound of ``tr(R_r − R)``)
    and ``trace`` (``∫ tr(Φ_F ΔK V ΔKᵀ Φ_Fᵀ)``, equal to ``tr(R_r − R)`` when ``ΔA = ΔC = 0``).
    """

    paper: float
    lemma1: float
    trace: float


class ModelBound(NamedTuple):
    """Theorem 4.1 as reconstructed: ``value = noise + 2 α₁ · coupling`` (eq 4.2).

    ``noise = ∫ tr(Φ_F ΔK V ΔKᵀ Φ_Fᵀ)``; ``coupling = ∫ ‖Φ_FᵀΦ_F‖‖ΔA‖ + ‖Φ_Fᵀ‖‖Φ_F K_M‖‖ΔC‖``;
    ``alpha1`` bounds ``‖T(σ)‖`` (4.5), ``beta`` bounds ``‖P‖`` (4.7); ``gain_T`` and
    ``gain_P`` are the small-gain factors (``value`` is ``inf`` when one is ≥ 1).
    """

    value: float
    noise: float
    coupling: float
    alpha1: float
    beta: float
    gain_T: float
    gain_P: float


class ErrorCovariance(NamedTuple):
    """``R_r`` (true error covariance of the nominal filter) and ``R`` (optimal, true model)."""

    R_r: FloatArray
    R: FloatArray


def error_covariance(true: ContinuousModel, nominal: ContinuousModel,
                     horizon: float | None, n_steps: int | None = None) -> ErrorCovariance:
    """``R_r`` from the joint covariance of ``[x; x̂]`` (exact up to RK4 on the grid).

    ``horizon=None``: the steady-state Kalman–Bucy filters; the joint covariance is
    then the stationary solution of its Lyapunov equation.
    """
    A, C, W, V = linear_matrices(true)
    A_M, C_M, _, _ = linear_matrices(nominal)
    n = A.shape[0]
    J = np.hstack([np.eye(n), -np.eye(n)])

    def joint(K_M: FloatArray) -> tuple[FloatArray, FloatArray]:
        Aa = np.block([[A, np.zeros((n, n))], [K_M @ C, A_M - K_M @ C_M]])
        Wa = scipy.linalg.block_diag(W, K_M @ V @ K_M.T)
        return Aa, Wa

    if horizon is None:
        K_M = kalman_bucy(nominal) @ np.linalg.solve(nominal.R, C_M).T
        Aa, Wa = joint(K_M)
        S = scipy.linalg.solve_continuous_lyapunov(Aa, -Wa)
        return ErrorCovariance(J @ S @ J.T, kalman_bucy(true))
    N = grid_steps(horizon, n_steps)
    K_M = fir_riccati(nominal, horizon, 2 * N).K                 # on the RK4 stage grid
    m = len(K_M)
    Aa = np.zeros((m, 2 * n, 2 * n))
    Aa[:, :n, :n] = A
    Aa[:, n:, :n] = K_M @ C
    Aa[:, n:, n:] = A_M - K_M @ C_M
    Wa = np.zeros((m, 2 * n, 2 * n))
    Wa[:, :n, :n] = W
    Wa[:, n:, n:] = K_M @ V @ np.swapaxes(K_M, 1, 2)

    def rhs(k: int, S: FloatArray) -> FloatArray:
        AS = Aa[k] @ S
        return AS + AS.T + Wa[k]

    S0 = scipy.linalg.block_diag(stationary_covariance(true), np.zeros((n, n)))
    S = _rk4(rhs, S0, horizon / N, N)[-1]
    return ErrorCovariance(J @ S @ J.T, fir_riccati(true, horizon, N).R[-1])


class Theorem21(NamedTuple):
    """``U(σ)`` and ``T(σ)`` of eqs 2.12–2.13 on the grid, ``(N+1, n, n)``; ``R_r = R + U(T)``."""

    sigma: FloatArray
    U: FloatArray
    T: FloatArray


def theorem21(true: ContinuousModel, nominal: ContinuousModel, horizon: float,
              n_steps: int | None = None) -> Theorem21:
    """Integrate Theorem 2.1 (eqs 2.12–2.14) by RK4 on the window grid.

        U' = F_M U + U F_Mᵀ + ΔK V ΔKᵀ + D Tᵀ + T Dᵀ,                U(0) = 0
        T' = F_M T + T Aᵀ + ΔK C R + D (Π − R),   D = ΔA − K_M ΔC,   T(0) = 0

    (``P(t − T + σ) = Π`` in the stationary setting of eq 2.5.)
    """
    A, C, _, V = linear_matrices(true)
    A_M, C_M, _, _ = linear_matrices(nominal)
    horizon = positive("horizon", horizon)
    N = grid_steps(horizon, n_steps)
    tru, nom = fir_riccati(true, horizon, 2 * N), fir_riccati(nominal, horizon, 2 * N)
    Pi = stationary_covariance(true)
    dA, dC, n = A_M - A, C_M - C, A.shape[0]

    def rhs(k: int, Y: FloatArray) -> FloatArray:
        U, T = Y[:n], Y[n:]
        F_M = A_M - nom.K[k] @ C_M
        dK = nom.K[k] - tru.K[k]
        D = dA - nom.K[k] @ dC
        dU = F_M @ U + U @ F_M.T + dK @ V @ dK.T + D @ T.T + T @ D.T
        dT = F_M @ T + T @ A.T + dK @ C @ tru.R[k] + D @ (Pi - tru.R[k])
        return np.concatenate([dU, dT])

    Y = _rk4(rhs, np.zeros((2 * n, n)), horizon / N, N)
    return Theorem21(np.linspace(0.0, horizon, N + 1), Y[:, :n], Y[:, n:])


def delta_pi1(true: ContinuousModel, nominal: ContinuousModel, horizon: float | None,
              n_steps: int | None = None) -> NoiseBound:
    """Theorem 3.1 (``ΔA = ΔC = 0``): the paper's Δπ₁ (eq 3.2), a valid bound, the exact trace.

        paper  = ∫_0^T ‖Φ_F ΔK ΔKᵀ Φ_Fᵀ‖_F dτ          (eq 3.2, docs/papers.md#001-eq-3-2)
        lemma1 = ∫_0^T ‖Φ_FᵀΦ_F‖_F ‖ΔK V ΔKᵀ‖_F dτ      (Lemma 1, eq 1.5: valid)
        trace  = ∫_0^T tr(Φ_F ΔK V ΔKᵀ Φ_Fᵀ) dτ          (= tr(R_r − R), eq 3.7)

    ``Φ_F = Φ_F(T, τ)`` of the nominal filter; ``horizon=None`` integrates the
    steady-state Kalman–Bucy filters over ``[0, ∞)``.
    """
    w = _Window(true, nominal, horizon, n_steps)
    dK = w.K_M - w.K
    X = w.Phi @ dK
    V = true.R
    paper = np.linalg.norm(X @ np.swapaxes(X, 1, 2), axis=(1, 2))
    PtP = np.linalg.norm(np.swapaxes(w.Phi, 1, 2) @ w.Phi, axis=(1, 2))
    lemma1 = PtP * np.linalg.norm(dK @ V @ np.swapaxes(dK, 1, 2), axis=(1, 2))
    trace = np.einsum("jik,kl,jil->j", X, V, X)
    return NoiseBound(*(float(simpson(f, x=w.s)) for f in (paper, lemma1, trace)))


def delta_pi1_from_start(true: ContinuousModel, nominal: ContinuousModel,
                         horizon: float | None, n_steps: int | None = None) -> float:
    """Eq 3.2 with ``Φ_F = Φ_F(τ, 0)``, the transition from the window start (module docstring).

        ∫_0^T ‖Φ_F(τ, 0) ΔK(τ) ΔK(τ)ᵀ Φ_F(τ, 0)ᵀ‖_F dτ

    A reading of the printed eqs 3.2–3.4, not a bound; ``horizon=None`` (steady state)
    gives the same value as :func:`delta_pi1`'s ``paper``.
    """
    w = _Window(true, nominal, horizon, n_steps)
    Phi = w.Phi if w.fir is None else w.fir.from_start()
    X = Phi @ (w.K_M - w.K)
    return float(simpson(np.linalg.norm(X @ np.swapaxes(X, 1, 2), axis=(1, 2)), x=w.s))


def delta_pi2(true: ContinuousModel, nominal: ContinuousModel, horizon: float | None,
              n_steps: int | None = None) -> ModelBound:
    """Theorem 4.1 (``ΔQ = ΔV = 0``), reconstructed: an upper bound of ``tr(R_r − R)``.

    Eqs 4.2–4.19 are garbled in print; what the equations allow is rebuilt as follows.

    1. Eq 4.17 (printed with ``Φ_M`` on the left) follows from 2.12 with ``Φ_F`` on
       both sides; its trace, by ``tr(Φ Y Φᵀ) = tr(ΦᵀΦ Y)`` and Lemma 1 (1.5), gives 4.18::

           tr(R_r − R) ≤ ∫ tr(Φ_F ΔK V ΔKᵀ Φ_Fᵀ)
                         + 2 ∫ {‖Φ_FᵀΦ_F‖ ‖ΔA‖ + ‖Φ_Fᵀ‖ ‖Φ_F K_M‖ ‖ΔC‖} ‖T(τ)‖ dτ

       (the first term is the trace, not 4.2's unnormed matrix; 4.2's
       ``‖ΔA T‖ … α₁`` is read ``‖ΔA‖ α₁`` via ``‖ΔA T‖ ≤ ‖ΔA‖‖T‖ ≤ ‖ΔA‖ α₁``).
    2. ``‖P‖ ≤ β`` (4.3, 4.7, 4.12–4.14). In the stationary setting of eq 2.5,
       ``P ≡ Π`` and 4.12 becomes ``Π = Π_M − ∫_0^∞ Φ_M (ΔA Π + Π ΔAᵀ) Φ_Mᵀ``, so
       ``‖Π‖ ≤ ‖Π_M‖ + γ_P ‖Π‖`` with ``γ_P = 2‖ΔA‖ ∫_0^∞ ‖e^{A_M s}‖² ds``, i.e.
       ``β = ‖Π_M‖ / (1 − γ_P)``. (The printed exponentials are Gronwall's lemma,
       which needs a kernel independent of the upper limit; ``Φ_M(t, τ)`` is not,
       so the inequality is closed by this small-gain argument instead. The
       printed exponent also lacks the factor 2 of 4.13.)
    3. ``‖T(σ)‖ ≤ α₁`` (4.4–4.9, 4.15–4.16): with ``Aᵀ = A_Mᵀ − ΔAᵀ`` in 2.13,
       ``T(σ) = T_M(σ) + ∫_0^σ Φ_F(σ,τ) {D (Π − R) − T ΔAᵀ} Φ_M(σ,τ)ᵀ dτ`` where
       ``T_M(σ) = ∫_0^σ Φ_F ΔK C R Φ_Mᵀ dτ`` (4.4, transposed order restored).
       Using ``‖Π − R‖ ≤ ‖Π‖ ≤ β`` (``0 ≤ Π − R ≤ Π``) and γ₁, γ₂ of 4.8–4.9::

           α₂ = sup_σ [‖T_M(σ)‖ + β ∫_0^σ γ₂(σ, τ) dτ],   γ_T = sup_σ ∫_0^σ γ₁(σ, τ) dτ,
           α₁ = α₂ / (1 − γ_T)                                        (4.5–4.6, small gain).

       For the steady-state Kalman–Bucy filter (``horizon=None``) ``T`` is
       constant and the same argument over ``[0, ∞)`` gives α₁ with ``T_M`` the
       solution of ``F_M T_M + T_M A_Mᵀ + ΔK C P = 0``.

    Norms are Frobenius (eq 1.3). The result is a valid upper bound (to quadrature
    accuracy); Table 1's values cannot be regenerated from the printed equations.
    """
    A, C, _, _ = linear_matrices(true)
    A_M, C_M, _, _ = linear_matrices(nominal)
    nA, nC = float(np.linalg.norm(A_M - A)), float(np.linalg.norm(C_M - C))
    w = _Window(true, nominal, horizon, n_steps)
    dK = w.K_M - w.K
    X = w.Phi @ dK
    noise = simpson(np.einsum("jik,kl,jil->j", X, true.R, X), x=w.s)
    fro = np.linalg.norm
    coupling = simpson(fro(np.swapaxes(w.Phi, 1, 2) @ w.Phi, axis=(1, 2)) * nA
                       + fro(w.Phi, axis=(1, 2)) * fro(w.Phi @ w.K_M, axis=(1, 2)) * nC, x=w.s)
    Pi_M = stationary_covariance(nominal)
    lag, E_M = _exp_grid(A_M, w.tail)
    gain_P = 2.0 * nA * simpson(fro(E_M, axis=(1, 2)) ** 2, x=lag)
    beta = fro(Pi_M) / (1.0 - gain_P) if gain_P < 1 else np.inf
    if horizon is None:
        F = A_M - w.K_M[0] @ C_M
        _, E_F = _exp_grid(F, w.tail)
        g = fro(E_M, axis=(1, 2)) * fro(E_F, axis=(1, 2))
        T_M = scipy.linalg.solve_sylvester(F, A_M.T, -dK[0] @ C @ w.R[0])
        alpha2 = fro(T_M) + beta * (nA + fro(w.K_M[0]) * nC) * simpson(g, x=lag)
        gain_T = nA * simpson(g, x=lag)
    else:
        alpha2, gain_T = _fir_T_bound(w, A_M, C, dK, nA, nC, beta)
    alpha1 = alpha2 / (1.0 - gain_T) if gain_T < 1 else np.inf
    value = noise + 2.0 * alpha1 * coupling
    return ModelBound(float(value), float(noise), float(coupling), float(alpha1), float(beta),
                      float(gain_T), float(gain_P))


def corners(box: Mapping[str, float]) -> list[dict[str, float]]:
    """The ``2^d`` corners ``{name: ±half_width}`` of an uncertainty box."""
    names = list(box)
    return [{k: sgn * float(box[k]) for k, sgn in zip(names, signs, strict=True)}
            for signs in itertools.product((1.0, -1.0), repeat=len(names))]


class WorstCase(NamedTuple):
    """The largest exact ``tr(R_r − R)`` over the corners of a box, its corner, and all values."""

    value: float
    corner: dict[str, float]
    values: list[tuple[dict[str, float], float]]


def worst_case(build: Callable[[Mapping[str, float]], tuple[ContinuousModel, ContinuousModel]],
               box: Mapping[str, float], horizon: float | None,
               n_steps: int | None = None) -> WorstCase:
    """Exact ``tr(R_r − R)`` (:func:`error_covariance`) on every corner of ``box``.

    ``box`` maps an uncertainty's name to its half-width ``d`` (the corners are
    ``±d``); ``build(corner)`` returns ``(true, nominal)``. The maximum over the
    corners is the worst case only where ``tr(R_r − R)`` is largest at a vertex;
    it is the value a bound evaluated at the box's edges must exceed.
    """
    values = []
    for corner in corners(box):
        ec = error_covariance(*build(corner), horizon, n_steps)
        values.append((corner, float(np.trace(ec.R_r - ec.R))))
    corner, value = max(values, key=lambda cv: cv[1])
    return WorstCase(value, corner, values)


def _fir_T_bound(w: _Window, A_M: FloatArray, C: FloatArray, dK: FloatArray, nA: float,
                 nC: float, beta: float) -> tuple[float, float]:
    """α₂ and γ_T of step 3 in :func:`delta_pi2` over a finite window (2-D kernels)."""
    if w.fir is None:
        raise ValueError("_fir_T_bound needs a finite horizon")
    fir = w.fir
    N, n = len(w.s) - 1, A_M.shape[0]
    _, E_M = _exp_grid(A_M, w.s[-1], N)              # e^{A_M (σ_i − σ_j)} = E_M[i − j]
    nE_M = np.linalg.norm(E_M, axis=(1, 2))
    Y = dK @ C @ w.R                                   # forcing of T_M: ΔK C R
    nKM = np.linalg.norm(w.K_M, axis=(1, 2))
    rows = np.eye(n)[None]                             # Φ_F(σ_i, σ_j), j = 0..i
    alpha2, gain_T = 0.0, 0.0
    for i in range(N + 1):
        if i:
            rows = np.concatenate([fir.step[i - 1] @ rows, np.eye(n)[None]])
        lags = i - np.arange(i + 1)
        nPhi = np.linalg.norm(rows, axis=(1, 2)) * nE_M[lags]
        T_M = _trapz(rows @ Y[: i + 1] @ np.swapaxes(E_M[lags], 1, 2), w.s[: i + 1])
        g2 = float(_trapz(nPhi * (nA + nKM[: i + 1] * nC), w.s[: i + 1]))
        alpha2 = max(alpha2, float(np.linalg.norm(T_M)) + beta * g2)
        gain_T = max(gain_T, nA * float(_trapz(nPhi, w.s[: i + 1])))
    return alpha2, gain_T


class _Window:
    """Grid quantities of the nominal filter and the true optimal one.

    FIR (finite ``horizon``): window grid ``s = σ``, ``Phi[j] = Φ_F(T, σ_j)``, and the
    nominal filter's solution ``fir``. Kalman (``horizon=None``): lag grid
    ``s ∈ [0, tail]``, ``Phi[j] = e^{F_M s_j}``, constant gains, ``fir = None``; ``tail``
    covers the decay of ``e^{F_M s}`` and ``e^{A_M s}``.
    """

    s: FloatArray
    Phi: FloatArray
    K: FloatArray
    K_M: FloatArray
    R: FloatArray
    tail: float
    fir: FIRSolution | None

    def __init__(self, true: ContinuousModel, nominal: ContinuousModel,
                 horizon: float | None, n_steps: int | None) -> None:
        _, C, _, V = linear_matrices(true)
        A_M, C_M, _, V_M = linear_matrices(nominal)
        if horizon is None:
            P, P_M = kalman_bucy(true), kalman_bucy(nominal)
            K = P @ np.linalg.solve(V, C).T
            K_M = P_M @ np.linalg.solve(V_M, C_M).T
            F = A_M - K_M @ C_M
            self.tail = _tail(A_M, F)
            self.s, self.Phi = _exp_grid(F, self.tail)
            m = len(self.s)
            self.K = np.broadcast_to(K, (m, *K.shape))
            self.K_M = np.broadcast_to(K_M, (m, *K.shape))
            self.R = np.broadcast_to(P, (m, *P.shape))
            self.fir = None
        else:
            N = grid_steps(positive("horizon", horizon), n_steps)
            tru, fir = fir_riccati(true, horizon, N), fir_riccati(nominal, horizon, N)
            self.s, self.Phi, self.K, self.K_M, self.R = (
                tru.sigma, fir.to_end(), tru.K, fir.K, tru.R)
            self.tail = _tail(A_M, A_M)
            self.fir = fir


def _tail(A_M: FloatArray, F: FloatArray) -> float:
    """A lag after which ``e^{A_M s}`` and ``e^{F s}`` have decayed by ``e^{-30}``."""
    rate = -max(np.max(np.linalg.eigvals(A_M).real), np.max(np.linalg.eigvals(F).real))
    if rate <= 0:
        raise ValueError("the nominal A_M and the filter's A_M − K_M C_M must be stable")
    return 30.0 / rate


def _exp_grid(F: FloatArray, length: float, n: int | None = None) -> tuple[FloatArray, FloatArray]:
    """``s_k = k δ`` on ``[0, length]`` and ``e^{F s_k}`` by repeated doubling of ``e^{F δ}``."""
    n = n or max(2000, int(np.ceil(length / 0.05)))
    n += n % 2                                          # even, for Simpson's rule
    s = np.linspace(0.0, length, n + 1)
    E = np.empty((n + 1,) + F.shape)
    E[0] = np.eye(F.shape[0])
    E[1] = scipy.linalg.expm(F * s[1])
    filled = 2
    while filled < n + 1:
        take = min(filled - 1, n + 1 - filled)          # E[1..take] are known
        E[filled:filled + take] = E[filled - 1] @ E[1:take + 1]
        filled += take
    return s, E


def _trapz(f: FloatArray, x: FloatArray) -> FloatArray:
    """The trapezoid rule over the leading axis (a 0-d array for scalar samples)."""
    if len(x) < 2:
        return np.zeros_like(f[0])
    d = np.diff(x)
    return np.tensordot(d, 0.5 * (f[1:] + f[:-1]), axes=(0, 0))


def _rk4(rhs: Callable[[int, FloatArray], FloatArray], y0: FloatArray, d: float, N: int
         ) -> FloatArray:
    """Classical RK4 over ``N`` steps of ``d``; ``rhs(k, y)`` is evaluated on a grid of ``2N``."""
    out = np.empty((N + 1,) + y0.shape)
    out[0] = y = y0
    for j in range(N):
        k = 2 * j
        k1 = rhs(k, y)
        k2 = rhs(k + 1, y + 0.5 * d * k1)
        k3 = rhs(k + 1, y + 0.5 * d * k2)
        k4 = rhs(k + 2, y + d * k3)
        y = y + d / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[j + 1] = y
    return out
