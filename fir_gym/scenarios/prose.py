"""Sentences formatted from computed results, and the check that no number is typed in by hand.

Every sentence of a report that carries a number is a :class:`Prose`: a ``str``
made by :func:`say` from a template and the values it formats, which keeps both.
:func:`literal_numbers` lists the digits a sentence carries in its *template*
(typed in, not computed) outside names (``x3``, ``Δ22``), references (``Table 1``,
``eq 29``, ``Fig. 2``, ``Theorem 2.1``, ``§5``, ``paper 000``) and formulas in
backticks (`` `2k (x − l0)` ``); the tests require it to be empty for every sentence of
every report, so a changed seed or setting changes every number it should.

    say("the EKF's NEES leaves the band from k = {k}", k=onset)
"""

from __future__ import annotations

import re
import string
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["Printed", "Prose", "join", "literal_numbers", "say"]

#: a reference to a numbered part of a paper (its digits are not results)
_REFERENCE = re.compile(
    r"(?:\b(?:Tables?|Figs?\.|eqs?|Eqs?|Theorems?|Thm|Cor|Lemma|Sim|sim|[Pp]apers?|"
    r"[Ss]ection|issue)\s+|§)"
    r"[0-9]+(?:\.[0-9]+)*(?:\s*(?:–|-|/|,|and|or)\s*[0-9]+(?:\.[0-9]+)*)*")
_FORMULA = re.compile(r"`[^`]*`")
#: a transition from the window start, Φ_F(τ, 0) (a symbol, not a number)
_SYMBOL = re.compile(r"Φ(?:_F)?\(\s*[τσ]\s*,\s*0\s*\)")
#: digits not part of a name (``x3``, ``Δ22``, ``delta_pi2``, ``x₁`` has none)
_DIGITS = re.compile(r"(?<![A-Za-z_0-9\u0370-\u03ff])[0-9]+")


class Prose(str):
    """A sentence formatted from ``values`` by ``template`` (see :func:`say`)."""

    template: str
    values: dict[str, Any]

    def __new__(cls, template: str, values: Mapping[str, Any]) -> Prose:
        text = super().__new__(cls, template.format(**values))
        text.template, text.values = template, dict(values)
        return text

    def __reduce__(self) -> tuple[Any, ...]:
        return (Prose, (self.template, self.values))


class Printed(str):
    """A number as a paper prints it (``"0.0250"``): an input, never a result of ours."""

    __slots__ = ()


def say(template: str, /, **values: Any) -> Prose:
    """``template.format(**values)``, remembering both (numbers come in as ``values``)."""
    return Prose(template, values)


def join(parts: Iterable[str], sep: str = ", ") -> Prose:
    """Sentences or fragments joined by ``sep`` (which must carry no number)."""
    parts = list(parts)
    if _DIGITS.search(sep):
        raise ValueError(f"a separator carries no number; got {sep!r}")
    template = sep.replace("{", "{{").replace("}", "}}").join(
        f"{{p{i}}}" for i in range(len(parts)))
    return Prose(template, {f"p{i}": p for i, p in enumerate(parts)})


def literal_numbers(text: Any) -> list[str]:
    """The numbers ``text`` carries that were typed in rather than formatted from a value.

    For a :class:`Prose`, the literal parts of its template are checked, and every
    string value it formats, recursively; a plain string is checked whole; a
    :class:`Printed` number (the paper's) and anything else (a number formatted into a
    template) carry none.
    """
    if isinstance(text, Printed):
        return []
    if isinstance(text, Prose):
        skeleton = "".join(literal + ("\0" if field is not None else "")
                           for literal, field, *_ in string.Formatter().parse(text.template))
        found = _numbers_in(skeleton)
        for value in text.values.values():
            found += literal_numbers(value)
        return found
    if isinstance(text, str):
        return _numbers_in(text)
    return []


def _numbers_in(text: str) -> list[str]:
    text = _FORMULA.sub(" ", text)
    text = _SYMBOL.sub(" ", text)
    text = _REFERENCE.sub(" ", text)
    return _DIGITS.findall(text)
