"""Classifying a difference between two sides: a violation, a difference both allowed, or a gap.

* **violation** (class a): the fuzzer's judges (:func:`manip.conformance.fuzz.judge.judge`: the
  transcript checks and the oracles, and :mod:`.oracles`) find a clause broken on one side's answers to
  the input and not on the other's: the clause is named, and the other side's answer is the conforming
  one.  Differences on later inputs of the same stream follow from the first such breach (their
  ``follows`` names it) and are counted with it: after a broken clause the two sides need not agree.
* **allowed** (class b): every part that differs is a freedom (:data:`manip.spec.model.FREEDOMS`) some
  clause or erratum of the spec data declares (``freedom = [...]``); those are named.
* **unexplained** (class c): neither: a candidate gap in the spec, shown with the guide section of the
  clause nearest to it.

Sans-I/O.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Literal

from manip.codecs.error_string import parse_error
from manip.codecs.errors import CodecError
from manip.conformance.diff.pairing import Difference, SideEvent
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, RequestStep
from manip.spec import SPEC
from manip.spec.constants import ServerOp

__all__ = ["CLASSES", "Finding", "FindingClass", "classify", "declared", "nearest_section"]

FindingClass = Literal["violation", "allowed", "unexplained"]
CLASSES: Final[tuple[FindingClass, ...]] = ("violation", "allowed", "unexplained")
_PART_CLAUSE: Final = {
    "error": "error-string.format",
    "async": "async.layout",
    "end": "error.fatal-then-close",
    "stray": "ncp.los",
}
"""The clause nearest a difference that names no request, by the first word of the part."""
_EXACT_CLAUSE: Final = {
    "error.args": "error-string.arg-values",
    "error.args-layout": "error-string.arg-layout",
    "error.severity": "error.severity-matches-opcode",
    "error.number": "error.fatal-request-number",
    "async.data": "async.codes",
}
"""The clause that speaks of exactly that part, nearer than the request's own."""


@dataclass(frozen=True)
class Finding:
    """One classified difference (module docstring)."""

    cls: FindingClass
    stream: str
    difference: Difference
    names: tuple[str, ...] = ()
    """violation: the clause(s) broken; allowed: the errata and clauses declaring the freedom."""
    violator: Literal["A", "B", "both", ""] = ""
    message: str = ""
    section: str = ""
    follows: str = ""
    """For a difference after a violation in its stream: that violation's clause."""
    shrunk: tuple[int, ...] | None = None
    """For a gap: the input numbers of the shortest stream found that still shows it."""
    freedoms: tuple[str, ...] = ()
    """For a difference both allowed: the freedoms it is (:func:`in_context` of its parts)."""


def declared(part: str) -> tuple[str, ...]:
    """The errata and clauses that declare ``part`` the implementation's choice (errata first)."""
    errata = [e.id for e in SPEC.errata.values() if part in e.freedom]
    clauses = [c.id for c in SPEC.clauses.values() if part in c.freedom and not c.retired]
    return (*errata, *clauses)


def _broken(sightings: Sequence[Sighting], number: int) -> dict[str, str]:
    """The clauses broken (with the judge's message) by the answers to input ``number``."""
    return {
        s.violation.clause or s.violation.kind: s.violation.message
        for s in sightings
        if s.number == number or (s.number is None and number >= 0)
    }


def nearest_section(diff: Difference, item: FuzzInput | None) -> tuple[str, str]:
    """The clause nearest a difference and its guide section: one about exactly that part, else the
    clauses of the request answered (else of the input's first request), else the part's kind's."""
    exact = SPEC.clauses.get(_EXACT_CLAUSE.get(diff.parts[0], ""))
    if exact is not None:
        return exact.id, exact.section
    answered = [_answered(e, item) for e in (diff.a, diff.b) if e is not None]
    first = next((s.opcode for s in item.steps if isinstance(s, RequestStep)), None) if item else None
    opcode = next((o for o in answered if o is not None), first)
    op = SPEC.requests.get(opcode) if opcode is not None else None
    if op is not None:
        for clause in SPEC.clauses.values():
            if clause.id.startswith(f"{op.name}.") and not clause.retired:
                return clause.id, clause.section
    head = diff.parts[0].split(".")[0]
    cid = _PART_CLAUSE.get(head, "request.one-reply")
    nearest = SPEC.clauses.get(cid)
    return (cid, nearest.section) if nearest is not None else ("", "")


def _unilateral(
    sightings_a: Sequence[Sighting], sightings_b: Sequence[Sighting], numbers: Sequence[int]
) -> list[tuple[int, Literal["A", "B"], str, str]]:
    """Each breach one side showed on an input and the other did not: (input, side, clause, message),
    in stream order."""
    out: list[tuple[int, Literal["A", "B"], str, str]] = []
    for number in numbers:
        broken_a, broken_b = _broken(sightings_a, number), _broken(sightings_b, number)
        out += [(number, "A", c, broken_a[c]) for c in sorted(set(broken_a) - set(broken_b))]
        out += [(number, "B", c, broken_b[c]) for c in sorted(set(broken_b) - set(broken_a))]
    return out


def classify(
    stream: str,
    differences: Sequence[Difference],
    sightings_a: Sequence[Sighting],
    sightings_b: Sequence[Sighting],
    inputs: dict[int, FuzzInput],
    *,
    units_differ: bool = False,
) -> list[Finding]:
    """Each difference of one stream, classified (module docstring).  A difference on an input where one
    side broke a clause the other did not is that violation; one after such an input follows from it (a
    side that broke a clause may answer out of step from then on: an extra reply is paired with the next
    request).  ``units_differ``: the two sides use different length units (erratum units), so a
    Cartesian move one refuses as out of reach and the other makes is both allowed, and so is every
    difference after it (the arm stands elsewhere on one side)."""
    out: list[Finding] = []
    order = list(inputs) if inputs else sorted({d.number for d in differences})
    breaches = _unilateral(sightings_a, sightings_b, order)
    position = {n: i for i, n in enumerate(order)}
    allowed: list[str] = []
    for diff in differences:
        here = position.get(diff.number, len(order))
        same = [b for b in breaches if b[0] == diff.number]
        earlier = [b for b in breaches if position.get(b[0], 0) < here]
        if same:
            same += [b for b in _about(diff, inputs.get(diff.number), breaches) if b not in same]
            sides = {b[1] for b in same}
            violator: Literal["A", "B", "both"] = "both" if len(sides) == 2 else same[0][1]
            names = tuple(dict.fromkeys(b[2] for b in same))
            out.append(Finding("violation", stream, diff, names, violator, same[0][3], _section(names[0])))
        elif about := _about(diff, inputs.get(diff.number), breaches):
            sides = {b[1] for b in about}
            violator = "both" if len(sides) == 2 else about[0][1]
            names = tuple(dict.fromkeys(b[2] for b in about))
            message = f"{about[0][3]} (judged at input {about[0][0]})"
            out.append(Finding("violation", stream, diff, names, violator, message, _section(names[0])))
        elif earlier:
            number, side, cid, _ = earlier[0]
            follows = f"{cid} (input {number})"
            out.append(Finding("violation", stream, diff, (cid,), side, "", _section(cid), follows))
        else:
            found = _free_or_gap(stream, diff, inputs.get(diff.number), units_differ=units_differ)
            if found.cls == "unexplained":
                found = _following(found, allowed)
            elif found.cls == "allowed":
                allowed += [f for f in found.freedoms if f in _CARRIED and f not in allowed]
            out.append(found)
    return out


_CARRIED: Final = ("answer.length-unit", "request.extension-served")
"""Freedoms whose difference changes what the two sides do next: after a Cartesian move one side made
and the other refused for its length unit, the arm stands elsewhere on one side (every later answer may
differ); after an extension refused by one side (request notifications), the asynchronous packets it
would have asked for do not come, and after one served by one side only (a motion extension), the
asynchronous packets of the motion it made come on that side alone and put the two sides' answers out
of step (the ``step`` part; no judge of either side found a reply missing or extra)."""


def _following(found: Finding, allowed: Sequence[str]) -> Finding:
    """A gap that follows from an earlier difference both allowed (:data:`_CARRIED`), as that one."""
    d = found.difference
    asynchronous = any(
        e is not None and e.kind == "packet" and e.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
        for e in (d.a, d.b)
    )
    for freedom in allowed:
        if freedom == "answer.length-unit" or asynchronous or d.parts == ("step",):
            names = declared(freedom)
            message = f"both conform: it follows from an earlier difference both allowed ({freedom})"
            return Finding(
                "allowed", found.stream, d, names, "", message, _section(names[-1]), freedoms=(freedom,)
            )
    return found


_ABOUT: Final = {"describe-self": "describe"}
"""The first word of the clauses about a request's answer, where it is not the request's name."""


def _about(
    diff: Difference, item: FuzzInput | None, breaches: Sequence[tuple[int, Literal["A", "B"], str, str]]
) -> list[tuple[int, Literal["A", "B"], str, str]]:
    """The breaches, anywhere in the stream, of a clause about the request the differing answer answers:
    what an answer states may be judged only by a later request that tests it (describe self's
    :operations by a request of a listed opcode, its :joint-limits by a joint angle beyond one), and
    the judge then attributes the breach to that request."""
    opcodes = {_answered(e, item) for e in (diff.a, diff.b) if e is not None}
    names = {SPEC.requests[o].name for o in opcodes if o is not None and o in SPEC.requests}
    prefixes = {f"{_ABOUT.get(n, n)}." for n in names}
    return [b for b in breaches if any(b[2].startswith(p) for p in prefixes)]


def _section(cid: str) -> str:
    clause = SPEC.clauses.get(cid)
    return clause.section if clause is not None else ""


_CONTEXTUAL: Final = frozenset({"opcode", "data", "count"})
"""Parts whose difference a request of the input may explain (:func:`in_context`)."""
_OPERATIONS: Final = re.compile(rb"\(:OPERATIONS((?: [0-7]+)*)\)")


def listed_extensions_only(a: bytes, b: bytes) -> bool:
    """Whether two describe-self reply packets differ only in the manip extension opcodes their
    ``:OPERATIONS`` lists name (erratum extension-range: a server may serve them or not, and lists what
    it serves, erratum describe-self-truthful)."""
    ma, mb = _OPERATIONS.search(a), _OPERATIONS.search(b)
    if ma is None or mb is None or _OPERATIONS.sub(b"", a) != _OPERATIONS.sub(b"", b):
        return False
    ops_a, ops_b = (frozenset(int(x, 8) for x in m.group(1).split()) for m in (ma, mb))
    return all(op in SPEC.requests and SPEC.requests[op].extension for op in ops_a ^ ops_b)


_UNIT_MOVES: Final = frozenset(
    {"incremental-move", "incremental-straight-move", "move", "straight-move", "solve-forwards"}
)
"""The requests whose clauses declare ``answer.length-unit`` (``incremental-move.data``,
``incremental-straight-move.data``, ``move.transform-data``, ``solve-forwards.data``): their dX dY dZ, or
their transform's position, are in the side's unit."""


def _unit_reach(diff: Difference | None) -> bool:
    """One side's answer is done and the other's a refusal as out of reach (TOR)."""
    if diff is None or diff.a is None or diff.b is None:
        return False
    kinds = set()
    for event in (diff.a, diff.b):
        if event.kind == "packet" and event.opcode == ServerOp.RESPONSE:
            kinds.add("done")
        elif event.kind == "packet" and event.opcode == ServerOp.NON_FATAL_ERROR:
            try:
                kinds.add(parse_error(event.data, body="packet").code)
            except (CodecError, ValueError):
                return False
    return kinds == {"done", "TOR"}


def _refused_unknown(diff: Difference | None) -> bool:
    """One side refused the request as an opcode it does not serve (C UOP): whatever the other side
    answered, the difference is whether the request is served."""
    for event in (diff.a, diff.b) if diff is not None else ():
        if event is not None and event.kind == "packet" and event.opcode == ServerOp.NON_FATAL_ERROR:
            with contextlib.suppress(CodecError, ValueError):
                if parse_error(event.data, body="packet").code == "UOP":
                    return True
    return False


def in_context(
    parts: tuple[str, ...],
    item: FuzzInput | None,
    diff: Difference | None = None,
    *,
    units_differ: bool = False,
) -> tuple[str, ...]:
    """The parts as the request answered explains them (the request each side's answer pairs with, else
    the input's only request): an answer to a manip extension opcode is ``request.extension-served`` (a
    server may refuse extensions as unknown, erratum extension-range), and so is a describe-self reply
    whose ``:OPERATIONS`` differ only in extension opcodes; the answer to set configuration is
    ``answer.configuration-bits`` (other bits refused or answered done, erratum set-configuration)."""
    ops = {_answered(e, item) for e in (diff.a, diff.b) if e is not None} if diff is not None else set()
    if diff is None and item is not None:
        ops = {_answered(None, item)}
    known = [SPEC.requests[o] for o in ops if o is not None and o in SPEC.requests]
    named = {op.name for op in known}
    extension = any(op.extension for op in known)
    describe = (
        diff is not None
        and diff.a is not None
        and diff.b is not None
        and listed_extensions_only(diff.a.data, diff.b.data)
    )
    reach = units_differ and bool(named & _UNIT_MOVES) and _unit_reach(diff)
    unserved = extension and _refused_unknown(diff)
    out: list[str] = []
    for part in parts:
        if unserved:
            part = "request.extension-served"
        elif part == "opcode" and reach:
            part = "answer.length-unit"
        elif (part in _CONTEXTUAL and extension) or (part == "data" and describe):
            part = "request.extension-served"
        elif part in _CONTEXTUAL and "set-configuration" in named:
            part = "answer.configuration-bits"
        if part not in out:
            out.append(part)
    return tuple(out)


def _answered(event: SideEvent | None, item: FuzzInput | None) -> int | None:
    """The opcode of the request an answer answers: paired, else the input's only request."""
    if event is not None and event.request is not None:
        return event.request
    requests = [s.opcode for s in item.steps if isinstance(s, RequestStep)] if item is not None else []
    return requests[0] if len(requests) == 1 else None


def _free_or_gap(
    stream: str, diff: Difference, item: FuzzInput | None, *, units_differ: bool = False
) -> Finding:
    names: list[str] = []
    freedoms = in_context(diff.parts, item, diff, units_differ=units_differ)
    for part in freedoms:
        allowing = declared(part)
        if not allowing:
            cid, section = nearest_section(diff, item)
            what = ", ".join(p for p in diff.parts if not declared(p))
            message = f"the answers differ in {what}, and no clause or erratum says which conforms"
            return Finding("unexplained", stream, diff, (cid,) if cid else (), "", message, section)
        names += [n for n in allowing if n not in names]
    message = f"both conform: {', '.join(freedoms)} is the implementation's choice"
    return Finding("allowed", stream, diff, tuple(names), "", message, _section(names[-1]), freedoms=freedoms)
