"""``fir-gym benchmark-controllers``: the published comparison of controllers on estimates.

All five plants — Orbit-v0 (a saddle held by thrust, position measured),
UncertainOscillator-v0 (a damped oscillator regulated to a setpoint, its damping a state),
CarrierMotion-v0 (deck-motion compensation: predict the deck one interval ahead),
VanDerPol-v0 (an unstable focus under heavy process and measurement noise) and
PendulumSlider-v0 (MuJoCo, every state measured with noise), with the episode settings of
the robustness benchmark's plan — and on each the kinds of :func:`plant_kinds`: PPO on the
``true`` state, the raw ``measurement``, a ``measurement-stack`` (the last K
measurements and actions), a ``recurrent`` policy (RecurrentPPO on the measurements),
PPO on the estimate of each of the plant's learned estimators in the robustness plan
(``ekf``, ``ukf`` and ``efir``; on the linear CarrierMotion-v0 ``kf``, ``ukf``, ``fir`` and
``ufir``) — the rows of README.md's table, and the JAX backend's plan — and the classical
``lqg`` (the LQR of the nominal model on the EKF's estimate; nothing trained). :data:`SEEDS`
seeds per learned kind, every run evaluated on the same :data:`EPISODES` episodes.

The table gives, per plant and kind, the interquartile mean (IQM) of the per-seed
mean returns with a 95 % bootstrap interval over the seeds and the shared evaluation
episodes (:func:`.stats.episode_bootstrap`: the LQG, deterministic given its seed, runs
once, and its interval comes from its episodes), the same normalised by the true-state
kind (``IQM(true) / IQM(kind)``: returns are costs, so 1 matches the true-state
controller and 0.5 costs twice as much), the closed-loop estimation RMSE per state and
the ANEES. :func:`answers` states, from those numbers (kinds compared by the interval
of their paired difference on the same bootstrap draws),
whether an estimate-fed controller matches the true-state one, whether a filter beats
memory and whether LQG beats the learned controllers. Learning curves per plant go to
``OUT/figures``.

Budget: the steps per plant (:data:`PLANTS`) were chosen so that three plants' run, 108
jobs (3 plants × (7 learned kinds × 5 seeds + the LQG)), took about 90 minutes on 2 cores
(``--backend joblib``); all five plants' 185 jobs take about five thirds of that.
``--quick`` (2 seeds, a few
thousand steps, 2 evaluation episodes) checks the whole pipeline in under 3 minutes
and its numbers mean nothing.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fir_gym.robustness.plan import PLAIN_KINDS
from fir_gym.robustness.plan import PLANTS as ROBUSTNESS_PLANTS
from fir_gym.tables import format_table

from .compare import make_configs, run_job, validate
from .curves import plot_learning_curves
from .stats import episode_bootstrap, iqm, percentile_interval

#: differences below this fraction of the returns count as a match (the true-state and LQG
#: controllers converge to the same saturated control on Orbit-v0: their intervals are
#: points 0.02 % apart, "apart" but not a difference anyone would act on)
MATCH = 0.01

#: per plant: the env options of the benchmark, the training steps and the kinds' options —
#: the robustness benchmark's plan (:data:`fir_gym.robustness.plan.PLANTS`), so that the two
#: benchmarks train the same controllers on the nominal plant
PLANTS: dict[str, dict[str, Any]] = {
    env_id: {"env_kwargs": dict(plan.env_kwargs), "steps": plan.steps,
             "kind_kwargs": {k: dict(v) for k, v in plan.estimator_kwargs.items()}}
    for env_id, plan in ROBUSTNESS_PLANTS.items()}
MEMORY = ("measurement-stack", "recurrent")
SEEDS = 5
EPISODES = 20
QUICK = {"seeds": 2, "steps": 2048, "episodes": 2}


def plant_kinds(env_id: str) -> tuple[str, ...]:
    """The benchmark's kinds on a plant, in table order: :data:`~fir_gym.robustness.plan.
    PLAIN_KINDS`, the plant's learned estimators in the robustness plan, and ``lqg``."""
    return (*PLAIN_KINDS, *ROBUSTNESS_PLANTS[env_id].learned_estimators, "lqg")


def chosen_kinds(env_id: str, kinds: Sequence[str] | None = None) -> list[str]:
    """The rows of a plant: :func:`plant_kinds`, only those in ``kinds`` when given, in table
    order (both backends' plans choose their rows by it)."""
    return [k for k in plant_kinds(env_id) if kinds is None or k in kinds]


#: every kind of some plant, in table order
KINDS = tuple(dict.fromkeys(k for env_id in PLANTS for k in plant_kinds(env_id) if k != "lqg")
              ) + ("lqg",)


def benchmark_jobs(out: Path, *, quick: bool = False, seeds: int | None = None,
                   plants: Sequence[str] | None = None, kinds: Sequence[str] | None = None
                   ) -> list[dict[str, Any]]:
    """Every (plant, kind, seed) job, checked (the classical kinds run once: seed 0).

    ``kinds``: only these rows (each a kind of :data:`KINDS`; a plant without one of them,
    such as ``ekf`` on CarrierMotion-v0, simply has no such row)."""
    n_seeds = seeds or (QUICK["seeds"] if quick else SEEDS)
    episodes = QUICK["episodes"] if quick else EPISODES
    unknown = sorted(set(kinds or ()) - set(KINDS))
    if unknown:
        raise ValueError(f"kinds must be among {', '.join(KINDS)}; got {', '.join(unknown)}")
    jobs = []
    for env_id in plants or PLANTS:
        if env_id not in PLANTS:
            raise ValueError(f"unknown benchmark plant {env_id!r}; plants are "
                             f"{', '.join(PLANTS)}")
        spec = PLANTS[env_id]
        steps = QUICK["steps"] if quick else spec["steps"]
        chosen = chosen_kinds(env_id, kinds)
        learned = [k for k in chosen if k != "lqg"]
        configs = make_configs(env_id, learned, range(n_seeds), steps=steps,
                               kind_kwargs={k: v for k, v in spec["kind_kwargs"].items()
                                            if k in learned},
                               env_kwargs=spec["env_kwargs"]) if learned else []
        if "lqg" in chosen:
            configs += make_configs(env_id, ["lqg"], [0], env_kwargs=spec["env_kwargs"])
        validate(configs)
        folder = out / env_id.split("/")[-1]
        jobs += [{"config": c, "run_dir": str(folder / f"{c.observation_kind}-seed{c.seed}"),
                  "episodes": episodes, "eval_seed": 10_000, "resume": True} for c in configs]
    if not jobs:
        raise ValueError(f"kinds {', '.join(kinds or ())}: no row on the plants chosen "
                         f"({', '.join(plants or PLANTS)})")
    return jobs


def run_benchmark(out: str | Path, *, quick: bool = False, runner: Any = None,
                  seeds: int | None = None, plants: Sequence[str] | None = None,
                  kinds: Sequence[str] | None = None) -> dict[str, Any]:
    """Run every job (of ``kinds`` only, when given: :func:`benchmark_jobs`), then write
    ``OUT/BENCHMARK.md``, ``OUT/results.json`` and figures."""
    from fir_gym.scenarios.runner import SERIAL

    out = Path(out)
    start = time.perf_counter()
    jobs = benchmark_jobs(out, quick=quick, seeds=seeds, plants=plants, kinds=kinds)
    results = (runner or SERIAL).map(run_job, jobs, desc="benchmark-controllers")
    seconds = time.perf_counter() - start
    tables = summarise(results)
    reused = sum(bool(r.get("reused")) for r in results)
    report = {"quick": quick, "seconds": seconds, "reused": reused, "jobs": len(results),
              "tables": tables, "answers": answers(tables), "results": results}
    out.mkdir(parents=True, exist_ok=True)
    figures = out / "figures"
    figures.mkdir(exist_ok=True)
    curves: dict[str, bool] = {}
    for env_id in tables:
        folder = out / env_id.split("/")[-1]
        runs = {k: sorted(folder.glob(f"{k}-seed*")) for k in plant_kinds(env_id)
                if k != "lqg"}
        written = plot_learning_curves(
            runs, figures / f"{env_id.split('/')[-1]}_learning_curves.png", title=env_id)
        curves[env_id] = written is not None
    report["learning_curves"] = curves
    (out / "results.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "BENCHMARK.md").write_text(markdown(report) + "\n")
    return report


def summarise(results: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Per plant, one row per kind: IQM and interval, normalised IQM, RMSE, ANEES.

    The intervals come from :func:`~.stats.episode_bootstrap`: each resample draws the
    shared evaluation episodes, then each kind's runs, so the LQG (one run: it is
    deterministic given its seed) gets an interval from its episodes, and a learned kind
    one from its seeds and episodes together. Each row keeps its runs' episode returns
    (``episode_returns``), from which :func:`answers` compares kinds on the same draws.
    """
    tables: dict[str, list[dict[str, Any]]] = {}
    for env_id in dict.fromkeys(r["config"]["env_id"] for r in results):
        rows = [r for r in results if r["config"]["env_id"] == env_id]
        per_kind = {k: [r for r in rows if r["kind"] == k] for k in plant_kinds(env_id)}
        per_kind = {k: runs for k, runs in per_kind.items() if runs}
        returns = {k: [list(map(float, r["returns"])) for r in runs]
                   for k, runs in per_kind.items()}
        draws = episode_bootstrap(returns)
        centres = {k: iqm([sum(e) / len(e) for e in returns[k]]) for k in per_kind}
        table = []
        for kind, runs in per_kind.items():
            low, high = percentile_interval(draws[kind])
            norm: tuple[float | None, float | None, float | None] = (None, None, None)
            if "true" in draws:
                ratio = draws["true"] / draws[kind]
                norm = (centres["true"] / centres[kind], *percentile_interval(ratio))
            rmse = [r["rmse"] for r in runs if r.get("rmse") is not None]
            anees = [r["anees"] for r in runs if r.get("anees") is not None]
            medians = [r["nees_median"] for r in runs if r.get("nees_median") is not None]
            in_band = [r["nees_in_band"] for r in runs if r.get("nees_in_band") is not None]
            table.append({
                "kind": kind, "seeds": len(runs), "episodes": len(returns[kind][0]),
                "iqm": centres[kind], "low": low, "high": high,
                "normalised": norm[0], "normalised_low": norm[1], "normalised_high": norm[2],
                "rmse": [sum(c) / len(c) for c in zip(*rmse, strict=True)] if rmse else None,
                "anees": sum(anees) / len(anees) if anees else None,
                "nees_median": sorted(medians)[len(medians) // 2] if medians else None,
                "nees_in_band": sum(in_band) / len(in_band) if in_band else None,
                "diverged_episodes": sum(r.get("diverged_episodes", 0) for r in runs),
                "episode_returns": returns[kind]})
        tables[env_id] = table
    return tables


def answers(tables: dict[str, list[dict[str, Any]]]) -> list[str]:
    """The three questions, answered per plant from the table's numbers."""
    out = []
    for env_id, table in tables.items():
        rows = {r["kind"]: r for r in table}
        draws = (episode_bootstrap({k: r["episode_returns"] for k, r in rows.items()})
                 if all("episode_returns" in r for r in table) else None)
        name = env_id.split("/")[-1]
        if "true" not in rows:
            continue
        best_filter = _best(rows, [k for k in rows if k not in (*PLAIN_KINDS, "lqg")])
        best_memory = _best(rows, MEMORY)
        learned = [k for k in rows if k not in ("lqg",)]
        best_learned = _best(rows, [k for k in learned if k != "true"])
        parts = []
        if best_filter:
            f = rows[best_filter]
            verdict = ("matches it (the interval contains 1)"
                       if f["normalised_low"] <= 1.0 <= f["normalised_high"] else
                       f"matches it within {MATCH:.0%}" if abs(f["normalised"] - 1.0) <= MATCH
                       else "falls short of it" if f["normalised_high"] < 1.0 else "beats it")
            parts.append(f"the best estimate-fed controller ({best_filter}) scores "
                         f"{f['normalised']:.2f} [{f['normalised_low']:.2f}, "
                         f"{f['normalised_high']:.2f}] of the true-state one and {verdict}")
        if best_filter and best_memory:
            verdict = _compare(rows, best_filter, best_memory, draws)
            parts.append(f"the best filter ({best_filter}) {verdict} the best memory "
                         f"baseline ({best_memory})")
        if "lqg" in rows and best_learned:
            parts.append(f"LQG {_compare(rows, 'lqg', best_learned, draws)} the best learned "
                         f"controller without the true state ({best_learned}), and "
                         f"{_compare(rows, 'lqg', 'true', draws)} PPO on the true state")
        out.append(f"{name}: " + "; ".join(parts) + ".")
    return out


def _best(rows: dict[str, dict[str, Any]], kinds: Sequence[str]) -> str | None:
    present = [k for k in kinds if k in rows]
    return max(present, key=lambda k: rows[k]["iqm"]) if present else None


def _compare(rows: dict[str, dict[str, Any]], a: str, b: str,
             draws: dict[str, Any] | None = None) -> str:
    """``matches`` (IQMs within :data:`MATCH` of each other), else ``beats``, ``loses to``
    or ``ties with``.

    With the bootstrap ``draws`` of :func:`~.stats.episode_bootstrap` the verdict is the
    95 % interval of the *paired* difference ``IQM(a) − IQM(b)`` (the same episode draws
    for both): a tie where it contains 0. Without them (a table of intervals only), two
    intervals that overlap are a tie.
    """
    ra, rb = rows[a], rows[b]
    values = f"{ra['iqm']:.4g} vs {rb['iqm']:.4g}"
    if abs(ra["iqm"] - rb["iqm"]) <= MATCH * max(abs(ra["iqm"]), abs(rb["iqm"])):
        return f"matches ({values}, within {MATCH:.0%})"
    if draws is not None:
        low, high = percentile_interval(draws[a] - draws[b])
        interval = f"paired difference [{low:.4g}, {high:.4g}]"
        if low > 0:
            return f"beats ({values}, {interval})"
        if high < 0:
            return f"loses to ({values}, {interval})"
        return f"ties with ({values}, {interval} contains 0)"
    if ra["low"] > rb["high"]:
        return f"beats ({values}, intervals apart)"
    if ra["high"] < rb["low"]:
        return f"loses to ({values}, intervals apart)"
    return f"ties with ({values}, intervals overlap)"


def markdown(report: dict[str, Any]) -> str:
    """The benchmark's tables and answers in Markdown."""
    lines = ["# Controllers on estimates: the benchmark", ""]
    if report.get("quick"):
        lines += ["**--quick run: tiny budgets, the numbers mean nothing.**", ""]
    for env_id, table in report["tables"].items():
        lines += [f"## {env_id}", ""]
        rows = []
        for r in table:
            norm = ("—" if r["normalised"] is None else
                    f"{r['normalised']:.2f} [{r['normalised_low']:.2f}, "
                    f"{r['normalised_high']:.2f}]")
            rmse = "—" if r["rmse"] is None else ", ".join(f"{v:.3g}" for v in r["rmse"])
            anees = "—" if r["anees"] is None else f"{r['anees']:.3g}"
            median = "—" if r.get("nees_median") is None else f"{r['nees_median']:.3g}"
            band = "—" if r.get("nees_in_band") is None else f"{r['nees_in_band']:.2f}"
            rows.append([r["kind"], r["seeds"], f"{r['iqm']:.4g} [{r['low']:.4g}, "
                         f"{r['high']:.4g}]", norm, rmse, median, band, anees])
        lines.append(format_table(["kind", "seeds", "IQM return [95% CI]",
                                   "normalised by true [95% CI]", "estimation RMSE per state",
                                   "NEES median / χ²'s", "in χ² band", "ANEES"], rows,
                                  markdown=True))
        episodes = max((r.get("episodes", 0) for r in table), default=0)
        if episodes:
            lines += ["", f"Intervals: 95 % bootstrap over the seeds and the {episodes} "
                          "evaluation episodes every kind shares (a one-seed kind: over its "
                          "episodes)."]
        if report.get("learning_curves", {}).get(env_id, True):
            lines += ["", f"![learning curves](figures/{env_id.split('/')[-1]}"
                          "_learning_curves.png)", ""]
        else:
            lines += ["", "No learning curves: no training episode finished in any run.", ""]
    lines += ["## Answers", ""] + [f"- {a}" for a in report["answers"]]
    wall = f"Wall time: {report['seconds'] / 60:.1f} min"
    if report.get("reused"):
        wall += (f" ({report['reused']} of {report['jobs']} jobs reused from an earlier run's "
                 "result.json: the time is not the benchmark's)")
    lines += ["", wall + "."]
    return "\n".join(lines)


def print_report(report: dict[str, Any]) -> None:
    print(markdown(report))
