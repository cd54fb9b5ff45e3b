"""Pairing two sides' answers to one stream, request by request, and naming the parts that differ.

What a side showed of a stream is a list of :class:`SideEvent` per input: each packet of the server on the
stream's connection in order (answers, multi-packet replies to their empty packet, asynchronous
packets), each end of a connection (EOF, CLS, LOS, with its text; after an EOF, the CLS or LOS that
followed it, or an end event saying none did), the answers to stray packets (and the STS answering an
SNS on the connection) and the stream's own end when it stalled or could not open.  Packet and
acknowledgement numbers are the NCP's and are never compared.  Each event has the time it was received
on the side's clock (virtual time on an embedded side, the real clock on an addressed one), and an
answer the time its request went out: never compared, only read by a scenario's check that judges when
the arm moved or a reply came.

:func:`compare` walks the two lists of each input position by position and returns a
:class:`Difference` for every position whose events differ, with the parts that differ:

* ``opcode``, ``count`` (one side has an event the other has not), ``end`` (how or why a
  connection ended), ``stray`` (what a stray packet was answered with), ``stream`` (stalled, not opened),
  ``step`` (the two answers answer different requests: one side sent a packet more or fewer before; the
  rest of the input is not compared, as every later position would differ for that one reason);
* an error string by its parts: ``error.number``, ``error.where``, ``error.severity``, ``error.code``,
  ``error.message``, ``error.args`` (the numbers), ``error.args-layout`` (the pad byte of erratum
  ``error-arg-layout``), ``error.text`` (one side's does not parse); two different codes that are both
  the 1985 guide's own (TOR and JOR, NAP and JOR) are ``error.guide-code``, which no freedom covers
  (but AWA against another for calibrate, hand or free joint is ``error.abort-scope``, erratum awa-scope).
  The numbers of two different messages are not compared: they are what each message says (erratum
  ``error-arg-values``);
* an asynchronous response: ``async.layout`` (6 or 8 bytes, erratum ``async-request-number``) and
  ``async.data`` (the condition code and words themselves);
* other data: ``data`` (compared as PDP-11 floats within :data:`FLOAT_TOLERANCE` where both sides'
  bytes read as floats, but a dirty zero or a zero against the least F magnitude differs whatever the
  tolerance), or ``data.length-unit`` when every float that differs is the other's times 25.4 (inches
  against millimetres, erratum ``units``).

Sans-I/O.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final, Literal

from manip.codecs.error_string import parse_error
from manip.codecs.errors import CodecError
from manip.codecs.pairing import ReplyPairing
from manip.codecs.pdp11float import unpack_f
from manip.conformance.fuzz.batch import BatchRun, DueAnswer
from manip.conformance.fuzz.session import Inbox
from manip.conformance.judge.packets import WirePacket
from manip.spec import SPEC
from manip.spec.constants import ANSWER_OPS, ERROR_STRING_OPS, ChaosOp, ServerOp

__all__ = ["FLOAT_TOLERANCE", "Difference", "SideEvent", "compare", "events_of"]

FLOAT_TOLERANCE: Final = 1e-5
"""Relative difference under which two floats are the same value (a PDP-11 F float has 24 bits)."""
INCH: Final = 25.4
SideEventKind = Literal["packet", "end", "stray", "stream"]
_ENDS: Final = {ChaosOp.CLS: "CLS", ChaosOp.LOS: "LOS", ChaosOp.EOF: "EOF"}
NO_CLS: Final = "none after the EOF: no CLS or LOS came, the link dropped or silence"
"""The end event that follows an EOF nothing followed (the connection watched to its end)."""


@dataclass(frozen=True)
class SideEvent:
    """One thing a side showed: a server packet (``opcode``, ``data``), a connection's end (``text``:
    how), an answer to a stray packet (``text``: the opcodes), the stream's own end."""

    kind: SideEventKind
    opcode: int = 0
    data: bytes = b""
    text: str = ""
    request: int | None = field(default=None, compare=False)
    """For an answer: the opcode of the request it answers, by the suite's one pairing rule
    (:class:`~manip.codecs.pairing.ReplyPairing`, erratum capture-pairing); not compared."""
    time: float = field(default=0.0, compare=False)
    """Seconds from the stream's start to when the side's packet came (the stream's end for a stalled
    stream), on the side's clock; not compared."""
    asked: float | None = field(default=None, compare=False)
    """For an answer: seconds from the stream's start to when its request went out; not compared."""

    def show(self) -> str:
        if self.kind == "packet":
            return f"0{self.opcode:o} {self.data.hex(' ') or '(no data)'}"
        return f"{self.kind}: {self.text}"


@dataclass(frozen=True)
class Difference:
    """Input ``number``'s event ``position`` differs in ``parts``; ``a``/``b``: each side's (None: none)."""

    number: int
    position: int
    parts: tuple[str, ...]
    a: SideEvent | None
    b: SideEvent | None

    @property
    def signature(self) -> tuple[int, int, tuple[str, ...]]:
        return self.number, self.position, self.parts


def events_of(run: BatchRun, inbox: Inbox) -> dict[int, list[SideEvent]]:
    """Everything a side showed of a stream, by input number (module docstring)."""
    out: dict[int, list[SideEvent]] = {}
    for conn in run.connections:
        pairing: ReplyPairing[WirePacket | None] = ReplyPairing()
        pairing.rfc(None)
        since = conn.t0 - run.started  # a connection's packets are timed from when it opened
        for wp in conn.packets:
            if wp.direction != "s2c":
                pairing.request(wp, wp.opcode, wp.data)
                continue
            number = conn.origin.get(id(wp), -1)
            name = _ENDS.get(ChaosOp(wp.opcode)) if wp.opcode in _ENDS else None
            at = since + wp.time
            if name is not None:
                text = f"{name} {wp.data.decode('ascii', 'replace')}".strip()
                event = SideEvent("end", wp.opcode, text=text, time=at)
            else:
                asked = pairing.server(wp.opcode, wp.data).request if wp.opcode in ANSWER_OPS else None
                event = SideEvent(
                    "packet",
                    wp.opcode,
                    bytes(wp.data),
                    request=asked.opcode if asked is not None else None,
                    time=at,
                    asked=since + asked.time if asked is not None else None,
                )
            out.setdefault(number, []).append(event)
            if wp.opcode == ChaosOp.EOF and conn.after_eof == "none":
                out[number].append(SideEvent("end", text=NO_CLS))
    for due in run.due_answers:
        came = inbox.strays.get(due.key, []) if due.key else []
        got = sorted({p.opcode for p, _ in came} | _sts_for(due))
        if due.what == "close":
            got_text = "dropped" if due.link is not None and due.link.ended is not None else "kept"
        else:
            got_text = " ".join(f"0{o:o}" for o in got) or "nothing"
        at = (came[0][1] if came else due.since) - run.started
        out.setdefault(due.number, []).append(SideEvent("stray", text=f"{due.what}: {got_text}", time=at))
    last = run.last_number
    end = run.duration
    if run.stalled:
        stalled = SideEvent("stream", text="stalled: an answer did not come in time", time=end)
        out.setdefault(last, []).append(stalled)
    if run.open_error is not None:
        out.setdefault(last, []).append(SideEvent("stream", text=f"not opened: {run.open_error}", time=end))
    return out


def _sts_for(due: DueAnswer) -> set[int]:
    """An SNS's STS, which comes on its connection (no stray): STS if one came after it was sent."""
    conn = due.connection
    if due.what != "sts" or conn is None or not any(t >= due.since for t in conn.sts_times):
        return set()
    return {ChaosOp.STS}


def compare(
    numbers: Sequence[int], a: dict[int, list[SideEvent]], b: dict[int, list[SideEvent]]
) -> list[Difference]:
    """Every position where the two sides' events differ, input by input in stream order."""
    out: list[Difference] = []
    for number in numbers:
        pairs = itertools.zip_longest(a.get(number, ()), b.get(number, ()))
        for position, (ea, eb) in enumerate(pairs):
            if _out_of_step(ea, eb):
                # The two answers answer different requests: one side sent a packet more or fewer
                # before; every later position of the input would differ for that one reason.
                out.append(Difference(number, position, ("step",), ea, eb))
                break
            parts = differing_parts(ea, eb)
            if parts:
                out.append(Difference(number, position, parts, ea, eb))
    return out


def _out_of_step(a: SideEvent | None, b: SideEvent | None) -> bool:
    return a is not None and b is not None and None not in (a.request, b.request) and a.request != b.request


def differing_parts(a: SideEvent | None, b: SideEvent | None) -> tuple[str, ...]:
    """The parts in which two events differ (empty: the same, floats within tolerance)."""
    if a is None or b is None:
        return ("count",)
    if a == b:
        return ()
    if a.kind != b.kind or a.opcode != b.opcode:
        return (
            ("opcode",)
            if a.kind == b.kind == "packet"
            else ("end",)
            if "end" in (a.kind, b.kind)
            else (a.kind,)
        )
    if a.kind != "packet":
        return (a.kind,)
    if a.opcode in ERROR_STRING_OPS:
        return _abort_scope(_error_parts(a.data, b.data), a, b)
    if a.opcode == ServerOp.ASYNCHRONOUS_RESPONSE:
        return _async_parts(a.data, b.data)
    return _data_parts(a.data, b.data)


def _error_parts(a: bytes, b: bytes) -> tuple[str, ...]:
    try:
        ea, eb = parse_error(a, body="packet"), parse_error(b, body="packet")
    except (CodecError, ValueError):
        return ("error.text",)
    parts = []
    if a[:2] != b[:2]:
        parts.append("error.number")
    for name in ("where", "severity", "code", "message"):
        if getattr(ea, name) != getattr(eb, name):
            parts.append(f"error.{name}")
    if ea.code != eb.code and _guide_code(ea.code) and _guide_code(eb.code):
        # Two of the 1985 guide's own codes mean different things: no choice of the implementation.
        parts[parts.index("error.code")] = "error.guide-code"
    if "error.message" in parts:
        # The numbers go with the message that says what they are (erratum error-arg-values): another
        # message's numbers are part of its difference, not one of their own.
        return tuple(parts)
    if ea.args != eb.args:
        parts.append("error.args")
    if not parts or _padded(a) != _padded(b):
        # The pad byte before the numbers (erratum error-arg-layout), or other bytes the parts do not show.
        parts.append("error.args-layout")
    return tuple(parts)


_MAY_ABORT: Final = frozenset(SPEC.request(n).opcode for n in ("calibrate", "hand", "free-joint"))
"""Requests that may move the arm without being motion requests: refusing them AWA while an abort stands
is the server's choice (erratum awa-scope)."""


def _abort_scope(parts: tuple[str, ...], a: SideEvent, b: SideEvent) -> tuple[str, ...]:
    """``error.guide-code`` as ``error.abort-scope`` where one side refused AWA a request of
    :data:`_MAY_ABORT` and the other refused it with another of the guide's codes."""
    if "error.guide-code" not in parts or a.request != b.request or a.request not in _MAY_ABORT:
        return parts
    try:
        codes = {parse_error(e.data, body="packet").code for e in (a, b)}
    except (CodecError, ValueError):
        return parts
    return (
        tuple("error.abort-scope" if p == "error.guide-code" else p for p in parts)
        if "AWA" in codes
        else parts
    )


def _guide_code(code: str) -> bool:
    known = SPEC.error_codes.get(code)
    return known is not None and known.origin == "guide"


def _padded(data: bytes) -> bool:
    """Whether a pad byte comes between an error string's NUL and its numbers (an odd count after it)."""
    nul = data.find(b"\0", 2)
    return nul >= 0 and (len(data) - nul - 1) % 2 == 1


def _async_parts(a: bytes, b: bytes) -> tuple[str, ...]:
    if len(a) == len(b):
        return ("async.data",)
    # 6 bytes: the 1985 guide's layout; 8: the request number first (erratum async-request-number).
    words_a, words_b = a[-6:], b[-6:]
    return (
        ("async.layout",)
        if words_a == words_b and {len(a), len(b)} == {6, 8}
        else ("async.layout", "async.data")
    )


def _floats(data: bytes) -> list[float] | None:
    if len(data) % 4:
        return None
    try:
        return [unpack_f(data, at) for at in range(0, len(data), 4)]
    except (CodecError, ValueError):
        return None


def _dirty(a: bytes, b: bytes) -> bool:
    """Whether a float of ``a`` or ``b`` has exponent 0 with other bits set where the other side's
    differs: it reads as zero, yet only all bits clear is an F zero (``float.dirty-zero``)."""
    for at in range(0, len(a) - 3, 4):
        wa, wb = a[at : at + 4], b[at : at + 4]
        if wa != wb and any(not _exponent(w) and any(w) for w in (wa, wb)):
            return True
    return False


def _floored(a: bytes, b: bytes) -> bool:
    """Whether a float of ``a`` or ``b`` is zero where the other side's has the least exponent (a
    magnitude below 2^-127): within tolerance of zero, yet a magnitude below 2^-128 is sent as zero
    (``float.range``), so one of them may be an underflow not flushed."""
    for at in range(0, len(a) - 3, 4):
        wa, wb = a[at : at + 4], b[at : at + 4]
        if (not any(wa) and _exponent(wb) == 1) or (not any(wb) and _exponent(wa) == 1):
            return True
    return False


def _exponent(word: bytes) -> int:
    """The exponent field of a PDP-11 F float (its first word low byte first)."""
    return (word[1] << 1 | word[0] >> 7) & 0xFF


def _close(x: float, y: float) -> bool:
    return math.isclose(x, y, rel_tol=FLOAT_TOLERANCE, abs_tol=FLOAT_TOLERANCE)


def _data_parts(a: bytes, b: bytes) -> tuple[str, ...]:
    if len(a) != len(b) or a[:2] != b[:2]:
        return ("data",)
    fa, fb = _floats(a[2:]), _floats(b[2:])
    if fa is None or fb is None:
        return ("data",)
    differing = [(x, y) for x, y in zip(fa, fb, strict=True) if not _close(x, y)]
    if not differing:
        return ("data",) if _dirty(a[2:], b[2:]) or _floored(a[2:], b[2:]) else ()
    if all(_close(x, y * INCH) or _close(y, x * INCH) for x, y in differing):
        return ("data.length-unit",)
    return ("data",)
