"""A griffe extension for the documentation site: Sphinx-style markup in docstrings as Markdown.

The docstrings are written to read well in a terminal and to be rendered by MkDocs: inline
code in double backticks (valid Markdown too) and, in places, Sphinx roles such as
``:class:`~.model.LinearModel``` and reStructuredText's ``text::`` before an indented
block. Rendered as Markdown those would show verbatim, so this extension, loaded by
mkdocstrings (``mkdocs.yml``), turns a role into inline code of its target's name (the last
component after ``~``) and ``text::`` into ``text:``. The docstrings themselves are left as
they are.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|attr|data|exc|obj|const):`(~?)([^`]+)`")
LITERAL_BLOCK = re.compile(r"(\S)::[ \t]*$", re.MULTILINE)


def _as_code(match: re.Match[str]) -> str:
    tilde, target = match.groups()
    target = target.lstrip(".")
    return f"`{target.rsplit('.', 1)[-1] if tilde else target}`"


def markdown_of(text: str) -> str:
    """``text`` with Sphinx roles as inline code and ``::`` block markers as ``:``."""
    return LITERAL_BLOCK.sub(r"\1:", ROLE.sub(_as_code, text))


class SphinxMarkupAsMarkdown(griffe.Extension):
    """Rewrite every loaded docstring with :func:`markdown_of`."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown_of(obj.docstring.value)
