"""The model contract: what a filter may know about a plant.

A :class:`StateSpaceModel` is the discrete-time stochastic system

    x[k+1] = f(x[k], u[k]) + G w[k],      w[k] ~ N(0, Q)
    y[k]   = h(x[k]) + v[k],              v[k] ~ N(0, R)

with sample period ``dt`` (docs/architecture.md#model-contract). Every
callable accepts a leading batch axis: ``x`` of shape ``(n_x,)`` or
``(B, n_x)``, ``u`` of shape ``(n_u,)`` or ``(B, n_u)``; the result has the
same leading shape. :class:`LinearModel` is the special case
``f = A x + B u``, ``h = C x``.

A plant's model is the filter's *belief*: it is built from nominal parameters
that may differ from the plant's true ones.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_batch, as_covariance, as_matrix, input_batch, positive

Dynamics = Callable[[FloatArray, FloatArray], FloatArray]
_Model = TypeVar("_Model", bound="StateSpaceModel")
Output = Callable[[FloatArray], FloatArray]
#: ``residual(a, b) -> a − b`` on batched states or measurements
Residual = Callable[[FloatArray, FloatArray], FloatArray]
#: ``mean(points (B, N, k), weights (N,)) -> (B, k)``
WeightedMean = Callable[[FloatArray, FloatArray], FloatArray]
#: the optional residual and mean hooks of a model (filterpy's names)
HOOKS = ("residual_x", "residual_y", "mean_x", "mean_y")

#: Relative step of the central finite differences, ``eps**(1/3)``: it balances
#: truncation error O(h²) against round-off O(eps/h) for a smooth function.
FD_RELATIVE_STEP = float(np.finfo(np.float64).eps ** (1.0 / 3.0))


class _ModelCore:
    """What every model shares: its callables, the noise matrices, the sizes, the checks.

    ``n_x`` comes from ``G`` (its rows) or from ``Q`` when ``G`` is absent, ``n_w``
    from ``Q``, ``n_y`` from ``R``; ``GQGT`` is ``G Q Gᵀ``.
    """

    def _set_core(self, *, required: dict[str, Any], optional: dict[str, Any], Q: ArrayLike,
                  R: ArrayLike, G: ArrayLike | None, n_u: int, dt: float, name: str | None,
                  definite_R: bool = False) -> None:
        for arg, fn in required.items():
            if not callable(fn):
                raise TypeError(f"{arg} must be callable; got {type(fn).__name__}")
        for arg, fn in optional.items():
            if fn is not None and not callable(fn):
                raise TypeError(f"{arg} must be callable or None; got {type(fn).__name__}")
        self.Q = _readonly(as_covariance("Q", Q))
        n_w = self.Q.shape[0]
        self.G = _readonly(np.eye(n_w) if G is None else as_matrix("G", G, (None, n_w)))
        self.R = _readonly(as_covariance("R", R, definite=definite_R))
        if isinstance(n_u, bool) or not isinstance(n_u, (int, np.integer)) or n_u < 0:
            raise ValueError(f"n_u must be a non-negative integer; got {n_u!r}")
        self.n_x, self.n_w = int(self.G.shape[0]), int(n_w)
        self.n_y, self.n_u = int(self.R.shape[0]), int(n_u)
        self.dt = positive("dt", dt)
        self.name = name or type(self).__name__
        self._GQGT = _readonly(self.G @ self.Q @ self.G.T)

    @property
    def GQGT(self) -> FloatArray:
        """State noise covariance (or intensity) ``G Q Gᵀ`` (``n_x x n_x``, read-only)."""
        return self._GQGT

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(name={self.name!r}, n_x={self.n_x}, n_y={self.n_y}, "
                f"n_u={self.n_u}, n_w={self.n_w}, dt={self.dt:g})")

    def _check_x(self, x: ArrayLike) -> FloatArray:
        return as_batch("x", x, self.n_x)

    def _input(self, u: ArrayLike | None, x: FloatArray) -> FloatArray:
        return input_batch(u, x, self.n_u)


class StateSpaceModel(_ModelCore):
    """Discrete-time nonlinear state-space model ``x⁺ = f(x, u) + G w``, ``y = h(x) + v``.

    Args:
        f: transition ``f(x, u) -> x⁺``, batched over a leading axis. It always
            receives ``u`` as an array of shape ``(..., n_u)`` (zeros when the
            caller passes ``None``; an empty last axis when ``n_u == 0``).
        h: measurement function ``h(x) -> y``, batched.
        Q: covariance of the process noise ``w`` (``n_w x n_w``; a scalar or a
            1-D array of variances is accepted). Symmetric positive semi-definite.
        R: covariance of the measurement noise ``v`` (``n_y x n_y``); symmetric
            positive semi-definite.
        dt: sample period in seconds (metadata for filters and reports).
        F: Jacobian ``∂f/∂x (x, u)``, shape ``(..., n_x, n_x)``. When omitted,
            central finite differences are used (see :meth:`F`).
        H: Jacobian ``∂h/∂x (x)``, shape ``(..., n_y, n_x)``; same fallback.
        G: noise input matrix ``(n_x, n_w)``; defaults to the identity, in which
            case ``n_w = n_x``.
        n_u: number of inputs.
        name: a label used in ``repr`` and reports.
        fF: optional ``fF(x, u) -> (f(x, u), F(x, u))`` computed together, for plants
            whose transition is an integrator that yields its Jacobian in the same
            pass (see :meth:`linearize`).
        residual_x, residual_y: optional batched differences ``residual(a, b) -> a − b``
            of states and of measurements (filterpy's names), for quantities that are not
            plain vectors: e.g. wrapping a bearing into ``[−π, π)``. Used by the EKF (the
            innovation), the UKF (every deviation from a mean) and their smoothers.
        mean_x, mean_y: optional weighted means ``mean(points (B, N, k), weights (N,)) ->
            (B, k)`` of sigma points (e.g. a circular mean of angles), used by the UKF and
            its smoother instead of ``Σ Wᵢ χᵢ``. A UKF on a model with any of the four
            runs on the numpy reference (the compiled twin does its sums in its own loop).

    ``n_x`` is inferred from ``G`` (its rows) or from ``Q`` when ``G`` is absent;
    ``n_y`` from ``R``. The state noise covariance is ``G Q Gᵀ``
    (:attr:`GQGT`).
    """

    is_linear: bool = False

    def __init__(
        self,
        *,
        f: Dynamics,
        h: Output,
        Q: ArrayLike,
        R: ArrayLike,
        dt: float = 1.0,
        F: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
        H: Callable[[FloatArray], FloatArray] | None = None,
        G: ArrayLike | None = None,
        n_u: int = 0,
        name: str | None = None,
        fF: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]] | None = None,
        residual_x: Residual | None = None,
        residual_y: Residual | None = None,
        mean_x: WeightedMean | None = None,
        mean_y: WeightedMean | None = None,
    ) -> None:
        hooks = {"residual_x": residual_x, "residual_y": residual_y, "mean_x": mean_x,
                 "mean_y": mean_y}
        self._set_core(required={"f": f, "h": h},
                       optional={"F": F, "H": H, "fF": fF, **hooks},
                       Q=Q, R=R, G=G, n_u=n_u, dt=dt, name=name)
        self._f = f
        self._h = h
        self._F = F
        self._H = H
        self._fF = fF
        self.residual_x, self.residual_y = residual_x, residual_y
        self.mean_x, self.mean_y = mean_x, mean_y

    @property
    def has_hooks(self) -> bool:
        """Whether any of ``residual_x, residual_y, mean_x, mean_y`` is set."""
        return any(getattr(self, a, None) is not None for a in HOOKS)

    # ------------------------------------------------------------------ callables
    def f(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """Transition ``f(x, u)`` for ``x`` of shape ``(n_x,)`` or ``(B, n_x)``."""
        x = self._check_x(x)
        return self._f(x, self._input(u, x))

    def h(self, x: ArrayLike) -> FloatArray:
        """Measurement function ``h(x)``, shape ``(n_y,)`` or ``(B, n_y)``."""
        return self._h(self._check_x(x))

    def F(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """Jacobian ``∂f/∂x``, shape ``(n_x, n_x)`` or ``(B, n_x, n_x)``.

        Analytic when the model was given ``F``; otherwise central finite
        differences ``(f(x + e_j s_j) - f(x - e_j s_j)) / (2 s_j)`` with
        ``s_j = eps**(1/3) * max(1, |x_j|)``, evaluated in one batched call
        of ``f`` (error O(s²) for smooth ``f``, about 1e-10 relative).
        """
        x = self._check_x(x)
        u = self._input(u, x)
        if self._F is not None:
            return self._F(x, u)
        return _central_jacobian(lambda z, uu: self._f(z, uu), x, u)

    def H(self, x: ArrayLike) -> FloatArray:
        """Jacobian ``∂h/∂x``, shape ``(n_y, n_x)`` or ``(B, n_y, n_x)``.

        Analytic when given, else the same central differences as :meth:`F`.
        """
        x = self._check_x(x)
        if self._H is not None:
            return self._H(x)
        return _central_jacobian(lambda z, _u: self._h(z), x, None)

    def linearize(self, x: ArrayLike, u: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """``(f(x, u), F(x, u))`` together: one integration when the model has ``fF``."""
        x = self._check_x(x)
        u = self._input(u, x)
        if self._fF is not None:
            return self._fF(x, u)
        return self.f(x, u), self.F(x, u)

    def f_and_F(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(f(x, u), F(x, u))`` for arrays a filter already holds in the right shapes.

        No argument checks (the filters' hot path; use :meth:`linearize` otherwise);
        a subclass's own ``f`` or ``F`` is called as it is, and ``F`` falls back to the
        finite differences of :meth:`F`. A bound method of the model, so a filter
        holding it copies and pickles with its model.
        """
        cls = type(self)
        fx = self._f(x, u) if cls.f is StateSpaceModel.f else self.f(x, u)
        if cls.F is StateSpaceModel.F and self._F is not None:
            return fx, self._F(x, u)
        return fx, self.F(x, u)

    def unchecked_callables(self) -> tuple[Callable[..., FloatArray], Callable[..., FloatArray],
                                           Callable[..., FloatArray], Callable[..., FloatArray]]:
        """The model's ``f, F, h, H`` for a filter's hot path, without the per-call checks.

        The public methods validate their arguments on every call; a filter already holds
        arrays of the right shapes, so it calls the plant's own functions. A subclass that
        overrides a public method keeps it; a missing Jacobian is the finite differences of
        :meth:`F` / :meth:`H`.
        """
        cls = type(self)
        f = self._f if cls.f is StateSpaceModel.f else self.f
        h = self._h if cls.h is StateSpaceModel.h else self.h
        F = self._F if (cls.F is StateSpaceModel.F and self._F is not None) else self.F
        H = self._H if (cls.H is StateSpaceModel.H and self._H is not None) else self.H
        return f, F, h, H

    def unchecked_linearizer(self) -> Callable[..., tuple[FloatArray, FloatArray]]:
        """``(x, u) -> (f(x, u), F(x, u))`` for a filter's hot path: the fused ``fF`` when the
        model has one (one pass of the plant's integrator instead of two), a subclass's own
        :meth:`linearize`, else :meth:`f_and_F` — a bound method or the model's own
        callable, so a filter holding it copies and pickles with its model."""
        cls = type(self)
        if cls.linearize is StateSpaceModel.linearize and self._fF is not None:
            return self._fF
        if cls.linearize is not StateSpaceModel.linearize:
            return self.linearize
        return self.f_and_F

    # ------------------------------------------------------------------ properties

    @property
    def has_analytic_jacobians(self) -> tuple[bool, bool]:
        """Whether ``F`` and ``H`` are analytic (True) or finite differences."""
        return self._F is not None, self._H is not None

    def replace(self: _Model, **changes: Any) -> _Model:
        """A copy with some constructor arguments replaced (e.g. ``Q=...``)."""
        kwargs = self._constructor_kwargs()
        unknown = set(changes) - set(kwargs)
        if unknown:
            raise ValueError(
                f"unknown argument(s) {sorted(unknown)} for {type(self).__name__}.replace; "
                f"expected some of {sorted(kwargs)}"
            )
        kwargs.update(changes)
        return type(self)(**kwargs)

    def _constructor_kwargs(self) -> dict[str, Any]:
        return {"f": self._f, "h": self._h, "Q": self.Q, "R": self.R, "dt": self.dt,
                "F": self._F, "H": self._H, "G": self.G, "n_u": self.n_u, "name": self.name,
                "fF": self._fF, **{a: getattr(self, a) for a in HOOKS}}


class SystemMatrices(NamedTuple):
    """Matrices of ``x[k+1] = A x[k] + B u[k] + G w[k]``, ``y[k] = C x[k] + v[k]`` at one ``k``."""

    A: FloatArray
    B: FloatArray
    C: FloatArray
    G: FloatArray
    Q: FloatArray
    R: FloatArray


class LinearModel(StateSpaceModel):
    """Linear time-invariant model ``x⁺ = A x + B u + G w``, ``y = C x + v``.

    Args:
        A: state matrix ``(n_x, n_x)``.
        C: output matrix ``(n_y, n_x)``.
        Q: covariance of ``w`` (``n_w x n_w``).
        R: covariance of ``v`` (``n_y x n_y``).
        B: input matrix ``(n_x, n_u)``; absent means no input (``n_u = 0``).
        G: noise input matrix ``(n_x, n_w)``; defaults to the identity.
        dt: sample period.

    ``A``, ``B``, ``C`` are exposed read-only; ``F`` and ``H`` return ``A`` and
    ``C`` (broadcast, read-only, over a batch).
    """

    is_linear = True

    def __init__(
        self,
        *,
        A: ArrayLike,
        C: ArrayLike,
        Q: ArrayLike,
        R: ArrayLike,
        B: ArrayLike | None = None,
        G: ArrayLike | None = None,
        dt: float = 1.0,
        name: str | None = None,
    ) -> None:
        A_ = as_matrix("A", A, (None, None))
        if A_.shape[0] != A_.shape[1]:
            raise ValueError(f"A must be square; got shape {A_.shape}")
        n_x = A_.shape[0]
        C_ = as_matrix("C", C if np.ndim(C) != 1 else np.atleast_2d(C), (None, n_x))
        B_ = np.zeros((n_x, 0)) if B is None else as_matrix(
            "B", B if np.ndim(B) != 1 else np.reshape(B, (n_x, -1)), (n_x, None))
        Q_ = as_covariance("Q", Q)
        if G is None and Q_.shape[0] != n_x:
            raise ValueError(f"Q must be {n_x}x{n_x} when G is absent (G = I); got {Q_.shape}")
        R_ = as_covariance("R", R)
        if R_.shape[0] != C_.shape[0]:
            raise ValueError(f"R must be {C_.shape[0]}x{C_.shape[0]} to match C; got {R_.shape}")
        self.A = _readonly(A_)
        self.B = _readonly(B_)
        self.C = _readonly(C_)
        super().__init__(f=self._linear_f, h=self._linear_h, Q=Q_, R=R_, dt=dt,
                         F=self._linear_F, H=self._linear_H, G=G, n_u=B_.shape[1], name=name)
        if self.n_x != n_x:
            raise ValueError(f"G must have {n_x} rows to match A; got shape {self.G.shape}")

    time_invariant = True

    def matrices(self, k: int = 0) -> SystemMatrices:
        """The system matrices at time ``k`` (constant for this model)."""
        return SystemMatrices(self.A, self.B, self.C, self.G, self.Q, self.R)

    def _linear_f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        out = x @ self.A.T
        if self.n_u:
            out = out + u @ self.B.T
        return out

    def _linear_h(self, x: FloatArray) -> FloatArray:
        return x @ self.C.T

    def _linear_F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.A if x.ndim == 1 else np.broadcast_to(self.A, x.shape[:-1] + self.A.shape)

    def _linear_H(self, x: FloatArray) -> FloatArray:
        return self.C if x.ndim == 1 else np.broadcast_to(self.C, x.shape[:-1] + self.C.shape)

    def _constructor_kwargs(self) -> dict[str, Any]:
        return {"A": self.A, "C": self.C, "Q": self.Q, "R": self.R,
                "B": self.B if self.n_u else None, "G": self.G, "dt": self.dt, "name": self.name}

    def __reduce__(self) -> tuple[Any, ...]:
        # Bound methods of self are stored as callables; rebuild from matrices instead.
        return (_rebuild_linear, (self._constructor_kwargs(),))

    @property
    def is_plain(self) -> bool:
        """Whether the model's hot-path ``f, F, h, H`` (:meth:`unchecked_callables`) and its
        :meth:`linearize` are this class's own — ``A x + B u``, ``A``, ``C x``, ``C`` — so that
        a filter may step with the matrices directly (a subclass overriding one is not)."""
        if type(self).linearize is not LinearModel.linearize:
            return False
        own = (LinearModel._linear_f, LinearModel._linear_F, LinearModel._linear_h,
               LinearModel._linear_H)
        return all(getattr(c, "__func__", None) is o and getattr(c, "__self__", None) is self
                   for c, o in zip(self.unchecked_callables(), own, strict=True))


def _rebuild_linear(kwargs: dict[str, Any]) -> LinearModel:
    return LinearModel(**kwargs)


def _central_jacobian(
    fun: Callable[[FloatArray, Any], FloatArray],
    x: FloatArray,
    u: FloatArray | None,
) -> FloatArray:
    """Central-difference Jacobian of ``fun`` at a (batch of) point(s), one batched call."""
    batched = x.ndim == 2
    X = x if batched else x[None]
    n_b, n = X.shape
    step = FD_RELATIVE_STEP * np.maximum(1.0, np.abs(X))            # (n_b, n)
    E = step[:, :, None] * np.eye(n)                                 # (n_b, n, n): row j = s_j e_j
    points = np.concatenate([X[:, None, :] + E, X[:, None, :] - E], axis=1).reshape(-1, n)
    if u is not None:
        U = np.broadcast_to(u if u.ndim == 2 else u[None], (n_b, u.shape[-1]))
        U = np.repeat(U, 2 * n, axis=0)
    else:
        U = None
    values = np.asarray(fun(points, U)).reshape(n_b, 2, n, -1)    # (n_b, ±, j, i)
    J = (values[:, 0] - values[:, 1]) / (2.0 * step[:, :, None])   # (n_b, j, i)
    J = np.swapaxes(J, 1, 2)                                        # (n_b, i, j)
    return J if batched else J[0]


def _readonly(a: FloatArray) -> FloatArray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


MatrixOrSchedule = ArrayLike | Callable[[int], ArrayLike]


class TimeVaryingLinearModel(StateSpaceModel):
    """Linear time-varying model ``x[k+1] = A_k x[k] + B_k u[k] + G_k w[k]``, ``y = C_k x + v``.

    Each of ``A, C, Q, R, B, G`` is either a constant array or a callable
    ``k -> array`` (``k`` is the time index of ``x[k]``: ``A(k)`` maps ``x[k]`` to
    ``x[k+1]``, ``C(k)`` measures ``x[k]``). Sizes are read from the matrices at
    ``k = 0``. Because the transition depends on ``k``, the time-free callables
    ``f, h, F, H`` of :class:`StateSpaceModel` are not defined; filters that
    support time variation read :meth:`matrices` instead.
    """

    is_linear = True
    time_invariant = False

    def __init__(
        self,
        *,
        A: MatrixOrSchedule,
        C: MatrixOrSchedule,
        Q: MatrixOrSchedule,
        R: MatrixOrSchedule,
        B: MatrixOrSchedule | None = None,
        G: MatrixOrSchedule | None = None,
        dt: float = 1.0,
        name: str | None = None,
    ) -> None:
        self._schedules = {"A": A, "C": C, "Q": Q, "R": R, "B": B, "G": G}
        m0 = self.matrices(0)
        super().__init__(f=_time_varying, h=_time_varying, Q=m0.Q, R=m0.R, dt=dt,
                         G=m0.G, n_u=m0.B.shape[1], name=name)

    def matrices(self, k: int = 0) -> SystemMatrices:
        """The system matrices at time ``k``, validated for shape and covariance."""
        get: dict[str, Any] = {key: (val(k) if callable(val) else val)
                               for key, val in self._schedules.items()}
        A = as_matrix(f"A({k})", get["A"], (None, None))
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError(f"A({k}) must be square; got shape {A.shape}")
        C = as_matrix(f"C({k})", np.atleast_2d(get["C"]), (None, n))
        B = np.zeros((n, 0)) if get["B"] is None else as_matrix(
            f"B({k})", np.reshape(get["B"], (n, -1)), (n, None))
        Q = as_covariance(f"Q({k})", get["Q"])
        G = np.eye(n) if get["G"] is None else as_matrix(
            f"G({k})", np.reshape(get["G"], (n, -1)), (n, Q.shape[0]))
        if get["G"] is None and Q.shape[0] != n:
            raise ValueError(f"Q({k}) must be {n}x{n} when G is absent; got {Q.shape}")
        R = as_covariance(f"R({k})", get["R"], C.shape[0])
        return SystemMatrices(A, B, C, G, Q, R)

    def f(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        raise TypeError(_TV_MESSAGE)

    def h(self, x: ArrayLike) -> FloatArray:
        raise TypeError(_TV_MESSAGE)

    def F(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        raise TypeError(_TV_MESSAGE)

    def H(self, x: ArrayLike) -> FloatArray:
        raise TypeError(_TV_MESSAGE)

    def replace(self, **changes: Any) -> TimeVaryingLinearModel:
        kwargs = {**self._schedules, "dt": self.dt, "name": self.name}
        unknown = set(changes) - set(kwargs)
        if unknown:
            raise ValueError(
                f"unknown argument(s) {sorted(unknown)}; expected some of {sorted(kwargs)}")
        return TimeVaryingLinearModel(**{**kwargs, **changes})


_TV_MESSAGE = ("a TimeVaryingLinearModel has no time-free f/h/F/H; "
               "use model.matrices(k) for the matrices at time k")


def _time_varying(*_: Any) -> FloatArray:
    raise TypeError(_TV_MESSAGE)
