"""Paper 000, simulation 2 (Fig. 2, Table 1): temporary model uncertainty, EFIR vs LKF/EKF/UKF.

``fir_gym/UncertainOscillator-v0`` with the paper's settings (eqs 29–31): Q = 0.4,
R = 0.1, Δ = 0.01, x0 = [0, 0, 0.5], δ_k = 0.15 for 350 ≤ k ≤ 400. Every filter
starts at the true state with P0 = 2 I; the EFIR has N = 10 (predictor form, open-
loop nominal, as the paper). Three ambiguities, every combination run
(:data:`READINGS`; docs/papers.md#000-eq-29-readings, #000-sim-2-noise-input and
docs/papers.md#000-sim-2-r-reading):

* eq (29): δ scales the state (``"state"``, as printed) or the rate term (``"rate"``);
* the filters' noise input: the plant's ``G = [0; Δ; 0]`` or ``G = I`` (Theorem 1's
  substitution ``G_k → I``, with ``Q = 0.4 I``);
* ``R = 0.1``: a variance (as eq 31 writes it) or a standard deviation (variance
  0.01, plant and filters).

Table 1 is the sum over k = 350..400 of the Monte Carlo RMSE of x₁ at each k.
Beside it: the floor no unbiased 10-measurement FIR estimate can beat
(:func:`unbiased_floor`, docs/papers.md#000-table-1-floor), and the claims of §5 around
Fig. 2 (:mod:`.paper000_oscillator_report`, docs/papers.md#000-sim-2-claims).
Each task simulates one reading's data (seeded chunks of the vector env) and runs a
group of filters on it; the client only assembles.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

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
from .plan import Task
from .prose import Printed, say

ENV_ID = "fir_gym/UncertainOscillator-v0"
X0 = (0.0, 0.0, 0.5)
P0 = 2.0 * np.eye(3)           # the filters' prior, P0 = 2 I
HORIZON = 10
WINDOW = (350, 400)                 # δ_k = 0.15 for these k (transitions x[k] → x[k+1])
DELTA = 0.15
#: Table 1 of paper 000 as printed (sum over k = 350..400 of the x1 RMSE)
PAPER_TABLE1 = {k: Printed(v) for k, v in
                {"EFIRF": "3.3969", "LKF": "44.4709", "EKF": "34.5498", "UKF": "13.3778"}.items()}
IIR = ("LKF", "EKF", "UKF")
#: the episode runs past the paper's k = 500 to measure the IIR filters' recovery
STEPS = {False: 1500, True: 800}
RUNS = {False: 100, True: 20}
CHUNK = 25
#: recovered once the RMSE stays within this factor of a pre-window level
RECOVERY_FACTOR = 2.0
PRE_WINDOW = (300, 349)
#: the readings: eq (29), the filters' noise input, what R = 0.1 is
UNCERTAINTY = {"eq29": "state", "rate": "rate"}
NOISE_INPUT = ("Gp", "GI")
R_READINGS = {"Rvar": 0.1, "Rstd": 0.1 ** 2}
FORMS = {"pred": "predictor", "filt": "filter"}
READINGS = [(u, g, r) for u in UNCERTAINTY for g in NOISE_INPUT for r in R_READINGS]
DEFAULT = ("eq29", "Gp", "Rvar")
#: the plant's process noise (eq 30)
Q_PAPER = 0.4
LEGEND = {
    "eq29": "δ scales the state, `x⁺ = diag(1+δ, 1+δ, 1) x + r(x)Δ` (eq 29 as printed)",
    "rate": "δ scales the rate term, `x⁺ = x + diag(1+δ, 1+δ, 1) r(x)Δ`",
    "Gp": "the filters use the plant's noise input `G = [0; Δ; 0]`",
    "GI": say("the filters assume G = I, Q = {q:g} I (Theorem 1's G_k → I)", q=Q_PAPER),
    "Rvar": say("R = {r:g} is the variance of v (eq 31)", r=R_READINGS["Rvar"]),
    "Rstd": say("R = {r:g} is its standard deviation (variance {v:g}, plant and filters)",
                r=R_READINGS["Rvar"], v=R_READINGS["Rstd"]),
    "pred": "the EFIR's window ends one step before the estimate (the paper's eq 13)",
    "filt": "its window ends at the estimate (the companion filter form)",
}


def code(reading: tuple[str, ...]) -> str:
    """``("eq29", "Gp", "Rvar")`` → ``"eq29·Gp·Rvar"``."""
    return "·".join(reading)


def plant_model(R: float) -> StateSpaceModel:
    """The env's model (δ = 0, G = [0; Δ; 0], Q = 0.4) with measurement variance ``R``."""
    env = gym.make(ENV_ID, R=R)
    model = env.unwrapped.model     # type: ignore[attr-defined]
    env.close()
    return model


def identity_noise_model(model: StateSpaceModel) -> StateSpaceModel:
    """The model with ``G = I``, ``Q = 0.4 I``: the filters' reading of Theorem 1's ``G_k → I``."""
    return StateSpaceModel(f=model.f, h=model.h, F=model.F, H=model.H,
                           Q=float(model.Q[0, 0]) * np.eye(model.n_x), R=model.R, dt=model.dt,
                           n_u=model.n_u, name="UncertainOscillator (filters assume G = I)")


def oscillator_filters(model: StateSpaceModel, *, variants: bool = True) -> dict[str, Any]:
    """Table 1's filters (keys as in the paper), the EFIR's filter form and, with
    ``variants``, its re-anchored nominal."""
    common: dict[str, Any] = {"x0": X0, "P0": P0, "nan_policy": "skip"}
    out: dict[str, Any] = {
        "EFIRF": ExtendedFIRFilter(model, horizon=HORIZON, form="predictor", **common),
        "EFIRF filter form": ExtendedFIRFilter(model, horizon=HORIZON, form="filter", **common),
        "LKF": LinearizedKalmanFilter(model, **common),
        "EKF": ExtendedKalmanFilter(model, **common),
        "UKF": UnscentedKalmanFilter(model, **common)}
    if variants:
        out["EFIR re-anchored nominal"] = ExtendedFIRFilter(
            model, horizon=HORIZON, form="predictor", nominal="reanchor", **common)
    return out


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
                  factor: float = RECOVERY_FACTOR, level: float | None = None
                  ) -> tuple[int | None, float]:
    """Steps after ``first_clean`` until the RMSE stays within ``factor`` × a level.

    The level is ``level`` when given (a common, absolute one), else the largest RMSE
    over ``pre`` (the filter's own: an IIR filter's error wanders slowly, so its mean
    would call that wandering a perturbation). Returns ``(steps, level)``; ``steps``
    is None when the RMSE has not recovered by the end of the run. ``first_clean`` is
    the first state produced by an unperturbed transition (401).
    """
    if level is None:
        level = float(np.max(rmse[pre[0]:pre[1] + 1]))
    bad = np.flatnonzero(~(rmse[first_clean:] <= factor * level))
    if not bad.size:
        return 0, level
    last = int(bad[-1])
    return (None if first_clean + last == len(rmse) - 1 else last + 1), level


def simulate(uncertainty: str, *, seed: int, runs: int, steps: int, R: float = 0.1,
             delta: float = DELTA) -> Any:
    """``runs`` episodes of the oscillator, seeded chunks of :data:`CHUNK` runs of the vector env.

    The chunks and their seeds depend only on ``seed`` and ``runs``: every task that
    needs the same data simulates the same bits.
    """
    kwargs = {"uncertainty": uncertainty, "delta_schedule": ((WINDOW[0], WINDOW[1], delta),),
              "R": R}
    return stack_episodes([simulate_vector(VectorTask(ENV_ID, task_seed(seed, 1, i), n, steps,
                                                      kwargs))
                           for i, n in enumerate(chunks(runs, CHUNK))])


def filter_group(task: tuple[str, str, str, int, int, int]) -> dict[str, Any]:
    """One reading's data and one noise-input group of filters; a runner task.

    ``task = (u, g, r, seed, runs, steps)`` with reading codes ``u`` (eq 29), ``g``
    (noise input) and ``r`` (what R is). Returns, per filter, the x₁ RMSE at every
    step and what the report needs of it.
    """
    u, g, r, seed, runs, steps = task
    ep = simulate(UNCERTAINTY[u], seed=seed, runs=runs, steps=steps, R=R_READINGS[r])
    model = plant_model(R_READINGS[r])
    model = model if g == "Gp" else identity_noise_model(model)
    out: dict[str, Any] = {}
    for name, f in oscillator_filters(model, variants=g == "Gp").items():
        fr = run_filter(f, ep.Y, ep.U)
        e1 = fr.x[..., 0] - ep.X[..., 0]
        rm = rmse_per_step(e1)
        rec, level = recovery_time(rm, WINDOW[1] + 1)
        out[name] = {"rmse1": rm, "table1": float(np.sum(rm[WINDOW[0]:WINDOW[1] + 1])),
                     "se": se_of_sum(e1, rm),
                     "recovery": rec, "pre_level": level, "flagged": int(np.sum(fr.diverged)),
                     "x3_end": float(np.nanmean(fr.x[-1, :, 2])),
                     "stable": bool(np.isfinite(rm).all() and rm.max() < 1e6)}
    out["peak_x1"] = float(np.nanmax(ep.X[..., 0]))
    return out


def floor_task(task: tuple[str, str]) -> np.ndarray:
    """:func:`unbiased_floor` for reading ``r`` and form ``f`` (codes); a runner task."""
    r, form = task
    return unbiased_floor(plant_model(R_READINGS[r]), FORMS[form])


def tasks(seed: int, quick: bool, runs: int | None) -> tuple[list[Any], list[Task]]:
    """The keys and tasks of simulation 2: every reading × noise-input group, and the floors."""
    steps, runs = STEPS[quick], runs or RUNS[quick]
    keys: list[Any] = []
    out = []
    for u, g, r in READINGS:
        keys.append((u, g, r))
        out.append(Task(filter_group, (u, g, r, seed, runs, steps),
                        cost=(6 if g == "Gp" else 5) * 1.7e-6 * runs * steps))
    for r in R_READINGS:
        for form in FORMS:
            keys.append(("floor", r, form))
            out.append(Task(floor_task, (r, form), cost=0.3))
    return keys, out


def collect(keys: list[Any], results: list[Any], *, quick: bool, runs: int | None
            ) -> dict[str, Any]:
    """The raw numbers of simulation 2 (``report.figures["oscillator"]``)."""
    out: dict[str, Any] = {"steps": STEPS[quick], "runs": runs or RUNS[quick], "readings": {},
                           "floor": {}}
    for key, res in zip(keys, results, strict=True):
        if key[0] == "floor":
            out["floor"][key[1:]] = res
        else:
            out["readings"][key] = res
    return out


def se_of_sum(err: np.ndarray, rmse: np.ndarray, window: tuple[int, int] = WINDOW) -> float:
    """The Monte Carlo standard error of Table 1's sum ``Σ_k RMSE_k`` (delta method).

    With ``RMSE_k = √(mean_b e²_kb)``, to first order the sum is the run average of
    ``z_b = Σ_k e²_kb / (2 RMSE_k)`` (plus a constant), so its standard error is
    ``std(z) / √M``; the correlation of the terms over k is kept.
    """
    sl = slice(window[0], window[1] + 1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        z = np.nansum(err[sl] ** 2 / (2.0 * rmse[sl, None]), axis=0)
    z = z[np.isfinite(z)]
    return float(np.std(z, ddof=1) / np.sqrt(len(z))) if len(z) > 1 else float("inf")
