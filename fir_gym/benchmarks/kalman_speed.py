"""Section 1 of ``fir-gym speed``: the Kalman family and the EFIR, against filterpy.

* KF, EKF and UKF on two models (2-state/1-output linear, 4-state/2-output
  nonlinear), one system and batched at B = 1024, beside filterpy's filters on the same
  models and data — on **consistent** data (noise as the model's ``R``) and on
  **mismatched** data (ten times the model's noise: the filter flags divergence and
  the flag stays raised, which the row reports), so the figures are not the happy
  path's only. Ratios ours / filterpy per step, batched throughput over looping
  filterpy, and each batched filter's gain over its own numpy path;
* the EFIR (n = 3, N = 10, paper 000's sim 2) against the EKF on the same model, and
  batched;
* the fixed cost of ``Estimator.step``: a one-state EKF whose model callables return
  ready arrays, at B = 1 and 64 — the whole step and, beside it, its compiled kernel
  called alone with the same arguments (the difference is the Python boundary:
  argument checks, dispatch, copies).
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from fir_gym.estimators import compiled

from ..tables import format_table
from . import _floors
from . import fir as fir_bench
from . import kalman as kalman_bench
from ._timing import counting, interleaved, per_call
from .targets import ratio

#: (model, row name, class, data, options); "kf": the converged (steady-state) regime,
#: "kf-full": the covariance recomputed (one measurement in 1000 missing)
KALMAN_CASES: tuple[tuple[str, str, str, str, dict[str, Any]], ...] = (
    ("linear", "kf", "KalmanFilter", "consistent", {}),
    ("linear", "kf", "KalmanFilter", "mismatched", {}),
    ("linear", "kf-full", "KalmanFilter", "consistent", {"skip": True}),
    ("linear", "ekf", "ExtendedKalmanFilter", "consistent", {}),
    ("linear", "ekf", "ExtendedKalmanFilter", "mismatched", {}),
    ("linear", "ukf", "UnscentedKalmanFilter", "consistent", {"alpha": 1.0}),
    ("nonlinear", "ekf", "ExtendedKalmanFilter", "consistent", {}),
    ("nonlinear", "ekf", "ExtendedKalmanFilter", "mismatched", {}),
    ("nonlinear", "ukf", "UnscentedKalmanFilter", "consistent", {"alpha": 1.0}),
    ("nonlinear", "ukf", "UnscentedKalmanFilter", "mismatched", {"alpha": 1.0}),
)


def kalman_section(quick: bool) -> dict[str, Any]:
    """The two models against filterpy, the EFIR against the EKF (paper 000's sim 2), and
    the step's fixed cost.

    Ours (one system), filterpy and ours batched at B = 1024 are timed in alternating
    blocks, so their ratios hold under a changing load.
    """
    from fir_gym import estimators as est

    calls, big_calls, reps = (200, 3, 5) if quick else (1000, 10, 12)
    models = kalman_bench.models()
    rows = []
    for mname, fname, cname, data, opts in KALMAN_CASES:
        model, cls = models[mname], getattr(est, cname)
        opts = dict(opts)
        skip = bool(opts.pop("skip", False))
        ours = kalman_bench.ours_stepper(cls, model, 1, skip, data, **opts)
        big = kalman_bench.ours_stepper(cls, model, 1024, skip, data, **opts)
        for k in range(2000):                           # past the transient (KF steady state)
            ours(k + 1)
            big(k + 1)
        runs = {"ours": (counting(ours), calls), "big": (counting(big), big_calls)}
        if compiled.ENABLED:                            # the same filter on its numpy path
            big_numpy = kalman_bench.ours_stepper(cls, model, 1024, skip, data, **opts)
            for k in range(2000):
                _floors.numpy_path(big_numpy, k + 1)
            runs["numpy"] = (counting(partial(_floors.numpy_path, big_numpy)), big_calls)
        fp = kalman_bench.filterpy_stepper(fname.split("-")[0], model, opts.get("alpha", 1.0),
                                           data)
        if fp is not None:
            runs["filterpy"] = (counting(fp), max(calls // 4, 50))
        t = interleaved(runs, reps)
        single, batched = 1e6 * t["ours"], 1e6 * t["big"] / 1024
        ref = 1e6 * t["filterpy"] if "filterpy" in t else None
        numpy_us = 1e6 * t["numpy"] / 1024 if "numpy" in t else None
        rows.append({"model": model.name, "filter": fname, "data": data, "single_us": single,
                     "batched_us": batched, "filterpy_us": ref, "ratio": ratio(single, ref),
                     "throughput_vs_filterpy": ratio(ref, batched),
                     "batched_numpy_us": numpy_us, "compiled_speedup": ratio(numpy_us, batched),
                     "flagged": bool(ours.estimator.diverged),      # type: ignore[attr-defined]
                     "flagged_batched": float(np.mean(big.estimator.diverged))})  # type: ignore
    efir = fir_bench.speed(steps=200 if quick else 500, repeats=5 if quick else 15)
    eb = _efir_batched(quick)
    efir_row = {"efir_us": 1e6 * efir["efir"], "ekf_us": 1e6 * efir["ekf"],
                "efir_over_ekf": efir["ratio"], **eb}
    return {"rows": rows, "efir": efir_row, "fixed_cost": fixed_cost(quick)}


def fixed_cost(quick: bool) -> list[dict[str, Any]]:
    """µs of a one-state EKF step whose model returns ready arrays, of its compiled kernel
    alone (same arguments), and of the step with its kernel a no-op (its Python side: the
    fixed cost), at B = 1 and 64."""
    out = []
    calls, reps = (2000, 5) if quick else (20000, 9)
    for n_batch in (1, 64):
        step = _floors.trivial_ekf_step(n_batch)
        runs = {"step": (step, calls)}
        if compiled.ENABLED:
            runs["kernel"] = (_floors.trivial_ekf_kernel(n_batch), calls)
        t = interleaved(runs, reps)
        python = None
        if compiled.ENABLED:
            with _floors.kalman_kernels_skipped():
                python = 1e6 * per_call(step, calls, reps)
        out.append({"batch": n_batch, "step_us": 1e6 * t["step"],
                    "kernel_us": 1e6 * t["kernel"] if "kernel" in t else None,
                    "python_us": python})
    return out


def _efir_batched(quick: bool) -> dict[str, Any]:
    """EFIR (n = 3, N = 10) at B = 1024 per system-step, alternating with filterpy's EKF."""
    from fir_gym.estimators import ExtendedFIRFilter

    model = fir_bench.sim2_model()
    rng = np.random.default_rng(2)
    x0 = np.array([0.0, 0.0, 0.5]) + 0.01 * rng.standard_normal((1024, 3))
    efir = ExtendedFIRFilter(model, horizon=10, x0=x0)
    ys = 0.48 + 0.3 * rng.standard_normal((64, 1024, 1))
    u = np.zeros((1024, 0))
    for k in range(12):
        efir.step(ys[k], None if k == 0 else u)
    runs = {"efir": (counting(lambda k: efir.step(ys[12 + k % 52], u)), 3 if quick else 10)}
    if compiled.ENABLED:
        slow = ExtendedFIRFilter(model, horizon=10, x0=x0)
        for k in range(12):
            _floors.numpy_path(lambda k: slow.step(ys[k], None if k == 0 else u), k)
        runs["numpy"] = (counting(lambda k: _floors.numpy_path(
            lambda k: slow.step(ys[12 + k % 52], u), k)), 3 if quick else 10)
    fp = kalman_bench.filterpy_stepper("ekf", model, 1.0)
    if fp is not None:
        runs["filterpy"] = (counting(fp), 50 if quick else 300)
    t = interleaved(runs, 3 if quick else 8)
    b = 1e6 * t["efir"] / 1024
    ref = 1e6 * t["filterpy"] if "filterpy" in t else None
    numpy_us = 1e6 * t["numpy"] / 1024 if "numpy" in t else None
    return {"batched_us": b, "filterpy_ekf_us": ref,
            "throughput_vs_filterpy_ekf": ratio(ref, b), "batched_numpy_us": numpy_us,
            "compiled_speedup": ratio(numpy_us, b)}


def print_kalman(res: dict[str, Any]) -> None:
    print("\n1. Kalman family on a linear 2x1 and a nonlinear 4x2 model, against filterpy "
          "(α = 1 for both UKFs)\n")
    rows = [[r["model"], r["filter"], r["data"], r["single_us"], r["filterpy_us"], r["ratio"],
             r["batched_us"], r["throughput_vs_filterpy"], r.get("compiled_speedup"),
             f"{'yes' if r['flagged'] else 'no'} / {r.get('flagged_batched', 0.0):.0%}"]
            for r in res["rows"]]
    print(format_table(["model", "filter", "data", "µs/step", "filterpy µs/step",
                        "ours/filterpy", "B=1024 µs/sys-step", "throughput ×filterpy",
                        "compiled ×numpy path", "flagged (one / share of 1024)"], rows,
                       floatfmt=".3g"))
    print("   kf: converged (steady-state) regime; kf-full: covariance recomputed (one "
          "measurement in 1000 missing); mismatched: the data's noise ten times the model's "
          "(the divergence flag is raised within ten steps and stays raised)")
    e = res["efir"]
    print(f"\n   EFIR (n = 3, N = 10) {e['efir_us']:.3g} µs/step = {e['efir_over_ekf']:.2f} × "
          f"the EKF's {e['ekf_us']:.3g} µs; batched B = 1024: {e['batched_us']:.3g} µs/sys-step"
          + ("" if e["throughput_vs_filterpy_ekf"] is None else
             f" = {e['throughput_vs_filterpy_ekf']:.3g} × the throughput of looping "
             f"filterpy's EKF ({e['filterpy_ekf_us']:.3g} µs) on the same model")
          + ("" if e.get("compiled_speedup") is None else
             f"; {e['compiled_speedup']:.3g} × its numpy path"))
    print("\n   Estimator.step's fixed cost (one-state EKF, model callables returning ready "
          "arrays): µs per step\n")
    print(format_table(["systems", "whole step", "its compiled kernel alone",
                        "the step with a no-op kernel (its Python side)"],
                       [[f["batch"], f["step_us"], f["kernel_us"], f["python_us"]]
                        for f in res["fixed_cost"]], floatfmt=".3g"))
