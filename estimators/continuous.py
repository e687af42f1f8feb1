"""A continuous-time model for the continuous(-discrete) filters of papers 001 and 002.

The plant is the Itô system

    dx = a(x, u) dt + G dw,        E[dw dwᵀ] = Q dt      (Q: spectral density of w)
    dz = h(x) dt + dv,             E[dv dvᵀ] = R dt      (R: measurement intensity)

(paper 002, eq 3.1; paper 001, eq 2.1 with ``a = A x``, ``h = C x``, ``V = R``).
The measurement is continuous; a sampled filter receives, every ``dt`` seconds,
its block-pulse coefficient — the interval average

    ȳ[k] = (1/dt) ∫_{t_{k-1}}^{t_k} dz = (1/dt) ∫ h(x) dt + v̄[k],   v̄[k] ~ N(0, R/dt)

(paper 002's "BPF coefficient of z"; see docs/papers.md#002-interval-average). The block-pulse
filter additionally needs a state-dependent factorisation ``A(x)`` with
``a(x, 0) = A(x) x`` (Pearson's form, paper 002 eq 2.2); the model carries it
when the plant provides one.

Every callable accepts ``x`` of shape ``(n_x,)`` or ``(B, n_x)`` and ``u`` of
shape ``(n_u,)`` or ``(B, n_u)``; results keep the leading shape.
:meth:`ContinuousModel.sampled` gives the discrete-time
:class:`~fir_gym.estimators.StateSpaceModel` view that the
:class:`~fir_gym.estimators.Estimator` base (and any discrete filter) reads.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_batch, as_matrix, positive
from .discretize import integrated_noise
from .model import StateSpaceModel, _central_jacobian, _ModelCore

__all__ = ["ContinuousModel"]

Drift = Callable[[FloatArray, FloatArray], FloatArray]
Output = Callable[[FloatArray], FloatArray]


class ContinuousModel(_ModelCore):
    """Continuous-time model ``dx = a(x, u) dt + G dw``, ``dz = h(x) dt + dv``.

    Args:
        a: drift ``a(x, u) -> ẋ``, batched; always receives ``u`` of shape
            ``(..., n_u)`` (zeros when the caller passes ``None``).
        h: measurement function ``h(x)``, batched.
        Q: spectral density of ``w`` (``n_w x n_w``; a scalar or a 1-D array of
            densities is accepted), positive semi-definite.
        R: intensity of the measurement noise ``v`` (``n_y x n_y``), positive
            definite (the continuous filters use ``R⁻¹``).
        dt: the sample period of the data — the length of one block-pulse
            interval; the interval-average measurement has covariance ``R/dt``.
        J: Jacobian ``∂a/∂x (x, u)``, shape ``(..., n_x, n_x)``; central finite
            differences when omitted.
        H: Jacobian ``∂h/∂x (x)``, shape ``(..., n_y, n_x)``; same fallback.
        A_of_x: factorisation ``A(x)`` with ``a(x, 0) = A(x) x`` (paper 002,
            eq 2.2), shape ``(..., n_x, n_x)``; needed by the block-pulse filter.
        G: noise input ``(n_x, n_w)``; defaults to the identity.
        n_u: number of inputs.
        name: a label for ``repr`` and reports.

    ``n_x`` comes from ``G`` (or ``Q`` when ``G`` is absent), ``n_y`` from ``R``.
    """

    def __init__(
        self,
        *,
        a: Drift,
        h: Output,
        Q: ArrayLike,
        R: ArrayLike,
        dt: float,
        J: Drift | None = None,
        H: Output | None = None,
        A_of_x: Output | None = None,
        G: ArrayLike | None = None,
        n_u: int = 0,
        name: str | None = None,
    ) -> None:
        self._set_core(required={"a": a, "h": h}, optional={"J": J, "H": H, "A_of_x": A_of_x},
                       Q=Q, R=R, G=G, n_u=n_u, dt=dt, name=name, definite_R=True)
        self._a, self._h, self._J, self._H, self._A_of_x = a, h, J, H, A_of_x
        #: ``R⁻¹`` (from a Cholesky solve); ``GQGT`` is the state noise intensity
        chol = np.linalg.cholesky(self.R)
        self.R_inv = _readonly(np.linalg.solve(chol.T, np.linalg.solve(chol, np.eye(self.n_y))))
        # linear models (see ContinuousModel.linear) set these
        self.A: FloatArray | None = None
        self.B: FloatArray | None = None
        self.C: FloatArray | None = None

    @classmethod
    def linear(
        cls,
        *,
        A: ArrayLike,
        C: ArrayLike,
        Q: ArrayLike,
        R: ArrayLike,
        dt: float,
        B: ArrayLike | None = None,
        G: ArrayLike | None = None,
        name: str | None = None,
    ) -> ContinuousModel:
        """The linear model ``ẋ = A x + B u + G w``, ``z = C x + v`` (paper 001, eq 2.1).

        Its factorisation is ``A(x) = A`` and its Jacobians are ``A`` and ``C``.
        """
        A_ = as_matrix("A", A, (None, None))
        n = A_.shape[0]
        if A_.shape != (n, n):
            raise ValueError(f"A must be square; got shape {A_.shape}")
        C_ = as_matrix("C", np.atleast_2d(C), (None, n))
        B_ = np.zeros((n, 0)) if B is None else as_matrix("B", np.reshape(B, (n, -1)), (n, None))
        A_, B_, C_ = _readonly(A_), _readonly(B_), _readonly(C_)
        lin = _LinearParts(A_, B_, C_)
        model = cls(a=lin.a, h=lin.h, Q=Q, R=R, dt=dt, G=G, n_u=B_.shape[1], name=name,
                    J=lin.J, H=lin.H, A_of_x=lin.A_of_x)
        if model.n_x != n or model.n_y != C_.shape[0]:
            raise ValueError(f"G, Q must give {n} states and R must be "
                             f"{C_.shape[0]}x{C_.shape[0]} to match A and C")
        model.A, model.B, model.C = A_, B_, C_
        return model

    # ------------------------------------------------------------------ callables
    def a(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """Drift ``a(x, u)``, shape ``(n_x,)`` or ``(B, n_x)``."""
        x = self._check_x(x)
        return self._a(x, self._input(u, x))

    def J(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """Jacobian ``∂a/∂x``: analytic when given, else central differences."""
        x = self._check_x(x)
        u = self._input(u, x)
        if self._J is not None:
            return np.asarray(self._J(x, u), dtype=np.float64)
        return _central_jacobian(lambda z, uu: self._a(z, uu), x, u)

    def h(self, x: ArrayLike) -> FloatArray:
        """Measurement function ``h(x)``, shape ``(n_y,)`` or ``(B, n_y)``."""
        return self._h(self._check_x(x))

    def H(self, x: ArrayLike) -> FloatArray:
        """Jacobian ``∂h/∂x``: analytic when given, else central differences."""
        x = self._check_x(x)
        if self._H is not None:
            return np.asarray(self._H(x), dtype=np.float64)
        return _central_jacobian(lambda z, _u: self._h(z), x, None)

    @property
    def has_factorisation(self) -> bool:
        """Whether the model carries ``A(x)`` (needed by the block-pulse filter)."""
        return self._A_of_x is not None

    def A_of_x(self, x: ArrayLike) -> FloatArray:
        """The factorisation ``A(x)`` with ``a(x, 0) = A(x) x`` (paper 002, eq 2.2)."""
        if self._A_of_x is None:
            raise TypeError(f"model {self.name!r} has no state-dependent factorisation A(x)")
        return np.asarray(self._A_of_x(self._check_x(x)), dtype=np.float64)

    # ------------------------------------------------------------------ discrete view
    def integrated_noise(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """The noise ``G w`` integrated over one interval ``dt`` through the linearisation at ``x``.

        ``Q_d(x) = ∫₀^dt e^{J s} G Q Gᵀ e^{Jᵀ s} ds`` with ``J = ∂a/∂x (x, u)``
        (:func:`~fir_gym.estimators.discretize.integrated_noise`, Van Loan's method): the
        covariance at ``t + dt`` of the linearised system started from a known state at
        ``x``. ``x`` of shape ``(n_x,)`` gives ``(n_x, n_x)``; ``(B, n_x)`` gives one
        matrix per state, ``(B, n_x, n_x)``.
        """
        return integrated_noise(self.J(x, u), self.dt, G=self.G, Q=self.Q)

    def sampled(self, substeps: int = 10, *, at: ArrayLike | None = None) -> StateSpaceModel:
        """The discrete-time view at period ``dt``, as a :class:`StateSpaceModel`.

        ``f`` is the noise-free flow over ``dt`` (classical RK4 with ``substeps``
        steps, input held), ``F`` its finite-difference Jacobian, ``h`` and ``H``
        as here. The process noise is the integrated noise ``Q_d`` of
        :meth:`integrated_noise` with ``G = I`` (``n_w = n_x``): exact for a linear
        model; for a nonlinear one it is taken at the linearisation ``at`` — a state
        ``(n_x,)``, or states ``(B, n_x)`` whose ``Q_d`` are averaged — with zero input,
        the origin when ``at`` is absent (the discrete contract has one constant
        ``G Q Gᵀ``; docs/estimators/models.md#process-noise). Not the first-order
        ``G Q Gᵀ dt``, which has the rank of ``G`` where the integrated noise is full
        rank. The measurement noise is ``R/dt`` (of the interval-average measurement,
        applied to ``h`` at the end of the interval — the approximation the discrete
        contract can express). It is what the Estimator base reads (sizes) and lets a
        discrete filter run on a continuous model.
        """
        substeps = positive("substeps", substeps, integer=True)
        points = np.zeros(self.n_x) if at is None else as_batch("at", at, self.n_x)
        Q_d = self.integrated_noise(points)
        if Q_d.ndim == 3:
            Q_d = np.mean(Q_d, axis=0)
        flow = _RK4Flow(self._a, self.dt / substeps, substeps)
        return StateSpaceModel(f=flow, h=self._h, H=self._H, Q=Q_d, R=self.R / self.dt,
                               dt=self.dt, n_u=self.n_u, name=f"{self.name} (sampled)")


class _LinearParts:
    """The callables of a linear continuous model (a class, not closures: picklable)."""

    def __init__(self, A: FloatArray, B: FloatArray, C: FloatArray) -> None:
        self.A, self.B, self.C = A, B, C

    def a(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return x @ self.A.T + u @ self.B.T

    def h(self, x: FloatArray) -> FloatArray:
        return x @ self.C.T

    def J(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return np.broadcast_to(self.A, x.shape[:-1] + self.A.shape)

    def H(self, x: FloatArray) -> FloatArray:
        return np.broadcast_to(self.C, x.shape[:-1] + self.C.shape)

    def A_of_x(self, x: FloatArray) -> FloatArray:
        return np.broadcast_to(self.A, x.shape[:-1] + self.A.shape)


class _RK4Flow:
    """The noise-free flow over one interval: classical RK4, ``substeps`` steps of ``tau``."""

    def __init__(self, a: Any, tau: float, substeps: int) -> None:
        self.a, self.tau, self.substeps = a, tau, substeps

    def __call__(self, x: FloatArray, u: FloatArray) -> FloatArray:
        a, tau = self.a, self.tau
        for _ in range(self.substeps):
            k1 = a(x, u)
            k2 = a(x + 0.5 * tau * k1, u)
            k3 = a(x + 0.5 * tau * k2, u)
            k4 = a(x + tau * k3, u)
            x = x + tau / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return x


def _readonly(a: ArrayLike) -> FloatArray:
    out = np.array(a, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out
