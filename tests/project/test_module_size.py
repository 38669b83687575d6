"""One concept per module: no module of the package is over 800 lines."""

from __future__ import annotations

from pathlib import Path

from tests.helpers import REPO

PACKAGE = REPO / "vivbench"
MAX_LINES = 800


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_modules_are_small():
    big = {str(p.relative_to(PACKAGE)): _lines(p) for p in sorted(PACKAGE.rglob("*.py")) if _lines(p) > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"
