"""Paper 002: the block-pulse Kalman filter on the stochastic Van der Pol oscillator.

The paper (§4) runs its filter once on ``ẋ1 = x2``, ``ẋ2 = −x1 + (1 − x1²) x2``
with noise input ``[1, 1]ᵀ w``, ``z = x1 + v``, ``Q = 5`` (scalar ``w``), ``R = 5``,
``P0 = 5 I``, ``x0 = [1, 1]``, ``m = 100`` block-pulse intervals over ``t_f = 10 s``,
and shows one figure (no numbers). Here the same settings run as a fixed-seed
Monte Carlo on ``fir_gym/VanDerPol-v0`` (zero force; each observation is the
interval average of ``z``, variance ``R/h = 50``), and the block-pulse Kalman
filter (BPF-KF) is compared with a continuous–discrete EKF on the same data.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.envs.van_der_pol import van_der_pol_continuous_model
from fir_gym.estimators.base import Estimator
from fir_gym.estimators.bpf import BlockPulseKalmanFilter
from fir_gym.estimators.cd_ekf import ContinuousDiscreteEKF
from fir_gym.estimators.continuous import ContinuousModel

from .report import Report
from .runner import SERIAL, Runner

ENV_ID = "fir_gym/VanDerPol-v0"
#: the paper's filter settings (§4)
PRIOR_MEAN = np.array([1.0, 1.0])
PRIOR_COV = 5.0 * np.eye(2)
#: the acceptance criterion of the project's issue 6
RMSE_RATIO_LIMIT = 1.1


@dataclass
class MonteCarlo:
    """Episodes of VanDerPol-v0: states ``(M, K+1, 2)``, measurements ``(M, K+1, 1)``.

    A run that terminated early (``|x| > state_bound``) has NaN after its last
    step; ``steps[i]`` is the number of valid steps of run ``i``.
    """

    states: np.ndarray
    measurements: np.ndarray
    steps: np.ndarray
    params: dict[str, Any]


def episode(seed: int) -> tuple[np.ndarray, np.ndarray, int]:
    """One zero-force episode of VanDerPol-v0 from ``seed``: states, measurements, valid steps.

    A runner task: module-level and seeded, so every backend gives the same numbers.
    """
    env = gym.make(ENV_ID)
    limit = env.spec.max_episode_steps
    X = np.full((limit + 1, 2), np.nan)
    Y = np.full((limit + 1, 1), np.nan)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    y, info = env.reset(seed=seed)
    X[0], Y[0] = info["state"], y
    k, done = 0, False
    while not done:
        y, _, terminated, truncated, info = env.step(action)
        k += 1
        X[k], Y[k] = info["state"], y
        done = terminated or truncated
    env.close()
    return X, Y, k + 1


def simulate(n_runs: int, seed: int = 0, runner: Runner | None = None) -> MonteCarlo:
    """``n_runs`` zero-force episodes of VanDerPol-v0 with seeds ``seed, seed+1, …``."""
    runner = runner or SERIAL
    out = runner.map(episode, [seed + i for i in range(n_runs)], desc="paper 002 episodes")
    env = gym.make(ENV_ID)
    params = dict(env.unwrapped.nominal_params)
    env.close()
    return MonteCarlo(np.stack([o[0] for o in out]), np.stack([o[1] for o in out]),
                      np.array([o[2] for o in out]), params)


def run_filter(estimator: Estimator, mc: MonteCarlo) -> tuple[np.ndarray, np.ndarray, list]:
    """Run a batched estimator over all runs; returns estimates, covariances and ``last_info``s.

    After a run's end its (NaN) measurements are skipped, so it only predicts.
    """
    est, cov, infos = [], [], []
    for k in range(mc.measurements.shape[1]):
        est.append(estimator.step(mc.measurements[:, k]))
        cov.append(estimator.P)
        infos.append(dict(estimator.last_info))
    return np.stack(est, axis=1), np.stack(cov, axis=1), infos


def _scores(mc: MonteCarlo, est: np.ndarray, cov: np.ndarray) -> dict[str, Any]:
    valid = np.arange(mc.states.shape[1])[None, :] < mc.steps[:, None]
    e = np.where(valid[..., None], mc.states - est, 0.0)
    sq = (e * e)[valid]
    nees = np.einsum("...i,...i->...", e, np.linalg.solve(cov, e[..., None])[..., 0])[valid]
    per_run = np.sqrt((e * e).sum(-1).sum(-1) / mc.steps)
    return {"x1": float(np.sqrt(sq[:, 0].mean())), "x2": float(np.sqrt(sq[:, 1].mean())),
            "total": float(np.sqrt(sq.sum(-1).mean())), "anees": float(nees.mean()),
            "per_run": per_run}


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """The Monte Carlo comparison (200 runs; 50 with ``quick``) as a :class:`Report`.

    ``figures`` holds ``ratio`` (RMSE of the BPF-KF over the CD-EKF's), the
    ``scores`` of every filter and the global recursion's ``breakdown`` times.
    """
    n_runs = runs or (50 if quick else 200)
    mc = simulate(n_runs, seed, runner)
    cm = van_der_pol_continuous_model(mc.params)
    sdc = ContinuousModel(a=cm.a, J=lambda x, u: cm.A_of_x(x), A_of_x=cm.A_of_x, h=cm.h,
                          H=cm.H, G=cm.G, Q=cm.Q, R=cm.R, dt=cm.dt, n_u=1)
    prior = {"x0": PRIOR_MEAN, "P0": PRIOR_COV, "nan_policy": "skip"}
    filters = {
        "BPF-KF (restarted Riccati)": BlockPulseKalmanFilter(cm, **prior),
        "BPF-KF (global Riccati, paper-literal)": BlockPulseKalmanFilter(cm, riccati="global",
                                                                        **prior),
        "CD-EKF (interval-average measurement)": ContinuousDiscreteEKF(cm, **prior),
        "CD-EKF (end-point measurement)": ContinuousDiscreteEKF(cm, measurement="end", **prior),
        "CD-EKF with A(x) for the covariance (diagnostic)": ContinuousDiscreteEKF(sdc, **prior),
    }
    scores, breakdown, run0 = {}, None, {}
    for name, f in filters.items():
        est, cov, infos = run_filter(f, mc)
        scores[name] = _scores(mc, est, cov)
        run0[name] = est[0]
        if "global" in name:
            flags = np.array([info.get("riccati_breakdown", np.zeros(n_runs, bool))
                              for info in infos])
            first = np.where(flags.any(0), flags.argmax(0), -1)
            breakdown = (first[first >= 0] * mc.params["h"], int((first < 0).sum()))
    ref = scores["CD-EKF (interval-average measurement)"]
    bpf = scores["BPF-KF (restarted Riccati)"]
    diff = bpf["per_run"] - ref["per_run"]
    rows = [[name, s["x1"], s["x2"], s["total"], s["total"] / ref["total"], s["anees"]]
            for name, s in scores.items()]
    n_term = int((mc.steps < mc.states.shape[1]).sum())
    ratio = bpf["total"] / ref["total"]
    sdc_total = scores["CD-EKF with A(x) for the covariance (diagnostic)"]["total"]
    avg_end = ref["per_run"] - scores["CD-EKF (end-point measurement)"]["per_run"]
    notes = [
        f"{n_runs} runs of {ENV_ID}, seeds {seed}..{seed + n_runs - 1}, zero force, t_f = 10 s, "
        f"m = 100 (h = {mc.params['h']} s); Q = 5, R = 5 (observation variance R/h = "
        f"{mc.params['R'] / mc.params['h']:g}), x0 = [1, 1], P0 = 5 I for every filter. "
        f"{n_term} run(s) left the domain |x| <= 20 early and are scored up to their end.",
        "Paper 002 reports only a figure (one run); there is no number to compare with.",
        f"Criterion RMSE(BPF-KF) <= {RMSE_RATIO_LIMIT} x RMSE(CD-EKF): ratio {ratio:.3f} "
        f"({'met' if ratio <= RMSE_RATIO_LIMIT else 'NOT met'}); paired per-run RMSE "
        f"difference {diff.mean():+.3f} +- {diff.std(ddof=1) / np.sqrt(n_runs):.3f} (1 s.e.).",
        f"Diagnostic: the CD-EKF with the factorisation A(x) in place of the Jacobian J(x) "
        f"for its covariance scores {sdc_total:.3f} against the BPF-KF's {bpf['total']:.3f} "
        f"and the CD-EKF's {ref['total']:.3f}: the difference between the two filters comes "
        "from the state-dependent factorisation (J21 has the extra −2 x1 x2, large where the "
        "estimate is poor), not from the block-pulse integration.",
        "Measurement model of the CD-EKF: the interval-average form (exact for a linear "
        "model, see the tests) against the end-point form h(x(t_k)) with variance R/h: paired "
        f"per-run RMSE difference {avg_end.mean():+.3f} +- "
        f"{avg_end.std(ddof=1) / np.sqrt(n_runs):.3f} (1 s.e.); the lag of the average "
        "(h x2 / 2 <= 0.3) is small against the noise std 7, and linearisation error dominates.",
        "ANEES (ideal 2, the state dimension): "
        + ", ".join(f"{name.split(' (')[0]} {s['anees']:.2f}" for name, s in
                    list(scores.items())[::2])
        + ("; the filters are overconfident in this strongly nonlinear, low-signal regime."
           if min(s["anees"] for s in scores.values()) > 2.5 else "."),
    ]
    if breakdown is not None:
        t, _ = breakdown
        notes.append(
            "Global (paper-literal) Riccati: conditioning breakdown (cond > "
            f"{filters['BPF-KF (global Riccati, paper-literal)'].max_condition:.0e}) detected in "
            f"{len(t)} of {n_runs} runs, median at t = {np.median(t) if len(t) else np.nan:.1f} s "
            f"(range {t.min() if len(t) else np.nan:.1f}-{t.max() if len(t) else np.nan:.1f} s); "
            "those runs continue on the restarted recursion from their last well-conditioned "
            "P and are flagged diverged, so its RMSE equals the restarted one.")
    report = Report(paper="002", title="Kalman filter for a nonlinear stochastic system via "
                    "block-pulse functions", notes=notes,
                    figures={"ratio": ratio, "scores": scores, "breakdown": breakdown,
                             "runs": n_runs, "run0": {"t": np.arange(mc.states.shape[1]) *
                                                      mc.params["h"], "x": mc.states[0],
                                                      "y": mc.measurements[0, :, 0],
                                                      "estimates": run0}})
    _compare(report, scores, ratio, n_runs)
    report.add_table("BPF-KF vs continuous-discrete EKF on VanDerPol-v0 (RMSE over runs and "
                     "steps; the paper has only a figure)",
                     ["filter", "RMSE x1", "RMSE x2", "RMSE ‖x‖", "÷ CD-EKF", "ANEES"], rows)
    return report


def _compare(report: Report, scores: dict[str, Any], ratio: float, n_runs: int) -> None:
    """Summary rows: the figure's claim and the BPF-KF against the CD-EKF (no paper numbers)."""
    bpf, ekf = scores["BPF-KF (restarted Riccati)"], scores["CD-EKF (interval-average measurement)"]
    reading = (f"VanDerPol-v0, Q = 5 (scalar w), R = 5 (interval average: R/h), P0 = 5I, "
               f"m = 100, t_f = 10 s; {n_runs} runs")
    report.compare("Fig. 1: the block-pulse KF tracks the Van der Pol state", "figure only",
                   f"RMSE x₁ {bpf['x1']:.3g}, x₂ {bpf['x2']:.3g} (measurement noise std "
                   f"{np.sqrt(50):.2g}); ANEES {bpf['anees']:.2f} (ideal 2)", reading,
                   "reproduced qualitatively (one run is plotted as the paper's figure with --out)"
                   + ("; the filter is overconfident (ANEES > 2) in this nonlinear, low-signal "
                      "regime" if bpf["anees"] > 2.5 else ""))
    report.compare("BPF-KF vs CD-EKF: RMSE ‖x‖", None,
                   f"{bpf['total']:.3g} vs {ekf['total']:.3g} (ratio {ratio:.3f})", reading,
                   f"the paper compares with nothing; criterion ratio ≤ {RMSE_RATIO_LIMIT} "
                   f"{'met' if ratio <= RMSE_RATIO_LIMIT else 'NOT met'}")
    sdc = scores["CD-EKF with A(x) for the covariance (diagnostic)"]
    for comp in ("x1", "x2"):
        report.compare(f"BPF-KF vs CD-EKF: RMSE {comp}", None,
                       f"{bpf[comp]:.3g} vs {ekf[comp]:.3g}", reading,
                       f"the CD-EKF with A(x) for its covariance scores {sdc[comp]:.3g}: the "
                       "difference comes from the factorisation A(x), not the block-pulse "
                       "integration")


def plot(report: Report, out_dir: str | Path) -> None:
    """Fig. 1 of paper 002: truth, measurements and estimates of one run."""
    from ._plotting import new_figure, save

    r0 = report.figures["run0"]
    t = r0["t"]
    fig, ax = new_figure(2, 1, height=3.0, sharex=True)
    ax[0].plot(t, r0["y"], ".", color="0.7", ms=3, label="measurement (interval average)")
    styles = {"BPF-KF (restarted Riccati)": ("C0", "-"),
              "CD-EKF (interval-average measurement)": ("C3", "--")}
    for i, a in enumerate(ax):
        a.plot(t, r0["x"][:, i], "k", lw=1.5, label="true state")
        for name, (colour, ls) in styles.items():
            a.plot(t, r0["estimates"][name][:, i], ls, color=colour, lw=1.0, label=name)
        a.set_ylabel(f"x{i + 1}")
    ax[0].set_ylim(np.nanmin(r0["x"][:, 0]) - 4, np.nanmax(r0["x"][:, 0]) + 4)
    ax[0].legend(fontsize=7)
    ax[1].set_xlabel("t (s)")
    ax[0].set_title("Paper 002 Fig. 1: Van der Pol, estimated and real states (run 0)")
    save(report, out_dir, "fig1_vdp", fig, "Paper 002 Fig. 1: truth and estimates (one run)")
