"""Case selection patterns: ``--select``, ``--skip`` and ``--known-failing`` share one grammar.

Case ids are dot-separated components (``server.describe.terminator``).  A pattern is matched
component by component:

* ``*`` (and other :mod:`fnmatch` wildcards ``?``, ``[...]``) match within one component;
* ``**`` matches any number of components, none included;
* a pattern also matches every case *under* what it names: ``server.describe`` selects
  ``server.describe.terminator`` (as if it ended in ``.**``).

An argument ``@FILE`` reads patterns from a file, one per line; ``#`` starts a comment, blank lines are
ignored.  :class:`PatternSet` counts what each pattern matched, so stale entries can be reported.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

__all__ = ["Pattern", "PatternError", "PatternSet", "expand_patterns", "match_id"]


class PatternError(ValueError):
    """A pattern or pattern file that cannot be used (the message says which)."""


@lru_cache(maxsize=4096)
def _match(pattern: tuple[str, ...], parts: tuple[str, ...]) -> bool:
    if not pattern:
        return True  # the pattern named a prefix: everything under it matches
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        return any(_match(rest, parts[i:]) for i in range(len(parts) + 1))
    if not parts:
        return False
    return fnmatch.fnmatchcase(parts[0], head) and _match(rest, parts[1:])


def match_id(pattern: str, case_id: str) -> bool:
    """Whether ``pattern`` selects ``case_id`` (see the module docstring)."""
    return _match(tuple(pattern.split(".")), tuple(case_id.split(".")))


@dataclass
class Pattern:
    text: str
    source: str
    """Where it came from: ``--select`` or ``FILE:LINE``."""
    matched: set[str] = field(default_factory=set)


def expand_patterns(items: Iterable[str], option: str) -> list[Pattern]:
    """Patterns from command-line items, reading ``@FILE`` items."""
    out: list[Pattern] = []
    for item in items:
        if item.startswith("@"):
            path = Path(item[1:])
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except OSError as exc:
                raise PatternError(f"{option} {item}: cannot read {path}: {exc.strerror}") from None
            for number, line in enumerate(lines, 1):
                text = line.split("#", 1)[0].strip()
                if text:
                    out.append(_checked(text, f"{path}:{number}"))
        else:
            out.append(_checked(item.strip(), option))
    return out


def _checked(text: str, source: str) -> Pattern:
    if not text or any(not part for part in text.split(".")) or any(ch.isspace() for ch in text):
        raise PatternError(f"{source}: {text!r} is not a case pattern (dot-separated, no spaces)")
    return Pattern(text, source)


@dataclass
class PatternSet:
    """Patterns with match counting."""

    patterns: list[Pattern] = field(default_factory=list)

    @classmethod
    def of(cls, items: Iterable[str], option: str) -> PatternSet:
        return cls(expand_patterns(items, option))

    def __bool__(self) -> bool:
        return bool(self.patterns)

    def matches(self, case_id: str) -> bool:
        """Whether any pattern selects ``case_id`` (every matching pattern counts the match)."""
        hit = False
        for pattern in self.patterns:
            if match_id(pattern.text, case_id):
                pattern.matched.add(case_id)
                hit = True
        return hit

    def unmatched(self) -> list[Pattern]:
        return [p for p in self.patterns if not p.matched]
