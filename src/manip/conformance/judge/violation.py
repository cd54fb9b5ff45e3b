"""The one record of "a clause was broken": :class:`Violation`, whoever found it.

A checker returns violations, the stateful model returns them, ``ctx.expect`` builds one when its
condition is false, a probe raises one inside :class:`~manip.conformance.suite.case.CaseFailure`,
replay and ``verify`` report them, and a case result lists them: the same frozen value all the way to
the JSON report, never copied field by field into another record.

What came is given as *evidence* (``seen=``): :func:`evidence` derives the text (``actual``) and the
bytes (``data``) from it, so a case says what it looked at, not how to print it:

* a :class:`~manip.conformance.judge.packets.WirePacket`: its description and data;
* anything with ``data`` bytes and a ``str`` (an ``Answer``, a Cougar ``WordReply``): both;
* a list or tuple of those: joined with ``"; "`` (``"nothing"`` when empty), the bytes concatenated;
* ``bytes``: shown in hex; a string: the text alone; anything else: its ``str``.
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
    "CarriesViolation",
    "FailureKind",
    "Shown",
    "Violation",
    "evidence",
    "shown_packet",
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
packet, no answer in time, the connection closed, a missing or unexpected message, the case's deadline;
``mismatch``, ``missing`` and ``stopped`` are replay's (a live answer that differs from the recorded
one, a session no client played, a replay that could not go on); ``crash``, ``traceback`` and
``uncounted_drop`` are the fuzzer's (the target gone, a traceback in its log, bad frames it dropped
without counting them; a target that stops answering is a ``timeout``, a request it never answers a
``missing_response``)."""
FAILURE_KINDS: Final[tuple[str, ...]] = get_args(FailureKind)

MAX_EVIDENCE_BYTES: Final = 4096
"""The most bytes a violation keeps as evidence (a runaway reply's text is cut, and the text says so)."""
MAX_TEXT: Final = 16_000
"""The most characters a violation's message, expected and actual texts keep."""

NOTHING: Final = "nothing"
"""What an empty list of evidence reads as."""


@runtime_checkable
class Shown(Protocol):
    """Evidence that carries its own bytes (an answer, a Cougar response)."""

    @property
    def data(self) -> bytes: ...


def evidence(seen: object) -> tuple[str, bytes]:
    """The text and the bytes that ``seen`` shows (see the module docstring)."""
    if isinstance(seen, WirePacket):
        return describe(seen), seen.data
    if isinstance(seen, bytes | bytearray):
        return bytes(seen).hex(), bytes(seen)
    if isinstance(seen, str):
        return seen, b""
    if isinstance(seen, Shown):
        return str(seen), bytes(seen.data)
    if isinstance(seen, Sequence) and all(isinstance(item, WirePacket | Shown) for item in seen):
        parts = [evidence(item) for item in seen]
        return "; ".join(text for text, _ in parts) or NOTHING, b"".join(data for _, data in parts)
    return str(seen), b""


def shown_packet(seen: object) -> WirePacket | None:
    """The packet the evidence ``seen`` is about: the packet itself, an answer's first packet (anything
    with ``packets``), the first of a list of those; None for text, bytes or nothing."""
    if isinstance(seen, WirePacket):
        return seen
    packets = getattr(seen, "packets", None)
    if isinstance(packets, Sequence) and packets and isinstance(packets[0], WirePacket):
        return packets[0]
    if isinstance(seen, list | tuple) and seen:
        return shown_packet(seen[0])
    return None


@dataclass(frozen=True)
class Violation:
    """One clause broken: a one-line message, the clause (None for a failure of the exchange itself,
    such as a deadline), its level, what was expected, what came and the bytes that showed it.

    ``level`` defaults to the clause's level in the spec; a violation without a clause takes the level
    of the case that found it (the runner fills it in).  ``invariant`` names the suite invariant whose
    machinery found it (``manip.conformance.suite.invariants``), when the case does not declare the
    clause.  ``packet``: the packet it is about, when one is (not compared)."""

    message: str
    clause: str | None = None
    level: Level | None = None
    expected: str = ""
    actual: str = ""
    data: bytes = b""
    kind: FailureKind = "wrong_value"
    invariant: str | None = None
    packet: WirePacket | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
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
        return cls(message, clause, None, expected, actual, data, kind, invariant, shown_packet(seen))

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
