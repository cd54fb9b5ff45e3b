"""What ``manip-conform replay`` compares between a recording and a live run, and what it masks.

A replayed session can never give byte-identical packets: the live connection numbers its packets
afresh, a second server has another name, floats may come out of a different (correct) computation.
These pure functions compare one recorded server answer (or asynchronous packet, or a client's request
for ``--serve``) with its live counterpart *field by field*, and return a :class:`Mismatch` per field
that differs, with its path (``joints[3]``, ``error.code``, ``describe.operations``...), both values
and both packets' bytes.

The mask list (erratum ``replay-masking``):

``packet-numbers``
    Request-number words are not compared as numbers but through the request-number mapping: a
    recorded answer quoting recorded request R must quote the live packet number of the request that
    replays R (and a fatal error's or an asynchronous packet's quoted number likewise).  A quoted
    number that names no recorded request must stay the same.
``initial-response``
    The initial RESPONSE quotes the RFC's packet number: the live one must quote the live RFC's.
``chaos-header``
    Chaos acknowledgements, packet numbers, indices, checksums, STS/SNS traffic and retransmissions are
    not compared at all (only data packets 0200-0377, in order, first copies).
``timestamps``
    Capture times and pacing are never compared (the protocol's data carry no clock).
``segment-base``
    Segment numbers (segment replies, segment-completed notifications) are compared relative to the
    first segment number of their session, on each side.
``floats``
    Floats are equal when they differ by at most :data:`FLOAT_REL_TOL` of the larger magnitude
    (eight units in the last place of a PDP-11 F float's 24-bit significand) or :data:`FLOAT_ABS_TOL`.
``describe-identity``
    The describe-self text is compared as one alist (however it is split into packets); the values of
    :data:`DESCRIBE_MASKED_KEYS` (``:unique-name``, ``:software-version``) name the implementation and
    are not compared, only present or absent.

Anything else is compared.  ``--ignore PATTERN`` (:func:`masked`) drops more mismatches by path.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.codecs.errors import CodecError
from manip.codecs.lisp import Cons, Keyword, Symbol, print_lisp
from manip.codecs.messages import ASYNC_SIZES, decode_async, decode_error, decode_reply, decode_request
from manip.conformance.judge.checks import WirePacket, describe, multi_text, parse_description, word
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import ERROR_REPLY_OPS, AsyncCondition, ServerOp
from manip.spec.notation import octal

__all__ = [
    "DESCRIBE_MASKED_KEYS",
    "FLOAT_ABS_TOL",
    "FLOAT_REL_TOL",
    "Mismatch",
    "NumberMap",
    "SegmentBase",
    "compare_answer",
    "compare_async",
    "compare_request",
    "floats_equal",
    "masked",
]

FLOAT_REL_TOL: Final = 2.0**-21
"""Relative tolerance of a float comparison: 8 ulp of a 24-bit significand."""
FLOAT_ABS_TOL: Final = 2.0**-20
"""Absolute tolerance, for values near zero (rotation entries of about 1e-7 are rounding noise)."""
DESCRIBE_MASKED_KEYS: Final = frozenset({"unique-name", "software-version"})


@dataclass(frozen=True)
class Mismatch:
    """One field of a live packet that differs from the recording."""

    path: str
    message: str
    recorded: str
    live: str
    recorded_bytes: bytes = b""
    live_bytes: bytes = b""
    clause: str | None = None

    def violation(self, clause: str | None) -> Violation:
        """The mismatch as a report's violation: expected and actual both name the field compared
        (``number: 36``, never a bare value beside the bytes of a whole packet); the recorded packet's
        data are said to be that."""
        data = self.recorded_bytes.hex(" ")
        recorded = f"; the recorded packet's data: {data}" if data else ""
        return Violation(
            self.message,
            clause,
            "MUST",
            f"{self.path}: {self.recorded}, as recorded{recorded}",
            f"{self.path}: {self.live}",
            self.live_bytes,
            "mismatch",
        )


@dataclass
class NumberMap:
    """Recorded request (and RFC) packet numbers -> the live packet numbers that replay them."""

    numbers: dict[int, int] = field(default_factory=dict)

    def add(self, recorded: int, live: int) -> None:
        self.numbers[recorded] = live

    def expected(self, recorded_word: int) -> int:
        """The number a live packet must quote where the recording quoted ``recorded_word``."""
        return self.numbers.get(recorded_word, recorded_word)


@dataclass
class SegmentBase:
    """The first segment number seen on each side of a session (mask ``segment-base``)."""

    recorded: int | None = None
    live: int | None = None

    def relative(self, recorded: int, live: int) -> tuple[int, int]:
        if self.recorded is None:
            self.recorded = recorded
        if self.live is None:
            self.live = live
        return (recorded - self.recorded) & 0xFFFF, (live - self.live) & 0xFFFF


def floats_equal(a: float, b: float) -> bool:
    """Equal within the replay tolerance (mask ``floats``)."""
    if a == b:
        return True
    if math.isnan(a) or math.isnan(b) or math.isinf(a) or math.isinf(b):
        return False
    return abs(a - b) <= max(FLOAT_REL_TOL * max(abs(a), abs(b)), FLOAT_ABS_TOL)


def masked(mismatches: Iterable[Mismatch], patterns: Sequence[str]) -> tuple[list[Mismatch], int]:
    """Drop the mismatches whose path matches an ``--ignore`` glob; returns (kept, how many dropped)."""
    kept: list[Mismatch] = []
    dropped = 0
    for m in mismatches:
        if any(fnmatch.fnmatchcase(m.path, p) for p in patterns):
            dropped += 1
        else:
            kept.append(m)
    return kept, dropped


# ------------------------------------------------------------------------------------- values


def _show(value: object) -> str:
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list) and all(isinstance(v, (int, float)) for v in value):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, (Keyword, Symbol, Cons, list)):
        return print_lisp(value, base=10)
    return repr(value)


def _values(path: str, recorded: object, live: object, add: Callable[[str, object, object], None]) -> None:
    """Compare two decoded values (numbers, strings, tuples, Lisp data) recursively."""
    if isinstance(recorded, bool) or isinstance(live, bool):
        if recorded != live:
            add(path, recorded, live)
        return
    if isinstance(recorded, (int, float)) and isinstance(live, (int, float)):
        if isinstance(recorded, float) or isinstance(live, float):
            if not floats_equal(float(recorded), float(live)):
                add(path, recorded, live)
        elif recorded != live:
            add(path, recorded, live)
        return
    if isinstance(recorded, (tuple, list)) and isinstance(live, (tuple, list)):
        if len(recorded) != len(live):
            add(f"{path}.length", len(recorded), len(live))
            return
        differing = [
            (i, r, v)
            for i, (r, v) in enumerate(zip(recorded, live, strict=True))
            if _differs(f"{path}[{i}]", r, v)
        ]
        if len(differing) > 1 and all(not isinstance(r, (tuple, list, Cons)) for _, r, _ in differing):
            # one mismatch for a vector (a transform with swapped words differs everywhere)
            where = ",".join(str(i) for i, _, _ in differing)
            add(f"{path}[{where}]", [r for _, r, _ in differing], [v for _, _, v in differing])
            return
        for i, r, v in differing:
            _values(f"{path}[{i}]", r, v, add)
        return
    if isinstance(recorded, Cons) and isinstance(live, Cons):
        _values(f"{path}.car", recorded.car, live.car, add)
        _values(f"{path}.cdr", recorded.cdr, live.cdr, add)
        return
    if recorded != live:
        add(path, recorded, live)


def _differs(path: str, recorded: object, live: object) -> bool:
    found: list[str] = []
    _values(path, recorded, live, lambda p, _r, _v: found.append(p))
    return bool(found)


class _Collector:
    """Builds the mismatches of one packet pair, all with the same bytes."""

    def __init__(self, recorded: WirePacket | None, live: WirePacket | None) -> None:
        self.recorded = recorded
        self.live = live
        self.out: list[Mismatch] = []

    def add(self, path: str, recorded: object, live: object, clause: str | None = None) -> None:
        r, v = _show(recorded), _show(live)
        self.out.append(
            Mismatch(
                path,
                f"{path}: recorded {r}, live {v}",
                r,
                v,
                self.recorded.data if self.recorded else b"",
                self.live.data if self.live else b"",
                clause,
            )
        )


def _guide_async(packet: WirePacket) -> bool:
    """An asynchronous response in the 1985 guide's layout (6 bytes, no request number: erratum
    ``async-request-number``)."""
    return packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE and len(packet.data) == ASYNC_SIZES["guide"]


def _number(c: _Collector, path: str, recorded: WirePacket, live: WirePacket, numbers: NumberMap) -> None:
    r, v = word(recorded.data), word(live.data)
    if r is None:
        if v is not None:
            c.add(path, "no request-number word", v)
        return
    want = numbers.expected(r)
    if v != want:
        clause = "response.echoes-request-number"
        if live.opcode == ServerOp.FATAL_ERROR:
            clause = "error.fatal-request-number"
        elif live.opcode == ServerOp.ASYNCHRONOUS_RESPONSE:
            clause = "async.layout"
        shown = f"{r}" if want == r else f"{r} (the replayed request is #{want})"
        c.add(path, shown, "missing" if v is None else v, clause)


# ------------------------------------------------------------------------------------- answers


def compare_answer(
    request_opcode: int | None,
    recorded: Sequence[WirePacket],
    live: Sequence[WirePacket],
    numbers: NumberMap,
    segments: SegmentBase,
) -> list[Mismatch]:
    """Compare the answer to one request (``request_opcode`` None: the initial RESPONSE to the RFC).

    ``recorded`` / ``live``: the answer's packets (one, or every packet of a multi-packet reply)."""
    if not recorded:
        if live:
            c = _Collector(None, live[0])
            c.add("answer", "no answer in the recording", describe(live[0]))
            return c.out
        return []
    first = recorded[0]
    if not live:
        c = _Collector(first, None)
        c.add("answer", describe(first), "no answer", "request.one-reply")
        return c.out
    c = _Collector(first, live[0])
    if first.opcode != live[0].opcode:
        recorded_op, live_op = octal(first.opcode), octal(live[0].opcode)
        c.add("opcode", f"{recorded_op} ({describe(first)})", f"{live_op} ({describe(live[0])})")
        return c.out
    if request_opcode is None:
        number_clause = "connect.initial-response-number"
        r, v = word(first.data), word(live[0].data)
        if r is not None and v != numbers.expected(r):
            c.add("request_number", f"{r} (the live RFC is #{numbers.expected(r)})", v, number_clause)
        if len(first.data) != len(live[0].data):
            c.add("data.length", len(first.data), len(live[0].data), number_clause)
        return c.out
    _number(c, "request_number", first, live[0], numbers)
    if first.opcode in ERROR_REPLY_OPS:
        c.out += _compare_error(first, live[0])
        return c.out
    op = SPEC.requests.get(request_opcode)
    if op is not None and op.response.form == "multi" and (len(first.data) > 2 or len(recorded) > 1):
        c.out += _compare_multi(recorded, live, numbers)
        return c.out
    c.out += _compare_reply(request_opcode, first, live[0], segments)
    return c.out


def _compare_reply(
    opcode: int, recorded: WirePacket, live: WirePacket, segments: SegmentBase
) -> list[Mismatch]:
    c = _Collector(recorded, live)
    op = SPEC.requests.get(opcode)
    try:
        want = decode_reply(recorded.data, op)
    except CodecError:
        if recorded.data[2:] != live.data[2:]:
            c.add("data", recorded.data[2:].hex(), live.data[2:].hex())
        return c.out
    try:
        got = decode_reply(live.data, op)
    except CodecError as exc:
        c.add("data", f"{len(recorded.data)} data bytes", f"{len(live.data)} data bytes ({exc})")
        return c.out
    if not want.values and not got.values:
        if want.payload != got.payload:
            c.add("data", want.payload.hex(), got.payload.hex())
        return c.out
    for name in want.values.keys() | got.values.keys():
        if name not in got.values or name not in want.values:
            c.add(name, want.values.get(name, "absent"), got.values.get(name, "absent"))
            continue
        r, v = want.values[name], got.values[name]
        if name == "segment" and isinstance(r, int) and isinstance(v, int):
            rel_r, rel_v = segments.relative(r, v)
            if rel_r != rel_v:
                c.add("segment", f"{r} (segment {rel_r} of the session)", f"{v} (segment {rel_v})")
            continue
        _values(name, r, v, c.add)
    return c.out


def _compare_multi(
    recorded: Sequence[WirePacket], live: Sequence[WirePacket], numbers: NumberMap
) -> list[Mismatch]:
    c = _Collector(recorded[-1], live[-1])
    for i, packet in enumerate(live[1:], start=1):  # the first wrong number stands for the rest
        sub = _Collector(recorded[min(i, len(recorded) - 1)], packet)
        _number(sub, f"packets[{i}].request_number", recorded[min(i, len(recorded) - 1)], packet, numbers)
        if sub.out:
            c.out += sub.out
            break
    r_done, v_done = (
        len(recorded[-1].data) == 2,
        len(live[-1].data) == 2 and live[-1].opcode == ServerOp.RESPONSE,
    )
    if r_done != v_done:
        c.add(
            "terminator",
            "an empty RESPONSE" if r_done else "none",
            "an empty RESPONSE" if v_done else f"none ({describe(live[-1])} last)",
            "multi.terminated-by-empty",
        )
    r_text, v_text = multi_text(recorded), multi_text(live)
    r_entries, _ = parse_description(r_text)
    v_entries, _ = parse_description(v_text)
    if r_entries is None or v_entries is None:
        if r_text != v_text:
            c.add("text", r_text, v_text)
        return c.out
    for key in sorted(r_entries.keys() | v_entries.keys()):
        path = f"describe.{key}"
        if key not in v_entries or key not in r_entries:
            c.add(
                path, "present" if key in r_entries else "absent", "present" if key in v_entries else "absent"
            )
        elif key not in DESCRIBE_MASKED_KEYS:
            _values(path, r_entries[key], v_entries[key], c.add)
    return c.out


def _compare_error(recorded: WirePacket, live: WirePacket) -> list[Mismatch]:
    c = _Collector(recorded, live)
    try:
        want = decode_error(recorded.opcode, recorded.data, align_args=False).error
    except CodecError:
        if recorded.data[2:] != live.data[2:]:
            c.add("error", recorded.data[2:].hex(), live.data[2:].hex())
        return c.out
    try:
        got = decode_error(live.opcode, live.data, align_args=False).error
    except CodecError as exc:
        c.add("error", want.render(), f"an unreadable error string ({exc})")
        return c.out
    for name in ("severity", "code", "where", "message"):
        r, v = getattr(want, name), getattr(got, name)
        if r != v:
            c.add(f"error.{name}", r, v)
    _values("error.args", tuple(want.args), tuple(got.args), c.add)
    return c.out


# ------------------------------------------------------------------------------------- asynchronous


def compare_async(
    recorded: WirePacket, live: WirePacket, numbers: NumberMap, segments: SegmentBase
) -> list[Mismatch]:
    """Compare an asynchronous packet (0203, 0204, 0205) with its live counterpart (same kind, same
    place in the order of its kind)."""
    c = _Collector(recorded, live)
    if recorded.opcode != live.opcode:
        c.add("opcode", octal(recorded.opcode), octal(live.opcode))
        return c.out
    if not _guide_async(recorded):  # the 1985 guide's 0203 has no request number to renumber
        _number(c, "request_number", recorded, live, numbers)
    if recorded.opcode != ServerOp.ASYNCHRONOUS_RESPONSE:
        c.out += _compare_error(recorded, live)
        return c.out
    try:
        want = decode_async(recorded.data)
    except CodecError:
        if recorded.data[2:] != live.data[2:]:
            c.add("async", recorded.data[2:].hex(), live.data[2:].hex())
        return c.out
    try:
        got = decode_async(live.data)
    except CodecError as exc:
        c.add(
            "async",
            f"{len(recorded.data)} data bytes",
            f"{len(live.data)} data bytes ({exc})",
            "async.layout",
        )
        return c.out
    if want.layout != got.layout:  # both conform (erratum async-request-number), but the server changed
        c.add(
            "async.layout",
            f"{want.layout} ({len(recorded.data)} bytes)",
            f"{got.layout} ({len(live.data)} bytes)",
        )
    if want.condition != got.condition:
        c.add("async.condition", want.condition_name, got.condition_name)
        return c.out
    if want.word2 != got.word2:
        c.add("async.word2", want.word2, got.word2)
    if want.condition == AsyncCondition.SEGMENT_COMPLETED:
        rel_r, rel_v = segments.relative(want.word3, got.word3)
        if rel_r != rel_v:
            c.add("async.segment", f"{want.word3} (segment {rel_r})", f"{got.word3} (segment {rel_v})")
    elif want.word3 != got.word3:
        c.add("async.word3", want.word3, got.word3)
    return c.out


# ------------------------------------------------------------------------------------- requests


def compare_request(recorded: WirePacket, live: WirePacket) -> list[Mismatch]:
    """Compare a client's request with the recorded one (``--serve``): opcode, then the decoded fields
    (floats with the tolerance), or the bytes when either does not decode."""
    c = _Collector(recorded, live)
    if recorded.opcode != live.opcode:
        recorded_op, live_op = octal(recorded.opcode), octal(live.opcode)
        c.add("opcode", f"{recorded_op} ({describe(recorded)})", f"{live_op} ({describe(live)})")
        return c.out
    try:
        want = decode_request(recorded.opcode, recorded.data).values
        got = decode_request(live.opcode, live.data).values
    except CodecError:
        if recorded.data != live.data:
            c.add("data", recorded.data.hex(), live.data.hex())
        return c.out
    for name in want.keys() | got.keys():
        _values(name, want.get(name, "absent"), got.get(name, "absent"), c.add)
    return c.out
