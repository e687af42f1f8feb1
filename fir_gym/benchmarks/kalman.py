"""Speed of the Kalman-family filters, against filterpy timed in the same run.

``python -m fir_gym.benchmarks.kalman`` prints µs per filter step (predict +
update) for KF, EKF and UKF, single (one system) and batched (B = 1024, µs per
system-step), on a 2-state/1-output linear model and a 4-state/2-output
nonlinear model, and — when filterpy is importable (``pip install ".[bench]"``)
— filterpy's ``KalmanFilter``/``ExtendedKalmanFilter``/``UnscentedKalmanFilter`` on
the same models with the same sigma-point parameters, and the ratios.

Targets: single-step KF and EKF at most filterpy's time, UKF at most
half of it, batched KF/EKF at most 0.5 µs per system-step. The KF figure is
measured after the Riccati recursion has converged (the steady-state regime of
``KalmanFilter``); the transient figure (``kf-full``: the same filter with one
measurement in 1000 missing, so the covariance is recomputed every step) is
printed beside it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from fir_gym.estimators import LinearModel, StateSpaceModel
from fir_gym.estimators.extended import ExtendedKalmanFilter
from fir_gym.estimators.kalman import KalmanFilter
from fir_gym.estimators.unscented import UnscentedKalmanFilter

from ._timing import counting, per_call

DT = 0.01


class Oscillators:
    """Two coupled nonlinear oscillators (4 states, 2 outputs), Euler-discretised; picklable."""

    @staticmethod
    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        x0, x1, x2, x3 = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
        return np.stack([x0 + DT * x1, x1 - DT * (np.sin(x0) + 0.1 * x1 - 0.2 * x2),
                         x2 + DT * x3, x3 - DT * (x2 + x2**3 - 0.2 * x0)], axis=-1)

    @staticmethod
    def F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = np.zeros(x.shape[:-1] + (4, 4))
        J[..., 0, 0] = J[..., 2, 2] = 1.0
        J[..., 0, 1] = J[..., 2, 3] = DT
        J[..., 1, 0] = -DT * np.cos(x[..., 0])
        J[..., 1, 1] = 1.0 - 0.1 * DT
        J[..., 1, 2] = 0.2 * DT
        J[..., 3, 0] = 0.2 * DT
        J[..., 3, 2] = -DT * (1.0 + 3.0 * x[..., 2] ** 2)
        J[..., 3, 3] = 1.0
        return J

    @staticmethod
    def h(x: np.ndarray) -> np.ndarray:
        return np.stack([x[..., 0], x[..., 2]], axis=-1)

    @staticmethod
    def H(x: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]), x.shape[:-1] + (2, 4))


def models() -> dict[str, StateSpaceModel]:
    """The two benchmark models."""
    lin = LinearModel(A=[[1.0, DT], [-DT, 1.0 - 0.05 * DT]], C=[[1.0, 0.0]],
                      Q=np.diag([1e-6, 1e-4]), R=[[1e-2]], dt=DT, name="linear 2x1")
    o = Oscillators()
    nonlin = StateSpaceModel(f=o.f, h=o.h, F=o.F, H=o.H, Q=np.eye(4) * 1e-4, R=np.eye(2) * 1e-2,
                             dt=DT, name="nonlinear 4x2")
    return {"linear": lin, "nonlinear": nonlin}


def _time(step: Callable[[int], Any], n: int, warmup: int) -> float:
    """µs per call of ``step(k)`` (``k`` counts on across blocks): best of 3 blocks of ``n``."""
    return per_call(counting(step), n, 3, warmup=warmup) * 1e6


#: the benchmark data, ``(noise, samples)``: zero-mean measurements whose standard deviation
#: is consistent with both models' ``R = 1e-2 I``, or ten times that (a mismatched model:
#: the filter rightly flags divergence — within a few hundred steps, on the 1024 distinct
#: samples, before the timing starts — and the flag stays raised); repeated cyclically
DATA = {"consistent": (0.1, 64), "mismatched": (1.0, 1024)}


def measurements(model: StateSpaceModel, batch: int, data: str) -> np.ndarray:
    """The cycle of measurements ``(samples, [batch,] n_y)`` of :data:`DATA`'s ``data``."""
    noise, samples = DATA[data]
    shape = (batch, model.n_y) if batch > 1 else (model.n_y,)
    return np.random.default_rng(0).normal(size=(samples, *shape)) * noise


def ours_stepper(cls: type, model: StateSpaceModel, batch: int, skip: bool = False,
                 data: str = "consistent", **opts: Any) -> Callable[[int], Any]:
    """``step(k)``: one step of our filter on ``batch`` systems (1: one system, ``(n_y,)``),
    on the measurements of ``data`` (:data:`DATA`); ``step.estimator`` is the filter."""
    Y = measurements(model, batch, data)
    shape, samples = Y.shape[1:], len(Y)
    if skip:
        opts["nan_policy"] = "skip"
    flt = cls(model, **opts)
    missing = np.full(shape, np.nan)

    def step(k: int) -> Any:
        return flt.step(missing if skip and k % 1000 == 0 else Y[k % samples])
    step.estimator = flt                                      # type: ignore[attr-defined]
    return step


def _ours(cls: type, model: StateSpaceModel, batch: int, n: int, skip: bool = False,
          **opts: Any) -> float:
    step = ours_stepper(cls, model, batch, skip, **opts)
    return _time(step, n, 200 if skip else (2000 if batch == 1 else 50)) / batch


def filterpy_stepper(kind: str, model: StateSpaceModel, alpha: float,
                     data: str = "consistent") -> Callable[[int], Any] | None:
    """``step(k)``: one predict + update of filterpy's filter on ``model`` (None: no filterpy),
    on the data of :func:`ours_stepper` for one system."""
    try:
        from filterpy.kalman import (
            ExtendedKalmanFilter as FpEKF,
        )
        from filterpy.kalman import (
            KalmanFilter as FpKF,
        )
        from filterpy.kalman import (
            MerweScaledSigmaPoints,
        )
        from filterpy.kalman import (
            UnscentedKalmanFilter as FpUKF,
        )
    except ImportError:
        return None
    Y = measurements(model, 1, data)
    samples = len(Y)
    u0 = np.zeros(model.n_u)
    if kind == "kf":
        assert isinstance(model, LinearModel)
        kf = FpKF(dim_x=model.n_x, dim_z=model.n_y)
        kf.F, kf.H, kf.Q, kf.R = model.A.copy(), model.C.copy(), model.GQGT.copy(), model.R.copy()

        def kf_step(k: int) -> None:
            kf.predict()
            kf.update(Y[k % samples])
        return kf_step
    if kind == "ekf":
        ekf = FpEKF(dim_x=model.n_x, dim_z=model.n_y)
        ekf.Q, ekf.R = model.GQGT.copy(), model.R.copy()

        def ekf_step(k: int) -> None:      # filterpy's EKF predict is linear: set F, move x by f
            x = ekf.x[:, 0]
            ekf.F = model.F(x, u0)
            ekf.x = model.f(x, u0)[:, None]
            ekf.P = ekf.F @ ekf.P @ ekf.F.T + ekf.Q
            ekf.update(Y[k % samples][:, None], lambda z: model.H(z[:, 0]),
                       lambda z: model.h(z[:, 0])[:, None])
        return ekf_step
    points = MerweScaledSigmaPoints(model.n_x, alpha=alpha, beta=2.0, kappa=0.0)
    ukf = FpUKF(dim_x=model.n_x, dim_z=model.n_y, dt=model.dt, points=points,
                fx=lambda x, dt: model.f(x, u0), hx=model.h)
    ukf.Q, ukf.R = model.GQGT.copy(), model.R.copy()

    def ukf_step(k: int) -> None:
        ukf.predict()
        ukf.update(Y[k % samples])
    return ukf_step


def _filterpy(kind: str, model: StateSpaceModel, n: int, alpha: float) -> float | None:
    step = filterpy_stepper(kind, model, alpha)
    return None if step is None else _time(step, n, 2000 if kind != "ukf" else 500)


def run(n: int = 5000, batch: int = 1024, n_batched: int = 200, alpha: float = 1.0
        ) -> list[dict[str, Any]]:
    """Time every filter; rows ``{model, filter, single_us, batched_us, filterpy_us, ratio}``.

    ``ratio`` is ours / filterpy (single step); ``alpha`` is the UKF spread used by
    both libraries (the default α = 1 keeps filterpy's textbook sums accurate).
    """
    ms = models()
    cases: list[tuple[str, str, type, dict[str, Any]]] = [
        ("linear", "kf", KalmanFilter, {}),
        ("linear", "kf-full", KalmanFilter, {"skip": True}),
        ("linear", "ekf", ExtendedKalmanFilter, {}),
        ("linear", "ukf", UnscentedKalmanFilter, {"alpha": alpha}),
        ("nonlinear", "ekf", ExtendedKalmanFilter, {}),
        ("nonlinear", "ukf", UnscentedKalmanFilter, {"alpha": alpha})]
    rows = []
    for mname, fname, cls, opts in cases:
        model = ms[mname]
        single = _ours(cls, model, 1, n, **opts)
        batched = _ours(cls, model, batch, n_batched, **opts)
        ref = _filterpy(fname.split("-")[0], model, max(n // 2, 200), alpha)
        rows.append({"model": model.name, "filter": fname, "single_us": single,
                     "batched_us": batched, "filterpy_us": ref,
                     "ratio": None if ref is None else single / ref})
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the table (``fir-gym bench kalman``; no options)."""
    if argv:
        raise SystemExit(f"fir-gym bench kalman takes no arguments; got {argv}")
    rows = run()
    print(f"{'model':15s} {'filter':8s} {'single µs':>10s} {'B=1024 µs/sys':>14s} "
          f"{'filterpy µs':>12s} {'ours/filterpy':>14s}")
    for r in rows:
        ref = "—" if r["filterpy_us"] is None else f"{r['filterpy_us']:.1f}"
        ratio = "—" if r["ratio"] is None else f"{r['ratio']:.2f}"
        print(f"{r['model']:15s} {r['filter']:8s} {r['single_us']:10.1f} {r['batched_us']:14.3f} "
              f"{ref:>12s} {ratio:>14s}")
    return 0


if __name__ == "__main__":
    main()
