"""The ``fir-gym`` command.

Subcommands:

* ``fir-gym list`` — the registered environments and estimators;
* ``fir-gym reproduce`` — the scripted benchmark episodes (for now: one scripted
  episode per environment with a table of state and measurement statistics;
  the papers' experiments are added as their estimators land);
* ``fir-gym bench NAME`` — a speed benchmark (ratios against a reference timed in
  the same run).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from . import __version__
from .tables import format_table

#: benchmark name -> module in fir_gym.benchmarks exposing main(argv)
BENCHMARKS = ("kalman", "fir")


def _cmd_list(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from . import ENV_IDS
    from .estimators import estimator_names

    rows = []
    for env_id in ENV_IDS:
        plant = gym.make(env_id).unwrapped
        rows.append([env_id, gym.spec(env_id).max_episode_steps, ", ".join(plant.state_names),
                     ", ".join(plant.measurement_names), ", ".join(plant.action_names)])
    print(format_table(["environment", "max steps", "state", "measurement", "action"], rows))
    print()
    print("estimators:", ", ".join(estimator_names()) or "(none registered)")
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .scenarios import episodes

    summaries = episodes.run_all(seed=args.seed)
    headers, rows = episodes.summary_rows(summaries)
    text = format_table(headers, rows, markdown=args.markdown)
    print(f"Scripted episodes (one per environment, seed {args.seed})\n")
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "episodes.md").write_text(format_table(headers, rows, markdown=True) + "\n")
        print(f"\nwrote {out / 'episodes.md'}")
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    try:
        module = importlib.import_module(f"fir_gym.benchmarks.{args.name}")
    except ModuleNotFoundError as err:
        if err.name == f"fir_gym.benchmarks.{args.name}":
            print(f"benchmark {args.name!r} is not available yet", file=sys.stderr)
            return 2
        raise
    return int(module.main(args.args) or 0)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fir-gym",
        description="Gymnasium plants from five state-estimation papers, with pluggable "
                    "Kalman- and FIR-family estimators.")
    parser.add_argument("--version", action="version", version=f"fir-gym {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("list", help="list environments and estimators")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("reproduce", help="run the scripted benchmark episodes")
    p.add_argument("--seed", type=int, default=0, help="seed of every episode (default 0)")
    p.add_argument("--out", type=str, default=None, help="folder for Markdown reports")
    p.add_argument("--markdown", action="store_true", help="print Markdown tables")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser("bench", help="run a speed benchmark")
    p.add_argument("name", choices=BENCHMARKS)
    p.add_argument("args", nargs=argparse.REMAINDER, help="arguments for the benchmark")
    p.set_defaults(func=_cmd_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
