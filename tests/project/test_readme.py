"""The README is a front page: short, current, and pointing only inside the repository."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.helpers import REPO, assert_close
from vivbench.report import HEADLINE_BEGIN, HEADLINE_END, headline_table, readme_with_headline

README = REPO / "README.md"
REPORT = REPO / "reports" / "default" / "report.md"


def test_headline_table_is_what_the_reference_report_says():
    text = README.read_text(encoding="utf-8")
    expected = readme_with_headline(text, headline_table(REPORT.read_text(encoding="utf-8")))
    assert text == expected, "README.md's headline table differs from reports/default/report.md: run `make readme`"


def test_readme_is_a_front_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 300
    assert len(text.encode("utf-8")) <= 20 * 1024
    first = "\n".join(text.splitlines()[:40])
    assert "make demo" in first and "make test" in first
    for lang in ("python", ""):
        for block in re.findall(rf"```{lang}\n(.*?)```", text, re.S):
            if "vivbench" in block:
                assert len(block.strip().splitlines()) <= 15, block


def test_readme_points_only_inside_the_repository():
    text = README.read_text(encoding="utf-8")
    assert "../" not in text and "DESIGN" not in text
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if re.match(r"https?://", target):
            continue
        assert (REPO / target).exists(), f"README links to {target}, which is not in the repository"


def test_headline_table_refuses_a_report_without_it():
    with pytest.raises(ValueError, match="Recovery side by side"):
        headline_table("# a report\n\n## Figures\n")
    table = headline_table(REPORT.read_text(encoding="utf-8"))
    with pytest.raises(ValueError, match="lacks the rows"):
        headline_table(REPORT.read_text(encoding="utf-8"), rows=("no such row",))
    with pytest.raises(ValueError, match="needs the lines"):
        readme_with_headline("# no markers\n", table)
    replaced = readme_with_headline(f"a\n{HEADLINE_BEGIN}\nold\n{HEADLINE_END}\nb\n", table)
    assert replaced == f"a\n{HEADLINE_BEGIN}\n\n{table}\n{HEADLINE_END}\nb\n"


def test_python_quickstart_runs_as_written(tmp_path, monkeypatch):
    """The README's Python quickstart, copied as it stands, runs in an empty directory (about 15 s)."""
    (block,) = [b for b in re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)]
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(block, "README.md (Python quickstart)", "exec"), namespace)  # noqa: S102 - our own README
    assert sorted(p.name for p in (tmp_path / "identify").glob("*.identify.nc")) == [f"E00{i}.identify.nc"
                                                                                     for i in range(1, 7)]
    regimes = namespace["regimes"]  # coverage: the share of window-equations with a regime flagged identifiable
    scored = regimes["regime"].values > 0
    assert scored.any()
    assert_close(regimes.attrs["coverage"], np.mean(regimes["identifiable"].values[scored]), what="coverage of the campaign regimes")
    assert namespace["model"].curves([7.0])["curves"].shape == (3, 4, 1)
