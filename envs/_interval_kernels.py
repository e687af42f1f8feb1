"""The ODE plants' interval maps as compiled loops (numba; ``None`` without it).

One env step of Van der Pol (:mod:`.van_der_pol`) is 100 stochastic Heun substeps
and one of Orbit (:mod:`.orbit`) 100 Euler substeps — ~30 numpy calls each per
substep on a batch, or ~40 µs of Python floats for one system. Each loop here runs
substeps outside and systems inside, so the inner loop has no dependency chain and
vectorises, and does the Python path's operations in the same order: the two give
the same bits (``tests/envs/test_fast_paths.py``).
"""

from __future__ import annotations

import numpy as np

from fir_gym.estimators._compiled import kernel


def _start_loops(u: np.ndarray, n_b: int, scale: float, jacobian: bool
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The scaled first input column per system (``u`` is ``(B, n_u)`` or one row for all)
    and the identity Jacobians the substeps multiply (empty without ``jacobian``)."""
    force = np.empty(n_b)
    for b in range(n_b):
        force[b] = u[b if u.shape[0] == n_b else 0, 0] * scale
    J = np.zeros((n_b, 2, 2) if jacobian else (0, 2, 2))
    for b in range(J.shape[0]):
        J[b, 0, 0] = 1.0
        J[b, 1, 1] = 1.0
    return force, J


_start = kernel(_start_loops)


def _heun_interval(x: np.ndarray, u: np.ndarray, dW: np.ndarray, noisy: bool,
                   substeps: int, eps: float, tau: float, u_max: float, jacobian: bool
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b = x.shape[0]
    force, Phi = _start(u, n_b, u_max, jacobian)
    half = 0.5 * tau
    x1 = x[:, 0].copy()
    x2 = x[:, 1].copy()
    x1_sum = 0.5 * x1
    for s in range(substeps):
        for b in range(n_b):
            dw = dW[s, b] if noisy else 0.0
            u1, u2, fb = x1[b], x2[b], force[b]
            a1 = -u1 + eps * (1.0 - u1 * u1) * u2 + fb
            y1 = u1 + u2 * tau + dw
            y2 = u2 + a1 * tau + dw
            b1 = -y1 + eps * (1.0 - y1 * y1) * y2 + fb
            if jacobian:
                c0, d0 = -1.0 - 2.0 * eps * u1 * u2, eps * (1.0 - u1 * u1)
                c1, d1 = -1.0 - 2.0 * eps * y1 * y2, eps * (1.0 - y1 * y1)
                m11, m12 = 1.0, tau
                m21, m22 = tau * c0, 1.0 + tau * d0
                s11 = 1.0 + half * m21
                s12 = half * (1.0 + m22)
                s21 = half * (c0 + c1 * m11 + d1 * m21)
                s22 = 1.0 + half * (d0 + c1 * m12 + d1 * m22)
                p11, p12 = Phi[b, 0, 0], Phi[b, 0, 1]
                p21, p22 = Phi[b, 1, 0], Phi[b, 1, 1]
                Phi[b, 0, 0] = s11 * p11 + s12 * p21
                Phi[b, 0, 1] = s11 * p12 + s12 * p22
                Phi[b, 1, 0] = s21 * p11 + s22 * p21
                Phi[b, 1, 1] = s21 * p12 + s22 * p22
            x1[b] = u1 + 0.5 * (u2 + y2) * tau + dw
            x2[b] = u2 + 0.5 * (a1 + b1) * tau + dw
            x1_sum[b] = x1_sum[b] + x1[b]
    x_end = np.empty((n_b, 2))
    x_end[:, 0] = x1
    x_end[:, 1] = x2
    return x_end, (x1_sum - 0.5 * x1) / substeps, Phi


#: ``heun_interval(x (B, 2), u (B or 1, n_u), dW (substeps, B), noisy, substeps, ε, τ, u_max,
#: jacobian)
#: -> (x_end (B, 2), mean of x1 (B,), Φ (B, 2, 2) or empty)``; ``None`` without numba
heun_interval = kernel(_heun_interval)


def _orbit_interval(x: np.ndarray, u: np.ndarray, substeps: int, mu: float, d: float,
                    thrust_max: float, jacobian: bool) -> tuple[np.ndarray, np.ndarray]:
    n_b = x.shape[0]
    r = x[:, 0].copy()
    v = x[:, 1].copy()
    a, J = _start(u, n_b, thrust_max, jacobian)
    for _ in range(substeps):
        for b in range(n_b):
            rb, vb = r[b], v[b]
            if jacobian:
                g = 2.0 * mu / (rb * rb * rb) * d
                j11, j12, j21, j22 = J[b, 0, 0], J[b, 0, 1], J[b, 1, 0], J[b, 1, 1]
                J[b, 0, 0] = j11 + d * j21
                J[b, 0, 1] = j12 + d * j22
                J[b, 1, 0] = j21 + g * j11
                J[b, 1, 1] = j22 + g * j12
            r[b] = rb + vb * d
            v[b] = vb + (a[b] - mu / (rb * rb)) * d
    x_next = np.empty((n_b, 2))
    x_next[:, 0] = r
    x_next[:, 1] = v
    return x_next, J


#: ``orbit_interval(x (B, 2), u (B or 1, n_u), substeps, μ, Δ, thrust_max, jacobian)
#: -> (x_next (B, 2), J (B, 2, 2) or empty)``; ``None`` without numba
orbit_interval = kernel(_orbit_interval)
