"""Paper 004: recursive FIR filters for time-invariant models — its theorems, checked numerically.

The paper has no numerical example. Its claims are verified on a documented
example, the aircraft-carrier model of paper 001 §V as ``fir_gym/CarrierMotion-v0``
samples it (T = 0.1 s, exact discretisation, R = V/T = 10; no input):

* the impulse responses by paper 004's Riccati-type recursions (Theorem 2.1,
  Cor 2.1, Cor 2.2 corrected, Theorem 3.1) equal the batch solution of the
  orthogonality conditions (2.4)/(3.2) (paper 000 Theorem 1, corrected) and the
  two-stage recursion — the three gain paths of :mod:`fir_gym.estimators.fir_gains`;
* time invariance: Theorem 2.1's gain depends on the window-start covariance, so it
  is constant only for a stationary process (Cor 2.1) or without a prior (Cor 2.2);
* the recursive filter/smoother (Theorem 4.1, Cor 4.1, corrected) equals the direct
  form on the first steps, then amplifies round-off by ρ^k (ρ: spectral radius of
  its 2n×2n transition, which has reciprocal eigenvalue pairs), unless it is
  re-initialised from the direct form. A second example with faster filter dynamics
  (the carrier sampled at T = 1 s with a 100× better sensor, v = 0.01) shows the
  growth the paper's recursion has in general.

The comparison the paper leaves as future work (FIR vs Kalman under paper 001's
model uncertainty) is :mod:`.paper004_carrier`. The examples and the checks' settings are
:mod:`.paper004_setup` (re-exported here).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fir_gym.estimators import (
    FIRFilter,
    LinearModel,
    RecursiveFIRFilter,
    TimeVaryingLinearModel,
    fir_gains,
)

from . import paper004_cost
from ._montecarlo import EpisodeTask, run_filter, simulate_episode, stack_episodes, task_seed
from .paper004_carrier import CORNERS, comparison_plan, corner_label, summary
from .paper004_setup import (
    ENV_ID,
    EXAMPLES,
    GAIN_HORIZONS,
    GROWN,
    PRIOR_SCALES,
    RECURSIVE_HORIZON,
    WINDOW_STARTS,
    example_model,
)
from .plan import Stage, Task, gather, run_plan
from .report import Report
from .runner import Runner

# the setup (.paper004_setup) is re-exported: paper004.EXAMPLES, paper004.example_model, ...
__all__ = ["ENV_ID", "EXAMPLES", "GAIN_HORIZONS", "GROWN", "PRIOR_SCALES", "RECURSIVE_HORIZON",
           "WINDOW_STARTS", "algebra_task", "example_model", "example_task", "gain_paths",
           "plan", "plot", "recursion_check", "run", "time_invariance"]

def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def gain_paths(model: LinearModel, horizons: tuple[int, ...] = GAIN_HORIZONS[False]
               ) -> list[list[Any]]:
    """Rows ``L | prior | form | (b) vs (a) | (c) vs (a)``: max relative differences of S and P."""
    A, C, R = model.A, model.C, model.R
    Qx = model.G @ model.Q @ model.G.T
    rows = []
    for L in horizons:
        win = fir_gains.make_window(A, C, Qx, R, L)
        for prior_name, prior in (("none (Cor 2.2)", None),
                                  ("stationary (Cor 2.1)", fir_gains.stationary_prior(A, Qx))):
            for form in ("filter", "predictor", "smoother"):
                ref = fir_gains.batch_gain(win, form, prior)
                diffs: list[Any] = []
                for path in (fir_gains.riccati_gain, fir_gains.two_stage_gain):
                    try:
                        g = path(win, form, prior)
                        diffs += [_rel(g.S, ref.S), _rel(g.P, ref.P)]
                    except ValueError:            # Cor 3.2: no no-prior Riccati smoother
                        diffs += ["n/a (Cor 3.2)", None]
                rows.append([L, prior_name, form, *diffs])
    return rows


def time_invariance(model: LinearModel) -> dict[str, Any]:
    """Theorem 2.1's gain against the window-start covariance (Cor 2.1, Cor 2.2)."""
    A, C, R = model.A, model.C, model.R
    Qx = model.G @ model.Q @ model.G.T
    L = RECURSIVE_HORIZON
    win = fir_gains.make_window(A, C, Qx, R, L)
    stationary = fir_gains.riccati_gain(win, "filter", fir_gains.stationary_prior(A, Qx)).S
    P, j, drift = np.zeros_like(Qx), 0, {}
    for start in WINDOW_STARTS:                     # a process started at a known state
        while j < start:
            P, j = A @ P @ A.T + Qx, j + 1
        drift[start] = _rel(fir_gains.riccati_gain(win, "filter", P).S, stationary)
    no_prior = fir_gains.riccati_gain(win, "filter").S
    limit = {c: _rel(fir_gains.riccati_gain(win, "filter", c * np.eye(2)).S, no_prior)
             for c in PRIOR_SCALES}
    return {"drift": drift, "limit": limit}


def recursion_check(model: LinearModel, Y: np.ndarray) -> dict[str, Any]:
    """Recursive (Cor 4.1, Thm 4.1) vs direct FIR filter on data ``Y (K+1, 1, 1)``."""
    L = RECURSIVE_HORIZON
    out: dict[str, Any] = {}
    for prior in (None, "stationary"):
        direct = run_filter(FIRFilter(model, horizon=L, prior=prior), Y).x[:, 0]
        scale = float(np.max(np.abs(direct[L:])))
        dev = {}
        for reinit in (None, "auto"):
            r = RecursiveFIRFilter(model, horizon=L, prior=prior, reinit_every=reinit)
            rec = run_filter(r, Y).x[:, 0]
            dev[reinit] = np.max(np.abs(rec - direct), axis=1) / scale
        grown = np.flatnonzero(dev[None] > GROWN)
        out["Cor 4.1 (no prior)" if prior is None else "Thm 4.1 (stationary prior)"] = {
            "rho": r.spectral_radius, "reinit_every": r.reinit_every, "dev": dev[None],
            "dev_reinit": dev["auto"], "first": float(np.max(dev[None][L - 1:3 * L])),
            "grown_at": None if not grown.size else int(grown[0]),
            "max_reinit": float(np.max(dev["auto"]))}
    return out


def example_task(task: tuple[int, int, bool]) -> dict[str, Any]:
    """Example ``i`` of :data:`EXAMPLES`: one seeded episode, the recursive-vs-direct check and,
    for the first, the re-derived time-varying gain against the fixed one (a runner task)."""
    i, seed, quick = task
    kw, steps = list(EXAMPLES.values())[i]
    ep = stack_episodes([simulate_episode(EpisodeTask(ENV_ID, task_seed(seed, 40, i),
                                                      steps if not quick else steps // 3, kw))])
    model = example_model(**kw)
    out: dict[str, Any] = {"recursion": recursion_check(model, ep.Y)}
    if i == 0:
        tv = TimeVaryingLinearModel(A=model.A, C=model.C, Q=model.Q, R=model.R, G=model.G,
                                    dt=model.dt)
        Y0 = ep.Y[:1000]
        fixed = run_filter(FIRFilter(model, horizon=RECURSIVE_HORIZON), Y0).x
        rederived = run_filter(FIRFilter(tv, horizon=RECURSIVE_HORIZON), Y0).x
        out["tv_dev"] = _rel(rederived[RECURSIVE_HORIZON:], fixed[RECURSIVE_HORIZON:])
    return out


def algebra_task(task: tuple[str, tuple[int, ...]]) -> Any:
    """The deterministic checks on the example model: ``"gains"``, ``"time"`` or ``"cost"``."""
    kind, horizons = task
    model = example_model()
    if kind == "gains":
        return gain_paths(model, horizons)
    if kind == "time":
        return time_invariance(model)
    return paper004_cost.count(model)


def plan(seed: int = 0, quick: bool = False, runs: int | None = None) -> Any:
    """The theorem checks (one task each), the examples, and the FIR-vs-Kalman comparison."""
    horizons = GAIN_HORIZONS[quick]
    local = Stage([Task(algebra_task, ("gains", horizons), cost=0.2),
                   Task(algebra_task, ("time", horizons), cost=0.1),
                   Task(algebra_task, ("cost", horizons), cost=1.5)]
                  + [Task(example_task, (i, seed, quick), cost=1.0 if quick else 2.5)
                     for i in range(len(EXAMPLES))], lambda out: out, desc="paper 004")

    def assemble(values: list[Any]) -> Report:
        (rows, ti, cost, *examples), comp = values
        rec = {name: ex["recursion"] for name, ex in zip(EXAMPLES, examples, strict=True)}
        report = Report("004", "Recursive FIR filters for discrete time-invariant state-space "
                        "models (no numerical example: theorems checked, future work done)")
        worst_path = max(v for row in rows for v in row[3:] if isinstance(v, float))
        report.figures.update({"gain_paths": rows, "gain_paths_max": worst_path,
                               "time_invariance": ti, "recursion": rec,
                               "tv_vs_fixed": examples[0]["tv_dev"], "comparison": comp,
                               "cost": cost})
        from .paper004_report import fill

        fill(report, horizons)
        return report

    return gather([local, comparison_plan(seed, quick, runs)], assemble, desc="paper 004")


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """The theorem checks and the FIR-vs-Kalman comparison (``runs`` sizes the latter)."""
    return run_plan(plan(seed, quick, runs), runner)


def plot(report: Report, out_dir: str | Path) -> None:
    """RMSE vs window length (the future-work comparison) and the recursion's round-off growth."""
    from ._plotting import legend_outside, new_figure, save

    comp = report.figures["comparison"]
    s = summary(comp)
    fig, ax = new_figure(1, 1, width=10.0, height=4.0)
    a = ax[0]
    dt = comp["dt"]
    for i, family in enumerate(("FIR, no prior (Cor 2.2)", "FIR, stationary prior (Cor 2.1)")):
        T = [(L - 1) * dt for L in comp["windows"]]
        for corner, ls in ((CORNERS[0], "-"), (s["worst"][s["best"][family]], "--")):
            a.loglog(T, [comp["rmse"][corner][(family, L)][0] for L in comp["windows"]],
                       ls, marker="o", color=f"C{i}", label=f"{family}, {corner_label(corner)}")
    for corner, ls in ((CORNERS[0], "-"), (s["worst"][("KF", None)], "--")):
        a.axhline(comp["rmse"][corner][("KF", None)][0], ls=ls, color="C3",
                  label=f"KF, {corner_label(corner)}")
    a.set_xlabel("window length (s)")
    a.set_ylabel("x₁ (deck displacement) RMSE\n(units of x₁)")
    a.set_title("Paper 004 future work: FIR vs KF on CarrierMotion-v0 under model uncertainty",
                fontsize=9)
    legend_outside(a)
    save(report, out_dir, "fir_vs_kf", fig, "Paper 004: FIR vs KF, RMSE vs window length")

    rec = report.figures["recursion"]
    fig, ax = new_figure(1, len(rec), width=10.0, height=3.6)
    for a, (name, r) in zip(ax, rec.items(), strict=True):
        for i, (form, v) in enumerate(r.items()):
            k = np.arange(len(v["dev"]))
            a.semilogy(k, np.maximum(v["dev"], 1e-18), color=f"C{i}",
                       label=f"{form}, no re-init (ρ = {v['rho']:.3f})")
            a.semilogy(k, np.maximum(v["dev_reinit"], 1e-18), ":", color=f"C{i}",
                       label=f"{form}, re-init every {v['reinit_every']}")
        a.set_title(name, fontsize=9)
        a.set_xlabel("k (steps)")
        a.set_ylabel("|recursive − direct| / max|direct|\n(relative, dimensionless)")
        legend_outside(a, below=True, fontsize=6)
    save(report, out_dir, "recursion_roundoff", fig,
         "Paper 004: round-off growth of the recursive FIR filter")
