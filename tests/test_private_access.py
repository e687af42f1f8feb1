"""No module reads or writes another object's private attributes (issue 25, item 3).

A static scan of the package: every ``obj._name`` (not a dunder) whose ``obj`` is not
``self``, ``cls`` or ``super()`` must be one of the few listed below, each with the reason it
is not a reach-in. State is passed as records (an estimator's ``state``, a plant's
``design_point()``), so a new reach-in fails here with its file and expression.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("fir_gym", "envs", "estimators")

#: (file, the object's expression, attribute) → why it is not another object's private state
ALLOWED: dict[tuple[str, str, str], str] = {
    # NamedTuple's public API is spelled with an underscore
    ("estimators/recursive_fir.py", "self._win", "_fields"): "NamedTuple API",
    ("estimators/recursive_fir.py", "self._win", "_replace"): "NamedTuple API",
    # a class's own members, used inside the module that defines the class
    ("estimators/model.py", "LinearModel", "_linear_f"): "LinearModel's own method, in model.py",
    ("estimators/model.py", "LinearModel", "_linear_F"): "LinearModel's own method, in model.py",
    ("estimators/model.py", "LinearModel", "_linear_h"): "LinearModel's own method, in model.py",
    ("estimators/model.py", "LinearModel", "_linear_H"): "LinearModel's own method, in model.py",
    ("estimators/unscented.py", "sp", "_finish"): "the sigma points' class is in unscented.py",
    # the Kalman family's public steps are a mixin of the estimator itself (est is self)
    ("estimators/public_steps.py", "est", "_stepping_with"): "est is self (a mixin)",
}

#: the batched hooks of PlantEnv (envs/_base.py) its native vector env calls: the interface a
#: plant author implements for envs/_vector.py, documented there (method calls, no state)
PLANT_HOOKS = {"_apply_params", "_in_domain", "_measure", "_perturb", "_reward",
               "_terminal_reward", "_transition", "_check_state", "_sample_initial_state"}


def reach_ins(root: Path = ROOT) -> list[tuple[str, str, str, int]]:
    found = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                        and not node.attr.startswith("__")):
                    continue
                owner = node.value
                if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
                    continue
                if (isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name)
                        and owner.func.id == "super"):
                    continue
                key = (rel, ast.unparse(owner), node.attr)
                if key in ALLOWED:
                    continue
                if rel == "envs/_vector.py" and node.attr in PLANT_HOOKS \
                        and isinstance(node.ctx, ast.Load):
                    continue
                found.append((*key, node.lineno))
    return found


def test_no_module_reaches_into_another_objects_private_attributes() -> None:
    found = reach_ins()
    assert not found, "private attributes read or written from outside their object:\n" + \
        "\n".join(f"  {f}:{line}: {obj}.{attr}" for f, obj, attr, line in found)


def test_the_scan_finds_a_reach_in(tmp_path: Path) -> None:
    """The scan is not vacuous: the reach-ins the issue named are caught, a filter's own
    attribute and a record's field are not."""
    (tmp_path / "estimators").mkdir()
    (tmp_path / "estimators" / "steps.py").write_text(
        "def predict(est, flt):\n    est._update_next = False\n    x = flt._x\n"
        "    est.state.update_next = False\n    return self._k, x\n")
    found = {(obj, attr) for _, obj, attr, _ in reach_ins(tmp_path)}
    assert found == {("est", "_update_next"), ("flt", "_x")}
