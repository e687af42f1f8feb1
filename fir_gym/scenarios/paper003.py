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
sums; :mod:`.paper003_report` writes the report.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..estimators import ExtendedKalmanFilter, UnscentedKalmanFilter, augment
from ._montecarlo import chunks
from .plan import Stage, Task, run_plan
from .prose import Printed, say
from .report import Report
from .runner import Runner

ENV_ID = "fir_gym/PendulumSlider-v0"
#: Table 4: state RMSE of the UKF estimate and of the measurement
PAPER_TABLE4 = {k: tuple(map(Printed, v)) for k, v in {
    "x": ("0.0010", "0.003"), "x_dot": ("0.0063", "0.0302"), "theta": ("0.0040", "0.0294"),
    "theta_dot": ("0.0361", "0.3008")}.items()}
#: Table 5: parameter errors (UKF: RMSE; LSM: error of the estimate)
PAPER_TABLE5 = {"UKF": {"mu": Printed("0.0044"), "M0": Printed("0.0010")},
                "LSM": {"mu": Printed("-0.0119"), "M0": Printed("-0.7251")}}
TRUE = {"mu": 0.2, "M0": 0.2}
DT = 1e-3
#: the paper's claims (§5, §6): within this share of the truth, within this time
WITHIN, CONVERGED_BY = 0.03, 0.1
#: a claim about one run holds when this share of the runs meets it
CLAIM_SHARE = 0.95
#: the time of the parameter snapshot of the tests and figures (s)
HALF = 0.5
DIFFERENCES = ("backward", "forward", "central")
PARAMS = ("mu", "M0")
#: the readings of the LSM's regression window (docs/papers.md#003-lsm-window): the whole record, or
#: only the Table 5 window (the samples from the cell's Table 5 scoring start ``t5`` on)
LSM_WINDOWS = ("whole", "window")


@dataclass(frozen=True)
class Cell:
    """One experiment: input ``amplitude · sin 2π·frequency·t`` N from ``[x_rest, 0, θ₀, 0]`` for
    ``seconds``, under ``dynamics``; Table 4 scored from ``t4``, Table 5 from ``t5`` seconds."""

    amplitude: float = 5.0
    frequency: float = 1.0
    theta0: float = 0.0
    seconds: float = 1.0
    dynamics: str = "physical"
    t4: float = 0.0
    t5: float = 0.1

    @property
    def steps(self) -> int:
        return round(self.seconds / DT)

    @property
    def label(self) -> str:
        """``A5·f1·θ0·T1`` (and the equations when printed)."""
        base = say("A{a:g}·f{f:g}·θ{t:g}·T{s:g}", a=self.amplitude, f=self.frequency,
                   t=self.theta0, s=self.seconds)
        return base if self.dynamics == "physical" else say(
            "{d}·{b}", d=self.dynamics.removeprefix("printed-"), b=base)


QUIET = Cell()
LIVELY = Cell(amplitude=10.0, theta0=0.5, seconds=5.0, t4=0.5, t5=0.5)
#: the named cells of the summary: (name, cell)
CELLS = {"quiet": QUIET, "lively": LIVELY,
         "eq15·quiet": replace(QUIET, dynamics="printed-eq15"),
         "eq15·lively": replace(LIVELY, dynamics="printed-eq15"),
         "eq5·quiet": replace(QUIET, dynamics="printed-eq5"),
         "eq5·lively": replace(LIVELY, dynamics="printed-eq5")}
DEFAULT = "quiet"
#: the sensitivity sweep (physical equations), full and quick
SWEEP_AXES: dict[bool, dict[str, tuple[float, ...]]] = {
    False: {"amplitude": (5.0, 10.0), "frequency": (1.0, 2.0), "theta0": (0.0, 0.5),
            "seconds": (1.0, 5.0)},
    True: {"amplitude": (5.0, 10.0), "frequency": (1.0,), "theta0": (0.0, 0.5),
           "seconds": (1.0,)}}
#: the two scorings of every sweep cell: (t4, t5)
SCORINGS = ((0.0, 0.1), (0.5, 0.5))
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


def make_env(cell: Cell) -> Any:
    """The cell's PendulumSlider-v0 (unwrapped, no time limit)."""
    return gym.make(ENV_ID, max_episode_steps=None, dynamics=cell.dynamics).unwrapped


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


def settle_index(err: np.ndarray, within: float = WITHIN) -> np.ndarray:
    """Per run and parameter, the first step from which ``|err| ≤ within·truth`` for good
    (``K+1`` if never); ``err`` is ``(K+1, B, 2)``."""
    truth = np.array([TRUE[p] for p in PARAMS])
    outside = ~(np.abs(err) <= within * truth)
    K1 = err.shape[0]
    last = K1 - 1 - np.argmax(outside[::-1], axis=0)            # last step outside
    return np.where(outside.any(axis=0), last + 1, 0).astype(int)


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
    from ._plotting import new_figure, save

    s = report.figures["series"]
    t = s["t"]
    names = ("x (m)", "ẋ (m/s)", "θ (rad)", "θ̇ (rad/s)")
    fig, ax = new_figure(4, 1, height=1.9, sharex=True)
    plot_estimates(t, s["ukf"][:, :4], s["X"], measurement=s["Y"], names=names, label="UKF",
                   color="C0", axes=ax)
    ax[0].legend(fontsize=7, ncol=3)
    ax[-1].set_xlabel("t (s)")
    ax[0].set_title(f"Paper 003 Fig. 3: estimated states (run 0, {DEFAULT})")
    save(report, out_dir, "fig3_states", fig, "Paper 003 Fig. 3: estimated states")
    truth = np.array([TRUE[p] for p in PARAMS])
    for fig_no, errors in ((4, False), (5, True)):
        fig, ax = new_figure(2, 1, height=2.4, sharex=True)
        shift = truth if errors else 0.0
        labels = [f"{p} error" if errors else p for p in PARAMS]
        # the Monte Carlo mean ± one standard deviation over the runs, then run 0
        plot_estimates(t, s["param_mean"] - shift, covariance=s["param_std"] ** 2, sigma=1,
                       names=labels, label="UKF, Monte-Carlo mean", color="C1", axes=ax)
        plot_estimates(t, s["ukf"][:, 4:] - shift, names=labels, label="UKF, run 0",
                       color="C0", axes=ax)
        for a, name in zip(ax, PARAMS, strict=True):
            a.axhline(0.0 if errors else TRUE[name], color="k", ls="--", lw=0.8,
                      label="zero error" if errors else "true value")
            a.set_ylim(-0.1 if errors else 0.1, 0.1 if errors else 0.3)
        ax[0].legend(fontsize=7)
        ax[-1].set_xlabel("t (s)")
        ax[0].set_title(f"Paper 003 Fig. {fig_no}: "
                        + ("errors of the estimated parameters" if errors
                           else "estimated μ and M0"))
        save(report, out_dir, f"fig{fig_no}_{'param_errors' if errors else 'params'}", fig,
             f"Paper 003 Fig. {fig_no}: " + ("parameter errors" if errors else "parameters"))
