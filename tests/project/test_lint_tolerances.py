"""Every comparison of floats in the tests goes through the shared tolerance helper (tests/helpers.py).

The helper insists on a reason beside any tolerance looser than its defaults; a
direct ``np.testing.assert_allclose``, ``np.allclose``, ``np.isclose``,
``pytest.approx`` or ``math.isclose`` would bypass that rule, so the test files
may not call them. The helper module itself is the one place that may.
"""

from __future__ import annotations

import ast

import pytest

from tests.helpers import REPO

TESTS = REPO / "tests"
#: Callables that compare floats with a tolerance of their own.
FORBIDDEN = {"assert_allclose", "allclose", "isclose", "approx", "assert_almost_equal", "assert_array_almost_equal",
             "assert_approx_equal"}
#: Files allowed to call them (relative to tests/): the helper that wraps them.
EXEMPT = {"helpers.py"}


def tolerance_bypasses(source: str) -> list[tuple[int, str]]:
    """(line, name) of every call or import of a forbidden comparison in a Python source."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in FORBIDDEN:
            found.append((node.lineno, node.attr))
        elif isinstance(node, ast.ImportFrom):
            found += [(node.lineno, a.name) for a in node.names if a.name in FORBIDDEN]
        elif isinstance(node, ast.Name) and node.id in FORBIDDEN:
            found.append((node.lineno, node.id))
    return sorted(set(found))


def test_no_test_file_compares_floats_around_the_helper():
    sources = sorted(TESTS.rglob("*.py"))  # every package folder of tests/, not only the top one
    assert {TESTS / "helpers.py", TESTS / "models" / "test_conformance.py",
            TESTS / "project" / "test_layout.py"} <= set(sources)
    breaches = [f"{path.relative_to(TESTS).as_posix()}:{line} uses {name}; use tests.helpers.assert_close "
                f"(or is_close, assert_not_close)"
                for path in sources if path.relative_to(TESTS).as_posix() not in EXEMPT
                for line, name in tolerance_bypasses(path.read_text(encoding="utf-8"))]
    assert not breaches, "\n".join(breaches)


@pytest.mark.parametrize("snippet", [
    "import numpy as np\nnp.testing.assert_allclose(1.0, 1.0)",
    "import numpy as np\nassert np.allclose([1.0], [1.0])",
    "import numpy as np\nassert np.isclose(1.0, 1.0)",
    "import pytest\nassert 1.0 == pytest.approx(1.0)",
    "import math\nassert math.isclose(1.0, 1.0)",
    "from numpy.testing import assert_allclose\nassert_allclose(1.0, 1.0)",
    "from pytest import approx\nassert 1.0 == approx(1.0)",
])
def test_the_lint_sees_each_bypass(snippet):
    assert tolerance_bypasses(snippet), snippet


def test_the_lint_leaves_the_helper_alone():
    assert tolerance_bypasses("from tests.helpers import assert_close\nassert_close(1.0, 1.0)") == []
