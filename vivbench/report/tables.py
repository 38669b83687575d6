"""Markdown table helpers shared by the report's sections."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["md_cell", "md_table", "produced_by"]


def md_cell(text) -> str:
    """``text`` as one Markdown table cell: ``|`` escaped, newlines folded to spaces."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def md_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    """A Markdown table: a header line, the separator and one line per row (no trailing newline)."""
    lines = ["| " + " | ".join(md_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(md_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def produced_by(command: str, note: str = "") -> str:
    """The line ``*Produced by:* `command` note`` under a figure or table."""
    return f"*Produced by:* `{command}`" + (f" {note}" if note else "")
