"""No dead code: every module-level definition of ``src/manip`` (function, class, constant) is referenced
somewhere, by its own module, another module, a test, a tool, a benchmark, an example or the docs.

The scan reads words, not imports, so it errs towards "referenced": a name mentioned in a comment, a
docstring or the docs counts (a namesake that another module defines and uses does not; a private name
counts only where ``src`` names it).  A module's own
``__all__`` does not count (listing a name exports it, it does not use it).  A definition that registers
itself by its decorator (a case, a command) is used by being registered.  Words are counted with a
regular expression and only the suspects are parsed, so the test takes a fraction of a second."""

from __future__ import annotations

import ast
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from tests.support.paths import ROOT

UNREFERENCED_ON_PURPOSE: dict[str, str] = {}
"""``module:name`` of definitions kept although nothing names them -> why (none at present)."""

_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TOP_LEVEL = re.compile(
    r"^((?:@.*\n(?:[ \t)\]].*\n)*)*)(?:async def|def|class) ([A-Za-z_]\w*)"  # decorators, a def or class
    r"|^([A-Za-z_]\w*)\s*(?::[^=\n]*)?=(?!=)",  # or an assignment, annotated or not
    re.MULTILINE,
)
_ALL = re.compile(r"^__all__(?:: [^=\n]*)? = \[\n.*?^\]\n|^__all__(?:: [^=\n]*)? = [^\n]*\n", re.M | re.S)
_REGISTERS = re.compile(r"^@(?:case\b|case\.each\b|\w+\.command\b|\w+\.group\b)", re.MULTILINE)
"""Decorators that register what they decorate: ``@case``, ``@case.each``, a click command or group."""
_FROM = re.compile(r"^\s*from (manip[\w.]*) import", re.MULTILINE)
_ELSEWHERE = ("tests", "tools", "bench", "examples", "docs")


@dataclass(frozen=True)
class _Module:
    defined: set[str]
    """The names it defines at top level (by pattern, not yet confirmed by :func:`_defined_at_top`)."""
    words: Counter[str]
    imports_from: set[str]


def _read(path: Path) -> _Module:
    text = path.read_text(encoding="utf-8")
    defined = set()
    for m in _TOP_LEVEL.finditer(text):
        name = m.group(2) or m.group(3)
        if not name.startswith("__") and not _REGISTERS.search(m.group(1) or ""):
            defined.add(name)
    return _Module(defined, Counter(_WORD.findall(_ALL.sub("", text))), set(_FROM.findall(text)))


def _defined_at_top(path: Path) -> set[str]:
    """What the module really defines at top level (the pattern may take a docstring's line for one)."""
    names: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
    return names


def _module(path: Path) -> str:
    return ".".join(path.relative_to(ROOT / "src").with_suffix("").parts)


def _used_elsewhere(name: str, path: Path, modules: dict[Path, _Module]) -> bool:
    """Another module names ``name`` and does not define it itself; for a private name, one that imports
    from ``path``'s module (``self._name`` elsewhere is another thing)."""
    module = _module(path)
    return any(
        name in other.words
        and name not in other.defined
        and (not name.startswith("_") or module in other.imports_from)
        for where, other in modules.items()
        if where != path
    )


def _unreferenced() -> list[str]:
    modules = {path: _read(path) for path in sorted((ROOT / "src" / "manip").rglob("*.py"))}
    outside: set[str] = set()
    for folder in _ELSEWHERE:
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in (".py", ".md"):
                outside.update(_WORD.findall(path.read_text(encoding="utf-8")))
    for path in (ROOT / "README.md", ROOT / "CONTRIBUTING.md", ROOT / "pyproject.toml"):
        outside.update(_WORD.findall(path.read_text(encoding="utf-8")))
    for path in (ROOT / "src" / "manip").rglob("*.toml"):
        outside.update(_WORD.findall(path.read_text(encoding="utf-8")))
    found = []
    for path, module in modules.items():
        suspects = {
            name
            for name in module.defined
            if module.words[name] <= 1
            and (name.startswith("_") or name not in outside)  # a private name is used in src or not at all
            and not _used_elsewhere(name, path, modules)
        }
        if suspects:
            found += [f"{_module(path)}:{name}" for name in sorted(suspects & _defined_at_top(path))]
    return found


def test_every_definition_is_referenced_somewhere() -> None:
    unreferenced = _unreferenced()
    dead = [name for name in unreferenced if name not in UNREFERENCED_ON_PURPOSE]
    assert not dead, f"defined but referenced nowhere (remove them, or explain them in the list): {dead}"
    found_a_use = [name for name in UNREFERENCED_ON_PURPOSE if name not in unreferenced]
    assert not found_a_use, f"kept on purpose but referenced now (take them off the list): {found_a_use}"
