"""The ``fir-gym`` command.

Subcommands:

* ``fir-gym list`` — the registered environments and estimators;
* ``fir-gym reproduce`` — one scripted episode per environment, then every
  experiment of the five papers with the paper's numbers beside ours, and the
  sweeps beyond them; ``--out DIR`` writes ``DIR/REPORT.md`` and its figures;
* ``fir-gym bench NAME`` — a speed benchmark (ratios against a reference timed in
  the same run);
* ``fir-gym train`` / ``evaluate`` / ``compare-controllers`` — controllers trained
  with stable-baselines3 on true states, raw measurements or estimates
  (needs the ``rl`` extra);
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


def _cmd_train(args: argparse.Namespace) -> int:
    from .training import RunConfig, evaluate, train

    config = RunConfig(env_id=args.env, observation_kind=args.estimator, algo=args.algo,
                       steps=args.steps, seed=args.seed, n_envs=args.n_envs,
                       observation=args.observation, estimator_kwargs=args.estimator_kwargs,
                       env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs)
    out = train(config, args.out, progress_bar=not args.no_progress)
    result = evaluate(out, episodes=args.episodes)
    print(f"{args.env} observing {args.estimator}: return {result.mean:.4g} ± {result.std:.3g} "
          f"over {args.episodes} episodes; saved in {out}")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .training import evaluate

    result = evaluate(args.model, episodes=args.episodes, seed=args.seed)
    print(f"return {result.mean:.4g} ± {result.std:.3g} over {args.episodes} episodes")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .training import compare_controllers, plot_learning_curves

    kinds = [k.strip() for k in args.observations.split(",") if k.strip()]
    seeds = list(range(args.seeds))
    summary = compare_controllers(args.env, kinds, seeds, args.out, steps=args.steps,
                                  algo=args.algo, episodes=args.episodes,
                                  estimator_kwargs=args.estimator_kwargs,
                                  env_kwargs=args.env_kwargs, algo_kwargs=args.algo_kwargs,
                                  n_envs=args.n_envs, progress_bar=not args.no_progress)
    rows = [[s["observation"], s["mean"], s["std"],
             " ".join(f"{r:.4g}" for r in s["per_seed"])] for s in summary]
    table = format_table(["observation", "mean return", "std over seeds", "per seed"], rows)
    print(table)
    Path(args.out, "comparison.md").write_text(
        format_table(["observation", "mean return", "std over seeds", "per seed"], rows,
                     markdown=True) + "\n")
    plot = plot_learning_curves(args.out, kinds, seeds, Path(args.out, "learning_curves.png"))
    print(f"wrote {Path(args.out, 'comparison.md')}" + (f" and {plot}" if plot else ""))
    return 0


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
    p.add_argument("--estimator", default="true",
                   help="what the controller sees: 'true', 'measurement' or an estimator name")
    p.add_argument("--observation", default="estimate",
                   help="estimate | estimate+covariance | estimate+measurement")
    p.add_argument("--algo", default="ppo", choices=["ppo", "sac"])
    p.add_argument("--steps", type=int, default=50_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--algo-kwargs", type=_json_dict, default={},
                   help="JSON object of algorithm options (PPO defaults: see fir_gym.training)")
    p.add_argument("--episodes", type=int, default=20, help="evaluation episodes")
    p.add_argument("--estimator-kwargs", type=_json_dict, default={})
    p.add_argument("--env-kwargs", type=_json_dict, default={})
    p.add_argument("--out", required=True, help="folder for the model, statistics and logs")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("evaluate", help="evaluate a trained controller")
    p.add_argument("--model", required=True, help="the folder `fir-gym train --out` wrote")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, default=10_000)
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser("compare-controllers",
                       help="train and compare controllers seeing different observations")
    p.add_argument("--env", required=True)
    p.add_argument("--observations", default="true,measurement,ekf",
                   help="comma-separated: true, measurement and/or estimator names")
    p.add_argument("--seeds", type=int, default=3, help="number of seeds per observation")
    p.add_argument("--steps", type=int, default=50_000)
    p.add_argument("--algo", default="ppo", choices=["ppo", "sac"])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--estimator-kwargs", type=_json_dict, default={},
                   help="JSON object: estimator name -> its options")
    p.add_argument("--env-kwargs", type=_json_dict, default={})
    p.add_argument("--algo-kwargs", type=_json_dict, default={})
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--out", required=True)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_cmd_compare)

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
