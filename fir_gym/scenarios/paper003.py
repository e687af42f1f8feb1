"""Paper 003: UKF-based state and parameter estimation of the pendulum-slider (Tables 4, 5).

The experiment: PendulumSlider-v0 with the paper's friction term, all four states
measured with ``R = diag([0.003, 0.03, 0.03, 0.3]²)`` at 1 kHz; the UKF (and, beside
it, the EKF) runs on the state augmented with ``[μ, M0]`` (constant: ``Q_params = 0``),
with ``Q = 1e-6 I``, ``P0 = I6`` and a zero initial estimate. The least-squares method
(LSM) regresses the equations of motion on finite-difference accelerations, over the whole
record or only the Table 5 window (:data:`LSM_WINDOWS`). A Monte Carlo over
measurement-noise seeds gives every figure as mean ± spread.

The paper gives neither the input, the initial state, the duration nor the window
its RMSEs are taken over (docs/papers.md#003-experiment-reading). A :class:`Cell`
fixes them (input ``A sin 2πft`` N, initial angle θ₀ from the rest position, duration
``T``) and the equations of motion (physical, or the printed eq 15 / eq 5 of
PendulumSlider-v0's ``dynamics``, docs/papers.md#003-printed-equations). Named cells
(:data:`CELLS`): ``quiet`` (5 N, 1 Hz, from rest, 1 s: our default), ``lively``
(10 N, 1 Hz, θ₀ = 0.5 rad, 5 s, scored from 0.5 s) and the printed equations on both;
:data:`SWEEP` varies amplitude, frequency, initial angle and duration. Each task is a
chunk of runs of one cell — episodes, the batched UKF/EKF, the LSM — reduced to per-run
sums; :mod:`.paper003_report` writes the report. The paper's numbers, the truth and the
cells are :mod:`.paper003_setup` (re-exported here).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..estimators import ExtendedKalmanFilter, UnscentedKalmanFilter, augment
from ._montecarlo import chunks
from .paper003_setup import (
    CELLS,
    CLAIM_SHARE,
    CONVERGED_BY,
    DEFAULT,
    DIFFERENCES,
    DT,
    ENV_ID,
    HALF,
    LIVELY,
    LSM_WINDOWS,
    PAPER_TABLE4,
    PAPER_TABLE5,
    PARAMS,
    QUIET,
    SCORINGS,
    SWEEP_AXES,
    TRUE,
    WITHIN,
    Cell,
    make_env,
    settle_index,
)
from .plan import Stage, Task, run_plan
from .report import Report
from .runner import Runner

# the setup (.paper003_setup) is re-exported: paper003.CELLS, paper003.Cell, ...
__all__ = ["CELLS", "CHUNK", "CLAIM_SHARE", "CONVERGED_BY", "DEFAULT", "DIFFERENCES", "DT",
           "ENV_ID", "HALF", "LIVELY", "LSM_WINDOWS", "PAPER_TABLE4", "PAPER_TABLE5", "PARAMS",
           "QUIET", "RUNS", "SCORINGS", "SWEEP_AXES", "SWEEP_GROUP", "SWEEP_RUNS", "TRUE",
           "WITHIN", "WITH_EKF", "Cell", "Episodes", "cell_input", "cell_task", "episode",
           "joint_estimates", "lsm_estimates", "lsm_first_sample", "lsm_starts", "make_env",
           "paper_input", "plan", "plot", "rate_mean_square", "replace_episodes", "run",
           "runs_for", "settle_index", "simulate", "sweep"]

#: Monte Carlo runs per second of a named cell, and per sweep cell (full, quick)
RUNS = {False: 50, True: 5}
SWEEP_RUNS = {False: 10, True: 3}
CHUNK = 10


def sweep(quick: bool) -> list[Cell]:
    """Every combination of :data:`SWEEP_AXES` (scored both ways, :data:`SCORINGS`)."""
    axes: dict[str, tuple[float, ...]] = SWEEP_AXES[quick]
    out = []
    for values in itertools.product(*axes.values()):
        v = dict(zip(axes, values, strict=True))
        out.append(Cell(amplitude=v["amplitude"], frequency=v["frequency"], theta0=v["theta0"],
                        seconds=v["seconds"]))
    return out


@dataclass
class Episodes:
    """``B`` noisy measurement records of the same deterministic trajectory."""

    Y: np.ndarray        # (K+1, B, 4) measurements y[0..K]
    X: np.ndarray        # (K+1, B, 4) true states
    actions: np.ndarray  # (K, B, 1) normalised inputs u[0..K-1]
    force_max: float
    model: Any           # the env's parametric model (the filters' belief)
    dynamics: Any        # the ODE with the same nominal parameters (for least squares)


def cell_input(k: np.ndarray | int, cell: Cell = QUIET, force_max: float = 10.0) -> np.ndarray:
    """The normalised action of ``A sin 2πft`` N at steps ``k`` (``force_max`` newtons per unit)."""
    return (cell.amplitude / force_max) * np.sin(2.0 * np.pi * cell.frequency * DT
                                                 * np.asarray(k, dtype=float))


def paper_input(k: np.ndarray | int) -> np.ndarray:
    """The normalised action of the default ``U = 5 sin 2πt`` N."""
    return cell_input(k)


def episode(task: tuple[int, float] | tuple[int, float, Cell]) -> tuple[np.ndarray, np.ndarray]:
    """One seeded episode of a cell (default :data:`QUIET`, ``seconds`` long): ``(y, x)``,
    each ``(K+1, 4)``."""
    seed, seconds, cell = (*task, QUIET) if len(task) == 2 else task
    env = make_env(cell)
    y0, info = env.reset(seed=seed, options={"state": [env.x_rest, 0.0, cell.theta0, 0.0]})
    ys, xs = [y0], [info["state"]]
    for k in range(round(seconds / DT)):
        y, _, terminated, _, info = env.step(np.array([cell_input(k, cell,
                                                                  env.params["force_max"])]))
        ys.append(y)
        xs.append(info["state"])
        if terminated:
            break
    env.close()
    return np.array(ys), np.array(xs)


def simulate(seeds: range | list[int], seconds: float, runner: Runner | None = None,
             cell: Cell = QUIET) -> Episodes:
    """Episodes of ``cell`` for ``seconds``, one per seed (one task each)."""
    plan = Stage([Task(episode, (seed, seconds, cell)) for seed in seeds], lambda out: out)
    return _episodes(run_plan(plan, runner), cell, round(seconds / DT))


def _episodes(out: list[tuple[np.ndarray, np.ndarray]], cell: Cell, steps: int) -> Episodes:
    env = make_env(cell)
    fmax = env.params["force_max"]
    actions = np.broadcast_to(cell_input(np.arange(steps), cell, fmax)[:, None, None],
                              (steps, len(out), 1)).copy()
    ep = Episodes(_stack([o[0] for o in out], steps), _stack([o[1] for o in out], steps),
                  actions, fmax, env.model, env.dynamics)
    env.close()
    return ep


def _stack(parts: list[np.ndarray], steps: int) -> np.ndarray:
    """Runs along axis 1, NaN after a run that left the rail."""
    out = np.full((steps + 1, len(parts), parts[0].shape[1]), np.nan)
    for b, p in enumerate(parts):
        out[:len(p), b] = p
    return out


def joint_estimates(episodes: Episodes, method: str = "ukf") -> np.ndarray:
    """Estimates ``(K+1, B, 6)`` of ``[x, ẋ, θ, θ̇, μ, M0]`` by the batched UKF or EKF."""
    model = augment(episodes.model, list(PARAMS))
    cls = {"ukf": UnscentedKalmanFilter, "ekf": ExtendedKalmanFilter}[method]
    filt = cls(model, x0=np.zeros(6), P0=np.eye(6), nan_policy="skip")
    out = [filt.step(episodes.Y[0])]
    for k in range(1, episodes.Y.shape[0]):
        out.append(filt.step(episodes.Y[k], episodes.actions[k - 1]))
    return np.array(out)


def lsm_first_sample(start: float, difference: str) -> int:
    """The first record sample the LSM of the equations at ``t_k ≥ start`` reads: ``k0 − 1``
    for backward and central differences (they need ``v_{k0−1}``), ``k0`` for forward ones."""
    k0 = round(start / DT)
    return k0 if difference == "forward" else max(k0 - 1, 0)


def lsm_estimates(episodes: Episodes, difference: str, start: float = 0.0) -> np.ndarray:
    """LSM ``(B, 2)`` estimates of ``[μ, M0]`` per run, regressing the equations of motion at
    the samples ``t_k ≥ start`` (``0``: the whole record; docs/papers.md#003-lsm)."""
    first = lsm_first_sample(start, difference)
    forces = episodes.actions[first:, :, 0] * episodes.force_max
    lsm = episodes.dynamics.least_squares_parameters
    return np.array([list(lsm(episodes.Y[first:, b], forces[:, b], difference).values())
                     for b in range(episodes.Y.shape[1])])


def lsm_starts(cell: Cell) -> tuple[float, ...]:
    """The starts of a cell's LSM regressions: the whole record (``0``), the cell's Table 5
    window and the sweep scorings' Table 5 windows (:data:`LSM_WINDOWS`)."""
    return tuple(sorted({0.0, cell.t5, *(t5 for _, t5 in SCORINGS)}))


def rate_mean_square(X: np.ndarray, start: float = 0.0) -> float:
    """``E[θ̇²]`` of the true states ``(K+1, B, 4)`` over the samples ``t_k ≥ start`` (from
    sample 1: the first backward-difference equation), NaN after a run left the rail."""
    return float(np.nanmean(X[max(round(start / DT), 1):, :, 3] ** 2))


def runs_for(cell: Cell, runs: int) -> int:
    """The runs of a cell: ``runs`` per second-long cell, fewer for longer ones (the same number
    of samples; at least two, for a spread)."""
    return max(2, round(runs / cell.seconds))


def cell_task(task: tuple[tuple[Cell, ...], int, int, int, bool]) -> list[dict[str, Any]]:
    """One chunk of one or more cells of the same duration and equations, batched through one
    filter; per cell its per-run sums (a runner task).

    ``task = (cells, seed, chunk, n, with_ekf)``: ``n`` episodes per cell from seed
    ``seed + chunk·CHUNK`` on, the UKF (and with ``with_ekf`` the EKF and run 0's series)
    on all of them at once, the LSM per run and regression window (:func:`lsm_starts`).
    """
    cells, seed, chunk, n, with_ekf = task
    seeds = range(seed + chunk * CHUNK, seed + chunk * CHUNK + n)
    parts = [_episodes([episode((s, c.seconds, c)) for s in seeds], c, c.steps) for c in cells]
    ep = replace_episodes(parts)
    truth = np.array([TRUE[p] for p in PARAMS])
    t = DT * np.arange(ep.X.shape[0])
    est = {m: joint_estimates(ep, m) for m in (("ukf", "ekf") if with_ekf else ("ukf",))}
    out = []
    for i, (cell, part) in enumerate(zip(cells, parts, strict=True)):
        runs = slice(i * n, (i + 1) * n)
        X, Y = ep.X[:, runs], ep.Y[:, runs]
        res: dict[str, Any] = {"n": n, "meas_sse": np.nansum((Y - X) ** 2, axis=0),
                               "samples": np.isfinite(Y[..., 0]).sum(axis=0),
                               "rate_ms": {s: rate_mean_square(X, s) for s in lsm_starts(cell)},
                               "lsm": {s: {d: lsm_estimates(part, d, s) for d in DIFFERENCES}
                                       for s in lsm_starts(cell)}
                               if np.isfinite(Y).all() else None}
        for method, e_all in est.items():
            e = e_all[:, runs]
            err = e[..., 4:] - truth
            r: dict[Any, Any] = {}
            for t4, t5 in {(cell.t4, cell.t5), *SCORINGS}:
                s4, s5 = t >= t4 - DT / 2, t >= t5 - DT / 2
                r[("state", t4)] = np.nansum((e[s4, :, :4] - X[s4]) ** 2, axis=0)
                r[("n", t4)] = np.isfinite(X[s4, :, 0]).sum(axis=0)
                r[("param", t5)] = np.nansum(err[s5] ** 2, axis=0)
                r[("n", t5)] = np.isfinite(err[s5, :, 0]).sum(axis=0)
            r.update({"end": err[-1], "half": e[min(round(HALF / DT), len(e) - 1), :, 4:],
                      "at_converged": err[min(round(CONVERGED_BY / DT), len(e) - 1)],
                      "settle": settle_index(err), "sum": np.nansum(err, axis=1),
                      "sumsq": np.nansum(err ** 2, axis=1)})
            if chunk == 0 and with_ekf:
                r["run0"] = e[:, 0]
            res[method] = r
        if chunk == 0 and with_ekf:
            res["series"] = {"X": X[:, 0], "Y": Y[:, 0]}
        out.append(res)
    return out


def replace_episodes(parts: list[Episodes]) -> Episodes:
    """Episodes of several cells side by side (same duration and model): one batch."""
    first = parts[0]
    return Episodes(np.concatenate([p.Y for p in parts], axis=1),
                    np.concatenate([p.X for p in parts], axis=1),
                    np.concatenate([p.actions for p in parts], axis=1), first.force_max,
                    first.model, first.dynamics)


#: the named cells run beside the UKF with the EKF (and give the figures' series)
WITH_EKF = ("quiet", "lively")
#: sweep cells batched through one filter per task
SWEEP_GROUP = 4


def plan(seed: int = 0, quick: bool = False, runs: int | None = None) -> Stage:
    """Named cells (:data:`CELLS`, ``runs`` per second) and the sweep (:data:`SWEEP_RUNS`)."""
    n_main = runs or RUNS[quick]
    n_sweep = min(n_main, SWEEP_RUNS[quick])
    jobs: list[tuple[tuple[str, ...], tuple[Cell, ...], int]] = [
        ((name,), (c,), runs_for(c, n_main)) for name, c in CELLS.items()]
    by_length: dict[float, list[Cell]] = {}
    for c in sweep(quick):
        by_length.setdefault(c.seconds, []).append(c)
    for group in by_length.values():
        for k in range(0, len(group), SWEEP_GROUP):
            cells = tuple(group[k:k + SWEEP_GROUP])
            jobs.append((("sweep",) * len(cells), cells, runs_for(cells[0], n_sweep)))
    keys, tasks = [], []
    for names, cells, n in jobs:
        with_ekf = names[0] in WITH_EKF
        for i, size in enumerate(chunks(n, CHUNK)):
            keys.append(list(zip(names, cells, strict=True)))
            sim = size * len(cells) * cells[0].seconds * (
                0.04 if cells[0].dynamics == "physical" else 0.06)
            cost = sim + cells[0].seconds * (0.3 if with_ekf else 0.2)
            tasks.append(Task(cell_task, (cells, seed, i, size, with_ekf), cost=cost))

    def then(results: list[Any]) -> Report:
        from .paper003_report import assemble

        merged: dict[tuple[str, Cell], list[Any]] = {}
        for key, res in zip(keys, results, strict=True):
            for name_cell, part in zip(key, res, strict=True):
                merged.setdefault(name_cell, []).append(part)
        return assemble(merged, n_main, n_sweep, quick)

    return Stage(tasks, then, desc="paper 003")


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Tables 4 and 5 on every named cell and the sensitivity sweep (:func:`plan`)."""
    return run_plan(plan(seed, quick, runs), runner)


def plot(report: Report, out_dir: str | Path) -> None:
    """Figs 3–5 of paper 003 (the default cell): states, parameter estimates and errors."""
    from ..plotting import plot_estimates
    from ._plotting import legend_outside, new_figure, save

    s = report.figures["series"]
    t = s["t"]
    names = ("x (m)", "ẋ (m/s)", "θ (rad)", "θ̇ (rad/s)")
    fig, ax = new_figure(4, 1, width=10.0, height=1.9, sharex=True)
    plot_estimates(t, s["ukf"][:, :4], s["X"], measurement=s["Y"], names=names, label="UKF",
                   color="C0", axes=ax)
    legend_outside(ax[0])
    ax[-1].set_xlabel("t (s)")
    ax[0].set_title(f"Paper 003 Fig. 3: estimated states (run 0, {DEFAULT})")
    save(report, out_dir, "fig3_states", fig, "Paper 003 Fig. 3: estimated states")
    truth = np.array([TRUE[p] for p in PARAMS])
    for fig_no, errors in ((4, False), (5, True)):
        fig, ax = new_figure(2, 1, width=10.0, height=2.4, sharex=True)
        shift = truth if errors else 0.0
        units = {"mu": "dimensionless", "M0": "N m s/rad"}          # the slider's friction
        labels = [f"{p} error ({units[p]})" if errors else f"{p} ({units[p]})" for p in PARAMS]
        # the Monte Carlo mean ± one standard deviation over the runs, then run 0
        plot_estimates(t, s["param_mean"] - shift, covariance=s["param_std"] ** 2, sigma=1,
                       names=labels, label="UKF, Monte-Carlo mean", color="C1", axes=ax)
        plot_estimates(t, s["ukf"][:, 4:] - shift, names=labels, label="UKF, run 0",
                       color="C0", axes=ax)
        for a, name in zip(ax, PARAMS, strict=True):
            a.axhline(0.0 if errors else TRUE[name], color="k", ls="--", lw=0.8,
                      label="zero error" if errors else "true value")
            a.set_ylim(-0.1 if errors else 0.1, 0.1 if errors else 0.3)
        legend_outside(ax[0])
        ax[-1].set_xlabel("t (s)")
        ax[0].set_title(f"Paper 003 Fig. {fig_no}: "
                        + ("errors of the estimated parameters" if errors
                           else "estimated μ and M0"))
        save(report, out_dir, f"fig{fig_no}_{'param_errors' if errors else 'params'}", fig,
             f"Paper 003 Fig. {fig_no}: " + ("parameter errors" if errors else "parameters"))
