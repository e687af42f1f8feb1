"""Joint state–parameter estimation: models with parameters, and the augmented state ``[x; θ]``.

A :class:`ParametricModel` is a family of state-space models indexed by physical
parameters ``θ``: ``x⁺ = f(x, u, θ) + G w``, ``y = h(x, θ) + v``. It *is* a
:class:`StateSpaceModel` (at its nominal ``θ``), so a plant can publish one as its
``model`` and every filter runs on it unchanged. :func:`augment` turns it into the
model of paper 003's joint estimation (eq 16): the state carries the chosen
parameters, which follow a random walk ``θ⁺ = θ + w_θ`` (constant when
``Q_params = 0``):

    [x; θ]⁺ = [f(x, u, θ); θ] + blkdiag(G, I) [w; w_θ],      y = h(x, θ) + v

with the Jacobians ``[[∂f/∂x, ∂f/∂θ], [0, I]]`` and ``[∂h/∂x, ∂h/∂θ]``. Every
callable is batched, *including* ``θ``: a batch of sigma points or of filters
evaluates the plant at per-sample parameter values in one call.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._validation import FloatArray, as_covariance
from .model import StateSpaceModel, _central_jacobian

__all__ = ["AugmentedModel", "ParametricModel", "augment"]

ParamDynamics = Callable[[FloatArray, FloatArray, FloatArray], FloatArray]
ParamOutput = Callable[[FloatArray, FloatArray], FloatArray]


class ParametricModel(StateSpaceModel):
    """A state-space model with named parameters ``θ``, evaluated at per-sample ``θ``.

    Args:
        f: ``f(x, u, theta) -> x⁺``; ``x (B, n_x)``, ``u (B, n_u)``,
            ``theta (B, n_θ)`` (or all unbatched), batched like :class:`StateSpaceModel`.
        h: ``h(x, theta) -> y``.
        params: nominal parameter values, ``{"name": value, ...}`` (order defines ``θ``).
        Q, R, dt, G, n_u, name: as for :class:`StateSpaceModel`.
        jac_f: optional ``jac_f(x, u, theta) -> (∂f/∂x, ∂f/∂θ)`` of shapes
            ``(..., n_x, n_x)`` and ``(..., n_x, n_θ)``; central differences otherwise.
        jac_h: optional ``jac_h(x, theta) -> (∂h/∂x, ∂h/∂θ)``.
        f_jac_f: optional ``f_jac_f(x, u, theta) -> (f, ∂f/∂x, ∂f/∂θ)`` computed together
            (one pass of an integrator that yields its Jacobians); it must equal ``f``
            and ``jac_f``. The nominal model then has a fused ``linearize``.

    As a :class:`StateSpaceModel` it behaves as the model at the nominal ``θ``
    (``f(x, u) = f(x, u, θ_nominal)``); :meth:`with_params` moves the nominal.
    """

    def __init__(self, *, f: ParamDynamics, h: ParamOutput, params: Mapping[str, float],
                 Q: ArrayLike, R: ArrayLike, dt: float = 1.0,
                 jac_f: Callable[..., tuple[FloatArray, FloatArray]] | None = None,
                 jac_h: Callable[..., tuple[FloatArray, FloatArray]] | None = None,
                 G: ArrayLike | None = None, n_u: int = 0, name: str | None = None,
                 f_jac_f: Callable[..., tuple[FloatArray, FloatArray, FloatArray]] | None = None
                 ) -> None:
        for arg, fn in (("f", f), ("h", h), ("jac_f", jac_f), ("jac_h", jac_h),
                        ("f_jac_f", f_jac_f)):
            if fn is not None and not callable(fn):
                raise TypeError(f"{arg} must be callable; got {type(fn).__name__}")
        if not isinstance(params, Mapping) or not params:
            raise TypeError("params must be a non-empty mapping of parameter names to values")
        theta = np.array([float(v) for v in params.values()])
        if not np.all(np.isfinite(theta)):
            raise ValueError(f"params must be finite; got {dict(params)}")
        self.param_names: tuple[str, ...] = tuple(str(k) for k in params)
        self.theta = theta
        self.theta.setflags(write=False)
        self._pf, self._ph, self._jac_f, self._jac_h = f, h, jac_f, jac_h
        self._f_jac_f = f_jac_f
        super().__init__(f=self._nominal_f, h=self._nominal_h, Q=Q, R=R, dt=dt,
                         F=self._nominal_F, H=self._nominal_H, G=G, n_u=n_u, name=name,
                         fF=None if f_jac_f is None else self._nominal_fF)

    @property
    def params(self) -> dict[str, float]:
        """The nominal parameters as a dict."""
        return dict(zip(self.param_names, self.theta.tolist(), strict=True))

    @property
    def n_theta(self) -> int:
        """Number of parameters."""
        return len(self.param_names)

    def with_params(self, **values: float) -> ParametricModel:
        """A copy whose nominal parameters are updated with ``values``."""
        unknown = sorted(set(values) - set(self.param_names))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {list(self.param_names)}")
        return self.replace(params={**self.params, **values})

    # ------------------------------------------------------------- parametric callables
    def f_theta(self, x: FloatArray, u: FloatArray, theta: FloatArray) -> FloatArray:
        """``f(x, u, θ)`` (batched, no validation)."""
        return self._pf(x, u, theta)

    def h_theta(self, x: FloatArray, theta: FloatArray) -> FloatArray:
        """``h(x, θ)`` (batched, no validation)."""
        return self._ph(x, theta)

    def jacobians_f(self, x: FloatArray, u: FloatArray, theta: FloatArray
                    ) -> tuple[FloatArray, FloatArray]:
        """``(∂f/∂x, ∂f/∂θ)``: analytic when given, else central differences in ``[x; θ]``."""
        if self._jac_f is not None:
            return self._jac_f(x, u, theta)
        n = x.shape[-1]
        J = _central_jacobian(lambda z, uu: self._pf(z[..., :n], uu, z[..., n:]),
                              np.concatenate([x, np.broadcast_to(
                                  theta, x.shape[:-1] + theta.shape[-1:])], axis=-1), u)
        return J[..., :n], J[..., n:]

    def jacobians_h(self, x: FloatArray, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(∂h/∂x, ∂h/∂θ)``: analytic when given, else central differences."""
        if self._jac_h is not None:
            return self._jac_h(x, theta)
        n = x.shape[-1]
        J = _central_jacobian(lambda z, _u: self._ph(z[..., :n], z[..., n:]),
                              np.concatenate([x, np.broadcast_to(
                                  theta, x.shape[:-1] + theta.shape[-1:])], axis=-1), None)
        return J[..., :n], J[..., n:]

    # ------------------------------------------------------------- nominal model
    def _nominal_f(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self._pf(x, u, self.theta)

    def _nominal_fF(self, x: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
        assert self._f_jac_f is not None                   # only handed out when given
        z, Fz, _ = self._f_jac_f(x, u, self.theta)
        return z, Fz

    def _nominal_h(self, x: FloatArray) -> FloatArray:
        return self._ph(x, self.theta)

    def _nominal_F(self, x: FloatArray, u: FloatArray) -> FloatArray:
        return self.jacobians_f(x, u, self.theta)[0]

    def _nominal_H(self, x: FloatArray) -> FloatArray:
        return self.jacobians_h(x, self.theta)[0]

    def _constructor_kwargs(self) -> dict[str, Any]:
        return {"f": self._pf, "h": self._ph, "params": self.params, "Q": self.Q, "R": self.R,
                "dt": self.dt, "jac_f": self._jac_f, "jac_h": self._jac_h, "G": self.G,
                "n_u": self.n_u, "name": self.name, "f_jac_f": self._f_jac_f}


class AugmentedModel(StateSpaceModel):
    """The model of ``[x; θ_s]`` built by :func:`augment` (``θ_s``: the estimated parameters).

    Attributes:
        base: the :class:`ParametricModel`.
        param_names: names of the estimated parameters, in state order after ``x``.
        n_base: ``n_x`` of the base model.
    """

    def __init__(self, base: ParametricModel, params: Sequence[str], Q_params: FloatArray,
                 name: str | None = None) -> None:
        self.base = base
        self.param_names = tuple(params)
        self.n_base = base.n_x
        self._index = np.array([base.param_names.index(p) for p in self.param_names])
        nb, ns, nw = base.n_x, len(self.param_names), base.n_w
        G = np.zeros((nb + ns, nw + ns))
        G[:nb, :nw] = base.G
        G[nb:, nw:] = np.eye(ns)
        Q = np.zeros((nw + ns, nw + ns))
        Q[:nw, :nw] = base.Q
        Q[nw:, nw:] = Q_params
        super().__init__(f=self._aug_f, h=self._aug_h, F=self._aug_F, H=self._aug_H, Q=Q,
                         R=base.R, dt=base.dt, G=G, n_u=base.n_u,
                         name=name or f"{base.name}+[{', '.join(self.param_names)}]")

    def split(self, z: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(x, θ_s)`` from an augmented state ``(n,)`` or ``(B, n)``."""
        z = np.asarray(z, dtype=np.float64)
        return z[..., :self.n_base], z[..., self.n_base:]

    def _theta(self, z: FloatArray) -> FloatArray:
        nominal = self.base.theta
        theta = np.array(np.broadcast_to(nominal, z.shape[:-1] + nominal.shape))
        theta[..., self._index] = z[..., self.n_base:]
        return theta

    def _aug_f(self, z: FloatArray, u: FloatArray) -> FloatArray:
        x_next = self.base.f_theta(z[..., :self.n_base], u, self._theta(z))
        return np.concatenate([x_next, z[..., self.n_base:]], axis=-1)

    def _aug_h(self, z: FloatArray) -> FloatArray:
        return self.base.h_theta(z[..., :self.n_base], self._theta(z))

    def _aug_F(self, z: FloatArray, u: FloatArray) -> FloatArray:
        nb = self.n_base
        Fx, Ft = self.base.jacobians_f(z[..., :nb], u, self._theta(z))
        J = np.zeros(z.shape[:-1] + (z.shape[-1], z.shape[-1]))
        J[..., :nb, :nb] = Fx
        J[..., :nb, nb:] = Ft[..., self._index]
        idx = np.arange(nb, z.shape[-1])
        J[..., idx, idx] = 1.0
        return J

    def _aug_H(self, z: FloatArray) -> FloatArray:
        nb = self.n_base
        Hx, Ht = self.base.jacobians_h(z[..., :nb], self._theta(z))
        return np.concatenate([Hx, Ht[..., self._index]], axis=-1)

    def _constructor_kwargs(self) -> dict[str, Any]:
        raise TypeError("an AugmentedModel cannot be replace()d; call augment() again")


def augment(model: ParametricModel, params: Sequence[str] | None = None,
            Q_params: ArrayLike = 0.0, *, name: str | None = None) -> AugmentedModel:
    """The model of the state ``[x; θ_s]`` for joint estimation (paper 003, eq 16).

    Args:
        model: a :class:`ParametricModel` (e.g. a plant's model).
        params: names of the parameters to estimate, in the order they follow ``x``
            in the state (default: all of ``model.param_names``). The others stay at
            their nominal values.
        Q_params: covariance of the parameter random walk ``w_θ``: a scalar (applied
            to each), a vector of variances, or a matrix. 0 (default) means
            constant parameters, paper 003's eq 16.
        name: label of the new model.

    Returns:
        an :class:`AugmentedModel` with ``n_x = model.n_x + len(params)``, usable with
        :class:`ExtendedKalmanFilter` and :class:`UnscentedKalmanFilter`; its ``F``
        and ``H`` are analytic when the model gives ``jac_f``/``jac_h``.
    """
    if not isinstance(model, ParametricModel):
        raise TypeError(f"model must be a ParametricModel (a model with named parameters); "
                        f"got {type(model).__name__}")
    names = model.param_names if params is None else tuple(params)
    if isinstance(params, str):
        raise TypeError("params must be a sequence of parameter names, not a string")
    unknown = [p for p in names if p not in model.param_names]
    if unknown or not names or len(set(names)) != len(names):
        raise ValueError(f"params must be distinct names among {list(model.param_names)}; "
                         f"got {list(names)}")
    Qp = np.asarray(Q_params, dtype=np.float64)
    if Qp.ndim == 0:
        Qp = np.full(len(names), float(Qp))
    Qp = as_covariance("Q_params", Qp, len(names))
    return AugmentedModel(model, names, Qp, name=name)
