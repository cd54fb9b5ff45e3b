"""Clause coverage: which cases check each clause, and which MUST clauses no case checks.

Scope (erratum ``conformance-scope``): a server run can observe what binds the server, what binds both
parties, and the links it runs over, and ``run --puma`` what binds the server's wrist side, so a MUST
clause of party ``server``, ``both``, ``link`` or ``puma`` with no case is a gap.  Clauses of party
``client`` are judged live by the client cases (``client.*``, run by ``manip-conform client`` against a
harness) and from recordings of a client (``manip-conform verify --judge client``; listed as
``verify:FAMILY``), and ``cougar`` ones by the Cougar target (``--cougar``); they are listed, and count as
gaps only when their party is asked for.

Cases are listed by what they declare (``@case(clauses=...)``), which is exactly what they may report
(:mod:`manip.conformance.suite.invariants`).  The suite's invariants, which judge every exchange of every
case whatever it declares, are listed beside them as ``invariant:NAME`` (``invariant:transcript``: the
runner's check of every recording; ``invariant:cougar-link``: the Cougar probe's), never under a case.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from manip.conformance.replay.verify import CLIENT_FAMILIES
from manip.conformance.suite.case import Case
from manip.conformance.suite.invariants import INVARIANTS
from manip.spec import SPEC

__all__ = ["DEFAULT_PARTIES", "ClauseCoverage", "coverage", "gaps"]

DEFAULT_PARTIES: Final = frozenset({"server", "both", "link", "puma"})


@dataclass(frozen=True)
class ClauseCoverage:
    clause: str
    level: str
    party: str
    cases: tuple[str, ...]
    """Case ids, then ``verify:FAMILY`` and ``invariant:NAME`` entries."""
    in_scope: bool

    @property
    def gap(self) -> bool:
        return self.in_scope and self.level == "MUST" and not self.cases

    @property
    def invariants(self) -> tuple[str, ...]:
        """The ``invariant:NAME`` entries: checked on every exchange, by the suite itself."""
        return tuple(c for c in self.cases if c.startswith("invariant:"))


def coverage(cases: Sequence[Case], parties: Iterable[str] = DEFAULT_PARTIES) -> list[ClauseCoverage]:
    """Every live clause of the spec with the ids of the cases that name it."""
    scope = frozenset(parties)
    by_clause: dict[str, list[str]] = {cid: [] for cid in SPEC.clauses}
    for item in cases:
        for clause in item.clauses:
            by_clause[clause].append(item.id)
    for family in CLIENT_FAMILIES:  # judged offline, from a recording of the client
        for clause in family.clauses:
            by_clause[clause].append(f"verify:{family.name}")
    by_invariant: dict[str, list[str]] = {cid: [] for cid in SPEC.clauses}
    for invariant in INVARIANTS.values():
        for clause in invariant.clauses:
            by_invariant[clause].append(invariant.label)
    return [
        ClauseCoverage(
            cid,
            c.level,
            c.party,
            tuple(sorted(by_clause[cid])) + tuple(sorted(by_invariant[cid])),
            c.party in scope,
        )
        for cid, c in SPEC.clauses.items()
        if not c.retired
    ]


def gaps(rows: Iterable[ClauseCoverage]) -> list[ClauseCoverage]:
    """MUST clauses in scope that no case checks."""
    return [row for row in rows if row.gap]
