"""Paper 003: UKF-based state and parameter estimation of the pendulum-slider (Tables 4, 5).

The experiment: PendulumSlider-v0 with the paper's friction term, from rest
(``x = x_rest``, 10.8 mm), driven by ``U = 5 sin 2πt`` N, all four states measured
with ``R = diag([0.003, 0.03, 0.03, 0.3]²)`` at 1 kHz. The UKF (and, beside it,
the EKF) runs on the state augmented with ``[μ, M0]`` (constant: ``Q_params = 0``),
with ``Q = 1e-6 I``, ``P0 = I6`` and a zero initial estimate. The least-squares
method (LSM) regresses the equations of motion on finite-difference accelerations.
A Monte Carlo over measurement-noise seeds gives every figure as mean ± std.

The paper gives neither the duration nor the initial state; we report the state
RMSE over the first second (and the parameter errors at 0.5 s, the paper's
"converged within 0.1 s" claim included).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..estimators import ExtendedKalmanFilter, UnscentedKalmanFilter, augment
from .report import Report
from .runner import SERIAL, Runner

#: Table 4: state RMSE of the UKF estimate and of the measurement
PAPER_TABLE4 = {"x": (0.0010, 0.003), "x_dot": (0.0063, 0.0302), "theta": (0.0040, 0.0294),
                "theta_dot": (0.0361, 0.3008)}
#: Table 5: parameter errors (UKF: RMSE; LSM: error of the estimate)
PAPER_TABLE5 = {"UKF": {"mu": 0.0044, "M0": 0.0010}, "LSM": {"mu": -0.0119, "M0": -0.7251}}
TRUE = {"mu": 0.2, "M0": 0.2}
DT = 1e-3


@dataclass
class Episodes:
    """``B`` noisy measurement records of the same deterministic trajectory."""

    Y: np.ndarray        # (K+1, B, 4) measurements y[0..K]
    X: np.ndarray        # (K+1, B, 4) true states
    actions: np.ndarray  # (K, B, 1) normalised inputs u[0..K-1]
    force_max: float
    model: object        # the env's parametric model (the filters' belief)
    dynamics: object     # the ODE with the same nominal parameters (for least squares)


def paper_input(k: np.ndarray | int) -> np.ndarray:
    """The normalised action of the paper's ``U = 5 sin 2πt`` N (``force_max`` = 10 N)."""
    return 0.5 * np.sin(2.0 * np.pi * np.asarray(k) * DT)


def episode(task: tuple[int, float]) -> tuple[np.ndarray, np.ndarray]:
    """One run ``(seed, seconds)`` of PendulumSlider-v0 from rest under the paper's input.

    Returns measurements and true states, each ``(K+1, 4)``; a runner task (seeded).
    """
    seed, seconds = task
    env = gym.make("fir_gym/PendulumSlider-v0", max_episode_steps=None).unwrapped
    y0, info = env.reset(seed=seed, options={"state": [env.x_rest, 0.0, 0.0, 0.0]})
    ys, xs = [y0], [info["state"]]
    for k in range(round(seconds / DT)):
        y, _, _, _, info = env.step(np.array([paper_input(k)]))
        ys.append(y)
        xs.append(info["state"])
    env.close()
    return np.array(ys), np.array(xs)


def simulate(seeds: range | list[int], seconds: float, runner: Runner | None = None) -> Episodes:
    """Run PendulumSlider-v0 from rest under the paper's input once per seed (one task each)."""
    runner = runner or SERIAL
    out = runner.map(episode, [(seed, seconds) for seed in seeds], desc="paper 003 episodes")
    env = gym.make("fir_gym/PendulumSlider-v0", max_episode_steps=None).unwrapped
    steps = round(seconds / DT)
    actions = np.broadcast_to(paper_input(np.arange(steps))[:, None, None],
                              (steps, len(out), 1)).copy()
    episodes = Episodes(np.stack([o[0] for o in out], axis=1), np.stack([o[1] for o in out],
                                                                       axis=1),
                        actions, env.params["force_max"], env.model, env.dynamics)
    env.close()
    return episodes


def joint_estimates(episodes: Episodes, method: str = "ukf") -> np.ndarray:
    """Estimates ``(K+1, B, 6)`` of ``[x, ẋ, θ, θ̇, μ, M0]`` by the batched UKF or EKF."""
    model = augment(episodes.model, ["mu", "M0"])
    cls = {"ukf": UnscentedKalmanFilter, "ekf": ExtendedKalmanFilter}[method]
    filt = cls(model, x0=np.zeros(6), P0=np.eye(6))
    out = [filt.step(episodes.Y[0])]
    for k in range(1, episodes.Y.shape[0]):
        out.append(filt.step(episodes.Y[k], episodes.actions[k - 1]))
    return np.array(out)


def lsm_estimates(episodes: Episodes, difference: str) -> np.ndarray:
    """LSM ``(B, 2)`` estimates of ``[μ, M0]`` per run."""
    forces = episodes.actions[:, :, 0] * episodes.force_max
    lsm = episodes.dynamics.least_squares_parameters
    return np.array([list(lsm(episodes.Y[:, b], forces[:, b], difference).values())
                     for b in range(episodes.Y.shape[1])])


def backward_bias_law(episodes: Episodes) -> float:
    """The errors-in-variables bias of the backward-difference LSM estimate of M0.

    With measured ``θ̇ = θ̇_true + n`` (``σ = 0.3``), the regression
    ``M0 θ̇ = ... - J (θ̇_k - θ̇_{k-1}) / dt`` (``J = I_c + m2 l²``) correlates its
    regressor with its target through ``n_k``:
    ``E[M0_hat] ≈ (M0 E[θ̇²] - J σ² / dt) / (E[θ̇²] + σ²)``.
    """
    J = _hinge_inertia(episodes.dynamics)
    sigma2 = float(episodes.model.R[3, 3])
    Et = _mean_square_rate(episodes)
    return (TRUE["M0"] * Et - J * sigma2 / DT) / (Et + sigma2) - TRUE["M0"]


def run(seed: int = 0, quick: bool = False, runs: int | None = None,
        runner: Runner | None = None) -> Report:
    """Reproduce Tables 4 and 5 (``quick``: 5 runs instead of 50)."""
    runs = runs or (5 if quick else 50)
    episodes = simulate(range(seed, seed + runs), seconds=1.0, runner=runner)
    report = Report("003", "UKF state and parameter estimation of a pendulum-slider")
    X, Y = episodes.X, episodes.Y
    measurement_rmse = np.sqrt(np.mean((Y - X) ** 2, axis=(0, 1)))
    est = {m: joint_estimates(episodes, m) for m in ("ukf", "ekf")}
    state_rmse = {m: np.sqrt(np.mean((e[:, :, :4] - X) ** 2, axis=(0, 1))) for m, e in est.items()}
    rows = []
    for i, name in enumerate(PAPER_TABLE4):
        paper_est, paper_meas = PAPER_TABLE4[name]
        ours = state_rmse["ukf"][i]
        rows.append([name, paper_est, ours, f"{100 * (ours / paper_est - 1):+.0f} %",
                     state_rmse["ekf"][i], paper_meas, measurement_rmse[i]])
    report.add_table(
        f"Table 4 — state RMSE over the first second ({runs} runs)",
        ["state", "paper UKF", "our UKF", "ours vs paper", "our EKF", "paper meas.", "our meas."],
        rows)

    truth = np.array([TRUE["mu"], TRUE["M0"]])
    at_half = {m: e[500, :, 4:] for m, e in est.items()}
    after_converged = {m: np.sqrt(np.mean((e[100:, :, 4:] - truth) ** 2, axis=(0, 1)))
                       for m, e in est.items()}
    lsm = {d: lsm_estimates(episodes, d) for d in ("backward", "forward", "central")}
    rows = []
    for j, name in enumerate(("mu", "M0")):
        for m in ("ukf", "ekf"):
            mean_err = at_half[m][:, j].mean() - truth[j]
            rows.append([name, m.upper(), PAPER_TABLE5["UKF"][name] if m == "ukf" else None,
                         after_converged[m][j],
                         f"{mean_err:+.4f} ± {at_half[m][:, j].std():.4f}",
                         f"{100 * mean_err / truth[j]:+.2f} %"])
        for d in ("backward", "forward", "central"):
            err = lsm[d][:, j] - truth[j]
            rows.append([name, f"LSM {d}", PAPER_TABLE5["LSM"][name] if d == "backward" else None,
                         None, f"{err.mean():+.4f} ± {err.std():.4f}",
                         f"{100 * err.mean() / truth[j]:+.1f} %"])
    report.add_table(
        f"Table 5 — parameter errors ({runs} runs; truth μ = M0 = 0.2)",
        ["param", "method", "paper", "our RMSE after 0.1 s",
         "our error at 0.5 s (LSM: from 1 s)", "relative"], rows)

    law = backward_bias_law(episodes)
    J = _hinge_inertia(episodes.dynamics)
    sigma2 = float(episodes.model.R[3, 3])
    attenuation = -TRUE["M0"] * sigma2 / (_mean_square_rate(episodes) + sigma2)
    report.figures.update({
        "state_rmse": state_rmse, "measurement_rmse": measurement_rmse,
        "params_at_half_second": at_half, "param_rmse_after_0.1s": after_converged,
        "lsm": lsm, "backward_bias_law": law,
        "series": {"t": DT * np.arange(X.shape[0]), "X": X[:, 0], "Y": Y[:, 0],
                   "ukf": est["ukf"][:, 0], "param_mean": est["ukf"][:, :, 4:].mean(axis=1),
                   "param_std": est["ukf"][:, :, 4:].std(axis=1)},
        "convergence": convergence(est["ukf"][:, :, 4:], truth),
    })
    _compare(report, runs)
    report.notes += [
        "Table 4: the state RMSE depends on the (unreported) duration; over the first second "
        "every UKF entry is within 30 % of the paper's.",
        f"Table 5, UKF: our M0 RMSE is about ten times the paper's 0.0010. The Monte-Carlo "
        f"spread of the UKF's M0 at 0.5 s is {100 * at_half['ukf'][:, 1].std() / 0.2:.1f} % of "
        "M0 and agrees with the filter's own covariance (tests/estimators/test_augment.py), so "
        "an RMSE of 0.0010 is not reachable with the paper's noise levels in this time; on "
        "noise-free data (paper §5 says 'data without noise') the error is below 3 % after "
        "0.5 s.",
        f"Table 5, LSM backward: the M0 bias is errors-in-variables, ≈ (M0 E[θ̇²] − J σ²/dt)/"
        f"(E[θ̇²] + σ²) − M0 = {law:+.3f} for this trajectory (E[θ̇²] = "
        f"{_mean_square_rate(episodes):.2f} rad²/s²); the paper's −0.7251 is the same "
        f"law for a livelier trajectory, E[θ̇²] ≈ {_energy_for_bias(-0.7251, J, sigma2):.1f} "
        "rad²/s² "
        "(the paper does not give its initial state or duration). Central differences remove "
        "the correlation; what remains is the errors-in-variables attenuation "
        f"−M0 σ²/(E[θ̇²] + σ²) = {attenuation:+.3f}.",
    ]
    return report


def convergence(params: np.ndarray, truth: np.ndarray, within: float = 0.03) -> dict[str, Any]:
    """When the UKF's parameters settle within ``within`` (3 %) of the truth (paper's claims).

    ``params`` is ``(K+1, B, 2)``. Returns, per parameter, the time after which the
    run-averaged estimate stays within the band, and the fraction of runs inside
    the band at 0.1 s and at the end.
    """
    out: dict[str, Any] = {}
    for j, name in enumerate(("mu", "M0")):
        inside = np.abs(params[:, :, j] - truth[j]) <= within * truth[j]
        mean_in = np.abs(params[:, :, j].mean(axis=1) - truth[j]) <= within * truth[j]
        out_idx = np.flatnonzero(~mean_in)
        settle = 0 if not out_idx.size else (None if out_idx[-1] == len(mean_in) - 1
                                             else int(out_idx[-1] + 1))
        out[name] = {"settle_time": None if settle is None else settle * DT,
                     "runs_within_at_0.1s": float(inside[100].mean()),
                     "runs_within_at_end": float(inside[-1].mean())}
    return out


def _settled_by(c: dict[str, Any], t: float) -> bool:
    """Whether the run-averaged estimate is within the band from ``t`` seconds on (+ one step)."""
    return c["settle_time"] is not None and c["settle_time"] <= t + 1.5 * DT


def _compare(report: Report, runs: int) -> None:
    """One summary row per number of Tables 4 and 5, and the two claims of §5."""
    f = report.figures
    reading = (f"PendulumSlider-v0, paper's friction term, from rest, U = 5 sin 2πt N, first "
               f"second; {runs} runs")
    for i, name in enumerate(PAPER_TABLE4):
        paper_est, paper_meas = PAPER_TABLE4[name]
        ours = float(f["state_rmse"]["ukf"][i])
        report.compare(f"Table 4: UKF estimate RMSE, {name}", paper_est, ours, reading,
                       f"{100 * (ours / paper_est - 1):+.0f} %; the duration is not given "
                       "(RMSE over the first second)")
        report.compare(f"Table 4: measurement RMSE, {name}", paper_meas,
                       float(f["measurement_rmse"][i]), reading, "the paper's R (std)")
    rmse = f["param_rmse_after_0.1s"]["ukf"]
    for j, name in enumerate(("mu", "M0")):
        report.compare(f"Table 5: UKF parameter RMSE, {name}", PAPER_TABLE5["UKF"][name],
                       float(rmse[j]), reading + "; RMSE over t ≥ 0.1 s",
                       "reproduced in magnitude" if rmse[j] <= 2 * PAPER_TABLE5["UKF"][name]
                       else "the Monte-Carlo spread with the paper's noise is larger than the "
                       "paper's RMSE: not reachable in this time (notes)")
    for j, name in enumerate(("mu", "M0")):
        err = f["lsm"]["backward"][:, j] - TRUE[name]
        report.compare(f"Table 5: LSM error, {name}", PAPER_TABLE5["LSM"][name],
                       float(err.mean()), reading + "; backward-difference accelerations",
                       "errors-in-variables bias: its size depends on the unreported "
                       "trajectory (notes)" if name == "M0" else
                       ("within" if abs(err.mean() - PAPER_TABLE5["LSM"][name]) <= 2 * err.std()
                        else "outside") + f" twice the run-to-run spread (± {err.std():.3f})")
    conv = f["convergence"]
    at_half = f["params_at_half_second"]["ukf"].mean(axis=0)
    rel = 100 * (at_half - np.array([TRUE["mu"], TRUE["M0"]])) / 0.2
    report.compare("§5 claim: estimated parameters within 3 %", "< 3 %",
                   f"mean error at 0.5 s: μ {rel[0]:+.2f} %, M0 {rel[1]:+.2f} %; runs within "
                   f"3 % at 1 s: μ {100 * conv['mu']['runs_within_at_end']:.0f} %, M0 "
                   f"{100 * conv['M0']['runs_within_at_end']:.0f} %", reading,
                   ("holds for the Monte-Carlo mean" if np.all(np.abs(rel) < 3) else
                    "the Monte-Carlo mean is not within 3 % for every parameter")
                   + ("; single runs scatter more than 3 %" if min(
                       conv[k]["runs_within_at_end"] for k in conv) < 1 else ""))
    settle = {k: ("not within 1 s" if v["settle_time"] is None else f"{v['settle_time']:.3f} s")
              for k, v in conv.items()}
    report.compare("§5 claim: converged within 100 samples (0.1 s)", "0.1 s",
                   f"mean estimate within 3 % from μ {settle['mu']}, M0 {settle['M0']}; runs "
                   f"within 3 % at 0.1 s: μ {100 * conv['mu']['runs_within_at_0.1s']:.0f} %, "
                   f"M0 {100 * conv['M0']['runs_within_at_0.1s']:.0f} %", reading,
                   ", ".join(f"{'reproduced' if _settled_by(conv[k], 0.1) else 'not reproduced'}"
                             f" for {k}" for k in conv)
                   + " (UKF from a zero estimate, P0 = I6, as the paper)")


def plot(report: Report, out_dir: str | Path) -> None:
    """Figs 3–5 of paper 003: states, parameter estimates and parameter errors."""
    from ._plotting import new_figure, save

    s = report.figures["series"]
    t = s["t"]
    names = ("x (m)", "ẋ (m/s)", "θ (rad)", "θ̇ (rad/s)")
    fig, ax = new_figure(4, 1, height=1.9, sharex=True)
    for i, a in enumerate(ax):
        a.plot(t, s["Y"][:, i], ".", color="0.75", ms=1.5, label="measured")
        a.plot(t, s["X"][:, i], "k--", lw=1.0, label="exact")
        a.plot(t, s["ukf"][:, i], "C0-.", lw=1.0, label="UKF")
        a.set_ylabel(names[i])
    ax[0].legend(fontsize=7, ncol=3)
    ax[-1].set_xlabel("t (s)")
    ax[0].set_title("Paper 003 Fig. 3: estimated states (run 0)")
    save(report, out_dir, "fig3_states", fig, "Paper 003 Fig. 3: estimated states")
    for fig_no, errors in ((4, False), (5, True)):
        fig, ax = new_figure(2, 1, height=2.4, sharex=True)
        for j, (a, name) in enumerate(zip(ax, ("mu", "M0"), strict=True)):
            truth = TRUE[name]
            shift = truth if errors else 0.0
            mean, sd = s["param_mean"][:, j] - shift, s["param_std"][:, j]
            a.plot(t, s["ukf"][:, 4 + j] - shift, "C0-.", lw=1.0, label="UKF, run 0")
            a.plot(t, mean, "C1", lw=1.0, label="UKF, Monte-Carlo mean ± std")
            a.fill_between(t, mean - sd, mean + sd, color="C1", alpha=0.25)
            a.axhline(0.0 if errors else truth, color="k", ls="--", lw=0.8,
                      label="zero error" if errors else "true value")
            a.set_ylim(-0.1 if errors else 0.1, 0.1 if errors else 0.3)
            a.set_ylabel(f"{name} error" if errors else name)
        ax[0].legend(fontsize=7)
        ax[-1].set_xlabel("t (s)")
        ax[0].set_title(f"Paper 003 Fig. {fig_no}: "
                        + ("errors of the estimated parameters" if errors
                           else "estimated μ and M0"))
        save(report, out_dir, f"fig{fig_no}_{'param_errors' if errors else 'params'}", fig,
             f"Paper 003 Fig. {fig_no}: " + ("parameter errors" if errors else "parameters"))


def _energy_for_bias(bias: float, J: float, sigma2: float) -> float:
    """Solve the bias law for ``E[θ̇²]``: ``(M0 E − J σ²/dt)/(E + σ²) = M0 + bias``."""
    return (J * sigma2 / DT + (TRUE["M0"] + bias) * sigma2) / (-bias)


def _mean_square_rate(episodes: Episodes) -> float:
    """``E[θ̇²]`` of the true trajectory."""
    return float(np.mean(episodes.X[1:, :, 3] ** 2))


def _hinge_inertia(dynamics: object) -> float:
    """``J = I_c + m2 l²``, the pendulum's inertia about the hinge."""
    return dynamics.I_c + dynamics.m2 * dynamics.l ** 2
