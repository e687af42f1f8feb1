"""The documentation site and the package's metadata files agree with the code.

``mkdocs build --strict`` (in ``.ci/run``) catches broken links and anchors and objects
that cannot be found, but it silently skips a name in a ``members:`` list that no longer
exists, and it cannot know that a new environment or estimator has no page. These tests
can, without MkDocs installed.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import fir_gym
from fir_gym import estimators

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: ``::: dotted.path`` and the ``members: [...]`` list of its options block, if any
DIRECTIVE = re.compile(r"^::: ([\w.]+)\n((?:[ \t]+.*\n|\n)*)", re.MULTILINE)
MEMBERS = re.compile(r"^\s+members:\s*\[([^\]]*)\]", re.MULTILINE)


def directives() -> list[tuple[str, str, list[str]]]:
    """``(page, dotted path, members)`` for every mkdocstrings directive of the site."""
    out = []
    for page in sorted(DOCS.rglob("*.md")):
        for target, options in DIRECTIVE.findall(page.read_text(encoding="utf-8")):
            listed = MEMBERS.search(options)
            members = [m.strip() for m in listed.group(1).split(",")] if listed else []
            out.append((str(page.relative_to(DOCS)), target, [m for m in members if m]))
    return out


def resolve(dotted: str) -> object:
    """The object at ``dotted``: the longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(dotted)


def rendered_names() -> set[str]:
    """Qualified names of everything the API pages render (directives and their members)."""
    names = set()
    for _, target, members in directives():
        names.add(target)
        names.update(f"{target}.{m}" for m in members)
    return names


def test_the_site_renders_something():
    assert len(directives()) > 20


@pytest.mark.parametrize(("page", "target", "members"), directives(),
                         ids=lambda v: v if isinstance(v, str) else None)
def test_every_rendered_object_exists(page, target, members):
    obj = resolve(target)
    missing = [m for m in members if not hasattr(obj, m)]
    assert missing == [], f"{page}: {target} has no {missing}"


def test_every_environment_has_its_page():
    import gymnasium as gym

    rendered = rendered_names()
    for env_id in fir_gym.ENV_IDS:
        cls = type(gym.make(env_id).unwrapped)
        assert f"{cls.__module__}.{cls.__qualname__}" in rendered, f"no page renders {env_id}"


def test_every_registered_estimator_is_rendered():
    rendered = rendered_names()
    for name in estimators.estimator_names():
        cls = estimators.estimator_class(name)
        assert f"{cls.__module__}.{cls.__qualname__}" in rendered, f"no page renders {name}"


def test_every_page_is_in_the_navigation():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    pages = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")}
    assert sorted(p for p in pages if p not in nav) == []


# ------------------------------------------------------------------ metadata files
def project_field(name: str) -> str:
    """A string field of pyproject.toml's ``[project]`` table (no TOML parser on Python 3.10)."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    table = text.split("\n[project]\n", 1)[1].split("\n[", 1)[0]
    match = re.search(rf'^{re.escape(name)} = (.+)$', table, re.MULTILINE)
    assert match, f"pyproject.toml's [project] has no {name}"
    return match.group(1).strip()


def citation_field(name: str) -> str:
    match = re.search(rf"^{name}:\s*(\S.*)$", (ROOT / "CITATION.cff").read_text(encoding="utf-8"),
                      re.MULTILINE)
    assert match, f"CITATION.cff has no top-level {name}"
    return match.group(1).strip().strip("\"'")


def test_version_and_licence_agree_everywhere():
    assert project_field("version") == f'"{fir_gym.__version__}"'
    assert fir_gym.__version__ == citation_field("version")
    assert project_field("license") == '"MIT"' and citation_field("license") == "MIT"
    assert '"LICENSE"' in project_field("license-files")
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")


def test_changelog_has_this_version_and_an_unreleased_section():
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert re.search(r"^## \[Unreleased\]$", changelog, re.MULTILINE)
    assert re.search(rf"^## \[{re.escape(fir_gym.__version__)}\] - \d{{4}}-\d\d-\d\d$",
                     changelog, re.MULTILINE)


def test_citation_lists_the_five_papers_with_authors():
    text = (ROOT / "CITATION.cff").read_text(encoding="utf-8")
    references = text.split("\nreferences:\n", 1)[1]
    entries = re.split(r"\n  - type: ", references)[1:]
    assert len(entries) == 5
    for entry in entries:
        assert re.search(r"^\s+title: \S", entry, re.MULTILINE)
        assert re.search(r"^\s+- family-names: \S", entry, re.MULTILINE), entry[:80]
