"""The Python code blocks of the user-guide pages run as written, so a page that drifts from the code fails.

Each page's blocks run in order in one namespace, in a directory holding a small identified
synthetic campaign as the pages assume it (``campaign/`` with the events, ``identify/`` with
their ``<event_id>.identify.nc``). A block that the page introduces as a module
(``in a module `my_methods.py```) is also written to that file, so that specs such as
``"my_methods:make"`` resolve. (The README's quickstart is run by tests/project/test_readme.py, the
worked property test of docs/testing.md by ``make test-wheel``.)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import REPO, assert_close

DOCS = REPO / "docs"
#: The pages whose Python blocks are run: the user paths of the engineer and the method researcher.
PAGES = ("field_workflow.md", "methods.md", "model_selection.md")
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
_MODULE = re.compile(r"module `([A-Za-z_][A-Za-z0-9_]*)\.py`")


def python_blocks(page: str) -> list[tuple[str | None, str]]:
    """(module name the page writes the block to, or None; code) of each Python block of a page."""
    text = (DOCS / page).read_text(encoding="utf-8")
    out = []
    for m in _BLOCK.finditer(text):
        before = text[:m.start()].rstrip().rsplit("\n\n", 1)[-1]  # the paragraph introducing the block
        module = _MODULE.search(before)
        out.append((module.group(1) if module else None, m.group(1)))
    return out


@pytest.fixture
def page_directory(small_results, tmp_path, monkeypatch):
    """A working directory with campaign/ (the identified events) and identify/ (their results)."""
    camp, _res_dir, results = small_results
    (tmp_path / "campaign").mkdir()
    (tmp_path / "identify").mkdir()
    for r in results:
        event_id = r.name.removesuffix(".identify.nc")
        (tmp_path / "campaign" / f"{event_id}.nc").symlink_to(next(f for f in camp.files if f.stem == event_id))
        (tmp_path / "identify" / r.name).symlink_to(r)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def run_page(page: str, directory: Path, monkeypatch) -> dict:
    """Run a page's Python blocks in order in one namespace; the namespace."""
    namespace: dict = {"__name__": f"docs_{page.removesuffix('.md')}"}
    for i, (module, code) in enumerate(python_blocks(page)):
        if module is not None:
            (directory / f"{module}.py").write_text(code, encoding="utf-8")
            monkeypatch.delitem(sys.modules, module, raising=False)
        exec(compile(code, f"docs/{page} (Python block {i + 1})", "exec"), namespace)  # noqa: S102 - our own docs
    return namespace


def test_the_pages_hold_python_blocks_and_modules_are_named():
    blocks = {page: python_blocks(page) for page in PAGES}
    assert len(blocks["methods.md"]) >= 4 and len(blocks["model_selection.md"]) >= 1
    assert len(blocks["field_workflow.md"]) >= 1
    assert [m for m, _ in blocks["methods.md"]][0] == "my_methods"


def test_methods_page_runs_as_written(page_directory, monkeypatch):
    """The plug-in, the verdict hook, the factories and the scoring of docs/methods.md (a few seconds)."""
    pytest.importorskip("pysindy")  # the adapters' block imports it (the `test` extra has it)
    from vivbench.validate import SCORE_KEYS, default_windows

    ns = run_page("methods.md", page_directory, monkeypatch)
    # The plug-in answers regime 1 (linear damping) everywhere: its coverage is 0 and its accuracy the
    # share of regime-1 windows in the truth.
    scores = ns["scores"]
    assert set(SCORE_KEYS) <= set(scores) and scores["coverage"] == 0.0
    assert_close(scores["accuracy_all"], scores["truth_share_regime1"])
    # The verdict hook flags the windows whose mean amplitude exceeds 5 cm, shape (W, S).
    record = ns["records"][0]
    start, end = default_windows(record)
    flags = ns["DampedWithVerdict"]().fit(ns["records"]).identifiable(record, start, end)
    assert flags.shape == (start.size, record.n_sections) and flags.dtype == bool
    # The factories of the page build methods.
    for factory in ("make", "windows", "campaign", "modal_least"):
        assert callable(getattr(ns[factory](), "fit", None)), factory


def test_model_selection_page_runs_as_written(page_directory, monkeypatch):
    """The selection of docs/model_selection.md on two short events (the heaviest block, about 20 s)."""
    ns = run_page("model_selection.md", page_directory, monkeypatch)
    curves = ns["curves"]["curves"]
    assert curves.sizes["wind"] == 13 and np.isfinite(curves.values).any()
    assert ns["flags"].shape == (ns["window_start"].size, ns["records"][0].n_sections)


def test_field_workflow_page_runs_as_written(page_directory, monkeypatch):
    """docs/field_workflow.md's Python after ``vivbench pool`` (the pooled model: a few seconds)."""
    from vivbench.cli import main

    assert main(["pool", "identify", "--model", "pooled", "--bootstrap", "4", "--block", "20"]) == 0
    ns = run_page("field_workflow.md", page_directory, monkeypatch)
    assert ns["model"].curves([7.0])["curves"].sizes["wind"] == 1
    assert set(np.unique(ns["regimes"]["regime"].values)) <= {0, 1, 2, 3, 4}
    assert ns["model"].predict(ns["record"]).shape == ns["record"].A.shape
