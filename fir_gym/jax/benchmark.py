"""``fir-gym benchmark-controllers --backend jax``: the controller benchmark's learned kinds
that the JAX backend has, every seed of a (plant, kind) in one compiled program.

The plan is the SB3 benchmark's (:data:`fir_gym.training.benchmark.PLANTS`: the plants'
episode settings and training steps, :data:`~fir_gym.training.benchmark.SEEDS` seeds,
:data:`~fir_gym.training.benchmark.EPISODES` evaluation episodes, the kinds' options such as
the windowed filters' horizon), its kinds per plant the SB3 benchmark's
(:func:`fir_gym.training.benchmark.chosen_kinds`: those of the robustness benchmark's
learned grid on the nominal plant, the rows of README.md's benchmark table) that the JAX
backend trains on the plant (:data:`fir_gym.jax.train.SUPPORTED`) — all of them; PPO with the
shipped recipe (:func:`fir_gym.jax.train.train`; RecurrentPPO's for ``recurrent``,
:mod:`fir_gym.jax.recurrent_ppo`). Each row reports the IQM of the seeds'
mean returns and its 95 % interval from the same bootstrap as the SB3 benchmark's
(:func:`fir_gym.training.stats.episode_bootstrap`: episodes, then seeds), on the JAX env's
own episode draws and on the numpy env's SB3 episodes (:func:`play_in_numpy_env`), the compile
and training times and the training rate. Given an SB3 benchmark (``--compare-with``: its
folder, or a Markdown file of its tables such as its ``BENCHMARK.md`` or README.md's
benchmark section), each row stands beside the SB3 row of the same plant and kind, with the
verdict: is the numpy-env IQM inside the SB3 interval?

The classical ``lqg`` row (the LQR of the plant's nominal model on the EKF's estimate, as the
SB3 benchmark runs it: nothing to train) is the numpy env's own —
:func:`fir_gym.training.evaluation.evaluate` on the same episodes — so the table has every
kind of README.md's; that row has no JAX-env column, no times.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from fir_gym.robustness.plan import EVAL_SEED
from fir_gym.tables import format_table
from fir_gym.training.benchmark import EPISODES, PLANTS, QUICK, SEEDS, chosen_kinds
from fir_gym.training.stats import episode_bootstrap, iqm, percentile_interval

from .registry import PLANTS as JAX_PLANTS
from .train import SUPPORTED, save, train

#: the learned kinds the JAX backend trains, on any plant (each plant has its subset:
#: :data:`fir_gym.jax.train.SUPPORTED`)
JAX_KINDS = tuple(dict.fromkeys(kind for kinds in SUPPORTED.values() for kind in kinds))


def chosen_plants(plants: list[str] | None = None) -> list[str]:
    """``plants`` checked (default: the benchmark's plants the JAX backend has); a
    ``ValueError`` naming them otherwise."""
    chosen = list(plants) if plants else [p for p in PLANTS if p in JAX_PLANTS]
    for env_id in chosen:
        if env_id not in PLANTS or env_id not in JAX_PLANTS:
            raise ValueError(f"plants must be among the benchmark's plants the jax backend "
                             f"has ({', '.join(p for p in PLANTS if p in JAX_PLANTS)}); got "
                             f"{env_id!r}")
    return chosen


def benchmark_plan(*, quick: bool = False, seeds: int | None = None,
                   plants: list[str] | None = None, kinds: list[str] | None = None
                   ) -> list[dict[str, Any]]:
    """Every (plant, kind) job: ``env_id``, ``kind``, ``seeds``, ``steps``, ``env_kwargs``,
    ``kind_kwargs`` (the SB3 benchmark's, e.g. the windowed filters' horizon), ``episodes``.
    Refuses a plant the JAX backend or the benchmark does not have."""
    chosen = chosen_plants(plants)
    unknown = sorted(set(kinds or ()) - {*JAX_KINDS, "lqg"})
    if unknown:
        raise ValueError(f"kinds must be among {', '.join((*JAX_KINDS, 'lqg'))}; got "
                         f"{', '.join(unknown)}")
    n_seeds = seeds or (QUICK["seeds"] if quick else SEEDS)
    jobs = []
    for env_id in chosen:
        spec = PLANTS[env_id]
        for kind in [k for k in chosen_kinds(env_id, kinds) if k in SUPPORTED[env_id]]:
            jobs.append({"env_id": env_id, "kind": kind, "seeds": n_seeds,
                         "steps": QUICK["steps"] if quick else spec["steps"],
                         "env_kwargs": dict(spec["env_kwargs"]),
                         "kind_kwargs": dict(spec["kind_kwargs"].get(kind, {})),
                         "episodes": QUICK["episodes"] if quick else EPISODES})
    return jobs


def run_benchmark(out: str | Path, *, quick: bool = False, seeds: int | None = None,
                  plants: list[str] | None = None, kinds: list[str] | None = None,
                  compare_with: str | Path | None = None, progress: bool = True,
                  jobs: int | None = None) -> dict[str, Any]:
    """Train every job of :func:`benchmark_plan`, save each run folder under ``out``, and
    write ``out/results.json`` and ``out/BENCHMARK.md``; the report dict.

    ``jobs``: worker processes (default: none, every row in this process). With ``jobs``
    > 1 the rows are handed to a pool of that many processes (joblib's, as the SB3
    backend's ``--backend joblib``), the costliest first (:func:`row_cost`), each row still
    every seed in one compiled program: on a CPU one XLA program of these small networks
    keeps about one core busy and vmapping seeds does not multiply its rate, so the cores
    are used by running rows side by side. The rows and their numbers are the same as in
    one process — every row is its own program and its own seeds (``tests/jax/
    test_benchmark.py``); only the times differ."""
    sb3 = _sb3_tables(compare_with) if compare_with else None
    out = Path(out)
    plan = benchmark_plan(quick=quick, seeds=seeds, plants=plants, kinds=kinds)
    classical = chosen_plants(plants) if kinds is None or "lqg" in kinds else []
    episodes = QUICK["episodes"] if quick else EPISODES
    tasks = [*[("learned", job, out) for job in plan],
             *[("lqg", {"env_id": env_id, "kind": "lqg", "episodes": episodes}, out)
               for env_id in classical]]
    start = time.perf_counter()
    rows = _run_rows(tasks, jobs, progress)
    tables = summarise(rows, sb3)
    report = {"backend": "jax", "quick": quick, "seconds": time.perf_counter() - start,
              "jobs": jobs or 1,
              "compare_with": str(compare_with) if compare_with else None, "tables": tables}
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "BENCHMARK.md").write_text(markdown(report) + "\n")
    return report


def row_cost(task: tuple[str, dict[str, Any], Path]) -> float:
    """A row's expected cost, to hand the costliest rows out first: its env-steps times
    the seeds, five times for ``recurrent`` (RecurrentPPO's two LSTMs: Orbit-v0's
    benchmark rows in one process trained in 78 s against 11–16 s for each PPO row,
    docs/jax.md), a token for the LQG row (nothing trained). Only the order matters."""
    what, job, _ = task
    if what == "lqg":
        return 1.0
    return job["steps"] * job["seeds"] * (5.0 if job["kind"] == "recurrent" else 1.0)


def run_row(task: tuple[str, dict[str, Any], Path]) -> dict[str, Any]:
    """One row of the report: a learned job trained (:func:`fir_gym.jax.train.train`),
    saved under ``out/<plant>/<kind>`` and played in the numpy env
    (:func:`play_in_numpy_env`), or the plant's :func:`lqg_row`. A module-level function of
    one argument, for the worker pool."""
    what, job, out = task
    if what == "lqg":
        return lqg_row(job["env_id"], job["episodes"])
    result = train(job["env_id"], job["kind"], job["seeds"], steps=job["steps"],
                   env_kwargs=job["env_kwargs"], kind_kwargs=job["kind_kwargs"],
                   episodes=job["episodes"])
    save(result, Path(out) / job["env_id"].split("/")[-1] / job["kind"])
    return {"env_id": job["env_id"], "kind": job["kind"], "seeds": result.seeds,
            "episode_returns": result.final_returns,
            "numpy_returns": play_in_numpy_env(result, job["episodes"]),
            "compile_seconds": result.compile_seconds,
            "train_seconds": result.train_seconds,
            "steps_trained": result.steps_trained,
            "steps_per_second": result.steps_trained * len(result.seeds)
            / result.train_seconds}


def _run_rows(tasks: list[tuple[str, dict[str, Any], Path]], jobs: int | None,
              progress: bool) -> list[dict[str, Any]]:
    """:func:`run_row` of every task, in ``tasks``' order: in this process, or handed to
    ``jobs`` worker processes the costliest first (:func:`row_cost`; so that no worker is
    left with a long row at the end, as the robustness benchmark orders its tasks)."""
    from fir_gym.scenarios.runner import Runner

    order = sorted(range(len(tasks)), key=lambda i: -row_cost(tasks[i]))
    parallel = bool(jobs and jobs > 1)
    with Runner("joblib" if parallel else "serial", jobs=jobs if parallel else None,
                progress=progress) as runner:
        done = runner.map(run_row, [tasks[i] for i in order],
                          desc="benchmark-controllers (jax)")
    rows: list[dict[str, Any]] = [{} for _ in tasks]
    for i, row in zip(order, done, strict=True):
        rows[i] = row
    return rows


def lqg_row(env_id: str, episodes: int, seed: int = EVAL_SEED) -> dict[str, Any]:
    """The classical ``lqg`` row of ``env_id``: :func:`fir_gym.training.evaluation.evaluate`
    of the SB3 benchmark's LQG configuration (one run, seed 0) on the numpy env's episodes
    ``seed + i``; no JAX-env returns, nothing trained."""
    from fir_gym.training.compare import make_configs
    from fir_gym.training.evaluation import evaluate

    config = make_configs(env_id, ["lqg"], [0], env_kwargs=PLANTS[env_id]["env_kwargs"])[0]
    result = evaluate(config, episodes=episodes, seed=seed)
    return {"env_id": env_id, "kind": "lqg", "seeds": [0], "episode_returns": None,
            "numpy_returns": [list(map(float, result.returns))], "compile_seconds": 0.0,
            "train_seconds": 0.0, "steps_trained": 0, "steps_per_second": None}


def play_in_numpy_env(result: Any, episodes: int, seed: int = EVAL_SEED
                      ) -> list[list[float]]:
    """Each trained seed's deterministic policy played in the *numpy* env on the SB3
    evaluation's episodes (episode ``i`` is the one a single env — ``make_single_env``, as
    ``fir-gym evaluate`` and the SB3 benchmark build it — plays from ``reset(seed=seed +
    i)``): ``[seed][episode]`` raw returns.

    ``result``: a :class:`fir_gym.jax.train.JaxTraining` with its train state — just trained
    (:func:`fir_gym.jax.train.train`) or read from a run folder
    (:func:`fir_gym.jax.train.load`); the plant's keywords are ``result.env_kwargs``, the
    kind's options ``result.kind_kwargs``. The policy acts on
    the observation through the run's final normalisation statistics, its Gaussian's mean
    clipped to the action box (:meth:`fir_gym.jax.train.Policy.mean_action`). The JAX and
    the numpy plants agree given the same noise (the parity tests), so these returns differ
    from the SB3 backend's only by the controllers — the same episodes, not merely the same
    distribution.

    A seed's episodes are played side by side — the robustness benchmark's
    :func:`fir_gym.robustness.closed_loop.play` on a ``SyncVectorEnv`` of those single envs
    (sub-env ``i`` reset with ``seed`` plays episode ``seed + i``) — the policy acting on the
    batch of their observations in one call, each row as a batch of one
    (:class:`~fir_gym.jax.policy.JaxPolicy`'s ``rowwise``): the returns are, bit for bit,
    those of the episodes played one at a time (``tests/jax/test_run_folder.py``), with a
    twentieth of the policy's calls. (The plants' native vector envs play the same episodes
    too, but CarrierMotion-v0's and PendulumSlider-v0's batched arithmetic differs from the
    single env's in the last bits.)"""
    import gymnasium as gym

    from fir_gym.robustness.closed_loop import play
    from fir_gym.training.kinds import recipe
    from fir_gym.training.vec_env import make_single_env

    from .policy import JaxPolicy

    kwargs = {**recipe(result.kind, result.kind_kwargs).kwargs(), **result.env_kwargs}
    env = gym.vector.SyncVectorEnv([lambda: make_single_env(result.env_id, **kwargs)
                                    for _ in range(episodes)])
    try:
        return [play(env, policy, seed).returns.tolist()
                for policy in JaxPolicy.every_seed(result, rowwise=True)]
    finally:
        env.close()


def _sb3_tables(source: str | Path) -> dict[str, dict[str, dict[str, Any]]]:
    """The SB3 benchmark's rows by plant and kind: from a ``benchmark-controllers`` folder's
    ``results.json``, or from a Markdown file with its tables (the folder's
    ``BENCHMARK.md``, or README.md's nominal cell of the robustness benchmark; see
    :func:`markdown_tables`)."""
    path = Path(source)
    if path.is_file() and path.suffix == ".md":
        tables = markdown_tables(path.read_text(encoding="utf-8"))
        if not tables:
            raise ValueError(f"--compare-with {source} has no benchmark table (a plant's "
                             "heading, then rows of kind | seeds | IQM return [95% CI])")
        return tables
    if not (path / "results.json").is_file():
        raise ValueError(f"--compare-with {source} is neither a benchmark-controllers folder "
                         "(it has no results.json) nor a Markdown file of its tables")
    data = json.loads((path / "results.json").read_text())
    return {env_id: {r["kind"]: r for r in table}
            for env_id, table in data.get("tables", {}).items()}


def markdown_tables(text: str) -> dict[str, dict[str, dict[str, Any]]]:
    """The rows ``kind | seeds | IQM [low, high] | ...`` of the benchmark tables in ``text``
    by plant (the plant named by the last ``## fir_gym/...`` or ``*fir_gym/...*`` line
    above): ``{"iqm", "low", "high", "seeds"}`` per kind. Where the text marks its
    benchmark section (README.md's ``<!-- benchmark:start -->`` … ``<!-- benchmark:end
    -->``), only that section is read."""
    import re

    start, end = "<!-- benchmark:start -->", "<!-- benchmark:end -->"
    if start in text:
        text = text.split(start, 1)[1].split(end, 1)[0]

    heading = re.compile(r"^(?:#+\s*|\*)(fir_gym/[\w.-]+)\*?\s*$")
    row = re.compile(r"^\|\s*([\w+-]+)\s*\|\s*(\d+)\s*\|\s*(-?[\d.e+]+)\s*\[(-?[\d.e+]+),"
                     r"\s*(-?[\d.e+]+)\]\s*\|")
    tables: dict[str, dict[str, dict[str, Any]]] = {}
    plant = None
    for line in text.splitlines():
        found = heading.match(line.strip())
        if found:
            plant = found.group(1)
            continue
        cells = row.match(line.strip())
        if plant and cells:
            kind, seeds, centre, low, high = cells.groups()
            tables.setdefault(plant, {})[kind] = {
                "iqm": float(centre), "low": float(low), "high": float(high),
                "seeds": int(seeds)}
    return tables


def summarise(rows: list[dict[str, Any]], sb3: dict[str, dict[str, dict[str, Any]]] | None
              ) -> dict[str, list[dict[str, Any]]]:
    """Per plant, one row per kind: the IQM over seeds and its 95 % interval (episodes, then
    seeds, resampled), times, and the SB3 row beside it where given."""
    tables: dict[str, list[dict[str, Any]]] = {}
    for env_id in dict.fromkeys(r["env_id"] for r in rows):
        mine = [r for r in rows if r["env_id"] == env_id]
        draws = episode_bootstrap({r["kind"]: r["episode_returns"] for r in mine
                                   if r["episode_returns"] is not None})
        numpy_draws = episode_bootstrap({r["kind"]: r["numpy_returns"] for r in mine})
        table = []
        for r in mine:
            centre = low = high = None               # the classical row: no JAX env
            if r["episode_returns"] is not None:
                centre = iqm([sum(e) / len(e) for e in r["episode_returns"]])
                low, high = percentile_interval(draws[r["kind"]])
            on_numpy = iqm([sum(e) / len(e) for e in r["numpy_returns"]])
            numpy_low, numpy_high = percentile_interval(numpy_draws[r["kind"]])
            row = {**r, "iqm": centre, "low": low, "high": high, "numpy_iqm": on_numpy,
                   "numpy_low": numpy_low, "numpy_high": numpy_high}
            other = (sb3 or {}).get(env_id, {}).get(r["kind"])
            if other is not None:
                row.update(sb3_iqm=other["iqm"], sb3_low=other["low"], sb3_high=other["high"],
                           sb3_seeds=other.get("seeds"),
                           inside=bool(other["low"] <= on_numpy <= other["high"]))
            table.append(row)
        tables[env_id] = table
    return tables


def markdown(report: dict[str, Any]) -> str:
    """The report as Markdown: one table per plant."""
    compare = report.get("compare_with")
    parts = ["**Benchmark: controllers on estimates, JAX backend** (PPO with the shipped "
             "recipe, every seed of a plant and kind in one compiled program; IQM of the "
             "seeds' mean returns over the evaluation episodes, 95 % interval resampling "
             "episodes then seeds" + ("; `--quick`: the numbers mean nothing" if
                                      report.get("quick") else "") + "). Each trained policy "
             "is evaluated twice: in the JAX env (its own episode draws) and in the numpy env "
             "on the SB3 benchmark's episodes (seeds 10000 + i) — the same plant (parity "
             "tests) and the same draws as the SB3 rows, so only the controllers differ."]
    if compare:
        parts.append(f"Beside it, the stable-baselines3 backend's row of the same plant and "
                     f"kind from `{compare}`; *inside*: the numpy-env IQM lies in the SB3 "
                     "interval.")
    for env_id, table in report["tables"].items():
        headers = ["kind", "seeds", "IQM return, JAX env [95% CI]",
                   "IQM return, numpy env [95% CI]", "compile s", "train s", "env-steps/s"]
        if compare:
            headers += ["SB3 IQM [95% CI]", "inside"]
        lines = []
        for r in table:
            learned = r["iqm"] is not None
            line = [r["kind"], len(r["seeds"]),
                    f"{r['iqm']:.4g} [{r['low']:.4g}, {r['high']:.4g}]" if learned else "—",
                    f"{r['numpy_iqm']:.4g} [{r['numpy_low']:.4g}, {r['numpy_high']:.4g}]",
                    f"{r['compile_seconds']:.1f}" if learned else "—",
                    f"{r['train_seconds']:.1f}" if learned else "—",
                    f"{r['steps_per_second']:.3g}" if learned else "—"]
            if compare:
                line += ([f"{r['sb3_iqm']:.4g} [{r['sb3_low']:.4g}, {r['sb3_high']:.4g}]",
                          "yes" if r["inside"] else "no"] if "sb3_iqm" in r else ["—", "—"])
            lines.append(line)
        parts.append(f"*{env_id}*\n\n" + format_table(headers, lines, markdown=True))
    parts.append(time_summary(report))
    return "\n\n".join(parts)


def time_summary(report: dict[str, Any]) -> str:
    """Where the run's time went, from its rows: the learned rows' compilation (or loading
    from the cache) and training summed, and the least wall time any schedule of them on
    the run's worker processes could take — the bound docs/jax.md ("The ceiling on this
    CPU") reads off the five-plant runs; the rest of the workers' time went to the
    evaluations in the numpy env, the LQG rows, starting the workers and waiting at the
    end."""
    rows = [r for table in report["tables"].values() for r in table if r["iqm"] is not None]
    compiling = sum(r["compile_seconds"] for r in rows)
    training = sum(r["train_seconds"] for r in rows)
    jobs = report.get("jobs") or 1
    seconds = report["seconds"]
    where = "in one process" if jobs == 1 else f"on {jobs} worker processes"
    rest = max(seconds * jobs - compiling - training, 0.0)
    of = "" if jobs == 1 else f" of the {seconds * jobs:.0f} worker-seconds"
    learned = f"{len(rows)} learned row" + ("" if len(rows) == 1 else "s")
    return (f"Whole run: {seconds:.0f} s {where}, compilation included. Its {learned} "
            f"compiled (or loaded from the cache) for {compiling:.0f} s and "
            f"trained for {training:.0f} s in all: no schedule {where} does that in less "
            f"than {(compiling + training) / jobs:.0f} s. The other {rest:.0f} s{of} went "
            "to the evaluations in the numpy env, the LQG rows, starting and waiting.")
