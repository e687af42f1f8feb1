"""fir_gym.jax is optional: nothing else imports it, and without its extra it says which.

These run without JAX installed (no importorskip): the scan is static and the import guard
is exercised with ``jax``/``gymnax`` hidden from a fresh interpreter.
"""

from __future__ import annotations

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def resolved_imports(path: Path) -> dict[str, list[str]]:
    """Every imported module of ``path`` (relative imports resolved) -> the names of the
    functions importing it (``"<module>"`` at module level)."""
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    found: dict[str, list[str]] = {}

    def visit(node: ast.AST, where: str) -> None:
        for child in ast.iter_child_nodes(node):
            inner = child.name if isinstance(child, (ast.FunctionDef,
                                                     ast.AsyncFunctionDef)) else where
            names: list[str] = []
            if isinstance(child, ast.Import):
                names = [alias.name for alias in child.names]
            elif isinstance(child, ast.ImportFrom):
                base = list(package[:len(package) - child.level + 1]) if child.level else []
                module = ".".join([*base, *([child.module] if child.module else [])])
                names = [module, *(f"{module}.{alias.name}" for alias in child.names)]
            for name in names:
                found.setdefault(name, []).append(where)
            visit(child, inner)

    visit(ast.parse(path.read_text(encoding="utf-8")), "<module>")
    return found


#: the places outside fir_gym.jax that import it, each inside the function that runs it
#: (nothing at module level): `fir-gym train --backend jax`, `fir-gym benchmark-controllers
#: --backend jax`, `fir-gym evaluate` on a JAX run folder, and the robustness benchmark's
#: learned grid with `learned_backend="jax"` (`benchmark-robustness --backend jax`), and a
#: JAX run's policy in `fir-gym watch` / `record --policy RUN`
ALLOWED = {("fir_gym/_commands.py", "train_jax"), ("fir_gym/_commands.py", "benchmark_jax"),
           ("fir_gym/_commands.py", "evaluate_jax"),
           ("fir_gym/robustness/benchmark.py", "run_benchmark"),
           ("fir_gym/episode_policy.py", "trained_policy"),
           # JAX's CPU device count, set before anything starts its backends
           ("fir_gym/cpu_devices.py", "request_cpu_devices")}
#: modules that exist to measure the JAX backend (`fir-gym speed training`): JAX inside their
#: functions only
MEASURING = {"fir_gym/benchmarks/jax_training.py"}


def test_nothing_outside_fir_gym_jax_imports_it_or_jax() -> None:
    offenders = []
    for package in ("fir_gym", "envs", "estimators"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if (ROOT / "fir_gym" / "jax") in path.parents:
                continue
            where = path.relative_to(ROOT).as_posix()
            bad = {(name, function) for name, functions in resolved_imports(path).items()
                   for function in functions
                   if (name.split(".")[0] in ("jax", "gymnax", "rejax")
                       or name.startswith("fir_gym.jax"))
                   and (where, function) not in ALLOWED
                   and not (where in MEASURING and function != "<module>")}
            if bad:
                offenders.append((where, sorted(bad)))
    assert not offenders


@pytest.mark.parametrize("missing", ["jax", "gymnax", "jaxlib"])
def test_without_the_extra_the_import_names_it(missing: str, tmp_path) -> None:
    code = (f"import sys; sys.modules[{missing!r}] = None\n"
            "try:\n    import fir_gym.jax\nexcept ImportError as e:\n    print(e)\n"
            "else:\n    print('imported')\n")
    # -P: the working folder stays off sys.path (tests/ holds a folder named jax, which would
    # import as a namespace package "jax" where JAX is not installed)
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True,
                         cwd=tmp_path, check=True).stdout.strip()
    assert out.count("\n") == 0 and 'pip install ".[jax]"' in out, out
    # the first package of the import order (jax, then gymnax) that is absent is named —
    # without the extra at all (CI), that is JAX whichever one the test hides
    jax_present = importlib.util.find_spec("jax") is not None
    named = "gymnax" if missing == "gymnax" and jax_present else "JAX"
    assert f"{named} is missing" in out, out
