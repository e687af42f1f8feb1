"""Speed benchmarks: each module measures ratios against a reference timed in the same run.

``fir-gym speed`` (:mod:`.speed`) runs them; its parser lives here, away from the
benchmarks' imports (Gymnasium, the estimators, numba), so ``fir-gym speed --help``
answers at once.
"""

from __future__ import annotations

import argparse

#: the sections of ``fir-gym speed``, in the order they run
SECTIONS = ("kalman", "estimators", "envs", "wrappers", "training", "fir")


def speed_parser() -> argparse.ArgumentParser:
    """The parser of ``fir-gym speed`` (and of its old name, ``fir-gym bench``)."""
    from .._cli_parser import Parser

    parser = Parser(prog="fir-gym speed",
                    description="Every speed figure of fir-gym in one run, as ratios to "
                                "references timed in the same run. `fir-gym bench` is the "
                                "same command under its old name.")
    parser.add_argument("--json", metavar="PATH", default=None,
                        help="also write the results as JSON ('-' for standard output; "
                             "default: none)")
    parser.add_argument("--quick", action="store_true", help="short timings (about 10x faster)")
    parser.add_argument("sections", nargs="*", choices=[*SECTIONS, "all"], default="all",
                        metavar="SECTION",
                        help=f"sections to run: {', '.join(SECTIONS)} or all (default: all)")
    parser.add_argument("--debug", action="store_true",
                        help="on an error, print its traceback as well as the one-line message")
    return parser
