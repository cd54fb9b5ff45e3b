"""Pure checkers over manip packets: what a server sent, judged against the spec's clauses.

Nothing here does I/O or reads a clock.  Every checker takes packets (:class:`WirePacket`: direction,
Chaos opcode, packet and ack numbers, data bytes, time) and returns a list of
:class:`~manip.conformance.judge.violation.Violation` (empty when everything conforms), each naming the
clause it breaks with what was expected, what came, and the bytes.  Live cases call them on what their
probe recorded; ``manip-conform verify`` calls them on a recording; the stateful machine uses
:func:`check_transcript` as its invariant.

Checkers, from the smallest up:

* :func:`check_server_opcode`, :func:`check_echo`, :func:`check_error_packet`,
  :func:`check_async_packet`, :func:`check_initial_response`: one packet;
* :func:`check_reply`: the answer to one request (one packet, or a multi-packet reply), by the
  response form the spec gives the request's opcode (done, data, segment, multi), including the refusal
  the spec demands for malformed requests (:func:`required_refusal`);
* :func:`check_description`: the describe-self text (alist readable, shapes of the known keys);
* :func:`check_transcript`: a whole connection in order: the initial RESPONSE, one answer per request
  in request order, free joint's discarded packet, asynchronous responses only when asked for, segment
  numbers increasing, nothing after a fatal error but the close.

A close or EOF seen by the recorder is a :class:`WirePacket` with the Chaos opcode CLS / EOF / LOS.
What a client sent is judged in :mod:`manip.conformance.judge.client_checks`.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.codecs.error_string import SPECIALS, ErrorMessage
from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.lisp import Cons, Keyword, LispValue, read_alist
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import AsyncResponse, decode_async, decode_error, decode_reply, decode_request
from manip.codecs.pairing import ANSWER_OPCODES, UNSOLICITED_OPCODES, ReplyPairing
from manip.conformance.judge.diagnosis import float_payload, floats_diagnosis, number_diagnosis
from manip.conformance.judge.packets import CLOSE_OPCODES, Direction, WirePacket, describe, opcode_name, word
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import ERROR_REPLY_OPS, AsyncCondition, ServerOp
from manip.spec.notation import a_or_an, octal

__all__ = [
    "ANSWER_OPCODES",
    "CLOSE_OPCODES",
    "TRANSCRIPT_CLAUSES",
    "UNSOLICITED_OPCODES",
    "Direction",
    "Refusal",
    "Violation",
    "WirePacket",
    "async_of",
    "check_async_packet",
    "check_description",
    "check_description_entries",
    "check_echo",
    "check_error_packet",
    "check_initial_response",
    "check_reply",
    "check_server_opcode",
    "check_transcript",
    "completed_segment",
    "describe",
    "description_operations",
    "multi_text",
    "parse_description",
    "required_refusal",
    "word",
]

ARM_SPECIFIC_SERVER_OPCODES: Final = range(0o250, 0o300)
TRANSCRIPT_CLAUSES: Final = frozenset(
    {
        "async.codes",
        "async.layout",
        "async.only-when-requested",
        "connect.initial-response",
        "connect.initial-response-number",
        "describe.alist-readable",
        "describe.alist-shape",
        "describe.brand-name",
        "describe.degrees-of-freedom",
        "describe.numbers-octal",
        "describe.operations",
        "describe.protocol-version",
        "describe.reply-shape",
        "describe.software-version",
        "describe.unique-name",
        "error-string.arg-layout",
        "error-string.args",
        "error-string.code",
        "error-string.format",
        "error-string.severity",
        "error-string.substitution",
        "error-string.where-no-colon",
        "error.fatal-request-number",
        "error.fatal-then-close",
        "error.non-fatal-is-reply",
        "error.severity-matches-opcode",
        "float.dirty-zero",
        "float.format",
        "float.reserved-operand",
        "free-joint.replies",
        "multi.same-request-number",
        "multi.terminated-by-empty",
        "request.data-length",
        "request.one-reply",
        "request.reserved-float",
        "request.unknown-opcode",
        "response.data-layout",
        "response.done-empty",
        "response.echoes-request-number",
        "response.segment-number",
        "response.server-opcodes",
        "response.word-byte-order",
        "segment.number-increases",
        "text.lispm-charset",
    }
)
"""Every clause :func:`check_transcript` (and the checkers it calls: :func:`check_reply`,
:func:`check_error_packet`, :func:`check_async_packet`, :func:`check_initial_response`,
:func:`check_description`...) may name.  A codec error naming another clause is reported under the
checker's default clause, so the set is closed: the runner's transcript invariant is attributed these
clauses whatever case it runs after (``manip.conformance.suite.invariants``)."""


@dataclass(frozen=True)
class Refusal:
    """What the spec requires for a request that must be refused: a non-fatal error of severity C."""

    clause: str
    reason: str
    codes: tuple[str, ...] = ()
    """The error codes manip's errata name for it (informational: only the severity is a MUST)."""


# ------------------------------------------------------------------------------------- single packets


def check_server_opcode(packet: WirePacket) -> list[Violation]:
    """Server packets use 0200-0205 or the arm-specific 0250-0277."""
    if packet.opcode in SPEC.server_opcodes or packet.opcode in ARM_SPECIFIC_SERVER_OPCODES:
        return []
    return [
        Violation.at(
            packet,
            "response.server-opcodes",
            f"server packet with opcode {octal(packet.opcode)}",
            expected="a server opcode 200-205 (or 250-277)",
            actual=f"opcode {octal(packet.opcode)}",
        )
    ]


def check_echo(request: WirePacket, reply: WirePacket) -> list[Violation]:
    """The reply's first data word is the request's packet number (a fatal error's: the last received),
    low byte first: the number sent high byte first breaks ``response.word-byte-order``."""
    number = word(reply.data)
    if number == request.packet_no:
        return []
    clause = "error.fatal-request-number" if reply.opcode == ServerOp.FATAL_ERROR else None
    clause = clause or "response.echoes-request-number"
    if number is not None and number == int.from_bytes(request.packet_no.to_bytes(2, "little"), "big"):
        clause = "response.word-byte-order"
    actual = "no request-number word" if number is None else f"request number {number}"
    cause = None if number is None else number_diagnosis(number, request.packet_no, what="request number")
    return [
        Violation.at(
            reply,
            clause,
            f"reply to request #{request.packet_no} ({opcode_name(request)}) carries the wrong number"
            + (f": {cause}" if cause else ""),
            expected=f"request number {request.packet_no} (the request's Chaos packet number)",
            actual=actual
            + (f" (the request's ack field is {request.ack_no})" if number == request.ack_no else ""),
        )
    ]


def check_error_packet(packet: WirePacket) -> list[Violation]:
    """The error string of an 0201, 0202, 0204 or 0205 packet (E.2), and its severity for the opcode."""
    data = packet.data
    if len(data) < 2:
        return [
            Violation.at(
                packet,
                "response.echoes-request-number",
                "error packet without a request number",
                expected="a request-number word then an error string",
                actual=f"{len(data)} data bytes",
            )
        ]
    out: list[Violation] = []
    try:
        error = decode_error(packet.opcode, data).error
    except CodecError as exc:
        if exc.clause != "error-string.arg-layout":
            return [
                _codec_violation(
                    exc, packet, "error-string.format", "an error string 'where: severity code message'"
                )
            ]
        out.append(_layout_violation(packet, str(exc)))
        try:
            error = decode_error(packet.opcode, data, align_args=False).error
        except CodecError as inner:
            out.append(_codec_violation(inner, packet, "error-string.format", "an error string"))
            return out
    else:
        nul = data.find(0, 2)
        if nul >= 0 and (len(data) - nul - 1) % 2 and (nul + 1) % 2 == 0:
            out.append(_layout_violation(packet, f"a pad byte at data byte {nul + 1}, an even offset"))
    out += _error_text_violations(error, packet)
    return out


def _layout_violation(packet: WirePacket, actual: str) -> Violation:
    return Violation.at(
        packet,
        "error-string.arg-layout",
        "the numbers after the NUL are neither packed after it nor aligned by one zero pad byte",
        expected="the numbers straight after the NUL, or after one zero pad byte when the NUL ends at an odd "
        "offset of the packet data (erratum error-arg-layout)",
        actual=actual,
    )


def _error_text_violations(error: ErrorMessage, packet: WirePacket) -> list[Violation]:
    out: list[Violation] = []
    shown = repr(error.render())

    def add(clause: str, message: str, expected: str, actual: str) -> None:
        out.append(
            Violation(message, clause, expected=expected, actual=actual, data=packet.data, packet=packet)
        )

    if ":" in error.where or not error.where:
        add(
            "error-string.where-no-colon",
            f"where part {error.where!r} is empty or has a colon",
            "a short where part without a colon",
            shown,
        )
    severity = SPEC.severities.get(error.severity)
    if severity is None:
        add(
            "error-string.severity",
            f"unknown severity {error.severity!r}",
            f"one of {', '.join(SPEC.severities)}",
            shown,
        )
    elif packet.opcode not in severity.server_opcodes:
        allowed = [s.letter for s in SPEC.severities.values() if packet.opcode in s.server_opcodes]
        add(
            "error.severity-matches-opcode",
            f"severity {error.severity} in {a_or_an(opcode_name(packet))} ({octal(packet.opcode)}) packet",
            f"one of {', '.join(allowed)} in opcode {octal(packet.opcode)}",
            shown,
        )
    if not (len(error.code) == 3 and error.code.isascii() and error.code.isalpha()):
        add("error-string.code", f"error code {error.code!r} is not three letters", "three letters", shown)
    if error.has_nul:
        wanted = sum(error.message.count(ch) for ch in SPECIALS)
        # one or more numbers per special character (E.2; erratum error-substitution), none without one
        if len(error.args) < wanted or (error.args and not wanted):
            add(
                "error-string.substitution",
                f"{len(error.args)} number(s) after the NUL for {wanted} ~/$ in the message",
                f"{wanted} number(s) or more, at least one per ~ or $"
                if wanted
                else "no number without a ~ or $",
                f"{len(error.args)} number(s): {list(error.args)}",
            )
    return out


def _codec_violation(exc: CodecError, packet: WirePacket, default: str, expected: str) -> Violation:
    clause = exc.clause if exc.clause in TRANSCRIPT_CLAUSES else default
    return Violation(str(exc), clause, expected=expected, actual=str(exc), data=packet.data, packet=packet)


def async_of(packet: WirePacket) -> AsyncResponse | None:
    """An asynchronous response's fields in either layout, told apart by length (manip's 8 bytes with
    the request number first, the 1985 guide's 6 without: erratum ``async-request-number``); None when
    its length is neither."""
    try:
        return decode_async(packet.data)
    except CodecError:
        return None


def completed_segment(packet: WirePacket) -> int | None:
    """The segment a segment-completed response (0203, condition 2, either layout) reports; None for
    any other packet."""
    message = async_of(packet) if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE else None
    if message is None or message.condition != AsyncCondition.SEGMENT_COMPLETED:
        return None
    return message.word3


def check_async_packet(packet: WirePacket, requested_mask: int | None = None) -> list[Violation]:
    """An asynchronous response (0203): layout, condition code, and (given the mask asked for) that it
    was requested.  ``requested_mask``: bit n = condition n+1 (request-notifications); None skips that."""
    message = async_of(packet)
    if message is None:
        return [
            Violation.at(
                packet,
                "async.layout",
                f"asynchronous response of {len(packet.data)} data bytes",
                expected="8 data bytes (request number, condition code, two words) or the 1985 guide's 6 "
                "(condition code, two words)",
                actual=f"{len(packet.data)} bytes",
            )
        ]
    condition, word2 = message.condition, message.word2
    out: list[Violation] = []
    code = SPEC.async_codes.get(condition)
    if code is None:
        out.append(
            Violation.at(
                packet,
                "async.codes",
                f"unknown condition code {condition}",
                expected=f"one of {sorted(SPEC.async_codes)}",
                actual=str(condition),
            )
        )
        return out
    if condition == AsyncCondition.GUARD_HIT and word2 not in (1, 2):
        out.append(
            Violation.at(
                packet,
                "async.layout",
                f"guard hit with stop/continue word {word2}",
                expected="1 (stop) or 2 (continue)",
                actual=str(word2),
            )
        )
    if condition == AsyncCondition.SEGMENT_COMPLETED and word2 != 0:
        out.append(
            Violation.at(
                packet,
                "async.layout",
                f"segment completed with reserved word {word2}",
                expected="0",
                actual=str(word2),
            )
        )
    if requested_mask is not None and not requested_mask >> code.notification_bit & 1:
        out.append(
            Violation.at(
                packet,
                "async.only-when-requested",
                f"asynchronous {code.name} that was not asked for",
                expected=f"no {code.name} responses (request-notifications mask {octal(requested_mask)})",
                actual=f"an asynchronous {code.name} response",
            )
        )
    return out


def check_initial_response(
    packet: WirePacket | None, rfc_packet_no: int | None = None, requests: Collection[int] = ()
) -> list[Violation]:
    """The first server packet is a RESPONSE (0200) holding only the RFC's packet number.  ``requests``:
    the packet numbers of the requests sent before it; a first packet carrying one of them (and not the
    RFC's) answers that request, so the initial RESPONSE never came."""
    number = word(packet.data) if packet is not None and not packet.is_close else None
    answers_request = number is not None and number in requests and number != rfc_packet_no
    if packet is None or packet.is_close or answers_request:
        said = f": the first server packet answers request #{number}" if answers_request else ""
        return [
            Violation(
                f"no initial RESPONSE after the connection opened{said}",
                "connect.initial-response",
                expected="a RESPONSE (200) packet first",
                actual="nothing" if packet is None else describe(packet),
                data=b"" if packet is None else packet.data,
                kind="missing_response",
                packet=packet,
            )
        ]
    if packet.opcode != ServerOp.RESPONSE:
        return [
            Violation.at(
                packet,
                "connect.initial-response",
                "the first server packet is not a RESPONSE",
                expected="a RESPONSE (200) packet first",
            )
        ]
    if len(packet.data) != 2 or (rfc_packet_no is not None and number != rfc_packet_no):
        expected = "only a request-number word" + (
            f" holding {rfc_packet_no}, the RFC's packet number" if rfc_packet_no is not None else ""
        )
        return [
            Violation.at(
                packet,
                "connect.initial-response-number",
                "the initial RESPONSE carries the wrong data",
                expected=expected,
                actual=f"{len(packet.data)} data bytes, first word {number}",
            )
        ]
    return []


# ------------------------------------------------------------------------------------- requests


def required_refusal(opcode: int, data: bytes) -> Refusal | None:
    """The refusal the spec demands for this request, or None when it is well formed.

    Unknown opcodes (request.unknown-opcode), data of the wrong length (request.data-length) and
    reserved-operand floats (request.reserved-float) must be answered with a non-fatal error of severity
    C.  Range errors (a speed of 2, say) are judged by the cases that know the ranges."""
    op = SPEC.requests.get(opcode)
    if op is None:
        reason = f"opcode {octal(opcode)} is not served by the spec"
        return Refusal("request.unknown-opcode", reason, ("UOP",))
    try:
        decode_request(opcode, data)
    except DecodeError as exc:
        if exc.clause == "request.data-length":
            return Refusal("request.data-length", f"{op.name}: {exc.message}", ("BDL",))
        if exc.clause == "float.reserved-operand":
            return Refusal(
                "request.reserved-float", f"{op.name}: reserved-operand float at byte {exc.offset}", ("BFL",)
            )
        return Refusal("request.data-length", f"{op.name}: {exc.message}", ("BDL", "BVA"))
    return None


def check_reply(request: WirePacket, answer: Sequence[WirePacket]) -> list[Violation]:
    """Judge the answer to one request: ``answer`` is the reply packet, or every packet of a
    multi-packet reply including its terminator (asynchronous packets already taken out)."""
    if not answer:
        return [
            Violation.at(
                request,
                "request.one-reply",
                f"no reply to request #{request.packet_no} ({opcode_name(request)})",
                expected="one reply",
                actual="nothing",
            )
        ]
    first = answer[0]
    out = check_server_opcode(first)
    if first.is_close:
        return [
            Violation.at(
                first,
                "request.one-reply",
                f"the connection ended before request #{request.packet_no} was answered",
                expected="one reply",
            )
        ]
    out += check_echo(request, first)
    refusal = required_refusal(request.opcode, request.data)
    if first.opcode in ERROR_REPLY_OPS:
        out += check_error_packet(first)
        if refusal is not None:
            out += _check_refusal(refusal, first)
        return out
    if refusal is not None:
        return [
            *out,
            Violation.at(
                first,
                refusal.clause,
                f"{refusal.reason}, but the server answered {describe(first)}",
                expected="a non-fatal error (202) of severity C",
            ),
        ]
    if first.opcode != ServerOp.RESPONSE:
        return [
            *out,
            Violation.at(
                first,
                "request.one-reply",
                f"the answer to #{request.packet_no} is {describe(first)}",
                expected="a RESPONSE or an error",
            ),
        ]
    op = SPEC.requests[request.opcode]
    if op.response.form == "multi":
        return out + _check_multi(op, request, answer)
    return out + _check_single(op, first)


def _check_refusal(refusal: Refusal, packet: WirePacket) -> list[Violation]:
    try:
        error = decode_error(packet.opcode, packet.data, align_args=False).error
    except CodecError:
        return []  # the format violations already say it
    if packet.opcode == ServerOp.NON_FATAL_ERROR and error.severity == "C":
        return []
    return [
        Violation.at(
            packet,
            refusal.clause,
            f"{refusal.reason}: answered with severity {error.severity} in {octal(packet.opcode)}",
            expected="a non-fatal error (202) of severity C",
            actual=repr(error.render()),
        )
    ]


_KIND_CLAUSE: Final[Mapping[str, str]] = {
    "done": "response.done-empty",
    "segment": "response.segment-number",
    "data": "response.data-layout",
}


def _check_single(op: RequestOpcode, packet: WirePacket) -> list[Violation]:
    kind = op.response.form
    try:
        decode_reply(packet.data, op)
    except CodecError as exc:
        clause = exc.clause if exc.clause in TRANSCRIPT_CLAUSES else _KIND_CLAUSE[kind]
        expected = {
            "done": "the request number only (2 data bytes)",
            "segment": "the request number and one segment-number word (4 data bytes)",
        }.get(kind, f"the request number then {_layout_text(op)}")
        # expected and actual describe the same thing: the whole data, its size and what is wrong in it
        where = f"{exc.path.rsplit('.', 1)[-1]}: " if exc.path else ""
        cause = floats_diagnosis(float_payload(op, packet.data)) if kind == "data" else None
        return [
            Violation.at(
                packet,
                clause,
                f"{op.name} reply: {exc}" + (f"; {cause}" if cause else ""),
                expected=expected,
                actual=f"{len(packet.data)} data bytes; {where}{exc.message}",
            )
        ]
    return []


def _layout_text(op: RequestOpcode) -> str:
    """The reply's data after the request number, and the size of the whole data when fixed (as the
    actual side counts it: ``joints (joints): 26 data bytes``)."""
    size = op.response.data.fixed_size
    names = ", ".join(f"{f.name} ({f.type.name})" for f in op.response.data.fields)
    floats = (
        ", every float a number" if any(f.type.element == "float" for f in op.response.data.fields) else ""
    )
    return f"{names}" + (f": {2 + size} data bytes{floats}" if size is not None else floats)


def _check_multi(op: RequestOpcode, request: WirePacket, answer: Sequence[WirePacket]) -> list[Violation]:
    out: list[Violation] = []
    texts = 0
    terminated = False
    for packet in answer:
        if packet.is_close or packet.opcode != ServerOp.RESPONSE:
            break
        number = word(packet.data)
        if number != request.packet_no:
            out.append(
                Violation.at(
                    packet,
                    "multi.same-request-number",
                    f"a packet of the {op.name} reply carries request number {number}",
                    expected=f"request number {request.packet_no} in every packet",
                    actual=f"request number {number}",
                )
            )
        if len(packet.data) <= 2:
            terminated = True
            break
        texts += 1
    last = answer[-1]
    if last.opcode in ERROR_REPLY_OPS:  # it cut the reply short
        out += check_echo(request, last) + check_error_packet(last)
    if not terminated:
        out.append(
            Violation.at(
                last,
                "multi.terminated-by-empty",
                f"the {op.name} reply is not ended by an empty packet",
                expected="an empty RESPONSE (request number only) after the text packets",
                actual=f"{texts} text packet(s), then {describe(last)}"
                if last.is_close or last.opcode != ServerOp.RESPONSE
                else f"{texts} text packet(s), no terminator",
            )
        )
    if texts == 0:
        out.append(
            Violation(
                f"the {op.name} reply has no text packet",
                "describe.reply-shape",
                expected="one or more text packets, then an empty one",
                actual="an empty reply",
                data=answer[0].data,
                packet=answer[0],
            )
        )
    return out


# ------------------------------------------------------------------------------------- describe self


def parse_description(text: str) -> tuple[dict[str, LispValue] | None, list[Violation]]:
    """Read the describe-self alist: the entries by keyword name, or None and the violations."""
    try:
        return read_alist(text), []
    except DecodeError as exc:
        clause = exc.clause if exc.clause in TRANSCRIPT_CLAUSES else "describe.alist-readable"
        return None, [
            Violation(
                f"describe-self text: {exc}",
                clause,
                expected="one Lisp-readable alist",
                actual=_excerpt(text, exc.offset),
                data=text.encode("utf-8", "replace"),
            )
        ]


def _excerpt(text: str, offset: int | None) -> str:
    if offset is None:
        return repr(text[:80])
    return f"...{text[max(0, offset - 30) : offset + 30]!r}... (offset {offset})"


def _scalar(value: LispValue) -> LispValue:
    """``(:key . v)`` gives v, ``(:key v)`` gives [v]: both mean v."""
    return value[0] if isinstance(value, list) and len(value) == 1 else value


def check_description(text: str, *, protocol_version: int = SPEC.protocol_version) -> list[Violation]:
    """The describe-self alist: readable, and the 1985 guide's keys shaped as E.1 says."""
    entries, out = parse_description(text)
    if entries is None:
        return out
    return check_description_entries(entries, text, protocol_version=protocol_version)


def check_description_entries(
    entries: Mapping[str, LispValue], text: str = "", *, protocol_version: int = SPEC.protocol_version
) -> list[Violation]:
    """The 1985 guide's keys of a read description (``text``: the raw text, kept as the violation's bytes)."""
    out: list[Violation] = []
    data = text.encode("utf-8", "replace")

    def add(clause: str, message: str, expected: str, actual: object) -> None:
        out.append(Violation(message, clause, expected=expected, actual=repr(actual), data=data))

    if "protocol-version" not in entries:
        add(
            "describe.protocol-version",
            "no :protocol-version in the description",
            f":protocol-version {protocol_version}",
            sorted(entries),
        )
    elif _scalar(entries["protocol-version"]) != protocol_version:
        add(
            "describe.protocol-version",
            "wrong :protocol-version",
            str(protocol_version),
            entries["protocol-version"],
        )
    for key, clause in (("brand-name", "describe.brand-name"), ("unique-name", "describe.unique-name")):
        value = _scalar(entries[key]) if key in entries else None
        if not isinstance(value, str):
            add(clause, f":{key} is missing or not a string", "a string", value)
    dof = _scalar(entries["degrees-of-freedom"]) if "degrees-of-freedom" in entries else None
    if not isinstance(dof, int) or dof <= 0:
        add(
            "describe.degrees-of-freedom",
            ":degrees-of-freedom is missing or not a positive number",
            "a number (6 for the Puma)",
            dof,
        )
    ops = entries.get("operations")
    if not isinstance(ops, list) or not all(_is_operation(o) for o in ops):
        add(
            "describe.operations",
            ":operations is missing or not a list of opcodes",
            "a list of numbers or (escape . code) pairs",
            ops,
        )
    if "software-version" in entries and not _is_version(entries["software-version"]):
        add(
            "describe.software-version",
            ":software-version has the wrong shape",
            "a number, or alternating keywords and numbers",
            entries["software-version"],
        )
    return out


def _is_operation(value: LispValue) -> bool:
    return (
        isinstance(value, int)
        or (isinstance(value, Cons) and isinstance(value.car, int) and isinstance(value.cdr, int))
        or (isinstance(value, list) and len(value) == 2 and all(isinstance(v, int) for v in value))
    )


def _is_version(value: LispValue) -> bool:
    value = _scalar(value)
    if isinstance(value, (int, float)):
        return True
    if not isinstance(value, list) or len(value) % 2:
        return False
    return all(
        isinstance(k, Keyword) and isinstance(v, (int, float))
        for k, v in zip(value[::2], value[1::2], strict=True)
    )


def description_operations(entries: Mapping[str, LispValue]) -> tuple[int, ...]:
    """The plain opcodes listed under :operations (escape pairs left out)."""
    ops = entries.get("operations")
    return tuple(o for o in ops if isinstance(o, int)) if isinstance(ops, list) else ()


def multi_text(answer: Iterable[WirePacket]) -> str:
    """The text of a multi-packet reply (the data after the request number of each text packet)."""
    return "".join(
        decode_lispm(p.data[2:]) for p in answer if p.opcode == ServerOp.RESPONSE and len(p.data) > 2
    )


# ------------------------------------------------------------------------------------- a whole connection


@dataclass
class _Pending:
    request: WirePacket | None
    """None: the RFC, answered by the initial RESPONSE (judged by :func:`check_initial_response`)."""
    discarded: bool = False
    """Sent while free joint waited: the spec answers it with done without executing it."""


@dataclass
class _Session:
    violations: list[Violation] = field(default_factory=list)
    pairing: ReplyPairing[_Pending] = field(default_factory=ReplyPairing)
    answer: list[WirePacket] = field(default_factory=list)
    """The packets so far of the answer being received (a multi-packet reply in progress)."""
    mask: int = 0
    mask_pending: dict[int, int] = field(default_factory=dict)
    last_segment: int | None = None
    fatal: WirePacket | None = None
    closed: bool = False
    answered_with_error: set[int] = field(default_factory=set)


def check_transcript(
    packets: Sequence[WirePacket],
    *,
    rfc_packet_no: int | None = None,
    expect_initial: bool = True,
    complete: bool = False,
) -> list[Violation]:
    """Judge one connection's packets in order (both directions, closes included).

    Server packets are tied to requests by :class:`~manip.codecs.pairing.ReplyPairing` (erratum
    ``capture-pairing``), the rule the capture view and replay use too.  ``expect_initial``: the
    recording starts at the open, so the first server packet must be the initial RESPONSE, and the
    first answer is the RFC's.  ``complete``: the recording ran to the end of the exchange, so a request
    still unanswered at the end is a violation (leave it False for a case that stopped early)."""
    s = _Session()
    if expect_initial:
        server = [p for p in packets if p.direction == "s2c"]
        first = server[0] if server else None
        before = packets[: packets.index(first)] if first is not None else packets
        sent = [p.packet_no for p in before if p.direction == "c2s" and not p.is_close]
        s.violations += check_initial_response(first, rfc_packet_no, sent)
        s.pairing.rfc(_Pending(None))
    for packet in packets:
        if packet.direction == "c2s":
            if not packet.is_close:
                _on_request(s, packet)
        elif packet.is_close:
            _finish_answer(s, s.pairing.close())
            s.closed = True
        else:
            _on_server_packet(s, packet)
    _finish_answer(s, s.pairing.in_progress)
    if s.fatal is not None and not s.closed and complete:
        s.violations.append(
            Violation(
                "the connection stayed open after a fatal error",
                "error.fatal-then-close",
                expected="CLS after the fatal error",
                actual="the connection open",
                data=s.fatal.data,
                packet=s.fatal,
            )
        )
    if complete and not s.closed:
        for item in s.pairing.outstanding():
            if item.request is None:
                continue  # no initial RESPONSE: check_initial_response said so
            s.violations.append(
                Violation(
                    f"request #{item.request.packet_no} ({opcode_name(item.request)}) was never answered",
                    "request.one-reply",
                    expected="one reply",
                    actual="nothing",
                    data=item.request.data,
                    packet=item.request,
                )
            )
    return s.violations


def _on_request(s: _Session, packet: WirePacket) -> None:
    item = _Pending(packet)
    item.discarded = s.pairing.request(item, packet.opcode, packet.data)
    if (
        not item.discarded
        and packet.opcode == SPEC.request("request-notifications").opcode
        and required_refusal(packet.opcode, packet.data) is None
    ):
        s.mask_pending[packet.packet_no] = word(packet.data) or 0


def _allowed_mask(s: _Session) -> int:
    mask = s.mask
    for pending in s.mask_pending.values():
        mask |= pending  # sent, not yet answered: the server may already act on it
    return mask


def _on_server_packet(s: _Session, packet: WirePacket) -> None:
    s.violations.extend(check_server_opcode(packet))
    place = s.pairing.server(packet.opcode, packet.data)
    if s.fatal is not None:
        s.violations.append(
            Violation.at(
                packet,
                "error.fatal-then-close",
                f"{describe(packet)} after a fatal error",
                expected="nothing but the close after a fatal error",
            )
        )
        return
    if place.role == "async":
        if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE:
            s.violations.extend(check_async_packet(packet, _allowed_mask(s)))
        else:
            s.violations.extend(check_error_packet(packet))
        return
    if place.role == "extra":
        number = word(packet.data)
        clause = "error.non-fatal-is-reply" if number in s.answered_with_error else "request.one-reply"
        s.violations.append(
            Violation.at(
                packet,
                clause,
                f"{describe(packet)} answers no outstanding request",
                expected="one reply per request",
                actual=f"an extra {describe(packet)}",
            )
        )
        return
    if place.role != "answer":
        return
    if packet.opcode == ServerOp.FATAL_ERROR:
        s.fatal = packet
    s.answer.append(packet)
    if place.final:
        _finish_answer(s, place.request)


def _finish_answer(s: _Session, item: _Pending | None) -> None:
    """Judge the answer collected for ``item`` (complete, or cut off by the close or the end)."""
    answer, s.answer = s.answer, []
    if item is None or not answer:
        return
    request = item.request
    if request is None:  # the RFC's: judged by check_initial_response, and an error string as such
        if answer[0].opcode != ServerOp.RESPONSE:
            s.violations.extend(check_error_packet(answer[0]))
        return
    if item.discarded:
        _check_discarded(s, request, answer[0])
        return
    found = check_reply(request, answer)
    if any(v.clause == "multi.same-request-number" for v in found) and _interleaved(
        request.packet_no, answer
    ):
        later = {
            p.request.packet_no for p in s.pairing.outstanding() if p is not None and p.request is not None
        }
        found = [_overtaken(v, later) for v in found]
    s.violations.extend(found)
    last = answer[-1]
    if len(answer) > 1 and last.opcode == ServerOp.RESPONSE and len(last.data) <= 2:
        s.violations.extend(check_description(multi_text(answer)))
    _after_answer(s, request, answer)


def _interleaved(number: int, answer: Sequence[WirePacket]) -> bool:
    """Whether the packets of ``answer`` carrying ``number`` are a whole description with packets of
    other numbers among them: another reply inside this one (rather than this one's packets numbered
    wrongly, whose text is whole only with theirs)."""
    numbers = [word(p.data) for p in answer]
    other = next((i for i, n in enumerate(numbers) if n != number), None)
    if other is None or number not in numbers[other + 1 :]:
        return False
    entries, problems = parse_description(
        multi_text([p for p, n in zip(answer, numbers, strict=True) if n == number])
    )
    return entries is not None and not problems


def _overtaken(violation: Violation, later: Collection[int]) -> Violation:
    """A packet of a multi-packet reply carrying the number of a request sent after it (``later``: those
    outstanding, when :func:`_interleaved`), said as what it is: that request answered before the reply
    ended (``request.one-reply``), not a wrong number."""
    packet = violation.packet
    number = word(packet.data) if packet is not None else None
    if violation.clause != "multi.same-request-number" or packet is None or number not in later:
        return violation
    return Violation.at(
        packet,
        "request.one-reply",
        f"request #{number} was answered before the multi-packet reply in progress ended",
        expected="each reply after the one before it, a multi-packet one ended by its terminator",
        actual=f"{describe(packet)} inside the reply",
    )


def _check_discarded(s: _Session, request: WirePacket, packet: WirePacket) -> None:
    s.violations.extend(check_echo(request, packet))
    if packet.opcode != ServerOp.RESPONSE or len(packet.data) != 2:
        s.violations.append(
            Violation.at(
                packet,
                "free-joint.replies",
                f"the packet after free joint (#{request.packet_no}, "
                f"{opcode_name(request)}) was answered with {describe(packet)}",
                expected="an empty done: the packet is discarded, not executed",
            )
        )


def _after_answer(s: _Session, request: WirePacket, answer: Sequence[WirePacket]) -> None:
    ok = answer[-1].opcode == ServerOp.RESPONSE
    if not ok:
        s.answered_with_error.add(request.packet_no)
    mask = s.mask_pending.pop(request.packet_no, None)
    if mask is not None and ok:
        s.mask = mask
    packet = answer[0]
    op = SPEC.requests.get(request.opcode)
    if ok and op is not None and op.response.form == "segment" and len(packet.data) == 4:
        segment = word(packet.data, 2)
        assert segment is not None
        if s.last_segment is not None and segment != (s.last_segment + 1) & 0xFFFF:
            s.violations.append(
                Violation.at(
                    packet,
                    "segment.number-increases",
                    f"segment {segment} follows segment {s.last_segment}",
                    expected=f"segment {(s.last_segment + 1) & 0xFFFF}",
                    actual=f"segment {segment}",
                )
            )
        s.last_segment = segment
