"""Which case a violation counts against: the clauses it declares, or one of the suite's invariants.

A case reports only the clauses it declares (``@case(clauses=...)``); ``manip-conform coverage`` maps
clauses to cases from those declarations, so a case reporting anything else would make the map wrong.
Besides the cases, the suite's own machinery checks some clauses on every exchange of every case, whatever
the case declares.  Those checks are *invariants*, and what they find is attributed to them:

* ``transcript``: after each case the runner judges every probe's recording with
  :func:`~manip.conformance.judge.checks.check_transcript` (one reply per request, echoes, error strings,
  reply shapes, asynchronous responses only when asked for...), and the Chaos probe itself fails a case
  when a request gets no answer or a connection opens without its initial RESPONSE.  A case that runs a
  checker of that family on its own answers (``ctx.check(check_reply(...))``) finds the same things; a
  violation of a clause the case does not declare is the invariant's.
* ``cougar-link``: the Cougar probe fails a case when the DRV-11J link breaks, a tick is not answered
  with its TICKED, or Cougar does not answer a command in time.
* ``client-wire``: after each client case (``manip-conform client``) the packets the client sent are
  judged (:mod:`manip.conformance.client.wire`): request layouts, no request before the initial
  RESPONSE, consecutive packet numbers, acknowledgements, the window.

So a violation is attributed to the case when it names a clause the case declares; to an invariant when
it came from that invariant's machinery (``CaseFailure.invariant``, ``SoftFailure.invariant``) and names
one of the invariant's clauses; and anything else is a bug of the suite (:func:`attribution_problem`):
``ctx.expect``/``ctx.fail`` raise :class:`~manip.conformance.suite.case.UndeclaredClauseError` at the call,
and the runner turns a violation that slipped past them into an ``error`` outcome.  ``coverage`` lists the
invariants beside the cases (``invariant:transcript``), never as a case's coverage.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from manip.conformance.judge.checks import TRANSCRIPT_CLAUSES
from manip.spec import SPEC

__all__ = ["CLIENT_WIRE", "COUGAR_LINK", "INVARIANTS", "TRANSCRIPT", "Invariant", "attribution_problem"]


@dataclass(frozen=True)
class Invariant:
    """A check of the suite's machinery that runs for every case; ``clauses`` are all it may report."""

    name: str
    clauses: frozenset[str]
    summary: str

    @property
    def label(self) -> str:
        """How coverage lists it beside case ids."""
        return f"invariant:{self.name}"


TRANSCRIPT: Final = Invariant(
    "transcript",
    TRANSCRIPT_CLAUSES,
    "every probe's recording judged after each case (check_transcript), and the probe's own waits",
)
COUGAR_LINK: Final = Invariant(
    "cougar-link",
    frozenset({"link.drv11j.framing", "cougar.word-link"}),
    "the Cougar probe: the DRV-11J link stays up, each TICK gets its TICKED, commands are answered",
)
CLIENT_WIRE: Final = Invariant(
    "client-wire",
    frozenset(
        {
            "request.opcode-range",
            "request-data.types",
            "move.transform-data",
            "client.initial-response",
            "ncp.packet-numbers",
            "ncp.acknowledge",
            "ncp.window",
        }
    ),
    "every client case's wire (manip-conform client): request layouts, no request before the initial "
    "RESPONSE, packet numbers, acknowledgements, the window",
)
INVARIANTS: Final[Mapping[str, Invariant]] = MappingProxyType(
    {i.name: i for i in (TRANSCRIPT, COUGAR_LINK, CLIENT_WIRE)}
)

for _invariant in INVARIANTS.values():
    _unknown = sorted(c for c in _invariant.clauses if c not in SPEC.clauses)
    if _unknown:
        raise RuntimeError(f"invariant {_invariant.name} names unknown clause(s) {_unknown}")


def attribution_problem(
    case_id: str, declared: Collection[str], clause: str | None, invariant: str | None
) -> str | None:
    """None when a violation of ``clause`` (reported through ``invariant``, if any) may count in case
    ``case_id``; otherwise what is wrong, naming the case and the clause."""
    if clause is None or clause in declared:
        return None
    if invariant is not None:
        known = INVARIANTS.get(invariant)
        if known is None:
            return f"case {case_id}: clause {clause} reported through unknown invariant {invariant!r}"
        if clause in known.clauses:
            return None
        return (
            f"case {case_id}: invariant {invariant} reported clause {clause}, which is not one of its "
            f"clauses (add it to the invariant's set if its checker really reports it)"
        )
    return (
        f"case {case_id} reported clause {clause}, which it does not declare "
        f"(declared: {', '.join(sorted(declared)) or 'none'}): declare it in @case(clauses=...) "
        "with the right level, or stop reporting it"
    )
