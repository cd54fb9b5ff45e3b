"""Which clauses a fault proves: the per-clause coverage table of ``docs/spec.md``, read from the registries.

A case that judges a clause is only shown to work when some defect makes it fail.  A fault switch of the
reference server (:class:`~manip.reference_server.faults.Fault`), the reference client
(:class:`~manip.reference_client.faults.ClientFault`) or the simulated Cougar
(:class:`~manip.cougar.faults.CougarFault`) *proves* a clause when the clause is among those the switch
declares it breaks (``clauses``) and its fault matrix requires a case that cites the clause to catch it:
one of the cases the switch declares catch it (``caught_by``: the server's matrix,
``tests/conformance/test_faults.py``, and the wrist side's, ``tests/conformance/puma/test_puma.py``,
require each to fail or warn; the client's and the Cougar's, to fail) declares the clause.

:func:`clause_proofs` gives, for every live clause of the spec: the cases that judge it (``@case``
declarations, the client recordings' ``verify:FAMILY`` judges and the suite's ``invariant:NAME`` checks,
as ``manip-conform coverage`` lists them), the switches that prove it, and whether a server written from
the 1985 guide alone has it judged: its status in the report of :data:`GUIDE_RUN`, a run of the suite
against the reference server's guide profile, which serves what the 1985 guide describes and no Puma
extension.  Nothing here is typed by hand: every fact comes from the case declarations, the spec, the
fault registries and that run's report.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from manip.conformance.output.coverage import ClauseCoverage, coverage
from manip.conformance.suite.case import Case
from manip.cougar.faults import CougarFault
from manip.reference_client.faults import ClientFault
from manip.reference_server.faults import Fault
from manip.spec import SPEC
from manip.spec.faults import FaultSwitch

__all__ = [
    "GUIDE_RUN",
    "NOT_RUN",
    "REGISTRIES",
    "ClauseProof",
    "Totals",
    "clause_proofs",
    "guide_statuses",
    "proves",
    "totals",
]

REGISTRIES: Final[Mapping[str, type[FaultSwitch]]] = {
    "server": Fault,
    "client": ClientFault,
    "cougar": CougarFault,
}
"""Each implementation's fault registry, by the name the table gives it."""
GUIDE_RUN: Final = ("run", "--server-profile", "guide", "--length-unit", "inch", "--seed", "5")
"""The ``manip-conform`` run whose report gives the guide-only column: the embedded reference server's
guide profile (no Puma extension opcode, lengths in inches, the guide's asynchronous layout) with its
world, in virtual time."""
NOT_RUN: Final = "n/a"
"""The guide-only column of a clause no case of :data:`GUIDE_RUN` cites (a clause of the client, the
Cougar or the Puma's wrist side); the others show the clause's status in that run's report (``held`` or
``broken``: judged; ``not-judged``: the cases citing it need what the 1985 guide does not offer, and say
what would judge it; ``not-exercised``: no check reached it, as for a link the embedded server is not
on)."""
_JUDGED: Final = frozenset({"held", "broken"})
"""The statuses of a clause a case came to a verdict on."""


@dataclass(frozen=True)
class ClauseProof(ClauseCoverage):
    """One clause's row of the coverage table: its coverage (what judges it), and what proves it."""

    faults: tuple[str, ...] = ()
    """The switches that prove it, as ``IMPLEMENTATION:NAME`` (``server:no-jor``)."""
    guide_only: str = NOT_RUN
    """Its status on a guide-only server (:data:`NOT_RUN`)."""

    @property
    def judged(self) -> bool:
        return bool(self.cases)

    @property
    def proven(self) -> bool:
        return bool(self.faults)


@dataclass(frozen=True)
class Totals:
    """The table's totals, over the live clauses."""

    proven: int
    """Judged by a case that a fault proves."""
    unproven: int
    """Judged, but proven by no fault."""
    unjudged: int
    """Judged by no case (INFO clauses apart)."""
    info: int
    """INFO clauses: statements of fact, not requirements; the spec data has no other notion of what the
    wire cannot show, so this is the count of what is not to be judged."""
    guide_only: int
    """Judged on a guide-only server (a case of :data:`GUIDE_RUN` came to a verdict on it)."""


def proves(fault: FaultSwitch, clause: str, cases: Mapping[str, Case]) -> bool:
    """``fault`` proves ``clause``: it declares it breaks the clause, and a case it declares catch it
    cites the clause."""
    return clause in fault.clauses and any(clause in cases[k].clauses for k in fault.caught_by if k in cases)


def guide_statuses(clause_status: Iterable[Mapping[str, object]]) -> dict[str, str]:
    """Each clause's status on a guide-only server, from the ``clause_status`` of :data:`GUIDE_RUN`'s JSON
    report."""
    return {str(row["clause"]): str(row["status"]) for row in clause_status}


def clause_proofs(cases: Sequence[Case], guide: Mapping[str, str]) -> list[ClauseProof]:
    """Every live clause with what judges it, the switches that prove it, and its status on a guide-only
    server (``guide``, from :func:`guide_statuses`; :data:`NOT_RUN` for a clause it does not list)."""
    by_id = {c.id: c for c in cases}
    rows = coverage(cases, {c.party for c in SPEC.clauses.values()})
    return [
        ClauseProof(
            **vars(row),
            faults=tuple(
                f"{name}:{fault.value}"
                for name, registry in REGISTRIES.items()
                for fault in registry
                if proves(fault, row.clause, by_id)
            ),
            guide_only=guide.get(row.clause, NOT_RUN),
        )
        for row in rows
    ]


def totals(rows: Iterable[ClauseProof]) -> Totals:
    """Count the rows: proven, judged but unproven, unjudged, INFO, judged on a guide-only server."""
    listed = list(rows)
    rules = [r for r in listed if r.level != "INFO"]
    return Totals(
        proven=sum(r.judged and r.proven for r in rules),
        unproven=sum(r.judged and not r.proven for r in rules),
        unjudged=sum(not r.judged for r in rules),
        info=len(listed) - len(rules),
        guide_only=sum(r.guide_only in _JUDGED for r in rules),
    )
