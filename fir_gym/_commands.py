"""What each ``fir-gym`` subcommand does (the parser: :mod:`._cli_parser`; the dispatch and
the error handling: :mod:`.cli`).

Every heavy import (Gymnasium's plants, the estimators and numba, stable-baselines3 and
PyTorch, Dask, imageio) happens inside the command that needs it, so ``fir-gym --help``
and every subcommand's ``--help`` load none of them. A command reports a user mistake
by raising (``ValueError``, ``TypeError``, a missing extra's ``ModuleNotFoundError``);
:func:`fir_gym.cli.main` turns it into one line and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .tables import format_table


def cmd_list(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from . import ENV_IDS
    from .estimators import estimator_names

    rows = []
    for env_id in ENV_IDS:
        plant: Any = gym.make(env_id).unwrapped
        rows.append([env_id, gym.spec(env_id).max_episode_steps, ", ".join(plant.state_names),
                     ", ".join(plant.measurement_names), ", ".join(plant.action_names)])
    print(format_table(["environment", "max steps", "state", "measurement", "action"], rows))
    print()
    print("estimators:", ", ".join(estimator_names()) or "(none registered)")
    from .conditions import describe_conditions

    print()
    print("conditions (fir-gym benchmark-robustness --conditions; docs/robustness.md):")
    print(format_table(["condition", "strength", "benchmark strengths", "what it does"],
                       describe_conditions()))
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Run every experiment chosen. With ``--out``: write REPORT.md and its figures there and
    print the verdict counts per paper and the report's path; without: print the whole
    report, then the counts. Either way the command's wall and CPU time (its worker
    processes' included) end it, on stderr: never in the report, which stays the same
    bytes for the same seed."""
    from .scenarios.stopwatch import Stopwatch

    with Stopwatch() as watch:
        from .scenarios import SCENARIOS, episodes
        from .scenarios.figures import save_figures, with_figures
        from .scenarios.plan import execute
        from .scenarios.report import vocabulary
        from .scenarios.report_file import write_report
        from .scenarios.runner import Runner
        from .scenarios.summary import summary_text

        out = Path(args.out) if args.out else None
        papers = [p for group in (args.paper or []) for p in group]
        wanted = [name for name in SCENARIOS
                  if not papers or name.removeprefix("paper") in papers]
        # the runner first: a missing extra (--backend dask) fails before any work is done
        with Runner(args.backend, jobs=args.jobs, scheduler=args.scheduler,
                    progress=not args.no_progress) as runner:
            names = [f"fir_gym.scenarios.{name}" for name in wanted]
            drawing = ["fir_gym.scenarios.figures", "fir_gym.plotting"] if out else []
            # the workers start and import the scenarios (and the plotting) while this
            # process does the same: their start-up is off the critical path
            runner.start(["fir_gym.scenarios.episodes", *names, *drawing])
            if out:
                out.mkdir(parents=True, exist_ok=True)
            modules = [importlib.import_module(name) for name in names]
            plans = [m.plan(seed=args.seed, quick=args.quick, runs=args.runs) for m in modules]
            if out:  # each scenario's figures: a task of the runner once its report is final
                plans = [with_figures(p, name) for p, name in zip(plans, wanted, strict=True)]
            # every scenario's tasks in one pool of work: a follow-up stage goes out as soon
            # as its own stage is done, so the workers stay busy across stages and scenarios
            summaries, *done = execute([episodes.plan(seed=args.seed), *plans], runner,
                                       desc="reproduce")
        reports = [save_figures(d, out) for d in done] if out else done
        headers, rows = episodes.summary_rows(summaries)
        if out:
            path = write_report(out, reports, episodes_table=(headers, rows))
    if out:          # the report is in the file: the terminal gets its summary and path
        print(summary_text(reports, markdown=args.markdown))
        print(f"\nwrote {path}")
    else:
        print("Verdicts\n\n" + vocabulary(markdown=False) + "\n")
        print(f"Scripted episodes (one per environment, seed {args.seed})\n")
        print(format_table(headers, rows, markdown=args.markdown))
        for report in reports:
            print("\n" + report.to_text(markdown=args.markdown))
        print("\n" + summary_text(reports, markdown=args.markdown))
    print(watch.line("fir-gym reproduce"), file=sys.stderr)
    return 0


def cmd_speed(argv: list[str]) -> int:
    """``fir-gym speed ...`` (and its old name ``fir-gym bench ...``): every option goes to
    :func:`fir_gym.benchmarks.speed.main`, which has its own parser."""
    from .benchmarks import speed_parser

    speed_parser().parse_args(argv)          # --help and mistakes before the heavy imports
    from .benchmarks import speed

    return int(speed.main(argv) or 0)


@contextmanager
def working(label: str, *, enabled: bool = True) -> Iterator[None]:
    """``label`` and the seconds elapsed on stderr while the block runs (one line, redrawn
    each second on a terminal; printed once otherwise), for work that reports no progress
    of its own."""
    if not enabled:
        yield
        return
    start, done = time.monotonic(), threading.Event()
    tty = sys.stderr.isatty()

    def tick() -> None:
        while not done.wait(1.0):
            print(f"\r{label} … {time.monotonic() - start:.0f} s", end="", file=sys.stderr,
                  flush=True)

    if tty:
        thread = threading.Thread(target=tick, daemon=True)
        thread.start()
    else:
        print(f"{label} …", file=sys.stderr, flush=True)
    try:
        yield
    finally:
        done.set()
        if tty:
            thread.join()
            print(f"\r{label}: {time.monotonic() - start:.0f} s", file=sys.stderr, flush=True)


def check_estimator_options(kind_kwargs: dict[str, Any]) -> None:
    """The estimator kinds' options checked at the estimator boundary, before any work:
    an option the filter does not take is named with the ones it accepts and a hint
    (``nominal=`` for noise, the near miss), as ``gym.make`` would say it."""
    from .estimators import estimator_class, estimator_names
    from .estimators.errors import check_options

    names = estimator_names()
    for kind, options in kind_kwargs.items():
        if not isinstance(options, dict):
            continue                      # the kinds' own check names the format
        if kind in names:
            check_options(estimator_class(kind), options, label=kind)
        elif kind == "lqg" and options.get("estimator", "ekf") in names:
            name = options.get("estimator", "ekf")
            check_options(estimator_class(name), [k for k in options if k != "estimator"],
                          label=f"lqg's estimator {name}")


def cmd_train(args: argparse.Namespace) -> int:
    if args.backend == "jax":
        return train_jax(args)
    if args.seeds != 1:
        raise ValueError("--seeds trains several seeds in one program with --backend jax; "
                         "the sb3 backend trains one (--seed), compare-controllers several")
    check_estimator_options(args.kind_kwargs)
    from .training import RunConfig, evaluate, kind_options, train
    from .training.compare import validate

    options = kind_options(args.kind_kwargs, [args.estimator])[args.estimator]
    config = RunConfig(env_id=args.env, observation_kind=args.estimator, algo=args.algo,
                       steps=args.steps, seed=args.seed, n_envs=args.n_envs,
                       observation=args.observation, kind_kwargs=options,
                       env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs,
                       eval_freq=args.eval_freq, checkpoint_freq=args.checkpoint_freq,
                       tensorboard=args.tensorboard, hyperparams=args.hyperparams)
    validate([config])
    out = train(config, args.out, progress_bar=not args.no_progress, resume=args.resume)
    source = out if config.observation_kind not in ("lqg", "pid") else config
    with working(f"evaluating {args.episodes} episodes", enabled=not args.no_progress):
        result = evaluate(source, episodes=args.episodes)
    print(f"{args.env} observing {args.estimator}: return {result.mean:.4g} ± {result.std:.3g} "
          f"over {args.episodes} episodes; saved in {out}")
    return 0


def train_jax(args: argparse.Namespace) -> int:
    """``fir-gym train --backend jax``: :func:`fir_gym.jax.train.train` for every seed at
    once, the run folder written by :func:`fir_gym.jax.train.save`."""
    from ._extras import require

    require("jax", "gymnax", "rejax")                  # a missing extra: its one line
    # fir_gym.jax is imported here only, when asked for (tests/jax/test_jax_boundary.py)
    from .jax import train as jax_train
    from .training.kinds import kind_options

    jax_train.check_supported(args.env, args.estimator, args.observation)
    refused = {"--algo sac": args.algo != "ppo",
               "--checkpoint-freq": bool(args.checkpoint_freq),
               "--tensorboard": bool(args.tensorboard)}
    if any(refused.values()):
        raise ValueError("the jax backend trains PPO and takes no "
                         + ", ".join(k for k, v in refused.items() if v))
    options = kind_options(args.kind_kwargs, [args.estimator])[args.estimator]
    rec = jax_train.recipe(args.env, steps=args.steps, n_envs=args.n_envs,
                           algo_kwargs=args.algo_kwargs, hyperparams=args.hyperparams,
                           kind=args.estimator)
    checkpoints = max(1, rec.steps // args.eval_freq) if args.eval_freq else 10
    seeds = list(range(args.seed, args.seed + args.seeds))
    call = {"steps": args.steps, "n_envs": args.n_envs, "algo_kwargs": args.algo_kwargs,
            "env_kwargs": args.env_kwargs, "hyperparams": args.hyperparams,
            "kind_kwargs": options, "checkpoints": checkpoints, "episodes": args.episodes}
    earlier = None
    if args.resume:            # this call's run at this code: reuse it, or continue it
        earlier = jax_train.finished_run(args.out, args.env, args.estimator, seeds, **call)
        if earlier is not None and earlier.recipe.steps == rec.steps:
            print(f"{jax_returns_line(args.env, args.estimator, earlier.final_returns)}; "
                  f"reused the finished run in {args.out} (--resume)")
            return 0
    with working(f"training {len(seeds)} seed(s) with jax", enabled=not args.no_progress):
        if earlier is not None:
            more = rec.steps - earlier.steps_trained
            result = jax_train.continue_training(
                earlier, rec.steps, checkpoints=max(1, more // args.eval_freq)
                if args.eval_freq else 10)
        else:
            result = jax_train.train(args.env, args.estimator, seeds, **call)
    out = jax_train.save(result, args.out)
    how = (f"continued from {earlier.steps_trained} steps (--resume), saved in {out}"
           if earlier is not None else f"saved in {out}")
    print(f"{jax_returns_line(args.env, args.estimator, result.final_returns)}; {how}")
    print(f"jax: compile {result.compile_seconds:.1f} s (cache {result.cache}), train "
          f"{result.train_seconds:.1f} s for {result.steps_trained} steps x {len(seeds)} seeds",
          file=sys.stderr)
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    if args.model:
        if args.kind or args.env:
            raise ValueError("give --model (a run folder) or --env with --kind, not both")
        if Path(args.model, "results.json").is_file() and not Path(args.model,
                                                                   "run.json").is_file():
            return evaluate_jax(args)
        if not Path(args.model, "run.json").is_file():
            what = "does not exist" if not Path(args.model).exists() else "has no run.json"
            raise ValueError(f"--model {args.model} is not a run folder of `fir-gym train` "
                             f"(it {what})")
    elif not (args.kind and args.env):
        raise ValueError("give --model (a run folder) or --env and --kind "
                         "(lqg or pid: nothing to train)")
    elif args.kind not in ("lqg", "pid"):
        raise ValueError(f"--kind {args.kind} is learned: train it, then evaluate "
                         "its folder with --model")
    check_estimator_options(args.kind_kwargs)
    from .training import RunConfig, evaluate, kind_options

    if args.model:
        source: Any = args.model
    else:
        options = kind_options(args.kind_kwargs, [args.kind])[args.kind]
        source = RunConfig(env_id=args.env, observation_kind=args.kind,
                           kind_kwargs=options, env_kwargs=args.env_kwargs)
    with working(f"evaluating {args.episodes} episodes", enabled=not args.no_progress):
        result = evaluate(source, episodes=args.episodes, seed=args.seed,
                          **({"best": args.best} if args.model else {}))
    line = f"return {result.mean:.4g} ± {result.std:.3g} over {args.episodes} episodes"
    if result.rmse is not None:
        line += "; estimation RMSE " + ", ".join(f"{v:.3g}" for v in result.rmse)
    if result.anees is not None:
        line += (f"; NEES: median {result.nees_median:.3g} of χ²'s, "
                 f"{result.nees_in_band:.0%} of steps in its 95 % band (a consistent filter: "
                 f"1 and 95 %), ANEES {result.anees:.3g} (1; a few steps with a nearly "
                 "singular P blow it up)" if result.nees_median is not None
                 else f"; ANEES {result.anees:.3g}")
    print(line)
    return 0


def jax_returns_line(env_id: str, kind: str, returns: list[list[float]]) -> str:
    """The summary line of a JAX run's ``[seed][episode]`` returns: their mean ± spread over
    every episode of every seed, and the IQM of the seeds' means (``train`` and ``evaluate``
    with ``--backend jax`` print it)."""
    import statistics

    from .training.stats import iqm

    every = [r for seed_returns in returns for r in seed_returns]
    spread = statistics.pstdev(every) if len(every) > 1 else 0.0
    return (f"{env_id} observing {kind}: return {statistics.fmean(every):.4g} ± {spread:.3g} "
            f"over {len(returns[0])} episodes x {len(returns)} seed(s), IQM over seeds "
            f"{iqm([statistics.fmean(r) for r in returns]):.4g}")


def evaluate_jax(args: argparse.Namespace) -> int:
    """``fir-gym evaluate --model RUN`` on a run folder of ``fir-gym train --backend jax``:
    every seed's deterministic policy (:func:`fir_gym.jax.train.load`) played in the numpy
    env on the episodes seeded ``--seed`` + i (:func:`fir_gym.jax.benchmark.
    play_in_numpy_env`); one line per seed, then the returns over all and the IQM over the
    seeds' means."""
    import statistics

    from ._extras import require

    require("jax", "gymnax", "rejax")                  # a missing extra: its one line
    refused = {"--best": args.best, "--env-kwargs": bool(args.env_kwargs),
               "--kind-kwargs": bool(args.kind_kwargs)}
    if any(refused.values()):
        raise ValueError(f"--model {args.model} was trained with --backend jax: evaluate plays "
                         "it with the plant and kind options of its results.json and takes no "
                         + ", ".join(k for k, v in refused.items() if v))
    # fir_gym.jax is imported here only, when asked for (tests/jax/test_jax_boundary.py)
    from .jax.benchmark import play_in_numpy_env
    from .jax.train import load

    result = load(args.model)
    with working(f"evaluating {args.episodes} episodes x {len(result.seeds)} seed(s)",
                 enabled=not args.no_progress):
        returns = play_in_numpy_env(result, args.episodes, args.seed)
    for seed, seed_returns in zip(result.seeds, returns, strict=True):
        print(f"seed {seed}: return {statistics.fmean(seed_returns):.4g} ± "
              f"{statistics.pstdev(seed_returns):.3g} over {args.episodes} episodes")
    print(jax_returns_line(result.env_id, result.kind, returns))
    return 0


def _runner(args: argparse.Namespace) -> Any:
    from .scenarios.runner import Runner

    return Runner(args.backend, jobs=args.jobs, scheduler=args.scheduler,
                  progress=not args.no_progress)


def cmd_compare(args: argparse.Namespace) -> int:
    from .training import compare_controllers, plot_learning_curves
    from .training.curves import kinds_with_curves

    kinds = [k.strip() for k in args.observations.split(",") if k.strip()]
    seeds = list(range(args.seeds))
    check_estimator_options(args.kind_kwargs)
    with _runner(args) as runner:
        summary = compare_controllers(
            args.env, kinds, seeds, args.out, steps=args.steps, algo=args.algo,
            episodes=args.episodes, kind_kwargs=args.kind_kwargs,
            env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs, n_envs=args.n_envs,
            observation=args.observation, eval_freq=args.eval_freq,
            checkpoint_freq=args.checkpoint_freq, tensorboard=args.tensorboard,
            resume=args.resume, runner=runner)
    headers = ["observation", "mean return", "std over seeds", "IQM [95% CI]", "per seed",
               "estimation RMSE", "NEES median / χ²'s", "in χ² band", "ANEES"]
    rows = [[s["observation"], s["mean"], s["std"],
             f"{s['iqm']:.4g} [{s['iqm_low']:.4g}, {s['iqm_high']:.4g}]",
             " ".join(f"{r:.4g}" for r in s["per_seed"]),
             "—" if s["rmse"] is None else ", ".join(f"{v:.3g}" for v in s["rmse"]),
             "—" if s.get("nees_median") is None else f"{s['nees_median']:.3g}",
             "—" if s.get("nees_in_band") is None else f"{s['nees_in_band']:.2f}",
             "—" if s["anees"] is None else f"{s['anees']:.3g}"] for s in summary]
    print(format_table(headers, rows))
    Path(args.out, "comparison.md").write_text(format_table(headers, rows, markdown=True) + "\n")
    runs = {k: [Path(args.out, f"{k}-seed{s}") for s in seeds] for k in kinds}
    plot = plot_learning_curves(runs, Path(args.out, "learning_curves.png"), title=args.env)
    print(f"wrote {Path(args.out, 'comparison.md')}" + (f" and {plot}" if plot else ""))
    if plot is None and any(runs.values()) and not kinds_with_curves(runs):
        print("no learning_curves.png: no training episode finished in any run (give --steps "
              "more than an episode's length times --n-envs)")
    return 0


def _listed(text: str | None) -> list[str] | None:
    """A comma-separated option as its non-empty items (``None`` when not given)."""
    return [item.strip() for item in text.split(",") if item.strip()] if text else None


def cmd_benchmark(args: argparse.Namespace) -> int:
    plants, kinds = _listed(args.plants), _listed(args.kinds)
    if args.backend == "jax":
        return benchmark_jax(args, plants, kinds)
    if args.compare_with:
        raise ValueError("--compare-with puts an SB3 benchmark beside the jax backend's: give "
                         "it with --backend jax")
    from .training.benchmark import print_report, run_benchmark

    with _runner(args) as runner:
        report = run_benchmark(args.out, quick=args.quick, runner=runner,
                               seeds=args.seeds, plants=plants, kinds=kinds)
    print_report(report)
    print(f"\nwrote {Path(args.out, 'BENCHMARK.md')}")
    return 0


def benchmark_jax(args: argparse.Namespace, plants: list[str] | None,
                  kinds: list[str] | None) -> int:
    """``fir-gym benchmark-controllers --backend jax``: :func:`fir_gym.jax.benchmark.
    run_benchmark` (every learned kind and the LQG row, or ``--kinds``), its tables printed."""
    from ._extras import require

    require("jax", "gymnax", "rejax")                  # a missing extra: its one line
    if args.scheduler:
        raise ValueError("--backend jax runs its rows in this process or, with --jobs N, in N "
                         "local worker processes: it takes no --scheduler")
    from .jax.benchmark import markdown, run_benchmark

    report = run_benchmark(args.out, quick=args.quick, seeds=args.seeds, plants=plants,
                           kinds=kinds, compare_with=args.compare_with,
                           progress=not args.no_progress, jobs=args.jobs)
    print(markdown(report))
    print(f"\nwrote {Path(args.out, 'BENCHMARK.md')}")
    return 0


def cmd_robustness(args: argparse.Namespace) -> int:
    from .robustness.benchmark import run_benchmark
    from .robustness.plan import check_selection
    from .robustness.report import rebuild

    out = Path(args.out)
    if args.report_only:
        report = rebuild(out)
        print(f"rebuilt {out / 'REPORT.md'} from {out / 'results.json'} "
              f"({len(report['tables'])} cells)")
        return 0
    plants, conditions = _listed(args.plants), _listed(args.conditions)
    check_selection(plants, conditions)              # a bad name fails before any work
    jax = args.backend == "jax"
    if jax and args.scheduler:
        raise ValueError("--backend jax runs in this process or, with --jobs N, in N local "
                         "worker processes: it takes no --scheduler")
    if not args.lqg_only:
        from ._extras import require

        if jax:
            require("jax", "gymnax", "rejax")
        else:
            require("stable_baselines3", "sb3_contrib")
    if jax:                                          # both grids' runner: --jobs processes
        args.backend = "joblib" if args.jobs and args.jobs > 1 else "serial"
    with _runner(args) as runner:
        report = run_benchmark(out, quick=args.quick, runner=runner, plants=plants,
                               conditions=conditions, seeds=args.seeds,
                               learned=not args.lqg_only,
                               learned_backend="jax" if jax else "sb3",
                               progress=not args.no_progress)
    for answer in report["answers"]:
        print("-", answer)
    print(f"\nLQG grid: {report['lqg_tasks']} tasks in {report['lqg_seconds']:.0f} s; learned "
          f"grid: {report['learned_tasks']} tasks in {report['learned_seconds']:.0f} s")
    print(f"wrote {out / 'REPORT.md'}, {out / 'results.json'} and {out / 'figures'}")
    return 0


def cmd_watch(args: argparse.Namespace) -> int:
    from .video import watch

    rec = watch(args.env, args.out, estimator=args.estimator, policy=args.policy,
                steps=args.steps, seed=args.seed, fps=args.fps, every=args.every,
                estimator_kwargs=args.estimator_kwargs, env_kwargs=args.env_kwargs,
                progress=not args.no_progress)
    print(f"wrote {rec.path}: {rec.frames} frames at {rec.fps:g} fps ({rec.seconds:.1f} s, "
          f"every {rec.every} steps), {rec.steps} steps, return {rec.episode_return:.4g}")
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    from .record import record

    data = record(args.env, args.out, estimator=args.estimator, policy=args.policy,
                  episodes=args.episodes, seed=args.seed, steps=args.steps,
                  estimator_kwargs=args.estimator_kwargs, env_kwargs=args.env_kwargs,
                  dataset_id=args.dataset_id)
    print(f"wrote {data.dataset_id} to {data.path}: {data.episodes} episodes, {data.steps} "
          f"steps (read it with MINARI_DATASETS_PATH={args.out} and "
          f"minari.load_dataset({data.dataset_id!r}))")
    return 0


#: the subcommand a parsed command line names -> the function that runs it (``speed`` and
#: ``bench`` hand their raw arguments to :func:`cmd_speed`; :func:`fir_gym.cli.main`)
COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "list": cmd_list, "reproduce": cmd_reproduce, "train": cmd_train,
    "evaluate": cmd_evaluate, "compare-controllers": cmd_compare,
    "benchmark-controllers": cmd_benchmark, "benchmark-robustness": cmd_robustness,
    "watch": cmd_watch, "record": cmd_record}
