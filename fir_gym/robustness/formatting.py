"""How the benchmark's numbers are written in its report and in the README: one rule for
both (a missing or non-finite number is a dash; intervals as ``centre [low, high]``)."""

from __future__ import annotations

import math
from typing import Any


def number(value: float | None, digits: int = 4) -> str:
    """``value`` to ``digits`` significant digits; ``—`` for None or a non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value:.{digits}g}"


def interval(centre: float | None, low: float | None, high: float | None,
             digits: int = 4) -> str:
    """``centre [low, high]``, or ``—`` without a centre."""
    if centre is None:
        return "—"
    return f"{number(centre, digits)} [{number(low, digits)}, {number(high, digits)}]"


def gap_interval(row: dict[str, Any]) -> str:
    """A row's estimation gap with its paired interval, or ``—`` (a row without one)."""
    if row.get("gap") is None:
        return "—"
    return f"{row['gap']:.2f} [{row['gap_low']:.2f}, {row['gap_high']:.2f}]"


def middle(strengths: list[float]) -> float:
    """A condition's middle strength (the one the README and the answers read)."""
    return strengths[len(strengths) // 2] if strengths else 0.0
