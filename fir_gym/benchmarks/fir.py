"""FIR-family benchmarks: gain growth with the horizon, EFIR speed against the EKF.

Run ``OPENBLAS_NUM_THREADS=1 python -m fir_gym.benchmarks.fir`` (``--quick`` for
a short run, ``--orbit`` to add the long Orbit-v0 accuracy run). Single-threaded
BLAS keeps the timings honest on a shared machine: a multi-threaded BLAS competing
with other processes slows the large batch-formula solves by up to 10x. It prints

1. **growth** — time per gain computation over a window of ``N`` measurements
   for path (c) (two-stage recursion + adjoint sweep, :func:`two_stage_gain`),
   path (c) on data (:class:`~fir_gym.estimators.fir.FIRFilter` on a
   time-varying model: one filter step) and path (a) (the stacked batch formula,
   :func:`batch_gain`), with the exponent ``α`` of a least-squares fit
   ``t ∝ N^α`` over the larger horizons (expected ≈ 1 for (c); (a) is O((N·n)³)
   in operations, its measured exponent approaches 3 only as the O(N²) assembly
   and BLAS efficiency stop mattering);
2. **speed** — one :class:`ExtendedFIRFilter` step (n = 3, N = 10) against one
   extended Kalman filter step on the same model (target ratio ≤ 2);
3. **batched** — EFIR microseconds per system-step at B = 1024 (target ≤ 5 µs).

The model of 2 and 3 is paper 000's simulation 2 (printed reading, δ = 0):
``x⁺ = x + [x2; −25 x1 − 10 x2 x3 + 12; 0] Δ + [0; Δ; 0] w``, ``y = x1 + v``,
Q = 0.4, R = 0.1, Δ = 0.01.
"""

from __future__ import annotations

import argparse
import os
import time
from functools import partial
from typing import Any

import numpy as np

from fir_gym.estimators import LinearModel, StateSpaceModel, TimeVaryingLinearModel
from fir_gym.estimators.efir import ExtendedFIRFilter
from fir_gym.estimators.fir import FIRFilter
from fir_gym.estimators.fir_gains import batch_gain, make_window, two_stage_gain

from ._timing import per_call

DT = 0.01


def sim2_model() -> StateSpaceModel:
    """Paper 000 simulation 2 (δ = 0) with analytic Jacobians, batched."""
    H0 = np.array([[1.0, 0.0, 0.0]])

    def f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        out = x.copy()
        out[..., 0] += x[..., 1] * DT
        out[..., 1] += (-25.0 * x[..., 0] - 10.0 * x[..., 1] * x[..., 2] + 12.0) * DT
        return out

    J0 = np.eye(3) + DT * np.array([[0.0, 1.0, 0.0], [-25.0, 0.0, 0.0], [0.0, 0.0, 0.0]])

    def F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = np.repeat(J0[None], x.shape[0], axis=0) if x.ndim == 2 else J0.copy()
        J[..., 1, 1] -= 10.0 * DT * x[..., 2]
        J[..., 1, 2] = -10.0 * DT * x[..., 1]
        return J

    def h(x: np.ndarray) -> np.ndarray:
        return x[..., :1].copy()

    def H(x: np.ndarray) -> np.ndarray:
        return np.repeat(H0[None], x.shape[0], axis=0) if x.ndim == 2 else H0.copy()

    return StateSpaceModel(f=f, h=h, F=F, H=H, Q=[[0.4]], R=[[0.1]], G=[[0.0], [DT], [0.0]],
                           dt=DT, name="paper000-sim2")


def _ekf(model: StateSpaceModel) -> Any:
    """fir-gym's EKF; a minimal inline one if it is not importable."""
    try:
        from fir_gym.estimators.extended import ExtendedKalmanFilter
        return ExtendedKalmanFilter(model, x0=[0.0, 0.0, 0.5], P0=2.0 * np.eye(3))
    except ImportError:                                    # pragma: no cover
        return _MinimalEKF(model)


class _MinimalEKF:
    """Textbook EKF step (predict with F, update with H), batched — a timing stand-in."""

    def __init__(self, model: StateSpaceModel) -> None:
        self.m, self.x, self.P = model, np.array([[0.0, 0.0, 0.5]]), 2.0 * np.eye(3)[None]

    def step(self, y: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        m = self.m
        F = m.F(self.x, u)
        x = m.f(self.x, u)
        P = F @ self.P @ np.swapaxes(F, 1, 2) + m.GQGT
        H = m.H(x)
        S = H @ P @ np.swapaxes(H, 1, 2) + m.R
        K = np.swapaxes(np.linalg.solve(S, H @ P), 1, 2)
        self.x = x + (K @ (np.atleast_2d(y) - m.h(x))[..., None])[..., 0]
        self.P = P - K @ H @ P
        return self.x


def fit_exponent(N: np.ndarray, t: np.ndarray) -> float:
    """Least-squares slope of ``log t`` against ``log N``."""
    return float(np.polyfit(np.log(N), np.log(t), 1)[0])


def growth(horizons: tuple[int, ...] = (25, 50, 100, 200, 400, 800),
           bank_horizons: tuple[int, ...] = (10, 50, 200, 800, 3200),
           fit_from: int = 100, bank_fit_from: int = 200) -> dict[str, Any]:
    """Cost against the horizon ``N``: gain paths (c) and (a), and a time-varying filter step.

    The filter step runs ``N`` staggered two-stage recursions in lock-step: O(N·n³)
    work in O(1) numpy calls, so its time is flat until the arrays are large; its
    exponent is fitted from ``bank_fit_from`` on.
    """
    rng = np.random.default_rng(0)
    n, p = 3, 1
    A = rng.normal(size=(n, n))
    A *= 0.95 / np.max(np.abs(np.linalg.eigvals(A)))
    C = rng.normal(size=(p, n))
    tv = TimeVaryingLinearModel(A=lambda k: A * (1 + 0.01 * np.sin(k)), C=C,
                                Q=0.1 * np.eye(n), R=np.eye(p))
    rows, bank_rows = [], []
    for N in horizons:
        win = make_window(A, C, 0.1 * np.eye(n), np.eye(p), N)
        tc = per_call(partial(two_stage_gain, win), 2, 5, warmup=0)
        ta = per_call(partial(batch_gain, win), 1, 3 if N < 800 else 2, warmup=0)
        rows.append((N, tc, ta))
    y = np.zeros(p)
    for N in bank_horizons:
        f = FIRFilter(tv, horizon=N)
        for _ in range(N + 2):
            f.step(y)
        bank_rows.append((N, per_call(partial(f.step, y), 20, 5, warmup=0)))
    R, Rb = np.array(rows), np.array(bank_rows)
    sel, selb = R[:, 0] >= fit_from, Rb[:, 0] >= bank_fit_from
    return {"rows": rows, "bank_rows": bank_rows,
            "alpha_c": fit_exponent(R[sel, 0], R[sel, 1]),
            "alpha_a": fit_exponent(R[sel, 0], R[sel, 2]),
            "alpha_bank": fit_exponent(Rb[selb, 0], Rb[selb, 1])}


def speed(horizon: int = 10, steps: int = 500, repeats: int = 15) -> dict[str, float]:
    """One EFIR step against one EKF step (single system, same model and data).

    The two are timed in alternating blocks and each keeps its best block, so a
    change of machine load during the run affects both alike.
    """
    model = sim2_model()
    filters = {"efir": ExtendedFIRFilter(model, horizon=horizon, x0=[0.0, 0.0, 0.5]),
               "ekf": _ekf(model)}
    ys = 0.48 + 0.3 * np.random.default_rng(1).standard_normal((steps, 1))
    best = dict.fromkeys(filters, np.inf)
    for flt in filters.values():
        for y in ys[:horizon + 5]:
            flt.step(y)
    for _ in range(repeats):
        for name, flt in filters.items():
            t0 = time.perf_counter()
            for y in ys:
                flt.step(y)
            best[name] = min(best[name], (time.perf_counter() - t0) / steps)
    return {**best, "ratio": best["efir"] / best["ekf"]}


def batched(n_batch: int = 1024, horizon: int = 10, steps: int = 10, repeats: int = 5
            ) -> dict[str, float]:
    """EFIR microseconds per system-step for ``n_batch`` systems in lock-step (best block)."""
    model = sim2_model()
    rng = np.random.default_rng(2)
    x0 = np.array([0.0, 0.0, 0.5]) + 0.01 * rng.standard_normal((n_batch, 3))
    efir = ExtendedFIRFilter(model, horizon=horizon, x0=x0)
    ys = 0.48 + 0.3 * rng.standard_normal((horizon + steps * repeats, n_batch, 1))
    for y in ys[:horizon]:
        efir.step(y)
    it = iter(ys[horizon:])
    t = per_call(lambda: efir.step(next(it)), steps, repeats, warmup=0)
    return {"us_per_system_step": t / n_batch * 1e6, "step_ms": t * 1e3}


def linear_speed(horizon: int = 10) -> dict[str, float]:
    """A time-invariant FIRFilter step (fixed gain, ring buffer) for reference."""
    m = LinearModel(A=[[1.0, DT], [0.0, 1.0]], C=[[1.0, 0.0]], Q=0.01 * np.eye(2), R=[[0.1]])
    f = FIRFilter(m, horizon=horizon)
    y = np.zeros(1)
    for _ in range(horizon + 2):
        f.step(y)
    return {"fir_step_us": per_call(lambda: f.step(y), 2000, 5, warmup=0) * 1e6}


def orbit_errors(steps: int = 20000, seed: int = 0) -> dict[str, Any]:
    """Max |EFIR error| on Orbit-v0 in paper 000's setting, for both nominals, noisy and not.

    N = 10, filter and nominal start [7.997, 1.992], zero thrust, R = 1e-3, model
    μ = 19.91 against the true 19.92244165; the run lasts until the body reaches
    the planet (about 11 800 steps) or ``steps``.
    """
    import gymnasium as gym

    import fir_gym  # noqa: F401  (registers the environments)

    env = gym.make("fir_gym/Orbit-v0", max_episode_steps=steps)
    plant: Any = env.unwrapped
    model = plant.model
    y, info = env.reset(seed=seed)
    keys = [(nom, nf) for nom in ("open-loop", "reanchor") for nf in (False, True)]
    filters = {key: ExtendedFIRFilter(model, horizon=10, form="predictor", nominal=key[0],
                                      x0=[7.997, 1.992]) for key in keys}
    worst = {key: np.zeros(2) for key in keys}
    first = {key: np.zeros(2) for key in keys}
    k, done = 0, False
    while not done:
        for (nom, nf), f in filters.items():
            x = f.step(info["state"][:1] if nf else y, None if k == 0 else np.zeros(1))
            if not f.last_info["startup"]:
                err = np.abs(x - info["state"])
                worst[nom, nf] = np.maximum(worst[nom, nf], err)
                if k < 1000:
                    first[nom, nf] = np.maximum(first[nom, nf], err)
        y, _, term, trunc, info = env.step(np.zeros(1))
        done, k = term or trunc, k + 1
    nominal = filters["open-loop", False].x_nominal
    assert nominal is not None
    return {"steps": np.array(k), "worst": worst, "first1000": first,
            "nominal_drift": nominal - info["state"]}


def growth_section(quick: bool) -> dict[str, Any]:
    """:func:`growth` at the horizons of a quick or a full run (``fir-gym speed fir``)."""
    return growth((25, 50, 100, 200, 400) if quick else (25, 50, 100, 200, 400, 800),
                  (10, 50, 200, 800) if quick else (10, 50, 200, 800, 3200))


def print_growth(g: dict[str, Any]) -> None:
    """The table of :func:`growth`: seconds per gain and per time-varying filter step."""
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    print(f"FIR gain growth: seconds per call (n = 3, p = 1; OPENBLAS_NUM_THREADS={threads})")
    print(f"{'N':>6} {'(c) two-stage gain':>20} {'(a) batch gain':>16}")
    for N, tc, ta in g["rows"]:
        print(f"{N:>6} {tc:>20.3e} {ta:>16.3e}")
    print(f"   fitted exponent (N >= 100): (c) {g['alpha_c']:.2f}, (a) {g['alpha_a']:.2f}")
    print(f"{'N':>6} {'time-varying FIRFilter step (bank of N windows)':>48}")
    for N, tb in g["bank_rows"]:
        print(f"{N:>6} {tb:>48.3e}")
    print(f"   fitted exponent (N >= 200): {g['alpha_bank']:.2f}")


def main(argv: list[str] | None = None) -> None:
    """Print the benchmarks (``--orbit`` adds the long Orbit-v0 accuracy run)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller horizons")
    ap.add_argument("--orbit", action="store_true", help="also the long Orbit-v0 run")
    args = ap.parse_args(argv)
    print("1. ", end="")
    print_growth(growth_section(args.quick))
    s = speed()
    print(f"2. speed (n = 3, N = 10, one system): EFIR {s['efir'] * 1e6:.1f} us, "
          f"EKF {s['ekf'] * 1e6:.1f} us, ratio {s['ratio']:.2f} (target <= 2)")
    b = batched()
    print(f"3. batched EFIR, B = 1024, N = 10: {b['us_per_system_step']:.2f} us per "
          f"system-step ({b['step_ms']:.2f} ms per step; target <= 5 us)")
    print(f"   (time-invariant FIRFilter step, N = 10: {linear_speed()['fir_step_us']:.1f} us)")
    if args.orbit:
        o = orbit_errors()
        print(f"4. Orbit-v0, paper 000 sim 1, predictor form, {int(o['steps'])} steps:")
        for (nom, nf), w in o["worst"].items():
            f1 = o["first1000"][nom, nf]
            print(f"   {nom:>9} {'noise-free' if nf else 'noisy':>10}: max |error| "
                  f"r {w[0]:.3g}, v {w[1]:.3g} (first 1000 steps: r {f1[0]:.3g}, v {f1[1]:.3g})")
        print(f"   open-loop nominal minus truth at the end: {o['nominal_drift']}")


if __name__ == "__main__":
    main()
