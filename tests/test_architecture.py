"""The arrows of ARCHITECTURE.md: estimators ← envs ← fir_gym."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "estimators": {"gymnasium", "gym", "mujoco", "torch", "stable_baselines3", "envs",
                   "fir_gym.envs", "fir_gym.wrappers", "fir_gym.scenarios", "matplotlib"},
    "envs": {"torch", "stable_baselines3", "fir_gym.wrappers", "fir_gym.scenarios"},
}


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_imports_point_the_agreed_way(package):
    offenders = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for name in imported_modules(path):
            if any(name == bad or name.startswith(bad + ".") for bad in FORBIDDEN[package]):
                offenders.append(f"{path.relative_to(ROOT)} imports {name}")
    assert offenders == []


def test_plants_import_no_concrete_filter():
    for path in sorted((ROOT / "envs").rglob("*.py")):
        for name in imported_modules(path):
            if name.startswith("fir_gym.estimators."):
                assert name.split(".")[2] in {"_validation", "model", "discretize", "augment",
                                              "continuous", "compiled"}, \
                    f"{path.name} imports {name}: plants publish models, never use filters"
