"""One name per concept: no class name is defined twice in ``src/`` (a reader who meets ``Request`` or
``Target`` should not have to find out which of several it is), except the pairs listed here, each with
the reason the two are kept apart."""

from __future__ import annotations

import ast
from collections import defaultdict

from tests.support.paths import ROOT

DELIBERATE: dict[str, str] = {
    "Obstacle": "the suite's world condition (what a case asks any world for, contract 2) and the simulated "
    "arm's model of one (what the reference world turns the condition into)",
}
"""Class names defined twice on purpose -> why."""


def _classes() -> dict[str, list[str]]:
    found: dict[str, list[str]] = defaultdict(list)
    for path in sorted((ROOT / "src").rglob("*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                found[node.name].append(str(path.relative_to(ROOT)))
    return found


def test_no_public_class_name_is_defined_twice() -> None:
    twice = {name: where for name, where in _classes().items() if len(where) > 1}
    unexplained = {name: where for name, where in twice.items() if name not in DELIBERATE}
    assert not unexplained, f"class names defined more than once: {unexplained}"


def test_every_deliberate_pair_still_exists() -> None:
    """A pair renamed away leaves the list, so the list never excuses a name that is gone."""
    classes = _classes()
    assert [name for name in DELIBERATE if len(classes.get(name, ())) < 2] == []
