"""Markdown of the results pages written by ``run_all.py`` (speed suite) and ``run_study.py`` (studies)."""

from __future__ import annotations

import ast
import math
import os
import platform
import resource
import sys
from datetime import datetime, timezone
from pathlib import Path

#: Lists of rows longer than this are left out of a page (they stay in the JSON file).
LIST_ROWS = 12


def first_line(path: Path) -> str:
    """First line of a script's module docstring (what it measures)."""
    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    return doc.splitlines()[0] if doc else ""


def fmt(x) -> str:
    """A figure as it is shown on a page: floats to 3 significant digits, long texts cut."""
    if isinstance(x, bool) or x is None or isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return str(x) if math.isnan(x) or math.isinf(x) else f"{x:.3g}"
    if isinstance(x, (list, tuple)) and x and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in x):
        text = "[" + ", ".join(fmt(v) for v in x) + "]"
    else:
        text = str(x)
    return text if len(text) <= 80 else text[:77] + "..."


def flatten(d: dict, prefix: str = ""):
    """(dotted key, value) of a nested dict; lists of more than LIST_ROWS dicts are summarised."""
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from flatten(value, name + ".")
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            if len(value) > LIST_ROWS:  # per-event rows: in the JSON file, not on the page
                yield name, f"{len(value)} rows (in the JSON results file)"
                continue
            for i, v in enumerate(value):
                yield from flatten(v, f"{name}[{i}].")
        else:
            yield name, value


def figures_table(figures: dict, skip: tuple[str, ...] = ("wall_s",)) -> list[str]:
    """The lines of a two-column Markdown table of a run's figures."""
    lines = ["| figure | value |", "|---|---|"]
    lines += [f"| {key} | {fmt(value).replace('|', '/')} |" for key, value in flatten(figures) if key not in skip]
    return lines


def is_rows(value) -> bool:
    """Whether ``value`` is a list of flat dicts (rows of a table)."""
    return (isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)
            and not any(isinstance(x, (dict, list)) and not (isinstance(x, list) and all(
                isinstance(y, (int, float)) for y in x)) for v in value for x in v.values()))


def rows_table(rows: list[dict]) -> list[str]:
    """The lines of a Markdown table with one row per dict (columns: every key, in first-seen order)."""
    columns = list(dict.fromkeys(k for row in rows for k in row))
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(fmt(row.get(c, "")).replace("|", "/") for c in columns) + " |" for row in rows]
    return lines


def run_metadata(wall_s: float) -> dict:
    """Where and when a run was made: Python, machine, CPUs, date (UTC), wall and CPU time, load average.

    The CPU time is this process's and its finished children's (user + system); on a machine
    shared with other work it is what the run itself cost, the wall time what it waited too.
    """
    self_, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = self_.ru_utime + self_.ru_stime + children.ru_utime + children.ru_stime
    return {"python": sys.version.split()[0], "machine": platform.machine(), "cpus": os.cpu_count(),
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "wall_s": wall_s,
            "cpu_s": cpu, "load_average_1min": os.getloadavg()[0]}


def written_by(command: str, meta: dict) -> str:
    """The sentence that opens a results page: the command, the machine and the run's wall time."""
    return (f"Written by `{command}` on {meta['date']} ({meta['cpus']} CPUs, {meta['machine']}, Python "
            f"{meta['python']}; BLAS single-threaded), in {meta['wall_s']:.0f} s{_cpu(meta)}. Every figure below "
            "was measured by that run; run the command again to update this page.")


def _cpu(meta: dict) -> str:
    if "cpu_s" not in meta:
        return ""
    return (f" (CPU time {meta['cpu_s']:.0f} s; load average {meta['load_average_1min']:.1f} on "
            f"{meta['cpus']} CPUs at the end: the machine was shared)" if meta["load_average_1min"] > meta["cpus"]
            else f" (CPU time {meta['cpu_s']:.0f} s)")
