"""The ``fir-gym`` argument parser: every option with its help text and its default.

Building the parser imports nothing heavy, and no command: the parsed namespace names its
subcommand (``args.command``), and :func:`fir_gym.cli.main` runs it from
:data:`fir_gym._commands.COMMANDS`. So ``fir-gym --help`` and every ``fir-gym CMD --help``
answer at once, and a command's own parser (``fir-gym speed``'s) can build on
:class:`Parser` without an import circle (docs/architecture.md#import-graph). A parse error
is one line, ``fir-gym CMD: error: ...``, and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any, NoReturn

from . import __version__

#: what ``reproduce --paper`` accepts
PAPERS = ("000", "001", "002", "003", "004", "sweeps")
#: what ``watch --policy`` accepts besides a run folder (fir_gym.episode_policy.POLICIES)
WATCH_POLICIES = ("zero", "lqg")


class Formatter(argparse.HelpFormatter):
    """argparse's formatter, with ``(default: X)`` after any option whose help does not
    already say its default (flags, off unless given, say nothing)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if ("default" in text or not action.option_strings or action.nargs == 0
                or action.default in (None, argparse.SUPPRESS)):
            return text
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (no usage block): the option, what
    was wrong, and where the help is."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: error: {message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def papers(text: str) -> list[str]:
    """``--paper``'s type: comma-separated experiments among :data:`PAPERS`."""
    chosen = [p.strip() for p in text.split(",") if p.strip()]
    bad = [p for p in chosen if p not in PAPERS]
    if bad or not chosen:
        raise argparse.ArgumentTypeError(f"experiments are among {','.join(PAPERS)}; "
                                         f"got {text!r}")
    return chosen


def json_dict(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"not valid JSON: {err}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"horizon\": 10}'")
    return value


def int_at_least(minimum: int) -> Any:
    """An argparse type: an integer >= ``minimum``, else a message naming the bound."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}; got {text!r}")
        return value
    parse.__name__ = f"integer >= {minimum}"
    return parse


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def _debug_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--debug", action="store_true",
                   help="on an error, print its traceback as well as the one-line message")


def _add_training_options(p: argparse.ArgumentParser) -> None:
    """The options train and compare-controllers share."""
    p.add_argument("--algo", default="ppo", choices=["ppo", "sac"],
                   help="stable-baselines3 algorithm (the recurrent kind is RecurrentPPO)")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="training timesteps (default: the plant's n_timesteps in the "
                        "shipped hyperparameter YAML)")
    p.add_argument("--n-envs", type=positive_int, default=None,
                   help="parallel sub-envs (default: the YAML's n_envs)")
    p.add_argument("--observation", default="estimate",
                   choices=["estimate", "estimate+covariance", "estimate+measurement"],
                   help="what an estimator kind shows the controller")
    p.add_argument("--kind-kwargs", "--estimator-kwargs", dest="kind_kwargs", type=json_dict,
                   metavar="JSON", default={}, help="JSON object: kind -> its options, e.g. "
                                    "'{\"efir\": {\"horizon\": 50}}' (default: none)")
    p.add_argument("--env-kwargs", type=json_dict, metavar="JSON", default={},
                   help="JSON object of plant options, e.g. '{\"max_episode_steps\": 300}' "
                        "(default: none)")
    p.add_argument("--algo-kwargs", type=json_dict, metavar="JSON", default={},
                   help="JSON object overriding the YAML's algorithm settings (default: none)")
    p.add_argument("--episodes", type=positive_int, default=20,
                   help="evaluation episodes per run")
    p.add_argument("--eval-freq", type=non_negative_int, default=0,
                   help="timesteps between evaluations that save the best model in "
                        "RUN/best (default: 0, none)")
    p.add_argument("--checkpoint-freq", type=non_negative_int, default=0,
                   help="timesteps between checkpoints in RUN/checkpoints (default: 0, none)")
    p.add_argument("--tensorboard", default=None, metavar="DIR",
                   help="write TensorBoard logs to DIR (needs tensorboard; default: none)")
    p.add_argument("--resume", action="store_true",
                   help="continue from the latest checkpoint; skip finished runs (--backend "
                        "jax: skip OUT's finished run of the same call and code; a JAX run is "
                        "written only when it has finished)")
    p.add_argument("--out", required=True, help="output folder (required)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _add_runner_options(p: argparse.ArgumentParser, what: str, jax: str = "") -> None:
    p.add_argument("--backend", default="serial",
                   choices=["serial", "joblib", "dask"] + (["jax"] if jax else []),
                   help=f"where the {what} run (default: serial, this process; dask needs "
                        'the cluster extra: pip install ".[cluster]")' + jax)
    p.add_argument("--jobs", type=positive_int, default=None,
                   help="worker processes for joblib/dask (default: the CPUs)" + (
                       "; jax: rows trained side by side in N processes (default: 1, this "
                       "process)" if jax else ""))
    p.add_argument("--scheduler", default=None,
                   help="address of a Dask scheduler (with --backend dask; default: a local "
                        "cluster)")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="fir-gym",
        description="Gymnasium plants from five state-estimation papers, with pluggable "
                    "Kalman- and FIR-family estimators.",
        epilog="A mistake prints one line and exits 2; add --debug for the traceback.")
    parser.add_argument("--version", action="version", version=f"fir-gym {__version__}")
    _debug_option(parser)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help: str, **kwargs: Any) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=kwargs.pop("description", help),
                           prog=f"fir-gym {name}", **kwargs)
        _debug_option(p)
        return p

    p = command("list", "list environments and estimators")

    p = command("reproduce", "reproduce every experiment of the papers, side by side with "
                             "the paper, and the sweeps beyond them")
    p.add_argument("--seed", type=int, default=0, help="seed of every episode")
    p.add_argument("--out", type=str, default=None,
                   help="folder for REPORT.md and its figures; the terminal then gets the "
                        "verdict counts per paper and the report's path (default: no files, "
                        "the whole report printed)")
    p.add_argument("--markdown", action="store_true", help="print Markdown tables")
    p.add_argument("--quick", action="store_true",
                   help="small Monte Carlo sizes (the numbers are noisier)")
    p.add_argument("--paper", action="append", type=papers, metavar="000,001,...,sweeps",
                   help="run only these papers' experiments (and/or the sweeps; default: all)")
    p.add_argument("--runs", type=positive_int, default=None,
                   help="Monte Carlo runs per experiment (default: each scenario's own)")
    _add_runner_options(p, "Monte Carlo runs")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")

    rl = 'Needs the rl extra: pip install torch==2.13.0 && pip install ".[rl]".'
    p = command("train", "train a controller with stable-baselines3 (or JAX: --backend jax)",
                description="Train a controller with stable-baselines3 and evaluate it. " + rl
                + " --backend jax trains PPO on fir_gym.jax instead (every plant, the kinds "
                  "fir_gym.jax has; the jax extra as well).")
    p.add_argument("--env", required=True,
                   help="environment id, e.g. fir_gym/VanDerPol-v0 (required)")
    p.add_argument("--estimator", "--kind", dest="estimator", default="true",
                   help="what the controller sees: true, measurement, measurement-stack, "
                        "recurrent, an estimator name, or lqg/pid (nothing to train)")
    p.add_argument("--seed", type=int, default=0, help="training seed")
    p.add_argument("--hyperparams", default=None, metavar="YAML",
                   help="an RL Zoo hyperparameter file (default: the shipped one)")
    p.add_argument("--backend", default="sb3", choices=["sb3", "jax"],
                   help="sb3 (default): stable-baselines3 on the numpy plant; jax: rejax's PPO "
                        "on fir_gym.jax (true, measurement, measurement-stack and the filters "
                        "it has: docs/jax.md; needs the jax extra: pip install \".[jax]\")")
    p.add_argument("--seeds", type=positive_int, default=1,
                   help="with --backend jax: train seeds SEED..SEED+N-1 in one compiled "
                        "program (default: 1)")
    _add_training_options(p)

    p = command("evaluate", "evaluate a trained controller, or LQG/PID",
                description="Evaluate a run folder of `fir-gym train`, or a classical "
                            "controller (LQG, PID) on a plant. " + rl)
    p.add_argument("--model", default=None, metavar="RUN",
                   help="the folder `fir-gym train --out` wrote (default: none; give --env "
                        "and --kind)")
    p.add_argument("--env", default=None, help="environment id, with --kind lqg or pid "
                                               "(default: none)")
    p.add_argument("--kind", default=None, help="lqg or pid, classical: nothing to train "
                                                "(default: none)")
    p.add_argument("--kind-kwargs", type=json_dict, metavar="JSON", default={},
                   help="JSON object: kind -> its options (default: none)")
    p.add_argument("--env-kwargs", type=json_dict, metavar="JSON", default={},
                   help="JSON object of plant options (default: none)")
    p.add_argument("--episodes", type=positive_int, default=20, help="evaluation episodes")
    p.add_argument("--seed", type=int, default=10_000, help="seed of the first episode")
    p.add_argument("--best", action="store_true",
                   help="evaluate the evaluation callback's best model (RUN/best)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")

    p = command("compare-controllers",
                "train and compare controllers seeing different observations",
                description="Train and compare controllers seeing different observations. "
                            + rl)
    p.add_argument("--env", required=True, help="environment id (required)")
    p.add_argument("--observations", default="true,measurement,ekf",
                   help="comma-separated kinds: true, measurement, measurement-stack, "
                        "recurrent, estimator names, lqg, pid")
    p.add_argument("--seeds", type=positive_int, default=3, help="seeds 0..N-1 per kind")
    _add_training_options(p)
    _add_runner_options(p, "(kind, seed) jobs")

    p = command("benchmark-controllers",
                "controllers on estimates: the five plants x their eight or nine kinds x 5 "
                "seeds (about 2.5 h on 2 cores)")
    p.add_argument("--quick", action="store_true",
                   help="2 seeds and tiny budgets: checks the pipeline in under 3 minutes")
    p.add_argument("--out", default="benchmark", help="output folder")
    p.add_argument("--seeds", type=positive_int, default=None,
                   help="seeds per learned kind (default: 5; 2 with --quick)")
    p.add_argument("--plants", default=None,
                   help="comma-separated subset of the plants (default: all five)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--compare-with", default=None, metavar="DIR",
                   help="with --backend jax: an SB3 benchmark's --out folder (or a Markdown "
                        "file of its tables, e.g. README.md), whose rows stand beside the JAX "
                        "rows (default: none)")
    p.add_argument("--kinds", default=None,
                   help="comma-separated subset of the rows' kinds, e.g. recurrent,lqg "
                        "(default: every kind of each plant)")
    _add_runner_options(p, "(plant, kind, seed) jobs",
                        jax="; jax: every learned kind (RecurrentPPO for recurrent) and the "
                            "LQG row, all seeds of a plant and kind in one compiled program "
                            '(the jax extra: pip install ".[jax]")')

    p = command("benchmark-robustness",
                "which estimator belongs in a closed loop when the model is wrong and the "
                "sensor misbehaves: every plant x condition x controller",
                description="The robustness benchmark (docs/robustness.md): the LQG on every "
                            "applicable estimator (plain and gated) and on the true state, "
                            "then PPO on true states, measurements, memories and estimates "
                            "trained on the nominal plant and with a condition on, each under "
                            "every condition and strength. The LQG grid needs the base "
                            "install; the learned grid the rl extra: " + rl)
    p.add_argument("--quick", action="store_true",
                   help="two plants, the middle strength, tiny budgets: checks the pipeline "
                        "in a few minutes (its numbers mean nothing)")
    p.add_argument("--out", default="robustness", help="output folder")
    p.add_argument("--plants", default=None,
                   help="comma-separated environment ids (default: all five)")
    p.add_argument("--conditions", default=None,
                   help="comma-separated conditions (default: all; see fir-gym list); "
                        "nominal is always run")
    p.add_argument("--seeds", type=positive_int, default=None,
                   help="seeds per learned kind and regime (default: 5; 1 with --quick)")
    p.add_argument("--lqg-only", action="store_true",
                   help="run the LQG grid only (no training; needs no extra)")
    p.add_argument("--report-only", action="store_true",
                   help="rebuild OUT/REPORT.md and the figures from OUT/results.json")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _add_runner_options(p, "tasks",
                        jax="; jax: the learned grid trained with fir_gym.jax (its kinds, "
                            "every regime; every seed of a plant, kind and regime in one "
                            "compiled program; the jax extra: pip install "
                            '".[jax]"), evaluated in the numpy envs; both grids in --jobs N '
                            'local processes (default: 1, this process)')

    p = command("watch", "record one episode as a GIF or MP4, the estimate drawn over the plant",
                description="Record one episode with the estimate (and its 2σ region, "
                            "magnified in an inset where it is under a few pixels) and the "
                            "measurement drawn over every frame. By default a frame is drawn "
                            "every N steps, N the steps of 1/fps seconds of the plant's time "
                            "(real time), larger where the clip would play longer than 20 s; "
                            "frames are written as they are drawn. A clip takes one render per "
                            "frame to make: about 2 ms for the numpy plants, 30-50 ms for the "
                            "MuJoCo PendulumSlider-v0 under software OpenGL, so the default "
                            "PendulumSlider-v0 GIF (251 frames) takes about 14 s of CPU and an "
                            "Orbit-v0 GIF (501 frames) about 5 s. Needs the video extra: "
                            'pip install ".[video]".')
    _add_episode_source(p, "the estimator drawn")
    # --steps and --every are checked by fir_gym.video.watch (the same message in Python)
    p.add_argument("--steps", type=int, default=None,
                   help="at most this many steps (default: the whole episode)")
    p.add_argument("--seed", type=int, default=0, help="the episode's seed")
    p.add_argument("--fps", type=float, default=None,
                   help="frames per second (default: the plant's render_fps, at most 50 for "
                        "a GIF: browsers play shorter GIF delays as 100 ms)")
    p.add_argument("--every", type=int, default=None,
                   help="draw every N-th step's frame (default: real time, "
                        "round(1 / (fps * dt)), raised so the clip lasts at most 20 s: "
                        "PendulumSlider-v0 20 for a GIF, 10 for an MP4; Orbit-v0 2)")
    _add_episode_options(p, '{"nominal": {"mu": 19.9}}')
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: a bar of the steps on stderr)")
    p.add_argument("--out", required=True,
                   help="the video file: FILE.gif or FILE.mp4 (required)")

    p = command("record", "write episodes as a Minari dataset (offline-RL data)",
                description="Play episodes with an estimator in the loop and write them as a "
                            "Minari dataset: the observations the controller saw, and the true "
                            "state, measurement, estimate, covariance and active conditions "
                            "in each step's infos. Episode i uses seed SEED+i. Needs the "
                            'dataset extra: pip install ".[dataset]".')
    _add_episode_source(p, "the estimator in the loop")
    p.add_argument("--episodes", type=positive_int, default=10, help="how many episodes")
    p.add_argument("--seed", type=int, default=0, help="the first episode's seed")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="at most this many steps per episode (default: the whole episode)")
    _add_episode_options(p, '{"sensor_faults": {"dropout": 0.1}}')
    p.add_argument("--dataset-id", default=None,
                   help="Minari's namespace/name-vN (default: "
                        "fir_gym/<plant>-<estimator>-<policy>-v0)")
    p.add_argument("--out", required=True,
                   help="the datasets' folder (Minari's MINARI_DATASETS_PATH); the dataset "
                        "goes to OUT/<dataset-id> (required)")

    for name in ("speed", "bench"):
        # parsed by the speed benchmark itself (fir_gym.cli.main hands it every argument);
        # listed here for `fir-gym --help`
        what = ("every speed figure in one run, as ratios to references timed in the same "
                "run (see fir-gym speed --help)") if name == "speed" else "the old name of speed"
        sub.add_parser(name, help=what, add_help=False)
    return parser


def _add_episode_source(p: argparse.ArgumentParser, estimator_role: str) -> None:
    """``--env``, ``--estimator`` and ``--policy`` of a scripted episode (watch, record)."""
    p.add_argument("--env", default=None,
                   help="environment id, e.g. fir_gym/Orbit-v0 (default with a run folder: "
                        "the run's)")
    p.add_argument("--estimator", default=None,
                   help=f"{estimator_role}, a registry name such as ekf (default with a run "
                        "that observes an estimator: that one)")
    p.add_argument("--policy", default="zero", metavar="|".join((*WATCH_POLICIES, "RUN")),
                   help="'zero' (no action), 'lqg' (the LQR of the plant's nominal model on "
                        "the estimate) or a run folder written by `fir-gym train`")


def _add_episode_options(p: argparse.ArgumentParser, env_example: str) -> None:
    """``--estimator-kwargs`` and ``--env-kwargs`` (JSON objects) of a scripted episode."""
    p.add_argument("--estimator-kwargs", type=json_dict, metavar="JSON", default={},
                   help="JSON object of estimator options, e.g. '{\"horizon\": 20}' "
                        "(default: none)")
    p.add_argument("--env-kwargs", type=json_dict, metavar="JSON", default={},
                   help=f"JSON object of gym.make options, e.g. '{env_example}' (default: none)")
