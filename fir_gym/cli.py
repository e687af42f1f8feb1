"""The ``fir-gym`` command.

Subcommands:

* ``fir-gym list`` — the registered environments and estimators;
* ``fir-gym reproduce`` — one scripted episode per environment, then every
  experiment of the five papers with the paper's numbers beside ours, and the
  sweeps beyond them; ``--out DIR`` writes ``DIR/REPORT.md`` and its figures;
* ``fir-gym bench NAME`` — a speed benchmark (ratios against a reference timed in
  the same run);
* ``fir-gym train`` / ``evaluate`` / ``compare-controllers`` /
  ``benchmark-controllers`` — controllers trained with stable-baselines3 on true
  states, raw or stacked measurements, a recurrent policy or estimates, beside LQG and
  PID (needs the ``rl`` extra);
* ``fir-gym watch`` — one episode recorded as a GIF or MP4, the estimate drawn over
  the plant (needs the ``video`` extra).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from . import __version__
from .tables import format_table

#: benchmark name -> module in fir_gym.benchmarks exposing main(argv)
BENCHMARKS = ("envs", "wrappers", "kalman", "fir")


def _cmd_list(args: argparse.Namespace) -> int:
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
    return 0


def _papers(text: str) -> list[str]:
    papers = [p.strip() for p in text.split(",") if p.strip()]
    known = ("000", "001", "002", "003", "004", "sweeps")
    bad = [p for p in papers if p not in known]
    if bad or not papers:
        raise argparse.ArgumentTypeError(f"experiments are among {','.join(known)}; "
                                         f"got {text!r}")
    return papers


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .scenarios import SCENARIOS, episodes
    from .scenarios.plan import execute
    from .scenarios.report import vocabulary, write_report
    from .scenarios.runner import Runner

    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    papers = [p for group in (args.paper or []) for p in group]
    wanted = [name for name in SCENARIOS
              if not papers or name.removeprefix("paper") in papers]
    modules = [importlib.import_module(f"fir_gym.scenarios.{name}") for name in wanted]
    plans = [episodes.plan(seed=args.seed)] + [
        m.plan(seed=args.seed, quick=args.quick, runs=args.runs) for m in modules]
    # every scenario's tasks in one map per stage: the workers stay busy across scenarios
    with Runner(args.backend, jobs=args.jobs, scheduler=args.scheduler,
                progress=not args.no_progress) as runner:
        summaries, *reports = execute(plans, runner, desc="reproduce")
    headers, rows = episodes.summary_rows(summaries)
    print("Verdicts\n\n" + vocabulary(markdown=False) + "\n")
    print(f"Scripted episodes (one per environment, seed {args.seed})\n")
    print(format_table(headers, rows, markdown=args.markdown))
    for module, report in zip(modules, reports, strict=True):
        if out and hasattr(module, "plot"):
            module.plot(report, out)
        print("\n" + report.to_text(markdown=args.markdown))
    if out:
        path = write_report(out, reports, episodes_table=(headers, rows))
        print(f"\nwrote {path}")
    return 0


def _cmd_speed(args: argparse.Namespace) -> int:
    try:
        module = importlib.import_module("fir_gym.benchmarks.speed")
    except ModuleNotFoundError as err:
        if err.name == "fir_gym.benchmarks.speed":
            print("fir-gym speed is not available yet", file=sys.stderr)
            return 2
        raise
    return int(module.main(args.args) or 0)


def _cmd_bench(args: argparse.Namespace) -> int:
    try:
        module = importlib.import_module(f"fir_gym.benchmarks.{args.name}")
    except ModuleNotFoundError as err:
        if err.name == f"fir_gym.benchmarks.{args.name}":
            print(f"benchmark {args.name!r} is not available yet", file=sys.stderr)
            return 2
        raise
    return int(module.main(args.args) or 0)


def _json_dict(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"not valid JSON: {err}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"horizon\": 10}'")
    return value


def _int_at_least(minimum: int) -> Any:
    """An argparse type: an integer >= ``minimum``, else a message naming the bound."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}; got {text!r}")
        return value
    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def _fail(command: str, err: Exception) -> int:
    """A bad kind, option or keyword argument: one line, no traceback."""
    message = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
    print(f"fir-gym {command}: error: {message}", file=sys.stderr)
    return 2


def _runner(args: argparse.Namespace) -> object:
    from .scenarios.runner import Runner

    return Runner(args.backend, jobs=args.jobs, scheduler=args.scheduler,
                  progress=not args.no_progress)


def _cmd_train(args: argparse.Namespace) -> int:
    from .training import RunConfig, evaluate, kind_options, train

    try:
        options = kind_options(args.kind_kwargs, [args.estimator])[args.estimator]
        config = RunConfig(env_id=args.env, observation_kind=args.estimator, algo=args.algo,
                           steps=args.steps, seed=args.seed, n_envs=args.n_envs,
                           observation=args.observation, kind_kwargs=options,
                           env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs,
                           eval_freq=args.eval_freq, checkpoint_freq=args.checkpoint_freq,
                           tensorboard=args.tensorboard, hyperparams=args.hyperparams)
        from .training.compare import validate

        validate([config])
    except (ValueError, TypeError, KeyError) as err:
        return _fail("train", err)
    out = train(config, args.out, progress_bar=not args.no_progress, resume=args.resume)
    source = out if config.observation_kind not in ("lqg", "pid") else config
    result = evaluate(source, episodes=args.episodes)
    print(f"{args.env} observing {args.estimator}: return {result.mean:.4g} ± {result.std:.3g} "
          f"over {args.episodes} episodes; saved in {out}")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .training import RunConfig, evaluate, kind_options

    try:
        if args.model:
            if args.kind or args.env:
                raise ValueError("give --model (a run folder) or --env with --kind, not both")
            result = evaluate(args.model, episodes=args.episodes, seed=args.seed,
                              best=args.best)
        else:
            if not (args.kind and args.env):
                raise ValueError("give --model (a run folder) or --env and --kind "
                                 "(lqg or pid: nothing to train)")
            if args.kind not in ("lqg", "pid"):
                raise ValueError(f"--kind {args.kind} is learned: train it, then evaluate "
                                 "its folder with --model")
            options = kind_options(args.kind_kwargs, [args.kind])[args.kind]
            config = RunConfig(env_id=args.env, observation_kind=args.kind,
                               kind_kwargs=options, env_kwargs=args.env_kwargs)
            result = evaluate(config, episodes=args.episodes, seed=args.seed)
    except (ValueError, TypeError, KeyError) as err:
        return _fail("evaluate", err)
    line = f"return {result.mean:.4g} ± {result.std:.3g} over {args.episodes} episodes"
    if result.rmse is not None:
        line += "; estimation RMSE " + ", ".join(f"{v:.3g}" for v in result.rmse)
    if result.anees is not None:
        line += f"; ANEES {result.anees:.3g}"
    print(line)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .training import compare_controllers, plot_learning_curves

    kinds = [k.strip() for k in args.observations.split(",") if k.strip()]
    seeds = list(range(args.seeds))
    try:
        with _runner(args) as runner:          # type: ignore[attr-defined]
            summary = compare_controllers(
                args.env, kinds, seeds, args.out, steps=args.steps, algo=args.algo,
                episodes=args.episodes, kind_kwargs=args.kind_kwargs,
                env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs, n_envs=args.n_envs,
                observation=args.observation, eval_freq=args.eval_freq,
                checkpoint_freq=args.checkpoint_freq, tensorboard=args.tensorboard,
                resume=args.resume, runner=runner)
    except (ValueError, TypeError, KeyError) as err:
        return _fail("compare-controllers", err)
    headers = ["observation", "mean return", "std over seeds", "IQM [95% CI]", "per seed",
               "estimation RMSE", "ANEES"]
    rows = [[s["observation"], s["mean"], s["std"],
             f"{s['iqm']:.4g} [{s['iqm_low']:.4g}, {s['iqm_high']:.4g}]",
             " ".join(f"{r:.4g}" for r in s["per_seed"]),
             "—" if s["rmse"] is None else ", ".join(f"{v:.3g}" for v in s["rmse"]),
             "—" if s["anees"] is None else f"{s['anees']:.3g}"] for s in summary]
    print(format_table(headers, rows))
    Path(args.out, "comparison.md").write_text(format_table(headers, rows, markdown=True) + "\n")
    runs = {k: [Path(args.out, f"{k}-seed{s}") for s in seeds] for k in kinds}
    plot = plot_learning_curves(runs, Path(args.out, "learning_curves.png"), title=args.env)
    print(f"wrote {Path(args.out, 'comparison.md')}" + (f" and {plot}" if plot else ""))
    return 0


def _cmd_benchmark(args: argparse.Namespace) -> int:
    from .training.benchmark import print_report, run_benchmark

    plants = [p.strip() for p in args.plants.split(",")] if args.plants else None
    try:
        with _runner(args) as runner:          # type: ignore[attr-defined]
            report = run_benchmark(args.out, quick=args.quick, runner=runner,
                                   seeds=args.seeds, plants=plants)
    except (ValueError, TypeError, KeyError) as err:
        return _fail("benchmark-controllers", err)
    print_report(report)
    print(f"\nwrote {Path(args.out, 'BENCHMARK.md')}")
    return 0


def _add_training_options(p: argparse.ArgumentParser) -> None:
    """The options train and compare-controllers share."""
    p.add_argument("--algo", default="ppo", choices=["ppo", "sac"],
                   help="stable-baselines3 algorithm (the recurrent kind is RecurrentPPO; "
                        "default ppo)")
    p.add_argument("--steps", type=_positive_int, default=None,
                   help="training timesteps (default: the plant's n_timesteps in the "
                        "shipped hyperparameter YAML)")
    p.add_argument("--n-envs", type=_positive_int, default=None,
                   help="parallel sub-envs (default: the YAML's n_envs)")
    p.add_argument("--observation", default="estimate",
                   choices=["estimate", "estimate+covariance", "estimate+measurement"],
                   help="what an estimator kind shows the controller (default estimate)")
    p.add_argument("--kind-kwargs", "--estimator-kwargs", dest="kind_kwargs", type=_json_dict,
                   default={}, help="JSON object: kind -> its options, e.g. "
                                    "'{\"efir\": {\"horizon\": 50}}' (default none)")
    p.add_argument("--env-kwargs", type=_json_dict, default={},
                   help="JSON object of plant options, e.g. '{\"max_episode_steps\": 300}' "
                        "(default none)")
    p.add_argument("--algo-kwargs", type=_json_dict, default={},
                   help="JSON object overriding the YAML's algorithm settings (default none)")
    p.add_argument("--episodes", type=_positive_int, default=20,
                   help="evaluation episodes per run (default 20)")
    p.add_argument("--eval-freq", type=_non_negative_int, default=0,
                   help="timesteps between evaluations that save the best model in "
                        "RUN/best (default 0: none)")
    p.add_argument("--checkpoint-freq", type=_non_negative_int, default=0,
                   help="timesteps between checkpoints in RUN/checkpoints (default 0: none)")
    p.add_argument("--tensorboard", default=None, metavar="DIR",
                   help="write TensorBoard logs to DIR (needs tensorboard; default none)")
    p.add_argument("--resume", action="store_true",
                   help="continue from the latest checkpoint; skip finished runs")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _add_runner_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--backend", default="serial", choices=["serial", "joblib", "dask"],
                   help="where the (kind, seed) jobs run (default: this process)")
    p.add_argument("--jobs", type=_positive_int, default=None,
                   help="worker processes for joblib/dask (default: the CPUs)")
    p.add_argument("--scheduler", default=None,
                   help="address of a Dask scheduler (with --backend dask; default: a local "
                        "cluster)")


def _cmd_watch(args: argparse.Namespace) -> int:
    from .video import MissingExtra, watch

    try:
        rec = watch(args.env, args.out, estimator=args.estimator, policy=args.policy,
                    steps=args.steps, seed=args.seed, fps=args.fps, every=args.every,
                    estimator_kwargs=args.estimator_kwargs, env_kwargs=args.env_kwargs)
    except (ValueError, TypeError, MissingExtra, gym_error()) as err:
        print(f"fir-gym watch: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {rec.path}: {rec.frames} frames at {rec.fps:g} fps, {rec.steps} steps, "
          f"return {rec.episode_return:.4g}")
    return 0


def gym_error() -> type[Exception]:
    """Gymnasium's error for an unknown environment id (and its other user errors)."""
    from gymnasium import error

    return error.Error


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fir-gym",
        description="Gymnasium plants from five state-estimation papers, with pluggable "
                    "Kalman- and FIR-family estimators.")
    parser.add_argument("--version", action="version", version=f"fir-gym {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list environments and estimators")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("reproduce", help="reproduce every experiment of the papers, side by side "
                                          "with the paper, and the sweeps beyond them")
    p.add_argument("--seed", type=int, default=0, help="seed of every episode (default 0)")
    p.add_argument("--out", type=str, default=None, help="folder for Markdown reports")
    p.add_argument("--markdown", action="store_true", help="print Markdown tables")
    p.add_argument("--quick", action="store_true",
                   help="small Monte Carlo sizes, under a minute (the numbers are noisier)")
    p.add_argument("--paper", action="append", type=_papers, metavar="000,001,...,sweeps",
                   help="run only these papers' experiments (and/or the sweeps)")
    p.add_argument("--runs", type=int, default=None,
                   help="Monte Carlo runs per experiment (default: each scenario's own)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (joblib/dask)")
    p.add_argument("--backend", default="serial", choices=["serial", "joblib", "dask"],
                   help="where the Monte Carlo runs (default: this process)")
    p.add_argument("--scheduler", default=None,
                   help="address of a Dask scheduler (with --backend dask; default: a local "
                        "cluster)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser("train", help="train a controller with stable-baselines3")
    p.add_argument("--env", required=True, help="environment id, e.g. fir_gym/VanDerPol-v0")
    p.add_argument("--estimator", "--kind", dest="estimator", default="true",
                   help="what the controller sees: true, measurement, measurement-stack, "
                        "recurrent, an estimator name, or lqg/pid (nothing to train); "
                        "default true")
    p.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    p.add_argument("--hyperparams", default=None, metavar="YAML",
                   help="an RL Zoo hyperparameter file instead of the shipped one")
    _add_training_options(p)
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("evaluate", help="evaluate a trained controller, or LQG/PID")
    p.add_argument("--model", default=None,
                   help="the folder `fir-gym train --out` wrote (default none: give --env "
                        "and --kind)")
    p.add_argument("--env", default=None, help="environment id, with --kind lqg or pid")
    p.add_argument("--kind", default=None, help="lqg or pid (classical: nothing to train)")
    p.add_argument("--kind-kwargs", type=_json_dict, default={},
                   help="JSON object: kind -> its options (default none)")
    p.add_argument("--env-kwargs", type=_json_dict, default={},
                   help="JSON object of plant options (default none)")
    p.add_argument("--episodes", type=_positive_int, default=20,
                   help="evaluation episodes (default 20)")
    p.add_argument("--seed", type=int, default=10_000,
                   help="seed of the first episode (default 10000)")
    p.add_argument("--best", action="store_true",
                   help="evaluate the evaluation callback's best model (RUN/best)")
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("compare-controllers",
                       help="train and compare controllers seeing different observations")
    p.add_argument("--env", required=True, help="environment id")
    p.add_argument("--observations", default="true,measurement,ekf",
                   help="comma-separated kinds: true, measurement, measurement-stack, "
                        "recurrent, estimator names, lqg, pid (default true,measurement,ekf)")
    p.add_argument("--seeds", type=_positive_int, default=3,
                   help="seeds 0..N-1 per kind (default 3)")
    _add_training_options(p)
    _add_runner_options(p)
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("benchmark-controllers",
                       help="the published benchmark: Orbit, VanDerPol, PendulumSlider x "
                            "eight kinds x 5 seeds (about 90 min on 2 cores)")
    p.add_argument("--quick", action="store_true",
                   help="2 seeds and tiny budgets: checks the pipeline in under 3 minutes")
    p.add_argument("--out", default="benchmark", help="output folder (default benchmark)")
    p.add_argument("--seeds", type=_positive_int, default=None,
                   help="seeds per learned kind (default 5; 2 with --quick)")
    p.add_argument("--plants", default=None,
                   help="comma-separated subset of the plants (default all three)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_runner_options(p)
    p.set_defaults(func=_cmd_benchmark)

    p = sub.add_parser(
        "watch", help="record one episode as a GIF or MP4, the estimate drawn over the plant",
        description="Record one episode with the estimate (and its 2σ region) and the "
                    "measurement drawn over every frame. Needs the video extra: "
                    'pip install "fir-gym[video]".')
    p.add_argument("--env", default=None,
                   help="environment id, e.g. fir_gym/Orbit-v0 (default with a run folder: "
                        "the run's)")
    p.add_argument("--estimator", default=None,
                   help="the estimator drawn, a registry name such as ekf (default with a run "
                        "that observes an estimator: that one)")
    p.add_argument("--policy", default="zero", metavar="zero|RUN",
                   help="'zero' (no action) or a run folder written by `fir-gym train` "
                        "(default: zero)")
    p.add_argument("--steps", type=int, default=None,
                   help="at most this many steps (default: the whole episode)")
    p.add_argument("--seed", type=int, default=0, help="the episode's seed (default: 0)")
    p.add_argument("--fps", type=float, default=None,
                   help="frames per second (default: the plant's render_fps)")
    p.add_argument("--every", type=int, default=1,
                   help="keep every N-th step's frame (default: 1, every step)")
    p.add_argument("--estimator-kwargs", type=_json_dict, default={},
                   help="JSON object of estimator options, e.g. '{\"horizon\": 20}'")
    p.add_argument("--env-kwargs", type=_json_dict, default={},
                   help="JSON object of gym.make options, e.g. '{\"nominal\": {\"mu\": 19.9}}'")
    p.add_argument("--out", required=True, help="the video file: FILE.gif or FILE.mp4")
    p.set_defaults(func=_cmd_watch)

    p = sub.add_parser("speed", help="every speed figure in one run, as ratios to references",
                       add_help=False)
    p.add_argument("args", nargs=argparse.REMAINDER,
                   help="options of the speed command (--json, --help, ...)")
    p.set_defaults(func=_cmd_speed)

    p = sub.add_parser("bench", help="run a speed benchmark")
    p.add_argument("name", choices=BENCHMARKS)
    p.add_argument("args", nargs=argparse.REMAINDER, help="arguments for the benchmark")
    p.set_defaults(func=_cmd_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from threadpoolctl import threadpool_limits

    argv = list(sys.argv[1:] if argv is None else argv)
    # `speed` and `bench NAME` hand everything after them, verbatim, to the benchmark's
    # own parser (argparse would otherwise claim options such as --json or --steps).
    if argv[:1] == ["speed"]:
        args = argparse.Namespace(func=_cmd_speed, args=argv[1:])
    elif argv[:1] == ["bench"] and len(argv) > 1 and argv[1] in BENCHMARKS:
        args = argparse.Namespace(func=_cmd_bench, name=argv[1], args=argv[2:])
    else:
        args = build_parser().parse_args(argv)
    try:
        # Every matrix here is small: a multi-threaded BLAS only adds thread hand-offs,
        # and on a busy machine its spinning threads can make a 2x2 solve cost ms.
        with threadpool_limits(limits=1, user_api="blas"):
            return int(args.func(args))
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
