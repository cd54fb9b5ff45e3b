"""The one record of "a clause was broken": :class:`Violation`, whoever found it.

A checker returns violations, the stateful model returns them, ``ctx.expect`` builds one when its
condition is false, a probe raises one inside :class:`~manip.conformance.suite.case.CaseFailure`,
replay and ``verify`` report them, and a case result lists them: the same frozen value all the way to
the JSON report, never copied field by field into another record.

What came is given as *evidence*, in one form (``seen=``): :func:`evidence` derives the text
(``actual``) and the bytes (``data``) from it, and :func:`seen_packets` the packets it judged (the
violation's ``packets``, which the report never cuts), so a case says what it looked at, not how to
print it:

* a :class:`~manip.conformance.judge.packets.WirePacket`: its description and data;
* anything with ``data`` bytes and a ``str`` (an ``Answer``, a Cougar ``WordReply``): both, and an
  answer's packets;
* a list or tuple of those: joined with ``"; "`` (``"nothing"`` when empty), the bytes concatenated;
* :func:`showing` (``showing(answer, "mask 5")``): the case's own words about what ``answer`` showed: the
  text is the case's, the bytes and packets the answer's;
* :func:`missing` (``missing("no CLS within 2 s", after=answer)``): a packet that never came; the
  violation's kind is ``missing_response``, the one kind of a case's check that may name no packet (it
  names those of ``after``, what the packet should have followed, when given);
* ``bytes``: shown in hex; a string: the text alone; anything else: its ``str``.  Text alone names no
  packet: the context then names the last packet of the case's recording, the one the check was reading
  (:meth:`~manip.conformance.suite.context.CaseContext.judged`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, Literal, Protocol, get_args, runtime_checkable

from manip.conformance.judge.packets import WirePacket, describe
from manip.spec import SPEC
from manip.spec.model import Level

__all__ = [
    "FAILURE_KINDS",
    "MAX_EVIDENCE_BYTES",
    "MAX_TEXT",
    "NEVER_CAME",
    "CarriesData",
    "CarriesViolation",
    "FailureKind",
    "Missing",
    "Shown",
    "Violation",
    "evidence",
    "missing",
    "seen_kind",
    "seen_packets",
    "showing",
]

FailureKind = Literal[
    "wrong_value",
    "malformed",
    "timeout",
    "closed",
    "missing_response",
    "unexpected_message",
    "deadline",
    "mismatch",
    "missing",
    "stopped",
    "crash",
    "traceback",
    "uncounted_drop",
]
"""What went wrong, for a violation (the report's ``kind``): a wrong value (the default), a malformed
packet, no answer in time, the connection closed, a missing or unexpected message (``missing_response``:
a packet that should have come never did, so no packet shows it), the case's deadline;
``mismatch``, ``missing`` and ``stopped`` are replay's (a live answer that differs from the recorded
one, a session no client played, a replay that could not go on); ``crash``, ``traceback`` and
``uncounted_drop`` are the fuzzer's (the target gone, a traceback in its log, bad frames it dropped
without counting them; a target that stops answering is a ``timeout``, a request it never answers a
``missing_response``)."""
FAILURE_KINDS: Final[tuple[str, ...]] = get_args(FailureKind)
NEVER_CAME: Final[frozenset[str]] = frozenset({"missing_response", "timeout", "closed", "deadline"})
"""The kinds of a violation about a packet that never came (an answer, a CLS, an asynchronous response;
the case's time ran out): the only violations that may name no packet.  Every other one names the
packets it judged, the culprit first."""

MAX_EVIDENCE_BYTES: Final = 4096
"""The most bytes a violation keeps as evidence (a runaway reply's text is cut, and the text says so)."""
MAX_TEXT: Final = 16_000
"""The most characters a violation's message, expected and actual texts keep."""

NOTHING: Final = "nothing"
"""What an empty list of evidence reads as."""


@runtime_checkable
class CarriesData(Protocol):
    """Evidence that carries its own bytes (an answer, a Cougar response)."""

    @property
    def data(self) -> bytes: ...


@dataclass(frozen=True)
class Shown:
    """Evidence in the case's own words: ``text`` says what ``of`` (an answer, packets, a Cougar
    response...) showed; the bytes and the packets are those of ``of``."""

    of: object
    text: str


@dataclass(frozen=True)
class Missing:
    """Evidence of a packet that never came: ``text`` says what did not (no packet can show it);
    ``after``: what it should have followed (the request, the frame we sent...), whose bytes and packets
    the violation keeps, or None."""

    text: str
    after: object = None


def showing(of: object, text: object) -> Shown:
    """Evidence ``of`` (an answer, packets...) in the case's own words ``text`` (its ``str``)."""
    return Shown(of, str(text))


def missing(text: object, *, after: object = None) -> Missing:
    """Evidence that what the check waited for never came: ``text`` says what (its ``str``), ``after``
    what it should have followed (an answer, a packet, the bytes we sent)."""
    return Missing(str(text), after)


def evidence(seen: object) -> tuple[str, bytes]:
    """The text and the bytes that ``seen`` shows (see the module docstring)."""
    if isinstance(seen, Shown):
        return seen.text, evidence(seen.of)[1]
    if isinstance(seen, Missing):
        return seen.text, b"" if seen.after is None else evidence(seen.after)[1]
    if isinstance(seen, WirePacket):
        return describe(seen), seen.data
    if isinstance(seen, bytes | bytearray):
        return bytes(seen).hex(), bytes(seen)
    if isinstance(seen, str):
        return seen, b""
    if isinstance(seen, CarriesData):
        return str(seen), bytes(seen.data)
    if isinstance(seen, Sequence) and all(isinstance(item, WirePacket | CarriesData) for item in seen):
        parts = [evidence(item) for item in seen]
        return "; ".join(text for text, _ in parts) or NOTHING, b"".join(data for _, data in parts)
    return str(seen), b""


def seen_packets(seen: object) -> tuple[WirePacket, ...]:
    """The packets the evidence ``seen`` judged: the packet itself, an answer's packets (anything with
    ``packets``), those of :func:`showing`'s evidence or of what a :func:`missing` one should have
    followed, those of each item of a list; none for text, bytes or nothing."""
    if isinstance(seen, WirePacket):
        return (seen,)
    if isinstance(seen, Shown):
        return seen_packets(seen.of)
    if isinstance(seen, Missing):
        return seen_packets(seen.after)
    packets = getattr(seen, "packets", None)
    if isinstance(packets, Sequence) and all(isinstance(p, WirePacket) for p in packets):
        return tuple(packets)
    if isinstance(seen, list | tuple):
        return tuple(p for item in seen for p in seen_packets(item))
    return ()


def seen_kind(seen: object) -> FailureKind:
    """The kind of a violation whose evidence is ``seen``: ``missing_response`` for :func:`missing`."""
    return "missing_response" if isinstance(seen, Missing) else "wrong_value"


@dataclass(frozen=True)
class Violation:
    """One clause broken: a one-line message, the clause (None for a failure of the exchange itself,
    such as a deadline), its level, what was expected, what came and the bytes that showed it.

    ``level`` defaults to the clause's level in the spec; a violation without a clause takes the level
    of the case that found it (the runner fills it in).  ``invariant`` names the suite invariant whose
    machinery found it (``manip.conformance.suite.invariants``), when the case does not declare the
    clause.  ``packet``: the packet it is about, when one is (its culprit); ``packets``: every packet it
    judged, the culprit first (a report keeps them all; neither is compared)."""

    message: str
    clause: str | None = None
    level: Level | None = None
    expected: str = ""
    actual: str = ""
    data: bytes = b""
    kind: FailureKind = "wrong_value"
    invariant: str | None = None
    packet: WirePacket | None = field(default=None, compare=False, repr=False)
    packets: tuple[WirePacket, ...] = field(default=(), compare=False, repr=False)

    def __post_init__(self) -> None:
        packets = tuple(self.packets)
        if self.packet is None and packets:
            object.__setattr__(self, "packet", packets[0])
        elif self.packet is not None and not any(p is self.packet for p in packets):
            packets = (self.packet, *packets)
        object.__setattr__(self, "packets", packets)
        if self.level is None and self.clause is not None and self.clause in SPEC.clauses:
            object.__setattr__(self, "level", SPEC.clauses[self.clause].level)
        for name in ("message", "expected", "actual"):
            text = getattr(self, name)
            if len(text) > MAX_TEXT:
                object.__setattr__(
                    self, name, f"{text[:MAX_TEXT]}... ({len(text) - MAX_TEXT:,} more characters)"
                )
        data = bytes(self.data)
        if len(data) > MAX_EVIDENCE_BYTES:
            cut = f" [the first {MAX_EVIDENCE_BYTES:,} of {len(data):,} bytes shown]"
            object.__setattr__(self, "actual", self.actual + cut)
            data = data[:MAX_EVIDENCE_BYTES]
        object.__setattr__(self, "data", data)

    @classmethod
    def of(
        cls,
        clause: str | None,
        message: str,
        *,
        expected: str = "",
        seen: object = None,
        kind: FailureKind = "wrong_value",
        invariant: str | None = None,
    ) -> Violation:
        """A violation whose ``actual`` and bytes come from the evidence ``seen`` (:func:`evidence`)."""
        actual, data = ("", b"") if seen is None else evidence(seen)
        kind = seen_kind(seen) if kind == "wrong_value" else kind
        return cls(message, clause, None, expected, actual, data, kind, invariant, packets=seen_packets(seen))

    @classmethod
    def at(
        cls, packet: WirePacket, clause: str, message: str, *, expected: str = "", actual: str | None = None
    ) -> Violation:
        """A violation about ``packet``, with its data; ``actual`` defaults to the packet's description."""
        shown = describe(packet) if actual is None else actual
        return cls(message, clause, expected=expected, actual=shown, data=packet.data, packet=packet)

    @property
    def strength(self) -> Level:
        """The level, MUST for a violation whose level is not known yet (for ordering)."""
        return self.level or "MUST"

    def __str__(self) -> str:
        return f"[{self.clause}] {self.message}"

    def to_json(self) -> dict[str, object]:
        return {
            "message": self.message,
            "clause": self.clause,
            "level": self.level,
            "expected": self.expected,
            "actual": self.actual,
            "bytes": self.data.hex(),
            "kind": self.kind,
        }


class CarriesViolation:
    """For an outcome that carries a :class:`Violation` (``CaseFailure``, a failed example): its
    fields, read through it (``exc.clause``...)."""

    violation: Violation

    @property
    def message(self) -> str:
        return self.violation.message

    @property
    def clause(self) -> str | None:
        return self.violation.clause

    @property
    def expected(self) -> str:
        return self.violation.expected

    @property
    def actual(self) -> str:
        return self.violation.actual

    @property
    def data(self) -> bytes:
        return self.violation.data

    @property
    def kind(self) -> FailureKind:
        return self.violation.kind

    @property
    def invariant(self) -> str | None:
        return self.violation.invariant

    @property
    def level(self) -> Level | None:
        return self.violation.level
