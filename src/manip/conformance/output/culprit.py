"""Which packets of a case a report keeps: the ones around each violation, not merely the first ones.

A case may exchange hundreds of packets and fail at the 250th.  :func:`culprit_index` finds the packet a
violation is about (the packet it carries, else the last packet whose data are the violation's bytes,
else, for a failure of the exchange itself such as a deadline, the last packet), :func:`judged_indices`
every packet it judged (its ``packets``), and :func:`kept_indices` picks the packets a report keeps: every
culprit, whatever the bound (a culprit is never cut), the opening of the connection, a window around
each culprit, then the earliest of the rest up to the report's bound.  The JSON report numbers every
kept packet by its place in the whole transcript (``n``) and names each violation's culprit by that
number (``packet``), so the HTML report can highlight the row and link to it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Final

from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation

__all__ = ["AFTER", "BEFORE", "OPENING", "culprit_index", "judged_indices", "kept_indices"]

OPENING: Final = 4
"""Packets kept from the start of the transcript (the connection's opening)."""
BEFORE: Final = 12
"""Packets kept before each culprit (the requests that led to it)."""
AFTER: Final = 6
"""Packets kept after each culprit (what the peer did next)."""

_WHOLE_EXCHANGE: Final = frozenset({"deadline", "timeout", "closed", "missing_response", "stopped"})
"""Failures about the exchange as a whole: their culprit is the last packet seen."""


def culprit_index(packets: Sequence[WirePacket], violation: Violation) -> int | None:
    """The index in ``packets`` of the packet ``violation`` is about, or None when none is known."""
    if violation.packet is not None:
        for i in range(len(packets) - 1, -1, -1):  # the very object first, else an equal packet
            if packets[i] is violation.packet:
                return i
        for i in range(len(packets) - 1, -1, -1):
            if packets[i] == violation.packet:
                return i
    if violation.data:
        for i in range(len(packets) - 1, -1, -1):
            if packets[i].data and violation.data.startswith(packets[i].data):
                return i
    if packets and violation.kind in _WHOLE_EXCHANGE:
        return len(packets) - 1
    return None


def judged_indices(packets: Sequence[WirePacket], violations: Iterable[Violation]) -> list[int]:
    """The indices in ``packets`` of every packet the ``violations`` judged (their ``packets``) and of
    their culprits (:func:`culprit_index`); those not among ``packets`` are left out."""
    where = {id(p): i for i, p in enumerate(packets)}
    found: set[int] = set()
    for violation in violations:
        found.update(where[id(p)] for p in violation.packets if id(p) in where)
        culprit = culprit_index(packets, violation)
        if culprit is not None:
            found.add(culprit)
    return sorted(found)


def kept_indices(total: int, culprits: Iterable[int], limit: int) -> list[int]:
    """The indices (ascending) of the packets a report keeps of ``total``: every culprit (even beyond
    ``limit``: a culprit is never cut), the opening, a window around each culprit (earliest culprits
    first), then the earliest others, ``limit`` in all when the culprits leave room."""
    must = {c for c in culprits if 0 <= c < total}
    chosen: set[int] = set(range(min(OPENING, total))) | must
    for culprit in sorted(must):
        window = range(max(0, culprit - BEFORE), min(total, culprit + AFTER + 1))
        if len(chosen | set(window)) > limit:
            break
        chosen.update(window)
    for i in range(total):
        if len(chosen) >= limit:
            break
        chosen.add(i)
    return sorted(chosen)
