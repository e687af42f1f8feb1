"""Mutation testing of the modules that carry the mathematics, and its table.

    pip install ".[mutation]"
    python scripts/mutation.py [MODULE ...] [--out docs/mutation.md] [--list]

The tool is cosmic-ray (https://cosmic-ray.readthedocs.io). It mutates the module's file
*in place*, one mutant at a time, runs a test command, and restores the file: that works
with this repository's package-dir mapping and its strict editable install, where the
installed ``fir_gym.estimators`` *is* ``estimators/`` — a tool that runs the tests on a
copied tree (mutmut 3's ``mutants/``) would test the unmutated installed files instead.

``pyproject.toml``'s ``[tool.fir-gym.mutation]`` says what is mutated and against what: each
module with the test files that cover it, so a module is run against its own tests, not
the whole suite, and a full run fits in about an hour on 2 cores. Run it on a checkout
nobody else is testing from (the files change under the tests while it runs), never in CI.

Each module's result — mutants, killed, survived, incompetent (the mutant does not even
import or compile: no test could run) and the kill rate over the competent ones — goes into
the table (``--out``, default ``docs/mutation.md``, rewritten for the modules run, with the
date and the commit), followed by the surviving mutants (line, operator, the diff's changed
line) for triage: each is killed by a new test with an oracle or recorded there as
equivalent with the reason.
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

try:
    import tomllib  # Python 3.11+
except ModuleNotFoundError:             # pragma: no cover - Python 3.10
    raise SystemExit("scripts/mutation.py needs Python 3.11 or newer (tomllib)") from None

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Outcome:
    """The mutants of one module by outcome, and the survivors' descriptions."""

    module: str
    killed: int = 0
    survived: int = 0
    incompetent: int = 0
    survivors: list[str] = field(default_factory=list)

    @property
    def competent(self) -> int:
        return self.killed + self.survived

    @property
    def rate(self) -> float:
        return self.killed / self.competent if self.competent else float("nan")


def configuration(root: Path = ROOT) -> tuple[float, dict[str, list[str]]]:
    """``(timeout per mutant in s, {module: [its test files]})`` from pyproject.toml."""
    table = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["fir-gym"]["mutation"]
    modules = {str(m): [str(t) for t in tests] for m, tests in table["modules"].items()}
    for module, tests in modules.items():
        missing = [p for p in (module, *tests) if not (root / p).exists()]
        if missing:
            raise SystemExit(f"[tool.fir-gym.mutation] names files that do not exist: {missing}")
    return float(table.get("timeout", 300.0)), modules


def run_module(module: str, tests: list[str], timeout: float, work: Path) -> Outcome:
    """cosmic-ray on one module against its tests; the outcome read from its session."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    config = work / "cosmic-ray.toml"
    session = work / f"{module.replace('/', '_')}.sqlite"
    command = " ".join([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                        *tests])
    config.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{module}"\n'
        f"timeout = {timeout}\n"
        "excluded-modules = []\n"
        f'test-command = "{command}"\n\n'
        "[cosmic-ray.distributor]\n"
        'name = "local"\n')
    for step in (["init", str(config), str(session)], ["exec", str(config), str(session)]):
        subprocess.run(["cosmic-ray", *step], cwd=ROOT, check=True)
    outcome = Outcome(module)
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            if result.test_outcome == TestOutcome.KILLED:
                outcome.killed += 1
            elif result.test_outcome == TestOutcome.SURVIVED:
                outcome.survived += 1
                spec = item.mutations[0]
                changed = next((line[1:].strip() for line in (result.diff or "").splitlines()
                                if line.startswith("+") and not line.startswith("+++")), "")
                outcome.survivors.append(f"line {spec.start_pos[0]}: {spec.operator_name} "
                                         f"→ `{changed}`")
            else:
                outcome.incompetent += 1
    return outcome


def table(outcomes: list[Outcome], commit: str) -> str:
    """The Markdown page: the per-module table, then each module's survivors."""
    today = datetime.date.today().isoformat()
    lines = [
        "# Mutation testing", "",
        f"Run {today} at commit `{commit}` by `python scripts/mutation.py` (cosmic-ray; the "
        "modules and the tests each is run against: `[tool.fir-gym.mutation]` in "
        "pyproject.toml). A mutant is killed when a test of its module fails; incompetent "
        "when it does not import or compile. The kill rate is over the competent mutants.", "",
        "| module | mutants | killed | survived | incompetent | kill rate |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for o in outcomes:
        total = o.competent + o.incompetent
        lines.append(f"| `{o.module}` | {total} | {o.killed} | {o.survived} | "
                     f"{o.incompetent} | {o.rate:.0%} |")
    for o in outcomes:
        if o.survivors:
            lines += ["", f"## Survivors in `{o.module}`", ""]
            lines += [f"- {s}" for s in o.survivors]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help="modules to mutate (default: every one "
                        "configured)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "mutation.md")
    parser.add_argument("--list", action="store_true", help="list the configured modules")
    args = parser.parse_args(argv)
    timeout, configured = configuration()
    if args.list:
        for module, tests in configured.items():
            print(f"{module}: {' '.join(tests)}")
        return 0
    unknown = [m for m in args.modules if m not in configured]
    if unknown:
        parser.error(f"not configured in [tool.fir-gym.mutation]: {unknown}")
    modules = args.modules or list(configured)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                            capture_output=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="fir-gym-mutation-") as work:
        outcomes = [run_module(m, configured[m], timeout, Path(work)) for m in modules]
    args.out.write_text(table(outcomes, commit))
    for o in outcomes:
        print(f"{o.module}: {o.killed}/{o.competent} killed ({o.rate:.0%}), "
              f"{o.incompetent} incompetent")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
