"""The report's leaderboard section: the tables and heat maps of ``vivbench leaderboard``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from urllib.parse import quote

from vivbench.core.errors import InputError
from vivbench.io.netcdf import atomic_path
from vivbench.validate.leaderboard_table import leaderboard_markdown, read_leaderboard
from vivbench.validate.scenarios import Scenario

__all__ = ["LEADERBOARD_TITLE", "leaderboard_section"]

LEADERBOARD_TITLE = "Leaderboard: methods on the scenario suite (`vivbench leaderboard`)"
_FIGURE = "leaderboard_heatmaps.png"


def _scenarios(directory: Path, names: list[str]) -> list[Scenario]:
    """The scenarios as the run recorded them (``scenarios/<name>/scenario.json``), for the legend."""
    out = []
    for name in names:
        path = directory / "scenarios" / name / "scenario.json"
        try:
            out.append(Scenario(**json.loads(path.read_text())["scenario"]))
        except (OSError, ValueError, KeyError, TypeError, InputError):
            continue  # a failed scenario has no record: the table says so, the legend leaves it out
    return out


def _command(directory: Path) -> str:
    recorded = directory / "command.txt"
    if recorded.is_file():
        return recorded.read_text().strip()
    return f"vivbench leaderboard --methods ... --out {directory}"


def leaderboard_section(directory, out_dir: Path, written: list[str]) -> list[str]:
    """Markdown lines of the leaderboard section; copies the figure into ``out_dir`` and names it in ``written``.

    Parameters
    ----------
    directory : output directory of ``vivbench leaderboard``, or None (the section says "not run")
    out_dir : the report's directory
    written : names of the figures the report wrote (appended to)
    """
    out = [f"## {LEADERBOARD_TITLE}", ""]
    if directory is None:
        return out + ["**Not run**: no `--leaderboard` directory was given.", ""]
    directory = Path(directory)
    if not directory.is_dir():
        return out + [f"**Not run**: the directory `{directory}` does not exist.", ""]
    rows = read_leaderboard(directory)
    scenarios = _scenarios(directory, list(dict.fromkeys(r["scenario"] for r in rows)))
    figure = None
    png = directory / "leaderboard.png"
    if png.is_file():
        with atomic_path(out_dir / _FIGURE, suffix=".png") as tmp:
            shutil.copyfile(png, tmp)
        written.append(_FIGURE)
        figure = quote(_FIGURE)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    out += [f"{len(methods)} method(s) on {len(scenarios) or 'the'} scenario(s), from `{directory}`.", "",
            f"*Produced by:* `{_command(directory)}`", ""]
    out += leaderboard_markdown(rows, scenarios=scenarios, figure=figure, heading="###").splitlines()
    out.append("")
    return out
