"""Pendulum-slider ODE of paper 003 (physical reading, with its errata), RK4-discretised.

A slider of mass ``m1`` moves along a horizontal rail on a spring of stiffness
``2k`` and rest length ``l0``; a pendulum (mass ``m2``, centre of mass at distance
``l`` from the hinge, inertia ``I_c`` about it) hangs from the slider with viscous
hinge friction ``M0``; the force ``U`` acts on the slider. With the pendulum's
centre of mass at ``(x − l sinθ, −l cosθ)`` the Lagrangian gives (paper 003,
eq 15 corrected: centripetal term ``+m2 l sinθ θ̇²`` on the left, where the paper
prints the opposite sign, and ``I_c + m2 l²`` where it prints ``m1 l²``):

    (m1+m2) ẍ + (−m2 l cosθ + s μ m2 l sinθ) θ̈ = U − 2k (x − l0) − m2 l sinθ θ̇²
                                                   − s μ ((m1+m2) g + m2 l cosθ θ̇²)
    −m2 l cosθ ẍ + (I_c + m2 l²) θ̈ = −M0 θ̇ − m2 g l sinθ

The ``μ`` terms are ``s μ N`` with the rail's normal force
``N = (m1+m2) g + m2 l (sinθ θ̈ + cosθ θ̇²)``; ``s`` is the friction mode:

* ``"paper"`` — ``s = 1``: the paper's sign-free term. It is a constant push
  that moves the rest position from ``l0`` = 25 mm to about 10.8 mm (it is
  not friction, and it is why ``μ`` is easy to identify);
* ``"coulomb"`` — ``s = tanh(ẋ / v_c)`` with ``coulomb_velocity = v_c``
  (default 0.01 m/s, smooth so that RK4 and the Jacobian stay accurate; the
  slope ``μN/v_c`` must stay below RK4's stability limit ``≈ 2.8 (m1+m2)/dt``),
  or the exact ``sign(ẋ)`` when ``coulomb_velocity = 0`` (stick-slip is then not
  resolved and the Jacobian ignores the jump);
* ``"none"`` — ``s = 0``.

**Printed equations** (``equations``; docs/papers.md#003-printed-equations and
docs/papers.md#003-eq-15). Paper 003 prints two other versions of these equations, both
unphysical, offered to run its experiment as printed:

* ``"printed-eq15"`` — eq (15), the state-space form the paper's UKF uses: the
  coupling ``−m2 l (cosθ − μ sinθ)`` is the Lagrangian's, but the centripetal term
  has the opposite sign (``+m2 l sinθ θ̇²`` on the right-hand side) and the hinge
  inertia is ``I_c + m1 l²`` (``m1`` where the Lagrangian gives ``m2``);
* ``"printed-eq5"`` — eq (5): as eq (15), and the slider's row couples through
  ``+m2 l (cosθ + μ sinθ) θ̈`` while the pendulum's row has ``−m2 l cosθ ẍ``: the
  mass matrix is not symmetric, so the model creates energy.

With ``σ_c`` the sign of the centripetal term on the right-hand side, ``σ_x`` that
of ``m2 l cosθ`` in the slider row's coupling and ``J`` the hinge inertia, all three
are ``M12 = σ_x m2 l cosθ + s μ m2 l sinθ``, ``M22 = J`` and
``b1 = U − 2k (x − l0) + σ_c m2 l sinθ θ̇² − s μ ((m1+m2) g + m2 l cosθ θ̇²)``:
physical ``(σ_c, σ_x, J) = (−1, −1, I_c + m2 l²)``, eq 15 ``(+1, −1, I_c + m1 l²)``,
eq 5 ``(+1, +1, I_c + m1 l²)``. The printed equations carry the paper's sign-free
friction term (``friction="paper"`` only).

One step integrates the ODE over ``dt`` with ``substeps`` classical RK4 steps,
the input held. The Jacobians are those of the RK4 map itself (stage-wise
sensitivity propagation of the analytic ODE Jacobian), exact to round-off.
Pure numpy: usable by the MuJoCo plant and by filters alike; picklable.
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike

from fir_gym.estimators import compiled
from fir_gym.estimators._validation import FloatArray, one_of, positive
from fir_gym.estimators.augment import ParametricModel

from ._interval_kernels import slider_rk4

#: Table 3 of paper 003
PAPER_PARAMS: dict[str, float] = {"m1": 0.654, "m2": 0.7925, "l": 0.2, "I_c": 0.0014, "k": 100.0,
                                  "l0": 0.025, "M0": 0.2, "mu": 0.2, "g": 9.8}
FRICTION_MODES = ("paper", "coulomb", "none")
#: the equations of motion: the Lagrangian's, and paper 003's printed eqs (15) and (5)
EQUATIONS = ("physical", "printed-eq15", "printed-eq5")
#: (σ_c, σ_x, hinge inertia uses m1) of each (module docstring)
_EQUATION_SIGNS = {"physical": (-1.0, -1.0, False), "printed-eq15": (1.0, -1.0, True),
                   "printed-eq5": (1.0, 1.0, True)}


class PendulumSliderDynamics:
    """The pendulum-slider ODE, its RK4 step and exact Jacobians (batched over a leading axis).

    State ``[x, ẋ, θ, θ̇]`` (m, m/s, rad, rad/s), input ``u = [U / input_scale]``,
    estimable parameters ``θ_p = [μ, M0]`` (:attr:`param_names`).

    Args:
        m1, m2, l, I_c, k, l0, M0, mu, g: physical parameters (defaults: paper 003, Table 3).
        dt: step length (s); substeps: RK4 steps per step.
        friction: ``"paper"``, ``"coulomb"`` or ``"none"`` (module docstring).
        equations: ``"physical"`` (default) or paper 003's printed ``"printed-eq15"`` /
            ``"printed-eq5"`` (unphysical; module docstring; numpy path only).
        coulomb_velocity: smoothing velocity of the Coulomb mode (0 for exact sign).
        input_scale: newtons per unit of input (the env's action scaling).
    """

    param_names = ("mu", "M0")

    def __init__(self, *, m1: float = 0.654, m2: float = 0.7925, l: float = 0.2,
                 I_c: float = 0.0014, k: float = 100.0, l0: float = 0.025, M0: float = 0.2,
                 mu: float = 0.2, g: float = 9.8, dt: float = 1e-3, substeps: int = 1,
                 friction: str = "paper", coulomb_velocity: float = 0.01,
                 input_scale: float = 1.0, equations: str = "physical") -> None:
        for name, val in (("m1", m1), ("m2", m2), ("l", l), ("k", k), ("g", g)):
            positive(name, val)
        for name, val in (("I_c", I_c), ("M0", M0), ("mu", mu), ("l0", l0),
                          ("coulomb_velocity", coulomb_velocity)):
            if not np.isfinite(val) or (name != "l0" and val < 0):
                raise ValueError(f"{name} must be a finite non-negative number; got {val!r}")
        one_of("friction", friction, FRICTION_MODES)
        self.equations = one_of("equations", equations, EQUATIONS)
        if equations != "physical" and friction != "paper":
            raise ValueError(f"equations={equations!r} carries paper 003's own friction term; "
                             f"friction must be 'paper', got {friction!r}")
        self._centripetal, self._coupling, m1_inertia = _EQUATION_SIGNS[equations]
        #: ``J``, the pendulum's inertia about the hinge in these equations
        self.hinge_inertia = I_c + (m1 if m1_inertia else m2) * l * l
        self.m1, self.m2, self.l, self.I_c, self.k, self.l0 = m1, m2, l, I_c, k, l0
        self.M0, self.mu, self.g = M0, mu, g
        self.dt = positive("dt", dt)
        self.substeps = positive("substeps", substeps, integer=True)
        self.friction, self.coulomb_velocity = friction, float(coulomb_velocity)
        self.input_scale = float(input_scale)
        #: the compiled step's constants ``[m1, m2, l, g, k, l0, I_c, v_c]`` and friction code
        self._kernel_constants = (np.array([m1, m2, l, g, k, l0, I_c, self.coulomb_velocity],
                                           dtype=np.float64), FRICTION_MODES.index(friction))

    @property
    def theta(self) -> FloatArray:
        """Nominal ``[μ, M0]``."""
        return np.array([self.mu, self.M0])

    # ------------------------------------------------------------------ the ODE
    def _friction_sign(self, xd: FloatArray) -> tuple[Any, Any]:
        if self.friction == "paper":
            return 1.0, 0.0
        if self.friction == "none":
            return 0.0, 0.0
        if self.coulomb_velocity == 0.0:
            return np.sign(xd), 0.0
        t = np.tanh(xd / self.coulomb_velocity)
        return t, (1.0 - t * t) / self.coulomb_velocity

    def derivatives(self, z: FloatArray, U: FloatArray, mu: FloatArray, M0: FloatArray,
                    jacobian: bool = False) -> tuple[FloatArray, FloatArray | None,
                                                     FloatArray | None]:
        """``ż = a(z, U, μ, M0)`` and, if asked, ``∂a/∂z (…, 4, 4)`` and ``∂a/∂[μ, M0] (…, 4, 2)``.

        ``U`` is the force in newtons. ``∂q̈/∂v = M⁻¹ (∂b/∂v − (∂M/∂v) q̈)`` for the
        mass matrix ``M`` and right-hand side ``b`` of the equations above.
        """
        m1, m2, l, g, k = self.m1, self.m2, self.l, self.g, self.k
        xd, th, w = z[..., 1], z[..., 2], z[..., 3]
        c, sn = np.cos(th), np.sin(th)
        s, ds = self._friction_sign(xd)
        mt, m2l = m1 + m2, m2 * l
        sc, sx = self._centripetal, self._coupling
        N0 = mt * g + m2l * c * w * w                  # normal force without the θ̈ part
        M11 = mt
        M22 = self.I_c + m2l * l if self.equations == "physical" else self.hinge_inertia
        M12 = sx * m2l * c + s * mu * m2l * sn
        M21 = -m2l * c
        b1 = U - 2.0 * k * (z[..., 0] - self.l0) + sc * m2l * sn * w * w - s * mu * N0
        b2 = -M0 * w - m2l * g * sn
        det = M11 * M22 - M12 * M21
        xdd = (M22 * b1 - M12 * b2) / det
        thdd = (M11 * b2 - M21 * b1) / det
        a = np.stack([xd, xdd, w, thdd], axis=-1)
        if not jacobian:
            return a, None, None
        zero = np.zeros_like(xdd)
        # columns: x, ẋ, θ, θ̇, μ, M0 — (∂b1/∂v − ∂M12/∂v θ̈, ∂b2/∂v − ∂M21/∂v ẍ)
        r1 = [zero - 2.0 * k,
              -mu * ds * N0 - mu * ds * m2l * sn * thdd,
              sc * m2l * c * w * w + s * mu * m2l * sn * w * w
              + (sx * m2l * sn - s * mu * m2l * c) * thdd,
              2.0 * m2l * w * (sc * sn - s * mu * c),
              -s * N0 - s * m2l * sn * thdd,
              zero]
        r2 = [zero, zero, -m2l * g * c - m2l * sn * xdd, zero - M0, zero, -w]
        R1, R2 = np.stack(r1, axis=-1), np.stack(r2, axis=-1)          # (…, 6)
        dxdd = (M22 * R1 - M12[..., None] * R2) / det[..., None]
        dthdd = (M11 * R2 - M21[..., None] * R1) / det[..., None]
        J = np.zeros(z.shape[:-1] + (4, 6))
        J[..., 0, 1] = 1.0
        J[..., 2, 3] = 1.0
        J[..., 1, :] = dxdd
        J[..., 3, :] = dthdd
        return a, J[..., :4], J[..., 4:]

    def propagate(self, x: FloatArray, u: FloatArray, theta: FloatArray, jacobian: bool = False
                  ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """One step of RK4 (``substeps`` times); with ``jacobian``, ``∂/∂x`` and ``∂/∂[μ, M0]``.

        With numba the same loop runs compiled, system by system
        (:func:`~._interval_kernels.slider_rk4`; equal to round-off, tested) — for the
        physical equations; the printed ones run this numpy loop.
        """
        if self.equations == "physical" and compiled.ENABLED:
            return self._propagate_compiled(x, u, theta, jacobian)
        U = self.input_scale * u[..., 0]
        theta = np.broadcast_to(theta, x.shape[:-1] + (2,))
        mu, M0 = theta[..., 0], theta[..., 1]
        h = self.dt / self.substeps
        z = x
        if jacobian:
            Fz = np.broadcast_to(np.eye(4), x.shape[:-1] + (4, 4)).copy()
            Fp = np.zeros(x.shape[:-1] + (4, 2))
        for _ in range(self.substeps):
            stages: list[FloatArray] = []
            Sz: list[FloatArray] = []
            Sp: list[FloatArray] = []
            for coef in (0.0, 0.5, 0.5, 1.0):
                zi = z if coef == 0.0 else z + (coef * h) * stages[-1]
                a, Az, Ap = self.derivatives(zi, U, mu, M0, jacobian)
                stages.append(a)
                if jacobian:
                    # ∂k_i/∂z0 = A_i (I + c h ∂k_{i-1}/∂z0);  ∂k_i/∂p = A_i c h ∂k_{i-1}/∂p + B_i
                    dz = Fz if coef == 0.0 else Fz + (coef * h) * Sz[-1]
                    dp = Fp if coef == 0.0 else Fp + (coef * h) * Sp[-1]
                    Az, Ap = cast(FloatArray, Az), cast(FloatArray, Ap)   # given: jacobian
                    Sz.append(Az @ dz)
                    Sp.append(Az @ dp + Ap)
            z = z + (h / 6.0) * (stages[0] + 2.0 * stages[1] + 2.0 * stages[2] + stages[3])
            if jacobian:
                Fz = Fz + (h / 6.0) * (Sz[0] + 2.0 * Sz[1] + 2.0 * Sz[2] + Sz[3])
                Fp = Fp + (h / 6.0) * (Sp[0] + 2.0 * Sp[1] + 2.0 * Sp[2] + Sp[3])
        return (z, Fz, Fp) if jacobian else (z, None, None)

    def _propagate_compiled(self, x: FloatArray, u: FloatArray, theta: FloatArray,
                            jacobian: bool) -> tuple[FloatArray, FloatArray | None,
                                                     FloatArray | None]:
        lead = x.shape[:-1]
        U = self.input_scale * np.asarray(u, dtype=np.float64)[..., 0]
        consts, friction = self._kernel_constants
        z, Fz, Fp = slider_rk4(np.asarray(x, dtype=np.float64).reshape(-1, 4),
                               np.ascontiguousarray(U).reshape(-1),
                               np.asarray(theta, dtype=np.float64).reshape(-1, 2), consts,
                               friction, self.dt / self.substeps, self.substeps, jacobian)
        if not jacobian:
            return z.reshape(lead + (4,)), None, None
        return z.reshape(lead + (4,)), Fz.reshape(lead + (4, 4)), Fp.reshape(lead + (4, 2))

    # ------------------------------------------------------------------ model callables
    def f_theta(self, x: FloatArray, u: FloatArray, theta: FloatArray) -> FloatArray:
        return self.propagate(x, u, theta)[0]

    def jac_f(self, x: FloatArray, u: FloatArray, theta: FloatArray
              ) -> tuple[FloatArray, FloatArray]:
        _, Fz, Fp = self.propagate(x, u, theta, jacobian=True)
        return cast(FloatArray, Fz), cast(FloatArray, Fp)           # not None: jacobian

    def f_jac_f(self, x: FloatArray, u: FloatArray, theta: FloatArray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``f`` and its Jacobians in one RK4 pass (``f`` is computed the same either way)."""
        z, Fz, Fp = self.propagate(x, u, theta, jacobian=True)
        return z, Fz, Fp                                        # type: ignore[return-value]

    def f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.f_theta(x, u, self.theta)

    def F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.jac_f(x, u, self.theta)[0]

    @staticmethod
    def h_theta(x: FloatArray, theta: FloatArray) -> FloatArray:
        return np.array(x, dtype=np.float64, copy=True)

    @staticmethod
    def jac_h(x: FloatArray, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        lead = np.shape(x)[:-1]
        return np.broadcast_to(np.eye(4), lead + (4, 4)), np.zeros(lead + (4, 2))

    def energy(self, x: ArrayLike) -> FloatArray:
        """Mechanical energy (kinetic + gravity + spring) of states ``(…, 4)``, in joules.

        The Lagrangian's (physical) energy, whatever :attr:`equations`: the printed
        equations do not conserve it (eq 5 creates energy).
        """
        x = np.asarray(x, dtype=np.float64)
        xd, th, w = x[..., 1], x[..., 2], x[..., 3]
        m2l = self.m2 * self.l
        kinetic = (0.5 * (self.m1 + self.m2) * xd**2 - m2l * np.cos(th) * xd * w
                   + 0.5 * (self.I_c + m2l * self.l) * w**2)
        return kinetic - m2l * self.g * np.cos(th) + self.k * (x[..., 0] - self.l0) ** 2

    def least_squares_parameters(self, y: ArrayLike, U: ArrayLike,
                                 difference: str = "backward") -> dict[str, float]:
        """Paper 003's LSM: ``μ`` and ``M0`` by least squares on the equations of motion.

        Both equations of motion are linear in one parameter each (paper mode, ``s = 1``):

            μ · N_k  = U_k − 2k (x − l0) − m2 l sinθ θ̇² − (m1+m2) ẍ + m2 l cosθ θ̈
            M0 · θ̇_k = −m2 g l sinθ − (I_c + m2 l²) θ̈ + m2 l cosθ ẍ

        (the printed equations change the signs ``σ_c``, ``σ_x`` and the inertia ``J`` of
        the module docstring: ``+ σ_c m2 l sinθ θ̇² − σ_x m2 l cosθ θ̈`` and ``− J θ̈``)

        with the normal force ``N = (m1+m2) g + m2 l (cosθ θ̇² + sinθ θ̈)``, so each
        parameter is one scalar regression, ``Σ φ r / Σ φ²``. The states are the
        measurements ``y[k]`` (all four measured); the accelerations are finite
        differences of the measured velocities:

        * ``"backward"``: ``(v_k − v_{k−1}) / dt`` — the noise of ``θ̇_k`` enters both the
          regressor ``θ̇_k`` and the target (through ``θ̈_k``), so the estimate of M0 is
          biased by about ``−(I_c + m2 l²) σ²_θ̇ / (dt E[θ̇²])``: the size and sign of
          paper 003's Table 5 (−0.7251);
        * ``"forward"``: ``(v_{k+1} − v_k) / dt`` — the same correlation, opposite sign;
        * ``"central"``: ``(v_{k+1} − v_{k−1}) / (2 dt)`` — independent of ``v_k``, so
          nearly unbiased (what remains is the errors-in-variables attenuation).

        ``U[k]`` is the force (N) held from sample ``k`` to ``k+1``; the equation at
        sample ``k`` uses the force acting around it: ``U[k−1]`` for backward
        differences, ``U[k]`` for forward ones, their mean for central ones.

        Args:
            y: measured states ``(K, 4)`` at this model's ``dt``.
            U: forces ``(K − 1,)`` or ``(K,)`` in newtons.
            difference: ``"backward"``, ``"forward"`` or ``"central"``.
        """
        Y = np.asarray(y, dtype=np.float64)
        F = np.asarray(U, dtype=np.float64).reshape(-1)
        if Y.ndim != 2 or Y.shape[1] != 4 or Y.shape[0] < 3:
            raise ValueError(f"y must have shape (K, 4) with K >= 3; got {Y.shape}")
        if F.shape[0] not in (Y.shape[0] - 1, Y.shape[0]):
            raise ValueError(f"U must have K - 1 = {Y.shape[0] - 1} or K entries; got {F.shape[0]}")
        if not (np.isfinite(Y).all() and np.isfinite(F).all()):
            raise ValueError("y and U must be finite")
        dt = self.dt                                     # one model step = one sample
        v = Y[:, [1, 3]]
        if difference == "backward":
            idx = np.arange(1, Y.shape[0])
            acc, force = (v[idx] - v[idx - 1]) / dt, F[idx - 1]
        elif difference == "forward":
            idx = np.arange(0, Y.shape[0] - 1)
            acc, force = (v[idx + 1] - v[idx]) / dt, F[idx]
        elif difference == "central":
            idx = np.arange(1, Y.shape[0] - 1)
            acc, force = (v[idx + 1] - v[idx - 1]) / (2.0 * dt), 0.5 * (F[idx - 1] + F[idx])
        else:
            raise ValueError(f"difference must be 'backward', 'forward' or 'central'; "
                             f"got {difference!r}")
        x, th, w = Y[idx, 0], Y[idx, 2], Y[idx, 3]
        xdd, thdd = acc[:, 0], acc[:, 1]
        m1, m2, l, g = self.m1, self.m2, self.l, self.g
        m2l, sn, c = m2 * l, np.sin(th), np.cos(th)
        normal = (m1 + m2) * g + m2l * (c * w * w + sn * thdd)
        sc, sx = self._centripetal, self._coupling
        J = self.I_c + m2l * l if self.equations == "physical" else self.hinge_inertia
        r1 = force - 2.0 * self.k * (x - self.l0) + sc * m2l * sn * w * w - (m1 + m2) * xdd \
            - sx * m2l * c * thdd
        r2 = -m2l * g * sn - J * thdd + m2l * c * xdd
        return {"mu": float(normal @ r1 / (normal @ normal)), "M0": float(w @ r2 / (w @ w))}

    def model(self, Q: ArrayLike = 1e-6, R: ArrayLike = (0.003**2, 0.03**2, 0.03**2, 0.3**2),
              name: str | None = None) -> ParametricModel:
        """The filter's :class:`ParametricModel` (all four states measured, eq 17–18 defaults).

        ``Q`` (scalar = per state, vector = diagonal, or matrix) and ``R`` default to
        paper 003's eqs 17–18: ``Q = 1e-6 I``, ``R = diag([0.003, 0.03, 0.03, 0.3]²)``.
        """
        Q_ = np.full(4, float(np.asarray(Q))) if np.ndim(Q) == 0 else Q
        return ParametricModel(f=self.f_theta, h=self.h_theta,
                               params={"mu": self.mu, "M0": self.M0}, Q=Q_, R=R, dt=self.dt,
                               jac_f=self.jac_f, jac_h=self.jac_h, n_u=1,
                               name=name or (f"PendulumSlider({self.friction})"
                                             if self.equations == "physical" else
                                             f"PendulumSlider({self.equations})"),
                               f_jac_f=self.f_jac_f)
