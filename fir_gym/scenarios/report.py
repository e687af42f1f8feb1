"""What a paper scenario returns: summaries with the paper's numbers beside ours, and notes.

A report opens with one or more *summaries*, tables of rows
``quantity | paper | ours | reading | verdict | why``: the setup shared by the rows
is one line above the table, the readings (named interpretations of an ambiguous
equation or an unreported setting) a legend between them, one reading a line, and each
row's reason is a numbered footnote below it. The verdict is one term of the fixed vocabulary
:data:`VERDICTS` (defined once at the top of REPORT.md), chosen from the numbers
by :func:`number_verdict` or :func:`claim`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..tables import format_table
from .prose import say

#: a Monte Carlo figure agrees with the paper's when within this relative distance (or two
#: standard errors of ours, or half a unit of the paper's last printed digit)
REL_TOL = 0.10

READING_VERDICT = "reproduced under reading"
#: the verdict vocabulary: term -> meaning
VERDICTS: dict[str, str] = {
    "reproduced": say(
        "ours agrees with the paper's number under the paper's setup as we read it: to the "
        "paper's printed precision, or for a Monte Carlo figure within {tol:.0f} % or two "
        "standard errors", tol=100 * REL_TOL),
    f"{READING_VERDICT} X": "it agrees (as above) only under the named reading X of an ambiguous "
                            "equation or of a setting the paper does not give",
    "not reproduced: bound": "a bound we compute (a minimum-variance floor, an exact error) puts "
                             "the paper's number out of reach under this reading",
    "not reproduced: ambiguous": "the number depends on what the paper does not determine (an "
                                 "unreported setting, a garbled equation); no reading we ran "
                                 "gives it",
    "not reproduced: differs": "the setup is determined under this reading and ours differs",
    "claim tested: holds": "a statement of the paper without a number, measured: it holds",
    "claim tested: fails": "a statement of the paper without a number, measured: it does not "
                           "hold",
    "beyond the paper": "a quantity the paper leaves open (future work, a comparison it does "
                        "not make), measured",
}
SUMMARY_HEADERS = ["quantity", "paper", "ours", "reading", "verdict", "why"]


def is_verdict(text: str) -> bool:
    """Whether ``text`` is a term of :data:`VERDICTS` (``X`` being any reading's name)."""
    return text in VERDICTS or (text.startswith(READING_VERDICT + " ")
                                and len(text) > len(READING_VERDICT) + 1)


def reproduced(reading: str | None = None) -> str:
    """``"reproduced"``, or ``"reproduced under reading X"`` for an alternative reading."""
    return "reproduced" if reading is None else f"{READING_VERDICT} {reading}"


def claim(holds: bool) -> str:
    """The verdict of a tested claim."""
    return "claim tested: holds" if holds else "claim tested: fails"


def printed_half_unit(paper: float | str) -> float:
    """Half a unit of the last printed digit of ``paper`` (``"0.0250"`` → 5e-5)."""
    text = str(paper).strip().lstrip("+-").lower()
    mantissa, _, exponent = text.partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 0.5 * 10.0 ** (-decimals + (int(exponent) if exponent else 0))


def agrees(paper: float | str, ours: float, *, se: float | None = None,
           rel: float = REL_TOL) -> bool:
    """Whether ``ours`` agrees with the paper's printed number.

    Deterministic (``se is None``): ``ours`` rounds to the printed value (within half a
    unit of its last digit). Monte Carlo: within ``rel`` of it, two standard errors of
    ours, or half a printed unit, whichever is widest.
    """
    p = float(paper)
    gap = abs(float(ours) - p)
    half = printed_half_unit(paper)
    if se is None:
        return gap <= half * (1 + 1e-9)
    return gap <= max(rel * abs(p), 2.0 * float(se), half)


def excluded_by(paper: float | str, floor: float, rel: float = REL_TOL) -> bool:
    """Whether a lower bound ``floor`` on the expected value excludes the paper's number.

    The paper's figure is itself an estimate, so it must lie below the floor by more
    than ``rel``.
    """
    return float(paper) < floor / (1.0 + rel)


def number_verdict(paper: float | str, ours: float, *, se: float | None = None,
                   reading: str | None = None, otherwise: str = "differs",
                   floor: float | None = None) -> str:
    """The verdict of one number: reproduced (under ``reading``), or ``not reproduced: otherwise``.

    ``otherwise`` is ``"bound"``, ``"ambiguous"`` or ``"differs"`` — the reason the
    caller has established for a disagreement. A lower bound ``floor`` that excludes the
    paper's number (:func:`excluded_by`) makes it ``"not reproduced: bound"`` whatever
    our estimate: a Monte Carlo figure near the paper's would then be scatter.
    """
    if floor is not None and excluded_by(paper, floor):
        return "not reproduced: bound"
    if agrees(paper, ours, se=se):
        return reproduced(reading)
    verdict = f"not reproduced: {otherwise}"
    if verdict not in VERDICTS:
        raise ValueError(f"otherwise must be 'bound', 'ambiguous' or 'differs'; got {otherwise!r}")
    return verdict


@dataclass
class Comparison:
    """One number (or claim) of the paper beside ours, with the reading and the verdict.

    ``paper`` is ``None`` for a quantity the paper leaves open; ``reading`` names the
    reading (the summary's legend defines it); ``note`` is the reason, printed as a
    footnote.
    """

    quantity: str
    paper: Any
    ours: Any
    reading: str
    verdict: str
    note: str = ""

    def __post_init__(self) -> None:
        if not is_verdict(self.verdict):
            raise ValueError(f"{self.quantity}: verdict {self.verdict!r} is not in the vocabulary "
                             f"({', '.join(VERDICTS)})")


@dataclass
class Summary:
    """A table of :class:`Comparison` rows with their shared setup and readings legend."""

    title: str
    setup: str
    readings: dict[str, str] = field(default_factory=dict)
    rows: list[Comparison] = field(default_factory=list)

    def compare(self, quantity: str, paper: Any, ours: Any, reading: str, verdict: str,
                note: str = "") -> Comparison:
        """Add a row ``quantity | paper | ours | reading | verdict`` with ``note`` as its reason."""
        row = Comparison(quantity, paper, ours, reading, verdict, note)
        self.rows.append(row)
        return row


@dataclass
class Table:
    """A detail table; ``setup`` is its one-line description."""

    title: str
    headers: list[str]
    rows: list[list[Any]]
    setup: str = ""


@dataclass
class Report:
    """A paper's experiment, reproduced: summaries, detail tables, notes and figures.

    ``figures`` holds the raw numbers for tests and plots; ``images`` the PNG files
    written by the scenario's ``plot(report, out_dir)`` (caption -> path).
    """

    paper: str
    title: str
    summaries: list[Summary] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)
    images: dict[str, str] = field(default_factory=dict)

    @property
    def comparisons(self) -> list[Comparison]:
        """Every summary row, in order."""
        return [row for s in self.summaries for row in s.rows]

    def summary(self, title: str, setup: str, readings: Mapping[str, str] | None = None
                ) -> Summary:
        """Start a summary table (``setup``: one line; ``readings``: code -> meaning)."""
        s = Summary(title, setup, dict(readings or {}))
        self.summaries.append(s)
        return s

    def add_table(self, title: str, headers: list[str], rows: list[list[Any]],
                  setup: str = "") -> None:
        self.tables.append(Table(title, headers, rows, setup))

    def sentences(self) -> list[Any]:
        """Every piece of prose of the report (for the checks on typed-in numbers)."""
        out: list[Any] = [self.title, *self.notes]
        for s in self.summaries:
            out += [s.title, s.setup, *s.readings.values()]
            for row in s.rows:
                out += [row.quantity, row.reading, row.note]
                if isinstance(row.ours, str):
                    out.append(row.ours)
        for t in self.tables:
            out += [t.title, t.setup]
        return out

    def to_text(self, markdown: bool = False) -> str:
        h2, h3 = ("## ", "### ") if markdown else ("", "")
        head = f"Paper {self.paper}: {self.title}" if self.paper.isdigit() else self.title
        parts = [h2 + head if markdown else f"{head}\n{'=' * len(head)}"]
        footnotes: dict[str, int] = {}
        for s in self.summaries:
            parts += ["", h3 + s.title, ""]
            if s.setup:
                parts.append(f"Setup: {s.setup}")
            if s.readings:                 # one reading a line: a legend, not a paragraph
                parts.append("Readings:")
                parts.extend(f"- {k} = {v}" for k, v in s.readings.items())
            if s.setup or s.readings:
                parts.append("")
            new: list[int] = []
            rows = []
            for row in s.rows:
                ref = ""
                if row.note:
                    if row.note not in footnotes:
                        footnotes[row.note] = len(footnotes) + 1
                        new.append(footnotes[row.note])
                    ref = f"[{footnotes[row.note]}]"
                rows.append([row.quantity, row.paper, row.ours, row.reading, row.verdict, ref])
            parts.append(format_table(SUMMARY_HEADERS, rows, markdown=markdown))
            if new:
                parts.append("")
                by_number = {n: note for note, n in footnotes.items()}
                parts.extend(f"- [{n}] {by_number[n]}" for n in new)
        for table in self.tables:
            parts += ["", h3 + table.title, ""]
            if table.setup:
                parts += [table.setup, ""]
            parts.append(format_table(table.headers, table.rows, markdown=markdown))
        if self.notes:
            parts += ["", "**Notes**" if markdown else "Notes:", ""]
            parts.extend(f"- {note}" for note in self.notes)
        if markdown and self.images:
            parts.append("")
            parts.extend(f"![{name}]({path})" for name, path in self.images.items())
        return "\n".join(parts) + "\n"


def vocabulary(markdown: bool = True) -> str:
    """The verdict vocabulary, one term a line (the top of REPORT.md)."""
    term = "**{}**" if markdown else "{}"
    return "\n".join(f"- {term.format(k)}: {v}" for k, v in VERDICTS.items())
