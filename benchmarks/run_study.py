"""Run one accuracy study and write its results page.

Usage::

    python benchmarks/run_study.py NAME [ARGS ...]
    python benchmarks/run_study.py NAME --help

The accuracy studies are not part of the speed suite (``make bench``): each asks what
the chain recovers on a given campaign, which takes its own inputs and time. A study is a
``study_<name>.py`` of this folder whose ``main(argv)`` parses ``ARGS`` and returns its
figures (a dict, or a list of rows). This command runs it and writes the figures, with the command line, the
machine and the wall time, to ``docs/results/studies/<name>.json`` and the page
``docs/results/studies/<name>.md`` (under Results on the documentation site); a ``findings``
list of sentences, which a study generates from its figures, opens the page. Nothing on a page
is typed by hand: run the command again to update it.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import importlib.util  # noqa: E402
import json  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _pages import figures_table, first_line, is_rows, rows_table, run_metadata, written_by  # noqa: E402
from _family_args import root_on_path  # noqa: E402

# A study's methods may live in its own module (``benchmarks.study_<name>:<method>``), resolved by name.
root_on_path()

HERE = Path(__file__).resolve().parent
PAGES = HERE.parent / "docs" / "results" / "studies"  # in the documentation site's Results

#: The accuracy studies: name -> script.
STUDIES = {path.stem.removeprefix("study_"): path for path in sorted(HERE.glob("study_*.py"))}


def run_study(name: str, argv: list[str]) -> dict:
    """Run study ``name`` with ``argv``; its figures with the run's metadata under ``_run``."""
    path = STUDIES[name]
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    saved, sys.argv = sys.argv, [str(path), *argv]
    try:
        spec.loader.exec_module(module)
        t0 = time.perf_counter()
        figures = module.main(argv)
        wall = time.perf_counter() - t0
    finally:
        sys.argv = saved
    if isinstance(figures, list):
        figures = {"rows": figures}
    if not isinstance(figures, dict):
        raise TypeError(f"{path.name}: main() returned {type(figures).__name__}, not a dict of figures")
    return {**figures, "_run": run_metadata(wall)}


def study_page(name: str, figures: dict, command: str) -> str:
    """The Markdown page of a study's run."""
    lines = [f"# Study `{name}`", "", first_line(STUDIES[name]), "", written_by(command, figures["_run"]), "",
             f"What the study does and how to read its figures: the docstring of `benchmarks/{STUDIES[name].name}`. "
             f"Every figure of the run is also in `docs/results/studies/{name}.json`.", ""]
    said = figures.get("findings")
    shown = isinstance(said, list) and bool(said) and all(isinstance(x, str) for x in said)
    if shown:  # sentences the study generated from its figures
        lines += ["## What the figures show", "", *(f"- {x}" for x in said), ""]
    lines += ["## Figures", ""]
    figures = {k: v for k, v in figures.items() if k != "_run" and not (k == "findings" and shown)}
    cases = {k: v for k, v in figures.items() if isinstance(v, dict) and is_rows([v])}
    if len(cases) >= 2:  # flat dicts of figures, one per case: one table of the cases
        figures = {**{k: v for k, v in figures.items() if k not in cases},
                   "cases": [{"case": k, **v} for k, v in cases.items()]}
    scalars = {k: v for k, v in figures.items() if not is_rows(v)}
    if scalars:
        lines += figures_table(scalars)
    for key, value in figures.items():
        if is_rows(value):
            lines += ([""] if lines[-1] else []) + [f"### {key}", ""] + rows_table(value)
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in STUDIES:
        print(f"run_study: give a study name first: {', '.join(STUDIES)}", file=sys.stderr)
        return 2
    name, args = argv[0], argv[1:]
    figures = run_study(name, args)
    PAGES.mkdir(exist_ok=True)
    (PAGES / f"{name}.json").write_text(json.dumps(figures, indent=2, default=float) + "\n", encoding="utf-8")
    command = shlex.join(["python", "benchmarks/run_study.py", name, *args])
    (PAGES / f"{name}.md").write_text(study_page(name, figures, command), encoding="utf-8")
    print(f"wrote {PAGES / f'{name}.md'} and {PAGES / f'{name}.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
