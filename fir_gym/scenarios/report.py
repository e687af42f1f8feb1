"""What a paper scenario returns: tables with the paper's numbers beside ours, and notes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..tables import format_table


@dataclass
class Table:
    title: str
    headers: list[str]
    rows: list[list[Any]]


@dataclass
class Report:
    """A paper's experiment, reproduced: its tables and the reasons for every difference."""

    paper: str
    title: str
    tables: list[Table] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)   # raw numbers for tests and plots

    def add_table(self, title: str, headers: list[str], rows: list[list[Any]]) -> None:
        self.tables.append(Table(title, headers, rows))

    def to_text(self, markdown: bool = False) -> str:
        head = f"## Paper {self.paper}: {self.title}" if markdown else \
            f"Paper {self.paper}: {self.title}\n{'=' * (len(self.title) + 11)}"
        parts = [head]
        for table in self.tables:
            parts.append(f"\n{'### ' if markdown else ''}{table.title}\n")
            parts.append(format_table(table.headers, table.rows, markdown=markdown))
        if self.notes:
            parts.append("\nNotes:" if not markdown else "\n**Notes**\n")
            parts.extend(f"- {note}" for note in self.notes)
        return "\n".join(parts) + "\n"
