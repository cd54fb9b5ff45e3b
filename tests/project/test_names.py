"""One name per concept, and one definition of it.

* No class name is defined twice in ``src/`` (a reader who meets ``Request`` or ``Target`` should not
  have to find out which of several it is);
* no public function or constant is exported (``__all__``) by two modules (``parse_address`` was three
  functions with three return types);
* no order or set of one concept's values (the levels, the hazard classes) is written out in two modules.

Each test has a list of the exceptions, each with the reason; a list entry that no longer applies fails
the test too, so the lists never excuse a name that is gone."""

from __future__ import annotations

import ast
import functools
from collections import defaultdict

from tests.support.paths import ROOT

DELIBERATE: dict[str, str] = {
    "Obstacle": "the suite's world condition (what a case asks any world for, contract 2) and the simulated "
    "arm's model of one (what the reference world turns the condition into)",
}
"""Class names defined twice on purpose -> why."""


def _classes() -> dict[str, list[str]]:
    found: dict[str, list[str]] = defaultdict(list)
    for module, tree in _modules().items():
        for node in tree.body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                found[node.name].append(module)
    return found


def test_no_public_class_name_is_defined_twice() -> None:
    twice = {name: where for name, where in _classes().items() if len(where) > 1}
    unexplained = {name: where for name, where in twice.items() if name not in DELIBERATE}
    assert not unexplained, f"class names defined more than once: {unexplained}"


def test_every_deliberate_pair_still_exists() -> None:
    """A pair renamed away leaves the list, so the list never excuses a name that is gone."""
    classes = _classes()
    assert [name for name in DELIBERATE if len(classes.get(name, ())) < 2] == []


@functools.cache
def _modules() -> dict[str, ast.Module]:
    """Every module of ``src``, parsed once for all the tests here."""
    return {
        str(path.relative_to(ROOT)): ast.parse(path.read_text(encoding="utf-8"))
        for path in sorted((ROOT / "src").rglob("*.py"))
    }


def _exported(tree: ast.Module) -> set[str]:
    """The names a module's ``__all__`` lists."""
    for node in tree.body:
        if (
            isinstance(node, ast.Assign | ast.AnnAssign)
            and isinstance(node.value, ast.List | ast.Tuple)
            and any(isinstance(t, ast.Name) and t.id == "__all__" for t in _targets(node))
        ):
            return {
                e.value for e in node.value.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)
            }
    return set()


def _targets(node: ast.Assign | ast.AnnAssign) -> list[ast.expr]:
    return node.targets if isinstance(node, ast.Assign) else [node.target]


def _defined(tree: ast.Module) -> set[str]:
    """The functions and constants a module defines at top level (classes have the test above)."""
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            names.update(t.id for t in _targets(node) if isinstance(t, ast.Name))
    return names


ENTRY_POINT = "main"
"""Every command's entry point is its module's ``main`` (``pyproject.toml``'s scripts name them)."""

DELIBERATE_NAMES: dict[str, str] = {
    "CONTRACT": "each contract's name and revision, on both of its sides: the suite and the harness for "
    "contract 1, the suite and the reference world for contract 2 (each side says what it speaks)",
    "load_schema": "each report schema's loader: the suite's (report.schema.json) and diff's "
    "(diff.schema.json)",
    "write_json": "each report's JSON writer: the suite's RunReport and diff's comparison",
    "write_junit": "each report's JUnit writer: the suite's RunReport and diff's comparison",
    "HELLO_TIMEOUT": "how long each contract's peer may take to say hello: contract 1's harness, "
    "contract 2's world",
    "MAX_LINE": "the longest line of contract 2, as the suite reads it and as the reference world does",
}
"""Public functions and constants exported by more than one module on purpose (or for now) -> why."""


def _exported_twice() -> dict[str, list[str]]:
    found: dict[str, list[str]] = defaultdict(list)
    for module, tree in _modules().items():
        for name in _exported(tree) & _defined(tree):
            found[name].append(module)
    return {name: where for name, where in found.items() if len(where) > 1 and name != ENTRY_POINT}


def test_no_exported_function_or_constant_is_defined_twice() -> None:
    """``parse_address`` was three functions with three return types: a name a module exports means one
    thing, wherever it is imported from."""
    unexplained = {name: where for name, where in _exported_twice().items() if name not in DELIBERATE_NAMES}
    assert not unexplained, f"functions or constants exported by more than one module: {unexplained}"
    gone = [name for name in DELIBERATE_NAMES if name not in _exported_twice()]
    assert not gone, f"no longer exported twice (take them off DELIBERATE_NAMES): {gone}"


def _members(value: ast.expr | None) -> frozenset[str] | None:
    """The strings a literal lists (a tuple, list or set of them, or a dict ranking them with numbers),
    when there are three or more: an order or a set of one concept's values."""
    if (
        isinstance(value, ast.Call)
        and isinstance(value.func, ast.Name)
        and value.func.id in ("frozenset", "tuple")
    ):
        value = value.args[0] if value.args else None
    if isinstance(value, ast.Tuple | ast.List | ast.Set):
        items = value.elts
    elif isinstance(value, ast.Dict) and all(
        isinstance(v, ast.Constant) and isinstance(v.value, int) for v in value.values
    ):
        items = [k for k in value.keys if k is not None]
    else:
        return None
    if len(items) < 3 or not all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in items):
        return None
    return frozenset(e.value for e in items if isinstance(e, ast.Constant) and isinstance(e.value, str))


DELIBERATE_LISTS: dict[str, str] = {
    "CONTROL / CONTROL_OPERATIONS": "contract 1's control operations on its two sides: the suite's "
    "(conformance.client.contract) and the reference harness's, a layer below, which must not import the "
    "suite; each is written from docs/client-harness.md",
}
"""Lists of one concept's values written in two modules on purpose (or for now), by their names -> why."""


def _lists_written_twice() -> dict[str, list[str]]:
    found: dict[frozenset[str], list[tuple[str, str]]] = defaultdict(list)
    for module, tree in _modules().items():
        for node in tree.body:
            if isinstance(node, ast.Assign | ast.AnnAssign) and (members := _members(node.value)):
                found[members] += [(t.id, module) for t in _targets(node) if isinstance(t, ast.Name)]
    return {
        " / ".join(sorted(name for name, _ in where)): [f"{module}:{name}" for name, module in where]
        for where in found.values()
        if len({module for _, module in where}) > 1
    }


def test_no_order_or_set_of_one_concept_is_written_twice() -> None:
    """The levels and the hazard classes were each listed in three modules: a module that needs one of
    them imports it (``manip.spec.model.LEVELS``, ``HAZARDS``), or derives what it needs from it."""
    twice = _lists_written_twice()
    unexplained = {names: where for names, where in twice.items() if names not in DELIBERATE_LISTS}
    assert not unexplained, f"one concept's values listed in more than one module: {unexplained}"
    gone = [names for names in DELIBERATE_LISTS if names not in twice]
    assert not gone, f"no longer listed twice (take them off DELIBERATE_LISTS): {gone}"


DIFF_PACKAGE = "src/manip/conformance/diff/"
"""Where "finding" names what the diff reports: a classified difference, which may be allowed."""


def test_a_violation_is_never_called_a_finding() -> None:
    """Outside ``manip-conform diff``, no name in ``src`` (function, class, argument, variable, attribute)
    says "finding": a breach of a clause is a violation, whoever reports it."""
    named = sorted(
        f"{module}:{node.lineno} {name}"
        for module, tree in _modules().items()
        if not module.startswith(DIFF_PACKAGE)
        for node in ast.walk(tree)
        for name in _names_bound(node)
        if "finding" in name.lower()
    )
    assert not named, named


def _names_bound(node: ast.AST) -> list[str]:
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return [node.name]
    if isinstance(node, ast.arg):
        return [node.arg]
    if isinstance(node, ast.Name):
        return [node.id]
    if isinstance(node, ast.Attribute):
        return [node.attr]
    return []
