"""Packets as a person reads them in a failure report: numbered, one line each, the data decoded.

A property or stateful case that fails shows the packets of its shrunk example this way instead of the
Python objects Hypothesis drew::

        1  c2s here 0201 (packet number 22, 0 data bytes): no data
        2  s2c response 0200 (request number 22, 50 data bytes): transform N=(1, 0, 0) O=(0, 1, 0) ...
    >   3  c2s free-joint 0220 (packet number 23, 2 data bytes): joint=7

Each line is :func:`~manip.conformance.judge.checks.describe` (requests with their Chaos packet number,
opcodes in octal) and then what the data say: a request's fields by the spec layout of its opcode, an
answer's by the layout of the request it names (found earlier in the listing; when it names none, the
last request sent on its connection), an error string
rendered, an asynchronous response's condition, a close's reason.  Data that do not decode are shown in
hex with the reason.  ``>`` marks the packets the failure is about.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Final

from manip.codecs.cougar import CougarMsg, WordStream
from manip.codecs.errors import CodecError
from manip.codecs.messages import (
    decode_async,
    decode_error,
    decode_reply,
    decode_request,
    response_layout,
)
from manip.conformance.judge.checks import WirePacket, describe, word
from manip.conformance.judge.packets import DRV11J, carries_data, link_words
from manip.spec import SPEC, Layout
from manip.spec.constants import ERROR_STRING_OPS, ServerOp
from manip.spec.notation import octal_words

__all__ = ["MAX_LISTED", "annotated", "decoded", "packet_listing", "show_value"]

MAX_LISTED: Final = 80
"""Lines of a listing; the earliest packets are left out beyond it (the failure is at the end)."""
MAX_TEXT: Final = 160
"""Characters shown of a text field (a describe-self packet's alist)."""
_TRANSFORM_COLUMNS: Final = ("N", "O", "A", "P")


def show_value(value: object) -> str:
    """A decoded value, short: floats to the 7 digits an F float holds, sequences in parentheses."""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return f"{value:.7g}"
    if isinstance(value, (bytes, bytearray)):
        return value.hex(" ") or "(none)"
    if isinstance(value, str):
        shown = repr(value[:MAX_TEXT])
        return shown + ("..." if len(value) > MAX_TEXT else "")
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(show_value(v) for v in value) + ")"
    return str(value)


def _fields(values: Mapping[str, object], layout: Layout) -> str:
    """``name=value, ...``; a transform as its four columns ``name N=(..) O=(..) A=(..) P=(..)``."""
    transforms = {f.name for f in layout.fields if f.type.name == "transform"}
    parts = []
    for name, value in values.items():
        if name in transforms and isinstance(value, (tuple, list)) and len(value) == 12:
            columns = [show_value(value[3 * i : 3 * i + 3]) for i in range(4)]
            shown = " ".join(f"{c}={v}" for c, v in zip(_TRANSFORM_COLUMNS, columns, strict=True))
            parts.append(f"{name} {shown}")
        else:
            parts.append(f"{name}={show_value(value)}")
    return ", ".join(parts)


def _undecoded(data: bytes, exc: CodecError) -> str:
    return f"does not decode ({exc.message}): {data.hex(' ')}"


def decoded(packet: WirePacket, request_opcode: int | None = None) -> str:
    """What ``packet``'s data say; ``request_opcode`` (for an answer) decodes a reply by its request's
    layout.  A DRV-11J record: its words and the Table 1 messages they make, or a raw frame's bytes."""
    if packet.link == DRV11J:
        return _decoded_words(packet)
    if packet.link:
        return packet.data.hex(" ", 2) or "(none)"
    if not carries_data(packet) and not packet.is_close:
        return f"data {packet.data.hex(' ') or '(none)'}"
    return _decoded_packet(packet, request_opcode)


def _decoded_packet(packet: WirePacket, request_opcode: int | None) -> str:
    data = packet.data
    if packet.is_close:
        return data.decode("ascii", "replace") or "(no reason given)"
    if packet.direction == "c2s":
        if packet.opcode not in SPEC.requests:
            return f"unknown opcode, data {data.hex(' ') or '(none)'}"
        try:
            request = decode_request(packet.opcode, data)
        except CodecError as exc:
            return _undecoded(data, exc)
        return _fields(request.values, request.op.request) or "no data"
    try:
        if packet.opcode == ServerOp.RESPONSE:
            op = SPEC.requests.get(request_opcode) if request_opcode is not None else None
            if len(data) == 2:
                return "empty (done, or the end of a multi-packet reply)"
            reply = decode_reply(data, op)
            if op is None:
                return f"data {reply.payload.hex(' ')} (no request before it to decode it by)"
            return _fields(reply.values, response_layout(op))
        if packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE:
            message = decode_async(data)
            number = message.request_number
            return f"{message.condition_name} (condition {message.condition}), words {message.word2} " + (
                f"and {message.word3}, for request number {number}"
                if number is not None
                else f"and {message.word3} (the 1985 guide's layout: no request number)"
            )
        if packet.opcode in ERROR_STRING_OPS:
            try:
                error = decode_error(packet.opcode, data)
            except CodecError:
                error = decode_error(packet.opcode, data, align_args=False)
            return repr(error.error.render())
    except CodecError as exc:
        return _undecoded(data, exc)
    return f"data {data.hex(' ') or '(none)'}"


def _decoded_words(packet: WirePacket) -> str:
    """A DRV-11J record's words in octal, and the Table 1 messages they make (a frame we sent may hold
    several commands, or part of one)."""
    words = link_words(packet)
    stream = WordStream("command" if packet.direction == "c2s" else "response")
    messages = [
        " ".join([item.name, *(f"{k}={show_value(v)}" for k, v in item.values.items())])
        for item in stream.feed(words)
        if isinstance(item, CougarMsg)
    ]
    rest = " (then an incomplete message)" if stream.pending else ""
    return f"{octal_words(words)}: " + ("; ".join(messages) or "no whole Table 1 message") + rest


def annotated(packets: Sequence[WirePacket], *, from_open: bool = False) -> list[tuple[WirePacket, str]]:
    """Each packet with what its data say (:func:`decoded`), answers decoded by the layout of the
    request they name.  ``from_open``: the packets start where their connections opened, so an empty
    RESPONSE before any request is the initial one."""
    requests: dict[tuple[int, int], int] = {}
    last: dict[int, int] = {}
    rows = []
    for packet in packets:
        request_opcode = None
        if packet.direction == "c2s" and not packet.is_close:
            requests[(packet.connection, packet.packet_no)] = last[packet.connection] = packet.opcode
        else:
            # the request the answer names; else (a wrong number) the last one sent, as answers come in order
            number = word(packet.data)
            request_opcode = requests.get((packet.connection, number if number is not None else -1))
            request_opcode = request_opcode or last.get(packet.connection)
        initial = from_open and packet.direction == "s2c" and packet.connection not in last
        if initial and packet.opcode == ServerOp.RESPONSE and len(packet.data) == 2:
            text = "the initial RESPONSE (its number is the RFC's packet number)"
        else:
            text = decoded(packet, request_opcode)
        rows.append((packet, text))
    return rows


def packet_listing(
    packets: Sequence[WirePacket],
    *,
    marked: Iterable[WirePacket] = (),
    from_open: bool = False,
    limit: int = MAX_LISTED,
) -> list[str]:
    """One numbered line per packet (see the module docstring); ``marked`` packets get a ``>``.
    ``from_open``: the packets start where their connections opened, so an empty RESPONSE before any
    request is the initial one."""
    chosen = {id(p) for p in marked}
    lines = []
    for index, (packet, text) in enumerate(annotated(packets, from_open=from_open), 1):
        mark = ">" if id(packet) in chosen else " "
        lines.append(f"  {mark} {index:>3}  {packet.direction} {describe(packet)}: {text}")
    if len(lines) > limit:
        left_out = len(lines) - limit
        return [f"      ... {left_out} earlier packets (the JSON report has every packet)", *lines[-limit:]]
    return lines
