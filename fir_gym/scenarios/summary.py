"""The summary at the top of REPORT.md, computed from the reports' own rows.

Per paper (one :class:`~.report.Report`), :func:`verdict_counts` tallies its summary rows
by verdict (the columns of :data:`COLUMNS`), and :func:`findings` picks the rows that
matter most by the rule :data:`FINDINGS_RULE` states:

1. the paper's *numbers that no reading reproduces*, each taken under the reading that
   comes closest to it, ranked by the factor between the paper's number and ours
   (``max(ours/paper, paper/ours)``, largest first);
2. then, to fill the remaining places, the *claims that fail*, in the report's order
   (a claim carries no magnitude to rank it by).

Nothing here is typed in: change a result and the summary follows.

    print(summary_text(reports))          # the terminal's short summary
    parts = summary_markdown(reports)     # REPORT.md's "Summary" section
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..tables import format_table
from .report import READING_VERDICT, Comparison, Report

#: the summary's verdict columns: short header -> the verdict (a reading's verdict is
#: counted under "under a reading" whatever the reading)
COLUMNS: dict[str, str] = {
    "reproduced": "reproduced",
    "under a reading": READING_VERDICT,
    "not: bound": "not reproduced: bound",
    "not: ambiguous": "not reproduced: ambiguous",
    "not: differs": "not reproduced: differs",
    "claim holds": "claim tested: holds",
    "claim fails": "claim tested: fails",
    "beyond": "beyond the paper",
}
#: how many findings each paper lists
FINDINGS_PER_PAPER = 3
#: the rule that picks the findings, printed under them
FINDINGS_RULE = (
    f"Findings: per paper, at most {FINDINGS_PER_PAPER} rows: first the paper's numbers that "
    "no reading reproduces, each under its closest reading, farthest first (by the factor "
    "between the paper's number and ours); then the claims that fail, in the report's order.")


def column(verdict: str) -> str:
    """The summary column (a key of :data:`COLUMNS`) that counts ``verdict``."""
    for header, term in COLUMNS.items():
        if verdict == term or (term == READING_VERDICT and verdict.startswith(term + " ")):
            return header
    raise ValueError(f"verdict {verdict!r} is not in the vocabulary")


def verdict_counts(report: Report) -> dict[str, int]:
    """``report``'s summary rows tallied per column of :data:`COLUMNS` (every column, zeros
    included, in order)."""
    tally = Counter(column(row.verdict) for row in report.comparisons)
    return {header: tally[header] for header in COLUMNS}


def label(report: Report) -> str:
    """The report's short name in the summary: ``Paper 000``, or its title up to a colon."""
    return f"Paper {report.paper}" if report.paper.isdigit() else report.title.split(":")[0]


def counts_table(reports: Sequence[Report], *, markdown: bool = True) -> str:
    """One row per report, its verdict counts and total, then the totals of every report."""
    headers = ["paper", *COLUMNS, "rows"]
    rows: list[list[Any]] = []
    total: Counter[str] = Counter()
    for report in reports:
        counts = verdict_counts(report)
        total.update(counts)
        rows.append([label(report), *counts.values(), sum(counts.values())])
    rows.append(["all", *(total[h] for h in COLUMNS), sum(total.values())])
    return format_table(headers, rows, markdown=markdown)


@dataclass(frozen=True)
class Finding:
    """One row that matters: ``factor`` is how far ours lies from the paper's number
    (``None`` for a failed claim)."""

    row: Comparison
    factor: float | None

    def text(self) -> str:
        """One line: the quantity, the paper's number beside ours, the reading, the verdict."""
        r = self.row
        ours = f"{float(r.ours):.4g}" if _number(r.ours) is not None else str(r.ours)
        if self.factor is None:
            reading = f"; reading {r.reading}" if r.reading else ""
            return f"{r.quantity}: {ours} ({r.verdict}{reading})"
        far = "∞" if math.isinf(self.factor) else f"{self.factor:.3g}"
        return (f"{r.quantity}: paper {r.paper}, ours {ours} under its closest reading "
                f"{r.reading}, a factor {far} apart ({r.verdict})")


def _number(value: Any) -> float | None:
    if isinstance(value, bool):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def factor(paper: float, ours: float) -> float:
    """How far apart two numbers are: ``max(ours/paper, paper/ours)`` of their magnitudes
    (1 when equal; infinite when one is zero or their signs differ)."""
    if paper == ours:
        return 1.0
    if paper == 0 or ours == 0 or (paper < 0) != (ours < 0):
        return math.inf
    ratio = abs(ours / paper)
    return max(ratio, 1.0 / ratio)


def findings(report: Report, n: int = FINDINGS_PER_PAPER) -> list[Finding]:
    """The ``n`` rows of ``report`` that matter most, by the rule of :data:`FINDINGS_RULE`."""
    by_quantity: dict[str, list[Comparison]] = {}
    for row in report.comparisons:
        by_quantity.setdefault(row.quantity, []).append(row)
    misses: list[Finding] = []
    for rows in by_quantity.values():
        numeric = [(factor(p, o), row) for row in rows if (p := _number(row.paper)) is not None
                   and (o := _number(row.ours)) is not None]
        reproduced = any(column(row.verdict) in ("reproduced", "under a reading")
                         for row in rows)
        if numeric and not reproduced:
            closest = min(numeric, key=lambda pair: pair[0])
            misses.append(Finding(closest[1], closest[0]))
    misses.sort(key=lambda f: -(f.factor or 0.0))           # stable: report order on ties
    claims = [Finding(row, None) for row in report.comparisons
              if column(row.verdict) == "claim fails"]
    return (misses + claims)[:n]


def summary_markdown(reports: Sequence[Report]) -> list[str]:
    """REPORT.md's summary: the counts table, then each paper's findings, then the rule."""
    parts = ["## Summary", "",
             "Rows per verdict (the vocabulary is defined below), counted from each "
             "section's verdict tables, those headed `quantity | paper | ours | reading | "
             "verdict`: one row per number or claim and reading. The detail tables below "
             "them, which repeat claims under further readings, are not counted.", "",
             counts_table(reports), ""]
    for report in reports:
        found = findings(report)
        if found:
            parts.append(f"**{label(report)}**")
            parts.append("")
            parts.extend(f"- {f.text()}" for f in found)
            parts.append("")
    parts += [FINDINGS_RULE, ""]
    return parts


def summary_text(reports: Sequence[Report], *, markdown: bool = False) -> str:
    """The terminal's short summary: the verdict counts per paper (a plain or Markdown table)."""
    return "Verdicts per paper (rows of each section's verdict tables)\n\n" + counts_table(
        reports, markdown=markdown)
