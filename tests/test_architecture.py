"""The arrows of docs/architecture.md#imports: estimators ← envs ← fir_gym."""

import ast
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "estimators": {"gymnasium", "gym", "mujoco", "torch", "stable_baselines3", "envs",
                   "fir_gym.envs", "fir_gym.wrappers", "fir_gym.scenarios", "matplotlib",
                   "fir_gym.controllers"},
    # a plant publishes its design point as a fir_gym.envs.DesignPoint: the controllers
    # import the plants' record, never the other way (docs/architecture.md#design-point)
    "envs": {"torch", "stable_baselines3", "fir_gym.wrappers", "fir_gym.scenarios",
             "fir_gym.controllers"},
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


# ---------------------------------------------------------------------------------------------
# Citations: the repository cites its own documents (docs/architecture.md, docs/papers.md) by
# anchor, never the design notes it was started from. The names are assembled here so that this
# file does not cite them itself.
OUTSIDE_DOCUMENTS = ("ARCHITECTURE" + ".md", "PAPERS" + ".md", "../" + "shared",
                     "/work/" + "shared")
#: ``docs/<page>.md#<anchor>`` as code and docstrings cite it
CITATION = re.compile(r"docs/((?:[\w-]+/)*[\w-]+\.md)#([\w-]+)")
#: the stable anchors of a page: ``<a id="...">`` before a heading, or ``{#...}`` after one
ANCHOR = re.compile(r"""<a\s+(?:id|name)=["']([^"']+)["']|\{\s*#([\w-]+)[^}]*\}""")


def tracked_files() -> list[Path]:
    """The files git tracks (the checkout's own, not build output or a venv)."""
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], check=True,
                             capture_output=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the citation checks read the tracked files")
    return [ROOT / name for name in out.decode().split("\0") if name and (ROOT / name).is_file()]


def anchors_of(page: Path) -> list[str]:
    return [a or b for a, b in ANCHOR.findall(page.read_text(encoding="utf-8"))]


def test_no_file_cites_the_outside_design_notes():
    offenders = []
    for path in tracked_files():
        data = path.read_bytes()
        offenders += [f"{path.relative_to(ROOT)} cites {name}" for name in OUTSIDE_DOCUMENTS
                      if name.encode() in data]
    assert offenders == [], "cite docs/architecture.md or docs/papers.md instead"


def test_every_cited_docs_anchor_exists():
    cited: dict[tuple[str, str], list[str]] = {}
    for path in tracked_files():
        text = path.read_bytes().decode("utf-8", errors="replace")
        for page, anchor in CITATION.findall(text):
            cited.setdefault((page, anchor), []).append(str(path.relative_to(ROOT)))
    assert cited, "no docs/...md#anchor citation found: the pattern no longer matches the code"
    anchors = {}
    missing = []
    for (page, anchor), where in sorted(cited.items()):
        target = ROOT / "docs" / page
        if not target.is_file():
            missing.append(f"docs/{page} (cited by {', '.join(where)}) does not exist")
            continue
        anchors.setdefault(page, set(anchors_of(target)))
        if anchor not in anchors[page]:
            missing.append(f"docs/{page}#{anchor} (cited by {', '.join(sorted(set(where)))}) "
                           "is not an anchor of the page")
    assert missing == []


@pytest.mark.parametrize("page", ["architecture.md", "papers.md"])
def test_anchors_are_unique(page):
    ids = anchors_of(ROOT / "docs" / page)
    assert ids, f"docs/{page} has no stable anchors"
    assert sorted(i for i in set(ids) if ids.count(i) > 1) == []
