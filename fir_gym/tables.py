"""Plain-text and Markdown tables for reports and benchmarks (no extra dependency)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def format_table(
    headers: Sequence[str],
    rows: Sequence[Sequence[Any]],
    *,
    floatfmt: str = ".4g",
    markdown: bool = False,
) -> str:
    """Format ``rows`` under ``headers`` as an aligned text table or a Markdown table.

    Floats use ``floatfmt``; ``None`` prints as an empty cell; other values use ``str``.
    Numeric columns are right-aligned.
    """
    cells = [[_cell(v, floatfmt) for v in row] for row in rows]
    if markdown:  # a literal | would end the cell
        cells = [[c.replace("|", "\\|") for c in row] for row in cells]
        headers = [h.replace("|", "\\|") for h in headers]
    for i, row in enumerate(cells):
        if len(row) != len(headers):
            raise ValueError(f"row {i} has {len(row)} cells; expected {len(headers)}")
    numeric = [all(_is_number(row[j]) for row in rows if row[j] is not None) and bool(rows)
               for j in range(len(headers))]
    widths = [max([len(h)] + [len(r[j]) for r in cells]) for j, h in enumerate(headers)]

    def line(values: Sequence[str]) -> str:
        parts = [v.rjust(w) if num else v.ljust(w)
                 for v, w, num in zip(values, widths, numeric, strict=True)]
        return ("| " + " | ".join(parts) + " |") if markdown else "  ".join(parts).rstrip()

    if markdown:
        rule = "|" + "|".join(("-" * (w + 1) + ":") if num else ("-" * (w + 2))
                              for w, num in zip(widths, numeric, strict=True)) + "|"
    else:
        rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(list(headers)), rule, *(line(r) for r in cells)])


def _cell(value: Any, floatfmt: str) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float) or (hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0):
        return format(float(value), floatfmt)
    return str(value)


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)) or (
        hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0)
