"""The shell commands of the README and the user-path pages run as written, in order, in an empty folder.

A page's shell blocks are its fenced blocks without a language (or ``bash``/``sh``/
``console``); their ``vivbench ...`` and ``python ...`` lines are the commands (a trailing
backslash continues a line, ``#`` starts a comment; ``make`` and ``pip`` lines are the set-up
that ``make test`` and ``make test-wheel`` check, other lines are file trees). Each command
runs through ``bash`` in the page's folder, ``vivbench`` and ``python`` being this
interpreter, and must exit 0. The files a page says the user brings (field mappings, the
bridge's properties, a package of methods) are made first from a synthetic campaign.

The field import's worked example runs in ``make test`` (one 20 min event: under a minute); the
pages whose commands take minutes run in the slow tests, with the settings the pages print: the README's
quickstart (6 events of 30 min), the field workflow (import to report on the two events it imports) and the
contributed-methods commands of docs/methods.md (a comparison grid and a leaderboard of two scenarios).
`make test-docs` runs these, and CI runs it.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import REPO

ROOT = REPO
#: The README and the pages of the three user paths (engineer, method researcher, test-suite author).
PAGES = ("README.md", "docs/field_workflow.md", "docs/field_import.md", "docs/methods.md", "docs/testing.md",
         "docs/user_guide.md")
_SHELL = ("", "bash", "sh", "shell", "console")
_SETUP = ("make ", "pip ")


def shell_blocks(page: str) -> list[str]:
    """The text of each shell block of a page (fenced, no language or a shell's)."""
    blocks, current, lang = [], None, ""
    for line in (ROOT / page).read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            if current is None:
                current, lang = [], line[3:].strip()
            else:
                if lang in _SHELL:
                    blocks.append("\n".join(current))
                current = None
            continue
        if current is not None:
            current.append(line)
    return blocks


def commands(page: str) -> list[str]:
    """The commands of a page's shell blocks, in order: ``vivbench ...`` and ``python ...`` lines."""
    out = []
    for block in shell_blocks(page):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words and words[0] in ("vivbench", "python"):
                command = re.sub(r"\s+#(?=\s|$).*$", "", line).strip()  # as typed: the shell expands its globs
                assert shlex.split(command) == words, f"{page}: cannot strip the comment of `{line}`"
                out.append(" ".join(command.split()) if "\"" not in command else command)
    return out


def setup_lines(page: str) -> list[str]:
    """The set-up lines (``make ...``, ``pip ...``) of a page's shell blocks."""
    return [line.strip() for block in shell_blocks(page) for line in block.splitlines()
            if line.strip().startswith(_SETUP)]


def run_commands(cmds: list[str], folder: Path, timeout: float = 3600.0) -> list[float]:
    """Run each command in ``folder`` through bash, ``vivbench``/``python`` being this interpreter; wall times."""
    shims = folder / ".shims"
    shims.mkdir(exist_ok=True)
    for name, target in (("vivbench", f'exec "{sys.executable}" -m vivbench "$@"'),
                         ("python", f'exec "{sys.executable}" "$@"')):
        (shims / name).write_text(f"#!/bin/sh\n{target}\n", encoding="utf-8")
        (shims / name).chmod(0o755)
    env = {**os.environ, "PATH": f"{shims}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), str(folder), os.environ.get("PYTHONPATH")) if p)}
    walls = []
    for cmd in cmds:
        t0 = time.perf_counter()
        proc = subprocess.run(["bash", "-c", cmd], cwd=folder, env=env, capture_output=True, text=True,
                              timeout=timeout)
        walls.append(time.perf_counter() - t0)
        assert proc.returncode == 0, f"`{cmd}` exited {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    return walls


def test_every_page_command_is_a_known_subcommand_with_known_options():
    """Fast: every command of the pages parses with the CLI's own parser (no page drifts from the options)."""
    import argparse

    from vivbench.cli import _parser

    parser = _parser()
    # every subcommand the parser knows (a module may register several, e.g. twin and twin-check)
    names = {name for action in parser._actions if isinstance(action, argparse._SubParsersAction)
             for name in action.choices}
    counts = {}
    for page in PAGES:
        cmds = [c for c in commands(page) if c.startswith("vivbench ")]
        counts[page] = len(cmds)
        for cmd in cmds:
            argv = shlex.split(cmd)[1:]
            assert argv[0] in names, f"{page}: `{cmd}`: no subcommand {argv[0]!r}"
            try:
                parser.parse_args(argv)
            except SystemExit:
                pytest.fail(f"{page}: `{cmd}` does not parse (see the usage above)")
    assert counts["README.md"] == 5 and counts["docs/field_workflow.md"] == 10
    assert counts["docs/field_import.md"] == 3 and counts["docs/methods.md"] == 2
    assert setup_lines("README.md") == ["make demo    # installs into .venv, runs the whole chain on the default "
                                        "campaign, writes demo/reports/demo/report.md",
                                        "make test    # installs into .venv and runs the test suite (slow studies "
                                        "excluded)"]
    assert setup_lines("docs/testing.md") == ['pip install "vivbench[testing]"']  # make test-wheel runs that path


def test_field_import_worked_example_runs_as_written(tmp_path):
    """docs/field_import.md: a 20 min synthetic event exported as field files, imported and identified."""
    import numpy as np

    from vivbench.io import read_event, read_result

    cmds = commands("docs/field_import.md")
    assert [c.split()[1] for c in cmds] == ["synth", "-c", "import", "identify"]
    run_commands(cmds, tmp_path)
    assert str(read_event(tmp_path / "F001.nc").attrs["event_id"]) == "F001"
    synthetic, imported = (read_result(tmp_path / "identify" / f"{e}.identify.nc") for e in ("E001", "F001"))
    # The page's claims: the same windows, and the same regime in every window.
    np.testing.assert_array_equal(imported["window_start"].values, synthetic["window_start"].values)
    np.testing.assert_array_equal(imported["regime"].values, synthetic["regime"].values)


@pytest.mark.slow
def test_readme_cli_quickstart_runs_as_written(tmp_path):
    """The README's CLI quickstart: 6 events of 30 min generated, identified, pooled, validated, reported."""
    cmds = commands("README.md")
    run_commands(cmds, tmp_path)
    assert len(list((tmp_path / "identify").glob("*.identify.nc"))) == 6
    assert (tmp_path / "identify" / "campaign.model.nc").is_file()
    assert (tmp_path / "reports" / "quick" / "report.md").is_file()


def _field_records(folder: Path, n_events: int) -> None:
    """What an engineer brings: F001.toml ... with their CSV files, and the bridge's properties."""
    from vivbench.io import export_csv, read_event

    run_commands([f"vivbench synth --events {n_events} --seed 2 --duration 20 --out synthetic"], folder)
    for i in range(1, n_events + 1):
        event_id = f"F{i:03d}"
        mapping = export_csv(read_event(folder / "synthetic" / f"E{i:03d}.nc"), folder / event_id,
                             wind_units="km/h", acc_units="g", time_format="iso8601", event_id=event_id)
        text = re.sub(r'file = "', f'file = "{event_id}/', mapping.read_text(encoding="utf-8"))
        (folder / f"{event_id}.toml").write_text(text, encoding="utf-8")
    shutil.copy(ROOT / "examples" / "greybox_bridge_default.toml", folder / "bridge_properties.toml")


@pytest.mark.slow
def test_field_workflow_runs_as_written(tmp_path):
    """docs/field_workflow.md from import to report, on the records it imports (F001, F002)."""
    cmds = commands("docs/field_workflow.md")
    _field_records(tmp_path, 2)
    run_commands(cmds, tmp_path)
    assert sorted(p.name for p in (tmp_path / "campaign").glob("*.nc")) == ["F001.nc", "F002.nc"]
    assert (tmp_path / "greybox" / "greybox.nc").is_file()
    assert (tmp_path / "twin" / "twin.json").is_file()
    assert (tmp_path / "reports" / "my_bridge" / "report.md").is_file()


@pytest.mark.slow
def test_contributed_methods_commands_run_as_written(tmp_path):
    """docs/methods.md's folder of methods: a grid with the built-in and the contributed method, the leaderboard.

    The folder is the page's tree with the page's ``Damped`` in ``damped/__init__.py``; the grid is
    the page's comment (``[grid] method = [...]``) on the small campaign of
    ``examples/compare_methods.toml``. The leaderboard scores the two scenarios the page names.
    """
    from tests.project.test_doc_snippets import python_blocks

    damped = next(code for module, code in python_blocks("methods.md") if module == "my_methods")
    package = tmp_path / "my_methods"
    (package / "damped").mkdir(parents=True)
    (package / "__init__.py").write_text("", encoding="utf-8")
    (package / "damped" / "__init__.py").write_text(damped, encoding="utf-8")
    cmds = commands("docs/methods.md")
    grid = re.search(r"(\[grid\] method = \[.*\])", next(b for b in shell_blocks("docs/methods.md")
                                                         if "--grid my_grid.toml" in b)).group(1)
    campaign = (ROOT / "examples" / "compare_methods.toml").read_text(encoding="utf-8").split("[base]")[0]
    (tmp_path / "my_grid.toml").write_text(campaign + grid.replace("] method", "]\nmethod") + "\n", encoding="utf-8")
    run_commands(cmds, tmp_path, timeout=4 * 3600.0)
    assert "my_methods.damped:make" in (tmp_path / "out" / "compare.csv").read_text(encoding="utf-8")
    assert "my_methods.damped:make" in (tmp_path / "board" / "leaderboard.md").read_text(encoding="utf-8")
