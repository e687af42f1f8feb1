"""Paper 000, simulation 1 (Fig. 1): rectilinear orbit determination, EKF against EFIR.

The plant is ``fir_gym/Orbit-v0`` as the paper sets it (eqs 27–28): Euler step
Δ = 1e-4, the range measured every M = 100 Euler steps with R = 1e-3, true
μ = 19.92244165, the filters' model μ = 19.91, x0 = [7.99, 1.99], no process
noise. The filters start from [7.997, 1.992]: the EKF with P0 = 2 I, the EFIR
(N = 10 *measurements*, the predictor form of eq 13, nominal trajectory run open
loop from the filter's initial state) as the paper; the EFIR's filter form and
its re-anchored nominal are named variants.

The paper does not give Fig. 1's horizon. We use 10⁴ measurement intervals (100
time units: the body rises to its apogee r ≈ 38.8 at k ≈ 5 900 and falls back to
r ≈ 25; it would reach the planet, r = 1, at k ≈ 11 770): long enough for the
EKF's inconsistency to grow by four orders of magnitude. ``quick`` uses 10³.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.envs.orbit import NOMINAL_MU, TRUE_MU
from fir_gym.estimators import ExtendedFIRFilter, ExtendedKalmanFilter, chi2_band

from ._montecarlo import (
    EpisodeTask,
    nees_per_step,
    rmse_per_step,
    run_filter,
    simulate_episode,
    stack_episodes,
    task_seed,
)
from .report import Report
from .runner import SERIAL, Runner

ENV_ID = "fir_gym/Orbit-v0"
X0_FILTER = (7.997, 1.992)
P0 = 2.0 * np.eye(2)
HORIZON = 10
STEPS = {False: 10_000, True: 1_000}
RUNS = {False: 30, True: 5}
#: the EKF counts as inconsistent once its run-averaged NEES leaves this χ² band for good
NEES_CONFIDENCE = 0.99
PAPER_FILTER = "EFIR predictor (paper)"
#: the EKF's initial transient is over by then (its error below σ_v from here on)
SETTLED = 100


def orbit_filters(model: Any) -> dict[str, Any]:
    """The filters of Fig. 1 (and the EFIR variants), all on the env's model (μ = 19.91)."""
    common = {"x0": X0_FILTER, "P0": P0, "nan_policy": "skip"}
    return {
        "EKF": ExtendedKalmanFilter(model, **common),
        PAPER_FILTER: ExtendedFIRFilter(model, horizon=HORIZON, form="predictor", **common),
        "EFIR filter form": ExtendedFIRFilter(model, horizon=HORIZON, form="filter", **common),
        "EFIR re-anchored nominal": ExtendedFIRFilter(model, horizon=HORIZON, form="predictor",
                                                      nominal="reanchor", **common),
    }


def run_orbit(report: Report, *, seed: int, quick: bool, runs: int | None,
              runner: Runner | None) -> dict[str, Any]:
    """Simulation 1: simulate ``runs`` episodes (one task per seed), filter them batched.

    Fills ``report`` (summary rows, a detail table, notes) and returns the raw
    numbers for ``report.figures["orbit"]``.
    """
    runner = runner or SERIAL
    steps, runs = STEPS[quick], runs or RUNS[quick]
    tasks = [EpisodeTask(ENV_ID, task_seed(seed, 0, i), steps) for i in range(runs)]
    ep = stack_episodes(runner.map(simulate_episode, tasks, desc="paper 000 sim 1"))
    env = gym.make(ENV_ID)
    model, sigma_v = env.unwrapped.model, float(np.sqrt(env.unwrapped.params["R"][0, 0]))
    env.close()
    lo, hi = chi2_band(2, runs, NEES_CONFIDENCE)
    out: dict[str, Any] = {"steps": steps, "runs": runs, "sigma_v": sigma_v,
                           "nees_band": (lo, hi), "filters": {}}
    for name, f in orbit_filters(model).items():
        fr = run_filter(f, ep.Y, ep.U, covariance=True)
        e = fr.x - ep.X
        nees = nees_per_step(e, fr.P)
        tail = slice(int(0.9 * steps), steps + 1)
        after = slice(HORIZON, steps + 1)             # from the first full window on
        above = np.flatnonzero(nees <= hi)
        out["filters"][name] = {
            "rmse1": rmse_per_step(e[..., 0]), "nees": nees, "e1_run0": e[:, 0, 0],
            "sd1": np.sqrt(fr.P[:, 0, 0, 0]),
            "max1": float(np.abs(e[after, :, 0]).max()),
            "rms1": float(np.sqrt(np.mean(e[after, :, 0] ** 2))),
            "rms1_tail": float(np.sqrt(np.mean(e[tail, :, 0] ** 2))),
            "rms2": float(np.sqrt(np.mean(e[after, :, 1] ** 2))),
            "inconsistent_from": int(above[-1] + 1) if above.size and above[-1] < steps else
            (None if above.size else 0),
            "flagged": int(np.sum(fr.diverged)),
        }
    _fill(report, out)
    return out


def _fill(report: Report, out: dict[str, Any]) -> None:
    f, K, sv = out["filters"], out["steps"], out["sigma_v"]
    ekf, efir = f["EKF"], f[PAPER_FILTER]
    k0 = min(SETTLED, K // 2)                         # after the EKF's initial transient
    marks = sorted({k for k in (k0, 1000, 5000, K) if k <= K})
    settled = slice(k0, K + 1)
    peak = {name: float(np.max(r["rmse1"][settled])) for name, r in f.items()}
    below = bool(np.all(ekf["rmse1"][settled] < efir["rmse1"][settled]))
    onset = ekf["inconsistent_from"]
    lo, hi = out["nees_band"]
    reading = (f"μ_model = {NOMINAL_MU} vs true {TRUE_MU}; EKF P0 = 2I; EFIR N = {HORIZON} "
               f"predictor, open-loop nominal; {out['runs']} runs, k = 0..{K}")
    if onset is None:
        verdict = (f"not reproduced within k ≤ {K}: the EKF's NEES is still inside its "
                   f"{100 * NEES_CONFIDENCE:g} % χ² band (the full run goes to 10⁴)")
    else:
        verdict = (f"reproduced as inconsistency only: from k = {onset} the EKF's NEES leaves "
                   f"its {100 * NEES_CONFIDENCE:g} % χ² band for good (its P shrinks without "
                   "process noise while the μ bias accumulates)")
    verdict += ("; its error stays below σ_v and below the EFIR's over the whole horizon, and the "
                "innovation test never flags it" if below and peak["EKF"] < sv and not
                ekf["flagged"] else "")
    report.compare(
        "Sim 1, Fig. 1: the EKF diverges, the EFIR stays bounded", "claim (figure only)",
        f"EKF NEES {ekf['nees'][marks[0]]:.3g} (k={marks[0]}) → {ekf['nees'][K]:.3g} (k={K}), "
        f"x₁ RMSE ≤ {peak['EKF']:.2g} for k ≥ {k0} (σ_v = {sv:.3g}); EFIR NEES ≈ "
        f"{np.mean(efir['nees'][HORIZON:]):.2f}, x₁ RMSE ≤ {peak[PAPER_FILTER]:.2g}",
        reading, verdict)
    for name in (PAPER_FILTER, "EKF"):
        report.compare(f"Sim 1: largest x₁ RMSE over k = {k0}..{K}, {name}", None, peak[name],
                       reading, f"the paper gives Fig. 1 only; max abs(e₁) over all runs and k ≥ "
                       f"{HORIZON}: {f[name]['max1']:.3g}")
        report.compare(f"Sim 1: RMS x₁ error, {name}, k ≥ {HORIZON}", None, f[name]["rms1"],
                       reading, f"last 10 % of the horizon: {f[name]['rms1_tail']:.3g}")
    report.compare(f"Sim 1: EKF NEES (run average) at k = {K}", None, float(ekf["nees"][K]),
                   reading, f"a consistent filter's run average lies in [{lo:.2f}, {hi:.2f}] "
                   f"({100 * NEES_CONFIDENCE:g} % χ² band); " + (
                       "the EKF is inside it at the end" if onset is None else
                       f"the EKF is above it for good from k = {onset}"))
    rows = [[name, r["max1"], peak[name], r["rms1"], r["rms1_tail"], r["rms2"],
             *[float(r["nees"][k]) for k in marks], r["flagged"]] for name, r in f.items()]
    report.add_table(
        f"Sim 1 (Fig. 1): x₁ estimation error and consistency, {out['runs']} runs, k = 0..{K}",
        ["filter", f"max abs(e₁) (k≥{HORIZON})", f"max RMSE₁ (k≥{k0})", "RMS e₁",
         "RMS e₁ last 10 %", "RMS e₂", *[f"NEES k={k}" for k in marks],
         "runs flagged diverged"], rows)
    tail_sd = float(np.mean(ekf["sd1"][int(0.9 * K):]))
    re_rel = abs(f["EFIR re-anchored nominal"]["rms1"] / efir["rms1"] - 1)
    report.notes += [
        f"Sim 1 horizon: the paper does not give Fig. 1's; we use k = 0..{K} measurement "
        "intervals (10⁴ in the full run: 100 time units, apogee r ≈ 38.8 at k ≈ 5 900; the body "
        "would reach r = 1 at k ≈ 11 770). The window counts measurements (10 measurements = "
        "1000 Euler steps), as docs/papers.md#000-sim-1-window establishes.",
        f"Sim 1: the EKF's own σ(x₁) falls to {ekf['sd1'][K]:.2g} while its actual RMS error over "
        f"the last 10 % of the horizon is {ekf['rms1_tail']:.2g} ({ekf['rms1_tail'] / tail_sd:.1f}"
        f"× its σ there); its NEES grows from {ekf['nees'][marks[0]]:.3g} at k = {marks[0]} to "
        f"{ekf['nees'][K]:.3g} at k = {K}. The error itself stays near {peak['EKF']:.2g}, below "
        f"σ_v = {sv:.3g}, so the normalised innovations look healthy and the EKF's divergence "
        f"test (NIS) {'never fires' if not ekf['flagged'] else 'fires'} ({ekf['flagged']} runs "
        "flagged). Over ~10⁴ steps the paper's 'diverges quickly' is a divergence of the "
        "consistency, not of the error magnitude.",
        f"Sim 1: the EFIR's error is that of an unbiased 10-measurement window (σ(x₁) = "
        f"{efir['sd1'][K]:.3g} predictor, {f['EFIR filter form']['sd1'][K]:.3g} filter form), "
        "bounded and consistent (NEES ≈ 2); the μ error adds a bias far below the noise over a "
        "0.1-time-unit window. The re-anchored nominal changes only the linearisation point, a "
        f"second-order effect here: its RMS x₁ error differs from the open-loop one by "
        f"{100 * re_rel:.2g} %.",
    ]
