"""One concept per module: no module of the package is over 800 lines."""

from __future__ import annotations

from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vivbench"
MAX_LINES = 800
#: Modules over the limit today, each still to be split (xfail strict: the mark goes once it is).
OVERSIZED = {
    "models/varying.py": "the varying model's basis, solves and persistence are still in one module",
    "models/greybox.py": "the grey-box refit's pieces are still in one module",
    "analysis/changes.py": "the change scans are still in one module",
}


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_modules_are_small():
    big = {str(p.relative_to(PACKAGE)): _lines(p) for p in sorted(PACKAGE.rglob("*.py"))
           if str(p.relative_to(PACKAGE)) not in OVERSIZED and _lines(p) > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"


@pytest.mark.parametrize("module", [pytest.param(m, marks=pytest.mark.xfail(strict=True, reason=why))
                                    for m, why in OVERSIZED.items()])
def test_oversized_modules_are_split(module):
    assert _lines(PACKAGE / module) <= MAX_LINES
