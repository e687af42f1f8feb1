"""Mutation testing of the modules that carry the mathematics, and its table.

    pip install ".[mutation]"
    python scripts/mutation.py [MODULE ...] [--results DIR] [--out docs/mutation.md]
    python scripts/mutation.py --table-only [--results DIR] [--out docs/mutation.md]
    python scripts/mutation.py --list

The tool is cosmic-ray (https://cosmic-ray.readthedocs.io). It mutates the module's file
*in place*, one mutant at a time, runs a test command, and restores the file: that works
with this repository's package-dir mapping and its strict editable install, where the
installed ``fir_gym.estimators`` *is* ``estimators/`` — a tool that runs the tests on a
copied tree (mutmut 3's ``mutants/``) would test the unmutated installed files instead.
The tests run as ``python -P -m pytest``: ``-P`` keeps the checkout's root off
``sys.path``, where the source folder ``fir_gym/`` (without its mapped sub-packages)
would shadow the installed package and make every test fail to import — every mutant
would then count as killed.

``pyproject.toml``'s ``[tool.fir-gym.mutation]`` says what is mutated and how:

* ``modules``: each module with the test files (or pytest node ids, ``file::test``) that
  cover it, so a module is run against its own tests, not the whole suite;
* ``operators``: the mutation operators kept (regular expressions on cosmic-ray's operator
  names) — the plausible slips of a numerical code (``+``/``−``, ``*``/``/``, ``**``→``*``,
  a comparison's boundary or its negation, a dropped minus or ``not``, a number off by one,
  a loop run zero times, ``and``/``or``, ``True``/``False``, ``break``/``continue``, an
  exception type); left out are cosmic-ray's replacements by bitwise and shift operators,
  ``%`` and ``//`` for float arithmetic (a type error or a wildly wrong number that any test
  kills: they inflate the rate), ``−x``→``+x`` (the same mutant as deleting the minus),
  ``−x``→``~x``/``not x``, the comparison replacements that are neither a boundary nor
  a negation, and the removal of decorators (``@njit`` off gives the same numbers slower);
* ``sample`` and ``seed``: how many of a module's kept mutants are run, drawn with a fixed
  seed (the same code gives the same sample), so that a full run of every module fits in
  about an hour on 2 cores; the kill rate is then an estimate and the table gives its 95 %
  (Wilson) interval;
* ``cold-cache``: the modules whose numba kernels are compiled into kernels of other files
  (an inlined piece or a called kernel): their mutants run with numba's cache emptied first
  — numba checks a cached kernel against its own file only, so a cached caller would run the
  unmutated callee (a gross mutant of ``estimators/compiled/linalg.py`` survived that way).
  Each of their mutants then compiles every kernel its tests use (a minute or two on 2
  cores), so they run ``cold-sample`` mutants instead of ``sample``;
* ``twin-only``: the modules (glob patterns) that hold compiled code only; every other
  module's tests run twice, with the compiled twins off (``FIR_GYM_NUMBA=0``: the numpy
  reference steps) and on — with the twins on alone, a mutant of a numpy reference goes
  unseen wherever the twin runs in its place (``estimators/_fir_bank.py``'s first run killed
  3 of 20);
* ``equivalent``: the mutants triaged as equivalent (they cannot change any result), each
  with its module, operator, mutated line and the reason; they leave the kill rate's
  denominator and are listed with their reason;
* ``killed-since``: survivors of a module's last run that a test added after it kills, each
  checked with ``scripts/apply_mutant.py`` (control first), with the test as ``reason``: the
  table counts them in its *now* column until a new run of the module replaces both.

Before a module's mutants, its tests run once unmutated (the baseline): if they fail, or
do not run at all, the run stops — a test command that cannot pass would kill every mutant.
Each mutant's timeout is five times the baseline's time (at least 60 s).

Each module's result goes to a JSON file in ``--results`` (default ``.mutation/``), and the
page (``--out``, default ``docs/mutation.md``) is written from every result there, with the
date and the commit of each: so two checkouts (each with its own virtual environment and
strict editable install) can share the modules between them and one ``--table-only`` joins
their results. Run it on a checkout nobody else is testing from (its files change under
the tests while it runs), never in CI.
"""

from __future__ import annotations

import argparse
import datetime
import fnmatch
import json
import math
import os
import random
import re
import shlex
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

try:
    import tomllib  # Python 3.11+
except ModuleNotFoundError:             # pragma: no cover - Python 3.10
    raise SystemExit("scripts/mutation.py needs Python 3.11 or newer (tomllib)") from None

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Triaged:
    """A surviving mutant triaged by hand: equivalent (``reason``: why it cannot change a
    result) or killed since by a later test (``reason``: the test)."""

    module: str
    operator: str
    mutated: str
    reason: str


@dataclass(frozen=True)
class Configuration:
    """``[tool.fir-gym.mutation]`` of pyproject.toml."""

    modules: dict[str, list[str]]
    operators: list[str]
    sample: int
    seed: int
    equivalent: list[Triaged]
    #: survivors of a module's last run killed by a test added after it (``reason``: the
    #: test), each checked with scripts/apply_mutant.py
    killed_since: list[Triaged]
    #: modules whose mutants run with numba's cache emptied, and their sample size
    cold_cache: list[str]
    cold_sample: int
    #: modules (glob patterns) that are compiled code only: their tests run with the twins on
    twin_only: list[str]

    def sample_size(self, module: str) -> int:
        return self.cold_sample if module in self.cold_cache else self.sample

    def keeps(self, operator: str) -> bool:
        return any(re.fullmatch(pattern, operator) for pattern in self.operators)

    def equivalent_reason(self, module: str, operator: str, mutated: str) -> str | None:
        return _find(self.equivalent, module, operator, mutated)

    def killed_by(self, module: str, operator: str, mutated: str) -> str | None:
        return _find(self.killed_since, module, operator, mutated)


def _find(entries: list[Triaged], module: str, operator: str, mutated: str) -> str | None:
    for e in entries:
        if (e.module, e.operator, e.mutated) == (module, operator, mutated):
            return e.reason
    return None


@dataclass
class Outcome:
    """The sampled mutants of one module by outcome, and the survivors."""

    module: str
    commit: str
    date: str
    kept: int = 0
    killed: int = 0
    incompetent: int = 0
    seconds: float = 0.0
    #: each surviving mutant: line, operator, the mutated line
    survivors: list[dict[str, object]] = field(default_factory=list)


def configuration(root: Path = ROOT) -> Configuration:
    """The mutation configuration from pyproject.toml, its files checked."""
    table = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["fir-gym"]["mutation"]
    modules = {str(m): [str(t) for t in tests] for m, tests in table["modules"].items()}
    for module, tests in modules.items():
        missing = [p for p in (module, *tests) if not (root / p.split("::")[0]).exists()]
        if missing:
            raise SystemExit(f"[tool.fir-gym.mutation] names files that do not exist: {missing}")
    equivalent = [Triaged(**e) for e in table.get("equivalent", [])]
    killed_since = [Triaged(**e) for e in table.get("killed-since", [])]
    cold = [str(m) for m in table.get("cold-cache", [])]
    unknown = sorted(({e.module for e in equivalent + killed_since} | set(cold))
                     - set(modules))
    if unknown:
        raise SystemExit("[tool.fir-gym.mutation] equivalent or cold-cache entries of "
                         f"unlisted modules: {unknown}")
    return Configuration(modules, [str(p) for p in table["operators"]], int(table["sample"]),
                         int(table["seed"]), equivalent, killed_since,
                         cold,
                         int(table.get("cold-sample", table["sample"])),
                         [str(p) for p in table.get("twin-only", [])])


def test_command(tests: list[str], cold_cache: Path | None = None, both_paths: bool = True
                 ) -> str:
    """The test command of a module (``-P``: the checkout's root stays off ``sys.path``).

    ``both_paths``: the tests run twice, first with the compiled twins off
    (``FIR_GYM_NUMBA=0``: every step takes the numpy reference, which is what a mutant of a
    reference changes — with the twins on, the twin runs instead and the mutant goes
    unseen), then as they are. With ``cold_cache``, numba's cache folder is emptied before
    the tests and used by them: a cached kernel of another file that inlined a function of
    the mutated module would otherwise run the unmutated code (numba checks only the
    kernel's own file's stamp).
    """
    pytest = " ".join([sys.executable, "-P", "-m", "pytest", "-x", "-q", "-p",
                       "no:cacheprovider", *tests])
    run = f"FIR_GYM_NUMBA=0 {pytest} && {pytest}" if both_paths else f"exec {pytest}"
    if cold_cache is not None:
        run = f"rm -rf {cold_cache} && export NUMBA_CACHE_DIR={cold_cache} && {run}"
    return f"sh -c '{run}'"


def baseline(module: str, command: str) -> float:
    """Run the module's tests unmutated; their time in s. Stops the run if they fail."""
    start = time.perf_counter()
    run = subprocess.run(shlex.split(command), cwd=ROOT, capture_output=True, text=True)
    if run.returncode != 0:
        tail = "\n".join(run.stdout.strip().splitlines()[-15:])
        raise SystemExit(f"the unmutated tests of {module} do not pass (exit "
                         f"{run.returncode}), so every mutant would count as killed:\n{tail}")
    return time.perf_counter() - start


def sample(items: list, config: Configuration, module: str) -> list:
    """The mutants run for a module: the kept operators' mutants, a seeded sample of them."""
    kept = [i for i in items if config.keeps(i.mutations[0].operator_name)]
    kept.sort(key=lambda i: (i.mutations[0].start_pos, i.mutations[0].operator_name,
                             i.mutations[0].occurrence))
    rng = random.Random(f"{config.seed}:{module}")
    size = config.sample_size(module)
    return kept if len(kept) <= size else rng.sample(kept, size)


def mutated_line(diff: str | None) -> str:
    """The changed line of a mutant's diff, stripped."""
    return next((line[1:].strip() for line in (diff or "").splitlines()
                 if line.startswith("+") and not line.startswith("+++")), "")


def run_module(module: str, config: Configuration, work: Path, commit: str) -> Outcome:
    """cosmic-ray on one module's sample against its tests; the outcome from its session."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome, WorkResult

    cold = module in config.cold_cache
    both = not any(fnmatch.fnmatch(module, pattern) for pattern in config.twin_only)
    command = test_command(config.modules[module], work / "numba-cold" if cold else None, both)
    timeout = max(60.0, 5.0 * baseline(module, command))
    cr_config = work / "cosmic-ray.toml"
    session = work / f"{module.replace('/', '_')}.sqlite"
    session.unlink(missing_ok=True)
    cr_config.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{module}"\n'
        f"timeout = {timeout}\n"
        "excluded-modules = []\n"
        f'test-command = "{command}"\n\n'
        "[cosmic-ray.distributor]\n"
        'name = "local"\n')
    subprocess.run(["cosmic-ray", "init", str(cr_config), str(session)], cwd=ROOT, check=True)
    outcome = Outcome(module, commit, datetime.date.today().isoformat())
    with use_db(str(session), WorkDB.Mode.open) as db:
        items = list(db.work_items)
        chosen = {i.job_id for i in sample(items, config, module)}
        outcome.kept = sum(config.keeps(i.mutations[0].operator_name) for i in items)
        db.set_multiple_results(
            [i.job_id for i in items if i.job_id not in chosen],
            WorkResult(output="not sampled", worker_outcome=WorkerOutcome.SKIPPED))
    start = time.perf_counter()
    subprocess.run(["cosmic-ray", "exec", str(cr_config), str(session)], cwd=ROOT, check=True)
    outcome.seconds = time.perf_counter() - start
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            if result.worker_outcome == WorkerOutcome.SKIPPED:
                continue
            if result.test_outcome == TestOutcome.KILLED:
                outcome.killed += 1
            elif result.test_outcome == TestOutcome.SURVIVED:
                spec = item.mutations[0]
                outcome.survivors.append({"line": spec.start_pos[0],
                                          "operator": spec.operator_name,
                                          "mutated": mutated_line(result.diff)})
            else:
                outcome.incompetent += 1
    outcome.survivors.sort(key=lambda s: (s["line"], s["operator"]))
    return outcome


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a proportion ``k / n``."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def table(outcomes: list[Outcome], config: Configuration) -> str:
    """The Markdown page: the per-module table, then each module's survivors."""
    commits = sorted({o.commit for o in outcomes})
    dates = sorted({o.date for o in outcomes})
    lines = [
        "# Mutation testing", "",
        f"Run {', '.join(dates)} at commit{'s' if len(commits) > 1 else ''} "
        f"{', '.join(f'`{c}`' for c in commits)} by `python scripts/mutation.py` (cosmic-ray; "
        "what is mutated, with which operators, against which tests, and the sample size: "
        "`[tool.fir-gym.mutation]` in pyproject.toml; how: the script's docstring). *Kept*: "
        "the module's mutants of the kept operators; *run*: the seeded sample of them that "
        "ran. A mutant is killed when a test of its module fails or times out; incompetent "
        "when it does not compile; equivalent when triaged as unable to change any number the "
        "module computes (its reason below; a mutant of drawing code only is listed as "
        "such). The kill rate is killed / (run − incompetent − equivalent), "
        "with its 95 % Wilson interval over the sample. *Killed since*: survivors of the "
        "module's run that a test added after it kills (each checked with "
        "`scripts/apply_mutant.py`, control first; the test is named below) — *now* counts "
        "them; a new run of the module replaces both.", "",
        "**Why cosmic-ray.** It mutates the module's own file in place and runs any test "
        "command, which is what this repository's package-dir mapping needs: the strict "
        "editable install serves `fir_gym.estimators` from `estimators/` itself, so a tool "
        "that copies the tree and tests the copy (mutmut 3's `mutants/` folder) would test "
        "the unmutated installed files. Its operators are filtered to the plausible slips of "
        "numerical code, and a seeded sample of each module's mutants runs, so that a full "
        "run fits in about an hour on 2 cores, two checkouts in parallel (the script's "
        "docstring says which operators and why).", "",
        "**Run it.** `pip install \".[mutation]\"`, then `python scripts/mutation.py "
        "[MODULE ...]` on a checkout nobody else is testing from (it edits the files while "
        "it runs); `--results DIR` shares one results folder between two checkouts, each "
        "with its own virtual environment, and `--table-only` writes this page from it. "
        "`python scripts/apply_mutant.py MODULE OLD NEW [pytest args]` applies one mutant in "
        "memory and runs the given tests: the check that a new test kills the survivor it "
        "was written for (with `OLD` = `NEW`, the control, the tests pass).", "",
        "| module | kept | run | killed | survived | equivalent | incompetent | kill rate "
        "| 95 % interval | time | commit | killed since | now |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---|---:|---:|",
    ]
    rows = []
    for o in sorted(outcomes, key=lambda o: o.module):
        equivalent = [s for s in o.survivors if config.equivalent_reason(
            o.module, str(s["operator"]), str(s["mutated"]))]
        survived = len(o.survivors) - len(equivalent)
        competent = o.killed + survived
        run = competent + len(equivalent) + o.incompetent
        rate = o.killed / competent if competent else float("nan")
        low, high = wilson(o.killed, competent)
        since = sum(1 for s in o.survivors if config.killed_by(
            o.module, str(s["operator"]), str(s["mutated"])))
        now = (o.killed + since) / competent if competent else float("nan")
        lines.append(f"| `{o.module}` | {o.kept} | {run} | {o.killed} | {survived} | "
                     f"{len(equivalent)} | {o.incompetent} | {rate:.0%} | "
                     f"{low:.0%}–{high:.0%} | {o.seconds / 60:.1f} min | `{o.commit}` | "
                     f"{since} | {now:.0%} |")
        rows.append((o, equivalent))
    total_killed = sum(o.killed for o in outcomes)
    total_competent = sum(o.killed + len(o.survivors) - len(eq) for o, eq in rows)
    lines += ["", f"Over all modules: {total_killed} of {total_competent} non-equivalent "
              f"mutants killed ({total_killed / max(total_competent, 1):.1%}), in "
              f"{sum(o.seconds for o in outcomes) / 60:.0f} min of mutant runs (summed over "
              "the modules; two checkouts in parallel take about half of it in wall time)."]
    for o, _ in rows:
        if not o.survivors:
            continue
        lines += ["", f"## Survivors in `{o.module}`", ""]
        for s in o.survivors:
            key = (o.module, str(s["operator"]), str(s["mutated"]))
            reason, test = config.equivalent_reason(*key), config.killed_by(*key)
            note = (f" — equivalent: {reason}" if reason else
                    f" — killed since by {test}" if test else "")
            lines.append(f"- line {s['line']}: {s['operator']} → `{s['mutated']}`{note}")
    return "\n".join(lines) + "\n"


def read_results(results: Path) -> list[Outcome]:
    return [Outcome(**json.loads(p.read_text())) for p in sorted(results.glob("*.json"))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help="modules to mutate (default: every one "
                        "configured)")
    parser.add_argument("--results", type=Path, default=ROOT / ".mutation",
                        help="folder of the per-module results (JSON)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "mutation.md")
    parser.add_argument("--list", action="store_true", help="list the configured modules")
    parser.add_argument("--table-only", action="store_true",
                        help="write the page from the results already in --results")
    args = parser.parse_args(argv)
    config = configuration()
    if args.list:
        for module, tests in config.modules.items():
            print(f"{module}: {' '.join(tests)}")
        return 0
    unknown = [m for m in args.modules if m not in config.modules]
    if unknown:
        parser.error(f"not configured in [tool.fir-gym.mutation]: {unknown}")
    args.results.mkdir(parents=True, exist_ok=True)
    if not args.table_only:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                                capture_output=True, check=True).stdout.strip()
        with tempfile.TemporaryDirectory(prefix="fir-gym-mutation-") as work:
            # one numba cache for the run, outside the checkout (the cold modules use their own)
            os.environ["NUMBA_CACHE_DIR"] = str(Path(work) / "numba")
            for module in args.modules or list(config.modules):
                o = run_module(module, config, Path(work), commit)
                name = module.replace("/", "_").removesuffix(".py") + ".json"
                (args.results / name).write_text(json.dumps(asdict(o), indent=1))
                print(f"{module}: {o.killed}/{o.killed + len(o.survivors)} killed, "
                      f"{o.incompetent} incompetent, {o.seconds:.0f} s", flush=True)
    outcomes = read_results(args.results)
    if not outcomes:
        raise SystemExit(f"no results in {args.results}")
    args.out.write_text(table(outcomes, config))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
