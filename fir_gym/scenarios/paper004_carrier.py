"""Paper 004's future work: FIR against Kalman filters under model uncertainty (CarrierMotion-v0).

Paper 004 (§I, §V) claims robustness to parameter changes for its FIR filters and
leaves the comparison with other filters for later. Here it is, on paper 001's
plant and uncertainty: the truth ``fir_gym/CarrierMotion-v0`` has Δ22 and Δc at
the corners of ``|Δ22| ≤ 0.006``, ``|Δc| ≤ 0.1`` (and at 0), while every filter
keeps the nominal model (Δ = 0; T = 0.1 s, R = V/T = 10):

* the Kalman filter (prior: the stationary covariance, mean 0);
* paper 004's FIR filter without a prior (Cor 2.2: minimum-variance *unbiased*);
* paper 004's FIR filter with the stationary prior (Cor 2.1),

for windows of ``L = N + 1`` measurements (paper 001's T = 1, 5, 7 s are
L = 11, 51, 71). All corners use the same seeds, so the comparison is paired.
The score is the x₁ (deck displacement) RMSE over k ≥ 250, when every window is full.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from fir_gym.estimators import FIRFilter, KalmanFilter

from ._montecarlo import VectorTask, chunks, run_filter, simulate_vector, stack_episodes, task_seed
from .plan import Stage, Task, run_plan
from .prose import say
from .runner import Runner

ENV_ID = "fir_gym/CarrierMotion-v0"
#: the truth's (Δ22, Δc): the nominal system, then the corners of paper 001's box
CORNERS: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.006, 0.1), (0.006, -0.1),
                                            (-0.006, 0.1), (-0.006, -0.1))
WINDOWS = {False: (6, 11, 21, 51, 71, 101, 201), True: (11, 51, 71)}
RUNS = {False: 100, True: 20}
CHUNK = 50
STEPS = 1000
SCORE_FROM = 250


def corner_label(corner: tuple[float, float]) -> str:
    d22, dc = corner
    return "nominal" if corner == (0.0, 0.0) else say("Δ22={a:+g}, Δc={b:+g}", a=d22, b=dc)


def comparison_filters(model: Any, prior_cov: np.ndarray, windows: tuple[int, ...]
                       ) -> dict[tuple[str, int | None], Any]:
    """``(family, L)`` → filter; ``L`` is None for the Kalman filter."""
    out: dict[tuple[str, int | None], Any] = {
        ("KF", None): KalmanFilter(model, x0=np.zeros(2), P0=prior_cov)}
    for L in windows:
        out[("FIR, no prior (Cor 2.2)", L)] = FIRFilter(model, horizon=L)
        out[("FIR, stationary prior (Cor 2.1)", L)] = FIRFilter(model, horizon=L,
                                                                prior="stationary")
    return out


def comparison_task(task: tuple[tuple[float, float], int, int, int, tuple[int, ...]]
                    ) -> dict[tuple[str, int | None], np.ndarray]:
    """One chunk at one corner: simulate it, run every filter; squared-error sums of x₁, x₂
    over k ≥ :data:`SCORE_FROM` per filter (a runner task)."""
    (d22, dc), seed, chunk, n, windows = task
    ep = stack_episodes([simulate_vector(VectorTask(ENV_ID, task_seed(seed, 4, chunk), n, STEPS,
                                                    {"delta22": d22, "delta_c": dc}))])
    env = gym.make(ENV_ID)
    model = env.unwrapped.model                            # type: ignore[attr-defined]
    prior_cov = env.unwrapped.stationary_cov               # type: ignore[attr-defined]
    env.close()
    return {key: np.sum((run_filter(f, ep.Y, ep.U).x[SCORE_FROM:] - ep.X[SCORE_FROM:]) ** 2,
                        axis=(0, 1))
            for key, f in comparison_filters(model, prior_cov, windows).items()}


def comparison_plan(seed: int, quick: bool, runs: int | None) -> Stage:
    """One task per (corner, chunk of runs); then the RMSE table of :func:`run_comparison`."""
    runs = runs or RUNS[quick]
    windows = WINDOWS[quick]
    sizes = chunks(runs, CHUNK)
    keys = [(corner, n) for corner in CORNERS for n in sizes]
    tasks = [Task(comparison_task, (corner, seed, i, n, windows),
                  cost=1e-3 * n * (1 + 2 * len(windows)))
             for corner in CORNERS for i, n in enumerate(sizes)]

    def then(results: list[Any]) -> dict[str, Any]:
        env = gym.make(ENV_ID)
        dt = float(env.unwrapped.model.dt)                 # type: ignore[attr-defined]
        env.close()
        rmse: dict[tuple[float, float], dict[tuple[str, int | None], tuple[float, float]]] = {}
        for corner in CORNERS:
            parts = [r for (c, _), r in zip(keys, results, strict=True) if c == corner]
            samples = runs * (STEPS + 1 - SCORE_FROM)
            rmse[corner] = {}
            for key in parts[0]:
                x1, x2 = np.sqrt(sum(p[key] for p in parts) / samples)
                rmse[corner][key] = (float(x1), float(x2))
        return {"rmse": rmse, "windows": windows, "runs": runs, "dt": dt}

    return Stage(tasks, then, desc="paper 004")


def run_comparison(*, seed: int, quick: bool, runs: int | None, runner: Runner | None = None
                   ) -> dict[str, Any]:
    """x₁ and x₂ RMSE of every filter at every corner: ``rmse[corner][(family, L)] = (x₁, x₂)``."""
    return run_plan(comparison_plan(seed, quick, runs), runner)


def summary(res: dict[str, Any]) -> dict[str, Any]:
    """Worst corner per filter, the best FIR of each family, and the KF, for the report."""
    rmse = res["rmse"]
    keys = list(rmse[CORNERS[0]])
    def worst_corner(key: tuple[str, int | None]) -> tuple[float, float]:
        return max(CORNERS[1:], key=lambda c: rmse[c][key][0])

    worst = {key: worst_corner(key) for key in keys}
    worst_val = {key: rmse[worst[key]][key][0] for key in keys}
    nominal = {key: rmse[CORNERS[0]][key][0] for key in keys}
    best = {}
    for family in ("FIR, no prior (Cor 2.2)", "FIR, stationary prior (Cor 2.1)"):
        cands = [k for k in keys if k[0] == family]
        best[family] = min(cands, key=lambda k: worst_val[k])
    return {"worst": worst, "worst_val": worst_val, "nominal": nominal, "best": best}


def table_rows(res: dict[str, Any]) -> tuple[list[str], list[list[Any]]]:
    """Rows ``filter | L | window (s) | x₁ RMSE per corner | worst ÷ nominal``."""
    rmse, dt = res["rmse"], res["dt"]
    s = summary(res)
    headers = ["filter", "L", "window (s)", *[corner_label(c) for c in CORNERS],
               "worst ÷ nominal"]
    rows = []
    for key in rmse[CORNERS[0]]:
        family, L = key
        rows.append([family, L, None if L is None else round((L - 1) * dt, 3),
                     *[rmse[c][key][0] for c in CORNERS], s["worst_val"][key] / s["nominal"][key]])
    return headers, rows
