"""The ODE plants' interval maps as compiled loops (numba; see ``fir_gym.estimators.compiled``).

One env step of Van der Pol (:mod:`.van_der_pol`) is 100 stochastic Heun substeps
and one of Orbit (:mod:`.orbit`) 100 Euler substeps — ~30 numpy calls each per
substep on a batch, or ~40 µs of Python floats for one system. Each loop here runs
substeps outside and systems inside, so the inner loop has no dependency chain and
vectorises, and does the Python path's operations in the same order: the two give
the same bits (``tests/envs/test_fast_paths.py``).

Without numba each name holds the uncompiled loop (:func:`fir_gym.estimators.compiled.jit`),
so calls type-check; callers dispatch on ``compiled.ENABLED``, which is False then, and
take their numpy path.
"""

from __future__ import annotations

import numpy as np

from fir_gym.estimators.compiled import jit


def _start_loops(u: np.ndarray, n_b: int, scale: np.ndarray, jacobian: bool
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The scaled first input column per system (``u`` is ``(B, n_u)`` or one row for all;
    ``scale`` ``(B,)`` or one for all) and the identity Jacobians the substeps multiply
    (empty without ``jacobian``)."""
    force = np.empty(n_b)
    for b in range(n_b):
        force[b] = u[b if u.shape[0] == n_b else 0, 0] * scale[b if scale.shape[0] == n_b
                                                               else 0]
    J = np.zeros((n_b, 2, 2) if jacobian else (0, 2, 2))
    for b in range(J.shape[0]):
        J[b, 0, 0] = 1.0
        J[b, 1, 1] = 1.0
    return force, J


_start = jit(_start_loops)


def _heun_interval(x: np.ndarray, u: np.ndarray, dW: np.ndarray, noisy: bool,
                   substeps: int, epsilon: np.ndarray, tau: float, u_max: np.ndarray,
                   jacobian: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b = x.shape[0]
    force, Phi = _start(u, n_b, u_max, jacobian)
    half = 0.5 * tau
    x1 = x[:, 0].copy()
    x2 = x[:, 1].copy()
    x1_sum = 0.5 * x1
    for s in range(substeps):
        for b in range(n_b):
            eps = epsilon[b if epsilon.shape[0] == n_b else 0]
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


#: ``heun_interval(x (B, 2), u (B or 1, n_u), dW (substeps, B), noisy, substeps, ε (B or 1,),
#: τ, u_max (B or 1,), jacobian)
#: -> (x_end (B, 2), mean of x1 (B,), Φ (B, 2, 2) or empty)``
heun_interval = jit(_heun_interval)


def _orbit_interval(x: np.ndarray, u: np.ndarray, substeps: int, mu_: np.ndarray, d: float,
                    thrust_max: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray]:
    n_b = x.shape[0]
    r = x[:, 0].copy()
    v = x[:, 1].copy()
    a, J = _start(u, n_b, thrust_max, jacobian)
    for _ in range(substeps):
        for b in range(n_b):
            mu = mu_[b if mu_.shape[0] == n_b else 0]
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


#: ``orbit_interval(x (B, 2), u (B or 1, n_u), substeps, μ (B or 1,), Δ, thrust_max (B or 1,),
#: jacobian)
#: -> (x_next (B, 2), J (B, 2, 2) or empty)``
orbit_interval = jit(_orbit_interval)


def _slider_derivatives(z: np.ndarray, U: float, mu: float, M0: float, c_: np.ndarray,
                        friction: int, jacobian: bool, a: np.ndarray, J: np.ndarray) -> None:
    """:meth:`PendulumSliderDynamics.derivatives` for one system: ``a`` (4,) and, with
    ``jacobian``, ``J = ∂a/∂[z, μ, M0]`` (4, 6), written in place; the same formulas.
    ``c_`` holds ``[m1, m2, l, g, k, l0, I_c, v_c]``; ``friction`` indexes
    ``FRICTION_MODES``: 0 paper, 1 Coulomb, 2 none."""
    m1, m2, l, g, k, l0, I_c, v_c = c_[0], c_[1], c_[2], c_[3], c_[4], c_[5], c_[6], c_[7]
    xd, th, w = z[1], z[2], z[3]
    c, sn = np.cos(th), np.sin(th)
    if friction == 0:
        s, ds = 1.0, 0.0
    elif friction == 2:
        s, ds = 0.0, 0.0
    elif v_c == 0.0:
        s, ds = np.sign(xd), 0.0
    else:
        t = np.tanh(xd / v_c)
        s, ds = t, (1.0 - t * t) / v_c
    mt, m2l = m1 + m2, m2 * l
    N0 = mt * g + m2l * c * w * w
    M11, M22 = mt, I_c + m2l * l
    M12 = -m2l * c + s * mu * m2l * sn
    M21 = -m2l * c
    b1 = U - 2.0 * k * (z[0] - l0) - m2l * sn * w * w - s * mu * N0
    b2 = -M0 * w - m2l * g * sn
    det = M11 * M22 - M12 * M21
    xdd = (M22 * b1 - M12 * b2) / det
    thdd = (M11 * b2 - M21 * b1) / det
    a[0], a[1], a[2], a[3] = xd, xdd, w, thdd
    if not jacobian:
        return
    r1_0 = 0.0 - 2.0 * k
    r1_1 = -mu * ds * N0 - mu * ds * m2l * sn * thdd
    r1_2 = -m2l * c * w * w + s * mu * m2l * sn * w * w - (m2l * sn + s * mu * m2l * c) * thdd
    r1_3 = -2.0 * m2l * w * (sn + s * mu * c)
    r1_4 = -s * N0 - s * m2l * sn * thdd
    r2_2 = -m2l * g * c - m2l * sn * xdd
    r2_3 = 0.0 - M0
    r2_5 = -w
    R1 = (r1_0, r1_1, r1_2, r1_3, r1_4, 0.0)
    R2 = (0.0, 0.0, r2_2, r2_3, 0.0, r2_5)
    for j in range(6):
        J[0, j] = 1.0 if j == 1 else 0.0
        J[2, j] = 1.0 if j == 3 else 0.0
        J[1, j] = (M22 * R1[j] - M12 * R2[j]) / det
        J[3, j] = (M11 * R2[j] - M21 * R1[j]) / det


_slider_derivatives_compiled = jit(_slider_derivatives)


def _slider_rk4(x: np.ndarray, U: np.ndarray, theta: np.ndarray, c_: np.ndarray,
                friction: int, h: float, substeps: int, jacobian: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_b = x.shape[0]
    z_out = np.empty((n_b, 4))
    Fz_out = np.zeros((n_b, 4, 4) if jacobian else (0, 4, 4))
    Fp_out = np.zeros((n_b, 4, 2) if jacobian else (0, 4, 2))
    z, zi = np.empty(4), np.empty(4)
    K = np.empty((4, 4))                        # the stages k_i
    Sz, Sp = np.empty((4, 4, 4)), np.empty((4, 4, 2))
    Fz, Fp = np.empty((4, 4)), np.empty((4, 2))
    dz, dp = np.empty((4, 4)), np.empty((4, 2))
    J = np.empty((4, 6))
    coefs = (0.0, 0.5, 0.5, 1.0)
    for b in range(n_b):
        mu = theta[b if theta.shape[0] == n_b else 0, 0]
        M0 = theta[b if theta.shape[0] == n_b else 0, 1]
        Ub = U[b if U.shape[0] == n_b else 0]
        z[:] = x[b]
        if jacobian:
            Fz[:, :] = 0.0
            for i in range(4):
                Fz[i, i] = 1.0
            Fp[:, :] = 0.0
        for _ in range(substeps):
            for st in range(4):
                coef = coefs[st]
                for i in range(4):
                    zi[i] = z[i] if coef == 0.0 else z[i] + (coef * h) * K[st - 1, i]
                _slider_derivatives_compiled(zi, Ub, mu, M0, c_, friction, jacobian, K[st], J)
                if jacobian:        # ∂k_i/∂z0 = A_i (I + c h ∂k_{i-1}/∂z0), ∂k_i/∂p likewise
                    for i in range(4):
                        for j in range(4):
                            dz[i, j] = Fz[i, j] if coef == 0.0 else \
                                Fz[i, j] + (coef * h) * Sz[st - 1, i, j]
                        for j in range(2):
                            dp[i, j] = Fp[i, j] if coef == 0.0 else \
                                Fp[i, j] + (coef * h) * Sp[st - 1, i, j]
                    for i in range(4):
                        for j in range(4):
                            v = 0.0
                            for q in range(4):
                                v += J[i, q] * dz[q, j]
                            Sz[st, i, j] = v
                        for j in range(2):
                            v = 0.0
                            for q in range(4):
                                v += J[i, q] * dp[q, j]
                            Sp[st, i, j] = v + J[i, 4 + j]
            for i in range(4):
                z[i] = z[i] + (h / 6.0) * (K[0, i] + 2.0 * K[1, i] + 2.0 * K[2, i] + K[3, i])
            if jacobian:
                for i in range(4):
                    for j in range(4):
                        Fz[i, j] = Fz[i, j] + (h / 6.0) * (
                            Sz[0, i, j] + 2.0 * Sz[1, i, j] + 2.0 * Sz[2, i, j] + Sz[3, i, j])
                    for j in range(2):
                        Fp[i, j] = Fp[i, j] + (h / 6.0) * (
                            Sp[0, i, j] + 2.0 * Sp[1, i, j] + 2.0 * Sp[2, i, j] + Sp[3, i, j])
        z_out[b] = z
        if jacobian:
            Fz_out[b] = Fz
            Fp_out[b] = Fp
    return z_out, Fz_out, Fp_out


#: ``slider_rk4(x (B, 4), U (B or 1,) newtons, θ (B or 1, 2) = [μ, M0], constants, friction
#: code, h, substeps, jacobian) -> (z (B, 4), ∂z/∂x (B, 4, 4), ∂z/∂θ (B, 4, 2))``: paper
#: 003's RK4 step with its stage-wise exact Jacobians
slider_rk4 = jit(_slider_rk4)
