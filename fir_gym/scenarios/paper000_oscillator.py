"""Paper 000, simulation 2 (Fig. 2, Table 1): temporary model uncertainty, EFIR vs LKF/EKF/UKF.

``fir_gym/UncertainOscillator-v0`` with the paper's settings (eqs 29–31): Q = 0.4,
R = 0.1, Δ = 0.01, x0 = [0, 0, 0.5], δ_k = 0.15 for 350 ≤ k ≤ 400. Every filter
uses the env's model — δ = 0, noise input ``G = [0; Δ; 0]`` with ``Q = 0.4`` — and
starts at the true state with P0 = 2 I; the EFIR has N = 10 (predictor form, open-
loop nominal, as the paper). Both readings of eq (29) run: ``"state"`` (printed:
δ scales the state) and ``"rate"`` (δ scales the rate term).

Table 1 is the sum over k = 350..400 of the Monte Carlo RMSE of x₁ at each k.
Beside it: the floor no unbiased 10-measurement FIR predictor can beat under
R = 0.1 (:func:`unbiased_floor`), the recovery time after the window, and a
diagnostic run in which the filters assume ``G = I`` (Theorem 1's substitution
``G_k → I``), which is not the plant's noise input.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.envs.uncertain_oscillator import UNCERTAINTY_READINGS
from fir_gym.estimators import (
    ExtendedFIRFilter,
    ExtendedKalmanFilter,
    LinearizedKalmanFilter,
    StateSpaceModel,
    UnscentedKalmanFilter,
    fir_gains,
)

from ._montecarlo import (
    VectorTask,
    chunks,
    rmse_per_step,
    run_filter,
    simulate_vector,
    stack_episodes,
    task_seed,
)
from .report import Report
from .runner import SERIAL, Runner

ENV_ID = "fir_gym/UncertainOscillator-v0"
X0 = (0.0, 0.0, 0.5)
P0 = 2.0 * np.eye(3)
HORIZON = 10
WINDOW = (350, 400)                 # δ_k = 0.15 for these k (transitions x[k] → x[k+1])
#: Table 1 of paper 000 (sum over k = 350..400 of the x1 RMSE)
PAPER_TABLE1 = {"EFIRF": 3.3969, "LKF": 44.4709, "EKF": 34.5498, "UKF": 13.3778}
#: the episode runs past the paper's k = 500 to measure the IIR filters' recovery
STEPS = {False: 1500, True: 800}
RUNS = {False: 100, True: 20}
CHUNK = 25
#: recovered once the RMSE stays within this factor of its own pre-window level
RECOVERY_FACTOR = 2.0
PRE_WINDOW = (300, 349)


def oscillator_filters(model: StateSpaceModel, *, variants: bool = True) -> dict[str, Any]:
    """Table 1's filters (keys as in the paper) and, with ``variants``, the EFIR variants."""
    common = {"x0": X0, "P0": P0, "nan_policy": "skip"}
    out = {"EFIRF": ExtendedFIRFilter(model, horizon=HORIZON, form="predictor", **common),
           "LKF": LinearizedKalmanFilter(model, **common),
           "EKF": ExtendedKalmanFilter(model, **common),
           "UKF": UnscentedKalmanFilter(model, **common)}
    if variants:
        out["EFIR filter form"] = ExtendedFIRFilter(model, horizon=HORIZON, form="filter",
                                                    **common)
        out["EFIR re-anchored nominal"] = ExtendedFIRFilter(
            model, horizon=HORIZON, form="predictor", nominal="reanchor", **common)
    return out


def identity_noise_model(model: StateSpaceModel) -> StateSpaceModel:
    """The env's model with ``G = I``, ``Q = 0.4 I``: the diagnostic reading (not the plant's)."""
    return StateSpaceModel(f=model.f, h=model.h, F=model.F, H=model.H,
                           Q=float(model.Q[0, 0]) * np.eye(model.n_x), R=model.R, dt=model.dt,
                           n_u=model.n_u, name="UncertainOscillator (filters assume G = I)")


def unbiased_floor(model: StateSpaceModel, form: str = "predictor", horizon: int = HORIZON,
                   window: tuple[int, int] = WINDOW) -> np.ndarray:
    """σ(x₁) of the minimum-variance unbiased FIR estimate at each k of ``window``.

    The EFIR's own perturbation model with no model error: Jacobians along the
    noise-free nominal from ``X0`` (which has settled at rest by k = 350), the
    window's R and G Q Gᵀ, the corrected Theorem 1 gain (path (a),
    :func:`~fir_gym.estimators.fir_gains.batch_gain`). Any unbiased FIR estimate
    over the same window has at least this error; summed over the window it is the
    floor of Table 1's EFIRF entry.
    """
    u = np.zeros(model.n_u)
    nominal = [np.asarray(X0, float)]
    for _ in range(window[1] + 1):
        nominal.append(model.f(nominal[-1], u))
    Qx, C = model.GQGT, model.H(nominal[0])
    sd = []
    for k in range(window[0], window[1] + 1):
        first = k - horizon if form == "predictor" else k - horizon + 1
        A = np.stack([model.F(nominal[j], u) for j in range(first, first + horizon)])
        res = fir_gains.batch_gain(fir_gains.make_window(A, C, Qx, model.R, horizon), form)
        sd.append(np.sqrt(res.P[0, 0]))
    return np.array(sd)


def recovery_time(rmse: np.ndarray, first_clean: int, pre: tuple[int, int] = PRE_WINDOW,
                  factor: float = RECOVERY_FACTOR) -> tuple[int | None, float]:
    """Steps after ``first_clean`` until the RMSE stays within ``factor`` × its pre-window level.

    The level is the largest RMSE over ``pre`` (an IIR filter's own error wanders slowly,
    so its mean would call that wandering a perturbation). Returns ``(steps, level)``;
    ``steps`` is None when the RMSE has not recovered by the end of the run.
    ``first_clean`` is the first state produced by an unperturbed transition (401).
    """
    level = float(np.max(rmse[pre[0]:pre[1] + 1]))
    bad = np.flatnonzero(~(rmse[first_clean:] <= factor * level))
    if not bad.size:
        return 0, level
    last = int(bad[-1])
    return (None if first_clean + last == len(rmse) - 1 else last + 1), level


def simulate(reading: str, *, seed: int, runs: int, steps: int, runner: Runner,
             delta: float = 0.15) -> Any:
    """``runs`` episodes of the oscillator under ``reading``, in seeded chunks of the vector env."""
    kwargs = {"uncertainty": reading, "delta_schedule": ((WINDOW[0], WINDOW[1], delta),)}
    tasks = [VectorTask(ENV_ID, task_seed(seed, 1, i), n, steps, kwargs)
             for i, n in enumerate(chunks(runs, CHUNK))]
    return stack_episodes(runner.map(simulate_vector, tasks, desc=f"paper 000 sim 2 ({reading})"))


def run_oscillator(report: Report, *, seed: int, quick: bool, runs: int | None,
                   runner: Runner | None) -> dict[str, Any]:
    """Simulation 2 under both readings; fills ``report`` and returns the raw numbers."""
    runner = runner or SERIAL
    steps, runs = STEPS[quick], runs or RUNS[quick]
    env = gym.make(ENV_ID)
    model = env.unwrapped.model
    env.close()
    floor = {form: unbiased_floor(model, form) for form in ("predictor", "filter")}
    out: dict[str, Any] = {"steps": steps, "runs": runs, "floor": floor, "readings": {}}
    first_clean = WINDOW[1] + 1
    for reading in UNCERTAINTY_READINGS:
        ep = simulate(reading, seed=seed, runs=runs, steps=steps, runner=runner)
        res: dict[str, Any] = {}
        for label, m in (("", model), (" [G = I]", identity_noise_model(model))):
            for name, f in oscillator_filters(m, variants=not label).items():
                fr = run_filter(f, ep.Y, ep.U)
                rm = rmse_per_step(fr.x[..., 0] - ep.X[..., 0])
                rec, level = recovery_time(rm, first_clean)
                total = float(np.sum(rm[WINDOW[0]:WINDOW[1] + 1]))
                res[name + label] = {"rmse1": rm, "table1": total, "recovery": rec,
                                     "pre_level": level, "flagged": int(np.sum(fr.diverged)),
                                     "x3_end": float(np.nanmean(fr.x[-1, :, 2])),
                                     "stable": bool(np.isfinite(rm).all() and rm.max() < 1e6)}
        out["readings"][reading] = res
        if reading == "state":
            out["peak_x1"] = float(np.nanmax(ep.X[..., 0]))
    _fill(report, out)
    return out


def _fmt_recovery(r: dict[str, Any], steps: int) -> str:
    if not r["stable"]:
        return "diverges"
    return f"> {steps - WINDOW[1] - 1}" if r["recovery"] is None else str(r["recovery"])


def _finite(v: float) -> bool:
    return bool(np.isfinite(v) and abs(v) < 1e6)


def _ordering(res: dict[str, Any], suffix: str = "") -> str:
    """The IIR filters sorted by their Table 1 sum, largest first ("LKF > EKF > UKF")."""
    names = sorted(("LKF", "EKF", "UKF"), key=lambda n: -res[n + suffix]["table1"])
    return " > ".join(names)


def _fill(report: Report, out: dict[str, Any]) -> None:
    K, M = out["steps"], out["runs"]
    fl_p, fl_f = (float(np.sum(out["floor"][f])) for f in ("predictor", "filter"))
    sd = out["floor"]["predictor"]
    readings = {"state": "uncertainty='state' (printed eq 29)",
                "rate": "uncertainty='rate' (milder reading)"}
    st, rt = out["readings"]["state"], out["readings"]["rate"]
    for name, paper in PAPER_TABLE1.items():
        for reading, text in readings.items():
            res = out["readings"][reading]
            if name == "EFIRF":
                note = (f"no unbiased N = 10 predictor beats the floor Σσ(x₁) = {fl_p:.2f} under "
                        "R = 0.1 (floor row)")
            elif reading == "state":
                note = ("filters use the plant's G = [0; Δ; 0]: tiny gains after 350 steps, they "
                        "cannot follow the ≈ 15 %/step growth; if they assume G = I: "
                        f"{res[name + ' [G = I]']['table1']:.4g}")
            else:
                note = ("δ scales the rate term, ≈ 0 at rest: the uncertainty is nearly invisible; "
                        f"G = I: {res[name + ' [G = I]']['table1']:.4g}")
            report.compare(f"Table 1: {name} (Σ_k=350..400 RMSE x₁)", f"{paper:g}",
                           res[name]["table1"], f"{text}; env's model (G = [0; Δ; 0]), {M} runs",
                           note)
    report.compare("Table 1: EFIRF floor (unbiased FIR predictor, N = 10, R = 0.1, no model "
                   "error)", f"{PAPER_TABLE1['EFIRF']:g}", fl_p,
                   "the EFIR's own linearisation along its nominal, corrected Theorem 1 gain",
                   f"σ(x₁) = {sd.min():.2f}–{sd.max():.2f} per step (filter form: Σ = {fl_f:.2f}); "
                   "the paper's EFIRF entry is below it: not reachable "
                   "(docs/papers.md#000-table-1-floor)")
    rec = ", ".join(f"{n} {_fmt_recovery(st[n], K)}" for n in ("EFIRF", "LKF", "EKF", "UKF"))
    fast = st["EFIRF"]["recovery"] is not None and all(
        st[n]["recovery"] is None or st[n]["recovery"] > st["EFIRF"]["recovery"]
        for n in ("LKF", "EKF", "UKF"))
    report.compare("Fig. 2 claim: after k = 400 the EFIR converges fast, the IIR filters slowly",
                   "claim (figure only)", f"steps after x[401] until the x₁ RMSE stays within "
                   f"{RECOVERY_FACTOR:g}× its largest pre-window value: {rec}", readings["state"],
                   ("reproduced" if fast else "NOT reproduced") + ": a FIR estimate forgets "
                   f"within N (the predictor's window y[k−10..k−1] is clean from k = "
                   f"{WINDOW[1] + 1 + HORIZON}); the EKF/UKF absorb the error into x̂₃, which has "
                   "no process noise")
    rows = []
    for reading in readings:
        for name, r in out["readings"][reading].items():
            paper = PAPER_TABLE1.get(name)
            rows.append([reading, name, None if paper is None else f"{paper:g}",
                         r["table1"] if _finite(r["table1"]) else "unstable",
                         r["pre_level"] if _finite(r["pre_level"]) else None,
                         _fmt_recovery(r, K),
                         r["flagged"]])
    report.add_table(
        f"Sim 2 (Table 1, Fig. 2): Σ_k=350..400 of the x₁ RMSE, {M} runs, k = 0..{K}",
        ["reading", "filter", "paper", "ours", "max RMSE k=300..349",
         f"recovery (steps, ≤ {RECOVERY_FACTOR:g}× pre level)", "runs flagged"], rows)
    iir = [st[n]["table1"] for n in ("LKF", "EKF", "UKF")]
    report.notes += [
        f"Sim 2 floor: along the EFIR's nominal (at rest by k = 350, x₂ ≈ 0) x₃ is almost "
        f"unobservable in a 10-measurement window; the unbiased predictor's σ(x₁) is "
        f"{sd.min():.2f}–{sd.max():.2f} per step, Σ = {fl_p:.2f} over k = 350..400 (filter form "
        f"{fl_f:.2f}): {fl_p / PAPER_TABLE1['EFIRF']:.1f}× the paper's 3.3969 before any model "
        f"error. Under the rate reading (δ has no effect at rest) our EFIRF gives "
        f"{rt['EFIRF']['table1']:.2f}, at this floor up to Monte Carlo error.",
        "Sim 2, IIR filters: with the plant's noise input G = [0; Δ; 0] the process noise moves "
        "x₂ by Δ·√0.4 ≈ 0.006 per step, so after 350 steps the LKF/EKF/UKF gains are tiny. Under "
        f"the printed reading (truth growing ≈ 15 % per step, x₁ up to "
        f"{out['peak_x1']:.3g}) they cannot follow: sums {min(iir):.4g}–{max(iir):.4g}. Under the "
        f"rate reading they sit far below the EFIR ({_ordering(rt)}). Neither gives the paper's "
        "44.47 / 34.55 / 13.38 (LKF > EKF > UKF). In the diagnostic rows '[G = I]' the filters "
        "assume Q = 0.4 I on every state (Theorem 1's substitution G_k → I; not the plant's "
        f"model): printed reading {_ordering(st, ' [G = I]')} with "
        + " / ".join(f"{st[n + ' [G = I]']['table1']:.4g}" for n in ("LKF", "EKF", "UKF"))
        + (" (the EKF [G = I] diverges after the window)" if not st["EKF [G = I]"]["stable"]
           else "")
        + ". The paper's filter G is ambiguous; the summary reports the env's model.",
        "Sim 2, EFIR variants: the re-anchored nominal is "
        + ("unstable" if not _finite(st["EFIR re-anchored nominal"]["table1"]) else "stable")
        + " on this plant: each window's nominal starts at the previous estimate, whose x̂₃ is "
        "nearly unobservable at rest, and the Euler step of the nominal diverges once the "
        "damping x₃ exceeds 2/(10Δ) = 20. The EFIRs are flagged 'diverged' by trace(P) > 1e12 "
        "for the same reason (σ(x̂₃) is huge) while their x₁ estimate is sound.",
        f"Sim 2 recovery: the run continues to k = {K} (the paper plots to 500); recovery time is "
        f"the number of steps after x[401] until the x₁ RMSE stays within {RECOVERY_FACTOR:g}× "
        f"its largest value over k = {PRE_WINDOW[0]}..{PRE_WINDOW[1]} ('> n': not within the run). "
        f"The EKF and UKF do not recover because the uncertainty was absorbed into the damping "
        f"estimate, which has no process noise: mean x̂₃ at k = {K} is "
        f"{st['EKF']['x3_end']:.3g} (EKF), {st['UKF']['x3_end']:.3g} (UKF), "
        f"{st['LKF']['x3_end']:.3g} (LKF) against the true 0.5.",
    ]
