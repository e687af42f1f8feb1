"""Paper 000: the extended FIR filter (EFIRF) for discrete nonlinear systems, both simulations.

* Simulation 1 (Fig. 1) — rectilinear orbit determination, EKF vs EFIR under a wrong
  gravitational parameter: :mod:`.paper000_orbit`.
* Simulation 2 (Fig. 2, Table 1) — the oscillator with a temporary uncertainty,
  EFIR vs LKF/EKF/UKF under every reading: :mod:`.paper000_oscillator` (the
  experiment) and :mod:`.paper000_oscillator_report` (its summary and claims).

``plot`` draws Fig. 1 (x₁ error, RMSE and NEES over the long horizon) and Fig. 2
(x₁ RMSE of every filter around the uncertainty window, under the two readings of eq 29).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import paper000_orbit as orbit
from . import paper000_oscillator as osc
from . import paper000_oscillator_report as osc_report
from .plan import Stage, gather, run_plan
from .report import Report
from .runner import Runner


def plan(seed: int = 0, quick: bool = False, runs: int | None = None) -> Any:
    """Both simulations side by side; ``runs`` sets both Monte Carlo sizes (default 30 and
    100; quick 5 and 20)."""
    keys, tasks = osc.tasks(seed, quick, runs)
    sim2 = Stage(tasks, lambda results: osc.collect(keys, results, quick=quick, runs=runs),
                 desc="paper 000")

    def assemble(values: list[Any]) -> Report:
        report = Report("000", "Extended FIR filter for discrete nonlinear systems (EFIRF)")
        report.figures["orbit"], report.figures["oscillator"] = values
        orbit.fill(report, values[0])
        osc_report.fill(report, values[1])
        return report

    return gather([orbit.plan(seed, quick, runs), sim2], assemble, desc="paper 000")


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Both simulations (:func:`plan` on ``runner``)."""
    return run_plan(plan(seed, quick, runs), runner)


def plot(report: Report, out_dir: str | Path) -> None:
    """Fig. 1 and Fig. 2 of paper 000 as PNGs under ``out_dir``."""
    from ..plotting import plot_errors, plot_nees
    from ._plotting import coincidence_note, coincident, legend_outside, new_figure, save

    o = report.figures["orbit"]
    K = o["steps"]
    k = np.arange(K + 1)
    N = orbit.HORIZON
    fig, ax = new_figure(3, 1, width=10.0, height=2.6, sharex=True)
    colours = {"EKF": "C3", orbit.PAPER_FILTER: "C0", "EFIR filter form": "C2",
               "EFIR re-anchored nominal": "C1"}
    truth = o["truth1_run0"]
    for name in (orbit.PAPER_FILTER, "EKF"):                          # the EKF on top
        plot_errors(k, truth + o["filters"][name]["e1_run0"], truth, names=["x₁"], label=name,
                    color=colours[name], axes=[ax[0]])
    sv = o["sigma_v"]
    ax[0].axhline(sv, color="k", ls=":", lw=0.8, label="±σ_v (measurement noise)")
    ax[0].axhline(-sv, color="k", ls=":", lw=0.8)
    ax[0].set_ylabel("x₁ error, run 0\n(length units)")
    ax[0].set_xlabel("")                                 # the shared k axis is labelled below
    # the EKF's NEES with its χ² band (fir_gym.plotting), the EFIR filters' beside it
    plot_nees(k[N:], o["filters"]["EKF"]["nees"][N:], dof=2, runs=o["runs"],
              confidence=orbit.NEES_CONFIDENCE, label="EKF", color=colours["EKF"], ax=ax[2])
    drawn = ("EFIR re-anchored nominal", "EFIR filter form", orbit.PAPER_FILTER, "EKF")
    # a curve hidden under another is named as such in the legend (computed, not assumed)
    same = {key: coincident({name: o["filters"][name][key][N:] for name in drawn})
            for key in ("rmse1", "nees")}
    for name in drawn:
        r, ls = o["filters"][name], ":" if "re-anchored" in name else "-"
        ax[1].semilogy(k[N:], r["rmse1"][N:], ls, lw=0.7, color=colours[name],
                       label=coincidence_note(name, same["rmse1"]))
        if name != "EKF":
            ax[2].semilogy(k[N:], r["nees"][N:], ls, lw=0.7, color=colours[name],
                           label=coincidence_note(name, same["nees"]))
    ax[1].semilogy(k[N:], o["filters"]["EKF"]["sd1"][N:], "--", lw=0.8, color="C3",
                   label="EKF's own σ(x₁)")
    ax[1].set_ylabel(f"x₁ RMSE, {o['runs']} runs\n(length units)")
    ax[2].set_ylabel("NEES, run average\n(dimensionless)")
    ax[2].set_xlabel(f"k (measurement intervals of {o['dt']:g} time units)")
    for a in ax:
        legend_outside(a)
    ax[0].set_title("Paper 000 Fig. 1: orbit determination, μ_model = 19.91 (true 19.9224)")
    save(report, out_dir, "fig1_orbit", fig, "Paper 000 Fig. 1: EKF vs EFIR on the orbit")

    s2 = report.figures["oscillator"]
    fig, ax = new_figure(2, 1, width=10.0, height=3.0)
    for a, u in zip(ax, osc.UNCERTAINTY, strict=True):
        res = s2["readings"][(u, "Gp", "Rvar")]
        kk = np.arange(len(res["EFIRF"]["rmse1"]))
        sl = slice(osc.WINDOW[0] - 50, None)
        for i, name in enumerate(("EFIRF", *osc.IIR)):
            a.semilogy(kk[sl], res[name]["rmse1"][sl], lw=0.9, color=f"C{i}", label=name)
        a.axvspan(osc.WINDOW[0], osc.WINDOW[1] + 1, color="0.9", label=f"δ = {osc.DELTA:g}")
        a.set_ylabel(f"x₁ RMSE, {s2['runs']} runs\n(units of x₁)")
        a.set_title(f"Paper 000 Fig. 2, reading {u}·Gp·Rvar", fontsize=9)
        a.set_xlabel("k (sampling steps Δ)")
        legend_outside(a)
    save(report, out_dir, "fig2_oscillator", fig,
         "Paper 000 Fig. 2: x1 RMSE around the uncertainty window, both readings of eq 29")
