"""fir_gym.jax is optional: nothing else imports it, and without its extra it says which.

These run without JAX installed (no importorskip): the scan is static and the import guard
is exercised with ``jax``/``gymnax`` hidden from a fresh interpreter.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def imports_of(path: Path) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
    return found


def test_nothing_outside_fir_gym_jax_imports_it_or_jax() -> None:
    offenders = []
    for package in ("fir_gym", "envs", "estimators"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if (ROOT / "fir_gym" / "jax") in path.parents:
                continue
            bad = {name for name in imports_of(path)
                   if name.split(".")[0] in ("jax", "gymnax") or name.startswith("fir_gym.jax")}
            if bad:
                offenders.append((path.relative_to(ROOT).as_posix(), sorted(bad)))
    assert not offenders


@pytest.mark.parametrize("missing", ["jax", "gymnax", "jaxlib"])
def test_without_the_extra_the_import_names_it(missing: str) -> None:
    code = (f"import sys; sys.modules[{missing!r}] = None\n"
            "try:\n    import fir_gym.jax\nexcept ImportError as e:\n    print(e)\n"
            "else:\n    print('imported')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT / "tests", check=True).stdout.strip()
    assert out.count("\n") == 0 and 'pip install ".[jax]"' in out, out
    assert ("gymnax is missing" if missing == "gymnax" else "JAX is missing") in out, out
