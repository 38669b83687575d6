"""No code outside ``vivbench/models/`` and ``vivbench/io/`` branches on a built-in model's class or fitted attributes.

Regimes, forecasts, validation and the report ask a model only through the protocol's names
(``vivbench.models.protocol``), so a user's model gets every feature a built-in one gets. An AST
scan finds the ways of telling models apart that the protocol replaces:

- ``isinstance``/``issubclass`` against a model class;
- ``getattr``/``hasattr`` of a fitted attribute (a name ending in ``_``) of another object than ``self``;
- a comparison with a model class's name (``"VaryingCoefficientSINDy"``, ``Cls.__name__``,
  ``type(m).__name__``).
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import vivbench.analysis
import vivbench.models
import vivbench.validate

ROOT = Path(vivbench.models.__file__).resolve().parents[1]
OWNERS = ("models", "io")  # the packages that define the models and their files

#: (path relative to vivbench/, the offending source text): why it stays.
ALLOWED: dict = {}


def _model_classes() -> set[str]:
    """Names of the model classes: vivbench.models' classes with ``fit`` or ``order_contributions``, and the
    wrappers that stand for a model (a selection, the validation's verdict wrappers)."""
    names = set()
    for module in (vivbench.models, vivbench.analysis, vivbench.validate):
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.isclass(obj) and (hasattr(obj, "order_contributions") or hasattr(obj, "window_verdicts")
                                         or name == "ModelSelection"):
                names.add(name)
            elif module is vivbench.models and inspect.isclass(obj) and hasattr(obj, "fit"):
                names.add(name)
    return names


def _names_in(node) -> set[str]:
    if isinstance(node, ast.Tuple):
        return set().union(*(_names_in(e) for e in node.elts))
    if isinstance(node, ast.Name):
        return {node.id}
    if isinstance(node, ast.Attribute):
        return {node.attr}
    return set()


def branches(source: str, classes: set[str]) -> list[tuple[int, str]]:
    """(line, source text) of every branch on a model's class or fitted attributes in ``source``."""
    tree = ast.parse(source)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            fn, args = node.func.id, node.args
            if fn in ("isinstance", "issubclass") and len(args) == 2 and _names_in(args[1]) & classes:
                found.append(node)
            elif (fn in ("getattr", "hasattr") and len(args) >= 2 and isinstance(args[1], ast.Constant)
                  and isinstance(args[1].value, str) and args[1].value.endswith("_")
                  and not args[1].value.startswith("_")
                  and not (isinstance(args[0], ast.Name) and args[0].id == "self")):
                found.append(node)
        elif isinstance(node, ast.Compare):
            for side in [node.left, *node.comparators]:
                if isinstance(side, ast.Constant) and side.value in classes:
                    found.append(node)
                    break
                if (isinstance(side, ast.Attribute) and side.attr == "__name__"
                        and (_names_in(side.value) & classes or isinstance(side.value, ast.Call))):
                    found.append(node)
                    break
    return sorted((n.lineno, ast.get_source_segment(source, n) or "") for n in found)


def test_no_branch_on_a_model_class_outside_models_and_io():
    classes = _model_classes()
    assert {"PooledSINDy", "VaryingCoefficientSINDy", "ModelSelection", "BinnedPolynomial"} <= classes
    offending, used = [], set()
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.split("/")[0] in OWNERS:
            continue
        for line, text in branches(path.read_text(), classes):
            if (rel, text) in ALLOWED:
                used.add((rel, text))
            else:
                offending.append(f"vivbench/{rel}:{line}: {text}")
    assert offending == [], "branches on a model's class or fitted attributes (use the protocol):\n" + "\n".join(offending)
    assert used == set(ALLOWED), f"allow-list entries that no longer match: {set(ALLOWED) - used}"


def test_the_scan_finds_each_kind_of_branch():
    """The scanner is not blind: each kind of branch in a snippet is found, the protocol's ways are not."""
    classes = {"PooledSINDy", "VaryingCoefficientSINDy"}
    bad = '''
if isinstance(model, (PooledSINDy, int)):
    pass
if getattr(model, "amplitude_ratios_", None) is None:
    pass
if hasattr(model, "gram_inv_"):
    pass
varying = pooled.attrs.get("model") == "VaryingCoefficientSINDy"
same = type(model).__name__ == name
'''
    assert [line for line, _ in branches(bad, classes)] == [2, 4, 6, 8, 9]
    good = '''
own = getattr(model, "window_verdicts", None)
fitted = getattr(self, "model_", None)
ok = isinstance(record, Record)
'''
    assert branches(good, classes) == []
