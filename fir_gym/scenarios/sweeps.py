"""Beyond the papers: what paper 000's experiments raise, swept.

1. **Model mismatch × window length** (Orbit-v0, paper 000 sim 1's setting): the
   x₁ RMSE of the EFIR (predictor form, open-loop nominal, as the paper) for
   windows N and of the EKF and UKF (P0 = 2 I) when the filters' μ is a fraction
   of the true one. A FIR window trades noise (falls with N) against model-error
   bias (grows with N, docs/papers.md#beyond-ufir); an IIR filter without process noise
   accumulates the bias instead.
2. **Recovery after a temporary uncertainty** (UncertainOscillator-v0, printed
   reading): δ on k = 350..400 of several sizes; the number of steps after the last
   perturbed state until each filter's x₁ RMSE stays within 2× its pre-window level
   (:func:`.paper000_oscillator.recovery_time`). A FIR filter forgets within N
   (docs/papers.md#beyond-forgetting); LKF, EKF and UKF are measured beside it.

Every grid cell is one task of the runner (the orbit cells get the shared,
seeded measurements as arguments; the recovery cells simulate their own), so
the sweep runs unchanged on local cores or a Dask cluster.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.envs.orbit import NOMINAL_MU, TRUE_MU
from fir_gym.estimators import ExtendedFIRFilter, ExtendedKalmanFilter, UnscentedKalmanFilter

from ._montecarlo import (
    EpisodeTask,
    VectorTask,
    chunks,
    rmse_per_step,
    run_filter,
    simulate_episode,
    simulate_vector,
    stack_episodes,
    task_seed,
)
from .paper000_orbit import ENV_ID as ORBIT_ID
from .paper000_orbit import P0 as ORBIT_P0
from .paper000_orbit import X0_FILTER
from .paper000_oscillator import (
    CHUNK,
    WINDOW,
    oscillator_filters,
    recovery_time,
)
from .paper000_oscillator import ENV_ID as OSC_ID
from .paper000_oscillator import P0 as OSC_P0
from .paper000_oscillator import X0 as OSC_X0
from .report import Report
from .runner import SERIAL, Runner

PAPER_RATIO = NOMINAL_MU / TRUE_MU
RATIOS = {False: (1.0, PAPER_RATIO, 0.98, 0.9), True: (PAPER_RATIO, 0.9)}
ORBIT_WINDOWS = {False: (5, 10, 25, 50, 100), True: (10, 50)}
ORBIT_STEPS = {False: 800, True: 300}
ORBIT_RUNS = {False: 10, True: 4}
SCORE_FROM = 100                       # every window is full from here on
DELTAS = {False: (0.02, 0.05, 0.1, 0.15), True: (0.05, 0.15)}
OSC_WINDOWS = {False: (5, 10, 20), True: (10,)}
OSC_STEPS = {False: 1500, True: 800}
OSC_RUNS = {False: 40, True: 10}


def orbit_cell(task: tuple[float, str, int | None, np.ndarray, np.ndarray]) -> float:
    """One cell: filter ``name`` (window ``N``) with μ = ratio × true on data ``(Y, X)``."""
    ratio, name, N, Y, X = task
    env = gym.make(ORBIT_ID)
    model = env.unwrapped.make_model(mu=ratio * TRUE_MU)
    env.close()
    common = {"x0": X0_FILTER, "P0": ORBIT_P0, "nan_policy": "skip"}
    f = {"EKF": lambda: ExtendedKalmanFilter(model, **common),
         "UKF": lambda: UnscentedKalmanFilter(model, **common),
         "EFIR": lambda: ExtendedFIRFilter(model, horizon=N, form="predictor", **common)}[name]()
    e = run_filter(f, Y).x[SCORE_FROM:, :, 0] - X[SCORE_FROM:, :, 0]
    return float(np.sqrt(np.mean(e * e)))


def recovery_cell(task: tuple[float, int, int, int, tuple[int, ...]]) -> dict[str, Any]:
    """One δ: simulate ``runs`` episodes (seeded chunks), run every filter, measure recovery."""
    delta, seed, runs, steps, windows = task
    kwargs = {"uncertainty": "state", "delta_schedule": ((WINDOW[0], WINDOW[1], delta),)}
    ep = stack_episodes([simulate_vector(VectorTask(OSC_ID, task_seed(seed, 5, i), n, steps,
                                                    kwargs))
                         for i, n in enumerate(chunks(runs, CHUNK))])
    env = gym.make(OSC_ID)
    model = env.unwrapped.model
    env.close()
    filters = {k: v for k, v in oscillator_filters(model, variants=False).items() if k != "EFIRF"}
    for N in windows:
        filters[f"EFIR N={N}"] = ExtendedFIRFilter(model, horizon=N, form="predictor", x0=OSC_X0,
                                                   P0=OSC_P0, nan_policy="skip")
    out = {}
    for name, f in filters.items():
        rm = rmse_per_step(run_filter(f, ep.Y, ep.U).x[..., 0] - ep.X[..., 0])
        rec, level = recovery_time(rm, WINDOW[1] + 1)
        out[name] = {"recovery": rec, "level": level,
                     "sum": float(np.sum(rm[WINDOW[0]:WINDOW[1] + 1]))}
    return out


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Both sweeps; ``runs`` sets both Monte Carlo sizes (default 10 and 40; quick 4, 10)."""
    runner = runner or SERIAL
    report = Report("sweeps", "Beyond the papers: model mismatch × window length, and "
                    "recovery after a temporary uncertainty")
    K, M = ORBIT_STEPS[quick], runs or ORBIT_RUNS[quick]
    ep = stack_episodes(runner.map(simulate_episode, [EpisodeTask(ORBIT_ID, task_seed(seed, 6, i),
                                                                  K) for i in range(M)],
                                   desc="sweeps: orbit data"))
    cells = [(r, name, N) for r in RATIOS[quick]
             for name, N in [("EKF", None), ("UKF", None)]
             + [("EFIR", N) for N in ORBIT_WINDOWS[quick]]]
    vals = runner.map(orbit_cell, [(r, n, N, ep.Y, ep.X) for r, n, N in cells],
                      desc="sweeps: mismatch x window")
    grid = {(r, n, N): v for (r, n, N), v in zip(cells, vals, strict=True)}
    deltas = DELTAS[quick]
    rec = runner.map(recovery_cell, [(d, seed, runs or OSC_RUNS[quick], OSC_STEPS[quick],
                                      OSC_WINDOWS[quick]) for d in deltas],
                     desc="sweeps: recovery")
    report.figures.update({"grid": grid, "ratios": RATIOS[quick], "windows": ORBIT_WINDOWS[quick],
                           "recovery": dict(zip(deltas, rec, strict=True)),
                           "osc_steps": OSC_STEPS[quick], "orbit_runs": M, "orbit_steps": K,
                           "sigma_v": float(np.sqrt(1e-3))})
    _fill(report)
    return report


def _fmt(rec: int | None, steps: int) -> str:
    return f"> {steps - WINDOW[1] - 1}" if rec is None else str(rec)


def _fill(report: Report) -> None:
    f = report.figures
    grid, ratios, windows = f["grid"], f["ratios"], f["windows"]
    reading = (f"Orbit-v0, filters' μ = ratio × {TRUE_MU}; EFIR predictor, open-loop nominal; "
               f"{f['orbit_runs']} runs, RMSE over k = {SCORE_FROM}..{f['orbit_steps']}")
    rows = []
    for r in ratios:
        efir = {N: grid[(r, "EFIR", N)] for N in windows}
        best = min(efir, key=efir.get)
        rows.append([f"{r:.5g}", grid[(r, "EKF", None)], grid[(r, "UKF", None)],
                     *efir.values(), best])
        report.compare(f"Mismatch μ_model/μ_true = {r:.5g}: x₁ RMSE, EKF / UKF / best EFIR",
                       None, f"{grid[(r, 'EKF', None)]:.3g} / {grid[(r, 'UKF', None)]:.3g} / "
                       f"{efir[best]:.3g} (N = {best})", reading,
                       "the papers leave it open; EFIR N = "
                       + ", ".join(f"{N}: {v:.3g}" for N, v in efir.items()))
    report.add_table("Model mismatch × window length: x₁ RMSE on Orbit-v0",
                     ["μ_model / μ_true", "EKF", "UKF", *[f"EFIR N={N}" for N in windows],
                      "best N"], rows)
    rec, steps = f["recovery"], f["osc_steps"]
    names = list(next(iter(rec.values())))
    rrows = [[d, *[_fmt(rec[d][n]["recovery"], steps) for n in names]] for d in rec]
    srows = [[d, *[rec[d][n]["sum"] for n in names]] for d in rec]
    for d, res in rec.items():
        report.compare(f"Recovery after δ = {d:g} on k = 350..400 (steps after x[401])", None,
                       ", ".join(f"{n} {_fmt(res[n]['recovery'], steps)}" for n in names),
                       "UncertainOscillator-v0, uncertainty='state', filters on the env's model",
                       "a FIR filter forgets within N (predictor: N steps); the IIR filters carry "
                       "the error in their state, the EKF/UKF also in x̂₃ (no process noise)")
    report.add_table(f"Recovery time (steps after x[401] until the x₁ RMSE stays within 2× its "
                     f"largest value over k = 300..349; run to k = {steps})", ["δ", *names], rrows)
    report.add_table("Σ_k=350..400 of the x₁ RMSE (Table 1's measure) for each δ",
                     ["δ", *names], srows)
    sweep_eps = [grid[(r, "EKF", None)] for r in ratios]
    efir_wins = [r for r in ratios
                 if min(grid[(r, "EFIR", N)] for N in windows) < grid[(r, "EKF", None)]]
    report.notes += [
        "Mismatch: over a window of N measurements the μ error biases the EFIR by about "
        "δμ/r²·(N·0.01)²/2, far below the noise for N ≤ 100 even at 10 % error, so the EFIR's "
        "RMSE falls with N like the end point of a straight-line fit, ≈ 2σ_v/√N; the EKF and "
        "UKF (no process noise) integrate the bias instead: RMSE "
        + " → ".join(f"{v:.2g}" for v in sweep_eps)
        + f" over the ratios {', '.join(f'{r:.4g}' for r in ratios)}. The best EFIR beats the "
        "EKF at the ratios " + (", ".join(f"{r:.4g}" for r in efir_wins) or "none")
        + f" (over k ≤ {f['orbit_steps']}; the EKF's bias keeps growing with time, Fig. 1).",
        "Recovery: the EFIR's recovery is at most N in the predictor form (its window "
        "y[k−N..k−1] is clean from k = 401 + N; 0 means its error never left the band); LKF "
        "recovers once the plant has settled (its "
        "linearisation never sees the data), EKF and UKF can take far longer because the "
        "uncertainty is absorbed into x̂₃, which has no process noise.",
    ]


def plot(report: Report, out_dir: str | Path) -> None:
    """RMSE vs window length per mismatch (with EKF/UKF), and recovery time vs δ."""
    from ._plotting import new_figure, save

    f = report.figures
    fig, ax = new_figure(1, 2, width=11.0, height=4.0)
    for i, r in enumerate(f["ratios"]):
        ax[0].loglog(f["windows"], [f["grid"][(r, "EFIR", N)] for N in f["windows"]], "o-",
                     color=f"C{i}", label=f"EFIR, μ ratio {r:.4g}")
        ax[0].axhline(f["grid"][(r, "EKF", None)], ls="--", color=f"C{i}",
                      label=f"EKF, μ ratio {r:.4g}")
    ax[0].axhline(f["sigma_v"], color="k", ls=":", label="σ_v")
    ax[0].set_xlabel("EFIR window N (measurements)")
    ax[0].set_ylabel("x₁ RMSE")
    ax[0].set_title("Orbit-v0: model mismatch × window", fontsize=9)
    ax[0].legend(fontsize=6)
    rec, steps = f["recovery"], f["osc_steps"]
    deltas = list(rec)
    cap = steps - WINDOW[1]
    for i, name in enumerate(next(iter(rec.values()))):
        vals = [cap if rec[d][name]["recovery"] is None else rec[d][name]["recovery"]
                for d in deltas]
        ax[1].plot(deltas, vals, "o-", color=f"C{i}", label=name)
    ax[1].set_yscale("symlog", linthresh=1.0)
    ax[1].axhline(cap, color="k", ls=":", label="end of run (not recovered)")
    ax[1].set_xlabel("δ on k = 350..400")
    ax[1].set_ylabel("recovery time (steps)")
    ax[1].set_title("UncertainOscillator-v0 (printed reading): recovery", fontsize=9)
    ax[1].legend(fontsize=6)
    save(report, out_dir, "sweeps", fig, "Sweeps: mismatch × window; recovery time vs δ")
