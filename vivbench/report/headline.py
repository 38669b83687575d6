"""The README's headline figures: a table taken from a committed reference report.

The front page quotes a few recovery figures. They are not typed: this module takes the
rows of the report's side-by-side recovery table (the realistic campaign against its
in-library twin) and writes them between two markers of the README, so that a test can
check that the README says what the committed report says.
"""

from __future__ import annotations

__all__ = ["HEADLINE_BEGIN", "HEADLINE_END", "HEADLINE_ROWS", "HEADLINE_SECTION", "headline_table",
           "readme_with_headline"]

#: The report's section whose table holds the headline figures.
HEADLINE_SECTION = "### Recovery side by side"

#: First cells of the rows taken, in the order shown.
HEADLINE_ROWS = (
    "chance level: share of the most common true regime",
    "window models: coverage (flagged identifiable)",
    "window models: regime accuracy, all windows",
    "window models: median rel. error of dA/dt on the true (A, U), windows with dynamics",
    "window models: rel. error of dA/dt on the true (A, U), energy-weighted over every window sample",
    "campaign model: coverage (flagged identifiable)",
    "campaign model: regime accuracy, flagged windows",
    "campaign model: regime accuracy, all windows",
    "campaign model: median rel. error of dA/dt on the true (A, U), windows with dynamics",
    "campaign model: rel. error of dA/dt on the true (A, U), energy-weighted over every sample",
    "campaign model: curve error over lock-in, net linear a_k1(U) (rel. RMS)",
)

#: Markers around the table in the README.
HEADLINE_BEGIN = "<!-- headline table: written by `make readme` from reports/default/report.md; do not edit -->"
HEADLINE_END = "<!-- end of headline table -->"


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def headline_table(report_text: str, rows=HEADLINE_ROWS) -> str:
    """The Markdown table of the headline figures of a report.

    Parameters
    ----------
    report_text : str
        A ``report.md`` written by ``vivbench report`` with ``--baseline`` (it holds the
        section :data:`HEADLINE_SECTION`).
    rows : sequence of str
        First cells of the rows to take, in the order wanted.

    Returns
    -------
    str
        The table's header, separator and the rows, one per line, with a final newline.

    Raises
    ------
    ValueError
        The report has no such section, no table in it, or lacks one of ``rows``.
    """
    lines = report_text.splitlines()
    try:
        start = lines.index(HEADLINE_SECTION)
    except ValueError:
        raise ValueError(f"the report has no section {HEADLINE_SECTION!r} (a report written with --baseline has)") from None
    table = []
    for line in lines[start + 1:]:
        if line.startswith("#"):
            break
        if line.startswith("|"):
            table.append(line)
        elif table:
            break
    if len(table) < 3:
        raise ValueError(f"the report's section {HEADLINE_SECTION!r} holds no table")
    by_label = {_cells(line)[0]: line.strip() for line in table[2:]}
    missing = [r for r in rows if r not in by_label]
    if missing:
        raise ValueError(f"the report's table lacks the rows {missing}")
    return "\n".join([table[0].strip(), table[1].strip(), *(by_label[r] for r in rows)]) + "\n"


def readme_with_headline(readme_text: str, table: str) -> str:
    """The README with ``table`` between :data:`HEADLINE_BEGIN` and :data:`HEADLINE_END`, blank lines around it.

    Raises
    ------
    ValueError
        The README lacks either marker, or has them out of order.
    """
    begin, end = readme_text.find(HEADLINE_BEGIN), readme_text.find(HEADLINE_END)
    if begin < 0 or end < begin:
        raise ValueError(f"the README needs the lines {HEADLINE_BEGIN!r} and then {HEADLINE_END!r}")
    head = readme_text[: begin + len(HEADLINE_BEGIN)]
    return f"{head}\n\n{table}\n{readme_text[end:]}"
