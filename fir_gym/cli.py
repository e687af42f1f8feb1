"""The ``fir-gym`` command.

Subcommands:

* ``fir-gym list`` — the registered environments and estimators;
* ``fir-gym reproduce`` — one scripted episode per environment, then every
  experiment of the five papers with the paper's numbers beside ours, and the
  sweeps beyond them; ``--out DIR`` writes ``DIR/REPORT.md`` and its figures;
* ``fir-gym speed [SECTION ...]`` — every speed figure, as ratios against references
  timed in the same run (``fir-gym bench`` is its old name);
* ``fir-gym train`` / ``evaluate`` / ``compare-controllers`` /
  ``benchmark-controllers`` — controllers trained with stable-baselines3 on true
  states, raw or stacked measurements, a recurrent policy or estimates, beside LQG and
  PID (needs the ``rl`` extra);
* ``fir-gym watch`` — one episode recorded as a GIF or MP4, the estimate drawn over
  the plant (needs the ``video`` extra).

A user mistake — a bad option, an unknown id or estimator, an estimator option the
filter does not take, a missing extra — prints one line, ``fir-gym CMD: error: ...``,
and exits with status 2; ``--debug`` prints the traceback as well. This module imports
only the standard library and the package's light modules: the commands
(:mod:`._commands`) import what they need when they run, so ``--help`` is instant.
"""

from __future__ import annotations

import os
import re
import sys
import traceback
from collections.abc import Sequence
from typing import Any

from . import _commands as commands
from ._cli_parser import PAPERS, Parser, build_parser
from ._cli_parser import papers as _papers  # noqa: F401  (tests import it here)
from ._extras import install_hint

__all__ = ["PAPERS", "Parser", "build_parser", "main", "user_error"]

#: the subcommands that hand every argument, verbatim, to the speed benchmark's parser
SPEED_COMMANDS = ("speed", "bench")

#: what Gymnasium appends when re-raising an entry point's error (``gym.make``)
_GYM_SUFFIX = re.compile(r" was raised from the environment creator for \S+ with kwargs .*$",
                         re.DOTALL)


def user_error(err: BaseException) -> str | None:
    """The one-line message for a user mistake, or ``None`` for a bug (re-raised).

    User mistakes are a missing package of an extra (the message says which
    ``pip install`` fixes it), and ``ValueError``/``TypeError``/``KeyError``, a file
    that is not there, and Gymnasium's own errors (an unknown id) — every public
    boundary of fir-gym refuses bad input with one of these, naming the argument.
    """
    if isinstance(err, ModuleNotFoundError):
        from ._extras import MissingExtra

        if isinstance(err, MissingExtra):
            return _one_line(str(err))
        hint = install_hint(err.name)
        return None if hint is None else hint
    errors: tuple[type[BaseException], ...] = (ValueError, TypeError, KeyError, OSError)
    if "gymnasium" in sys.modules:
        from gymnasium import error as gym_error

        errors = (*errors, gym_error.Error)
    if not isinstance(err, errors):
        return None
    text = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
    return _one_line(_GYM_SUFFIX.sub("", text)) or type(err).__name__


def _one_line(text: str) -> str:
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # --debug anywhere before a `--` shows the traceback of an error (it is in every
    # --help; taken out here so that it works in any position)
    end = argv.index("--") if "--" in argv else len(argv)
    debug = "--debug" in argv[:end]
    if debug:
        argv = [a for i, a in enumerate(argv) if not (a == "--debug" and i < end)]
    command = argv[0] if argv else ""
    if command in SPEED_COMMANDS:
        # `speed` and its old name `bench` hand everything after them, verbatim, to the
        # benchmark's own parser (argparse would otherwise claim options such as --json)
        run: Any = lambda: commands.cmd_speed(argv[1:])   # noqa: E731
        command = "speed"
    else:
        args = build_parser().parse_args(argv)
        command = args.command
        run = lambda: commands.COMMANDS[command](args)    # noqa: E731
    from threadpoolctl import threadpool_limits

    try:
        # Every matrix here is small: a multi-threaded BLAS only adds thread hand-offs,
        # and on a busy machine its spinning threads can make a 2x2 solve cost ms.
        with threadpool_limits(limits=1, user_api="blas"):
            return int(run())
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print(f"fir-gym {command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:
        message = user_error(err)
        if message is None:
            raise
        if debug:
            traceback.print_exc()
        print(f"fir-gym {command}: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
