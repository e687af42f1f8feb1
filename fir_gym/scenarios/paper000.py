"""Paper 000: the extended FIR filter (EFIRF) for discrete nonlinear systems, both simulations.

* Simulation 1 (Fig. 1) — rectilinear orbit determination, EKF vs EFIR under a wrong
  gravitational parameter: :mod:`.paper000_orbit`.
* Simulation 2 (Fig. 2, Table 1) — the oscillator with a temporary uncertainty,
  EFIR vs LKF/EKF/UKF under both readings of eq (29): :mod:`.paper000_oscillator`.

``plot`` draws Fig. 1 (x₁ error, RMSE and NEES over the long horizon) and Fig. 2
(x₁ RMSE of every filter around the uncertainty window, both readings).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .paper000_orbit import HORIZON, PAPER_FILTER, run_orbit
from .paper000_oscillator import WINDOW, run_oscillator
from .report import Report
from .runner import Runner


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Both simulations; ``runs`` sets both Monte Carlo sizes (default 30 and 100; quick 5, 20)."""
    report = Report("000", "Extended FIR filter for discrete nonlinear systems (EFIRF)")
    report.figures["orbit"] = run_orbit(report, seed=seed, quick=quick, runs=runs, runner=runner)
    report.figures["oscillator"] = run_oscillator(report, seed=seed, quick=quick, runs=runs,
                                                  runner=runner)
    return report


def plot(report: Report, out_dir: str | Path) -> None:
    """Fig. 1 and Fig. 2 of paper 000 as PNGs under ``out_dir``."""
    from ._plotting import new_figure, save

    orbit = report.figures["orbit"]
    K = orbit["steps"]
    k = np.arange(K + 1)
    fig, ax = new_figure(3, 1, height=2.6, sharex=True)
    colours = {"EKF": "C3", PAPER_FILTER: "C0", "EFIR filter form": "C2",
               "EFIR re-anchored nominal": "C1"}
    for name, lw in ((PAPER_FILTER, 0.5), ("EKF", 1.2)):          # the EKF on top
        ax[0].plot(k, orbit["filters"][name]["e1_run0"], lw=lw, color=colours[name], label=name)
    sv = orbit["sigma_v"]
    ax[0].axhline(sv, color="k", ls=":", lw=0.8, label="±σ_v (measurement noise)")
    ax[0].axhline(-sv, color="k", ls=":", lw=0.8)
    ax[0].set_ylabel("x₁ error, run 0")
    order = ["EFIR re-anchored nominal", "EFIR filter form", PAPER_FILTER, "EKF"]
    for name in order:                       # the re-anchored variant equals the paper's EFIR
        r, ls = orbit["filters"][name], ":" if "re-anchored" in name else "-"
        ax[1].semilogy(k[HORIZON:], r["rmse1"][HORIZON:], ls, lw=0.7, color=colours[name],
                       label=name)
        ax[2].semilogy(k[HORIZON:], r["nees"][HORIZON:], ls, lw=0.7, color=colours[name],
                       label=name)
    ax[1].semilogy(k[HORIZON:], orbit["filters"]["EKF"]["sd1"][HORIZON:], "--", lw=0.8,
                   color="C3", label="EKF's own σ(x₁)")
    ax[1].set_ylabel(f"x₁ RMSE ({orbit['runs']} runs)")
    lo, hi = orbit["nees_band"]
    ax[2].axhspan(lo, hi, color="0.85", label="99 % χ² band")
    ax[2].set_ylabel("NEES (run average)")
    ax[2].set_xlabel("k (measurement intervals of 0.01)")
    for a in ax:
        a.legend(fontsize=7, loc="upper left")
    ax[0].set_title("Paper 000 Fig. 1: orbit determination, μ_model = 19.91 (true 19.9224)")
    save(report, out_dir, "fig1_orbit", fig, "Paper 000 Fig. 1: EKF vs EFIR on the orbit")

    osc = report.figures["oscillator"]
    fig, ax = new_figure(2, 1, height=3.0)
    for a, (reading, res) in zip(ax, osc["readings"].items(), strict=True):
        kk = np.arange(len(next(iter(res.values()))["rmse1"]))
        sl = slice(WINDOW[0] - 50, None)
        for i, name in enumerate(("EFIRF", "LKF", "EKF", "UKF")):
            a.semilogy(kk[sl], res[name]["rmse1"][sl], lw=0.9, color=f"C{i}", label=name)
        a.axvspan(WINDOW[0], WINDOW[1] + 1, color="0.9", label="δ = 0.15")
        a.set_ylabel(f"x₁ RMSE ({osc['runs']} runs)")
        a.set_title(f"Paper 000 Fig. 2, uncertainty='{reading}'")
        a.legend(fontsize=7, loc="upper right")
    ax[-1].set_xlabel("k")
    save(report, out_dir, "fig2_oscillator", fig,
         "Paper 000 Fig. 2: x1 RMSE around the uncertainty window, both readings")
