"""The decoded view of a capture: which connection a packet belongs to, what it means, what it answers.

Theory of operation
===================

:class:`Annotator` is sans-I/O: it is fed the packets of a capture in the order they were seen, each with
its link id and direction (``c2s`` client to server, ``s2c`` back), and returns an :class:`Annotation`.
The recorder uses it to write the JSON view; the reader runs the same code over the raw frames, so both
always agree and a file without the view can still be read.

* **Connections.**  A connection is keyed by (link, client host, client index): the source of a ``c2s``
  packet, the destination of an ``s2c`` one.  A ``c2s`` RFC opens a new connection unless it repeats the
  RFC that opened the current one (a retransmission).  Connections are numbered from 1 in the order
  they appear.
* **Retransmissions.**  A controlled packet (RFC, OPN, EOF, data) whose packet number was already seen
  in the same direction of the same connection is marked ``retransmission`` and pairs like the first.
* **Pairs.**  Every request (and the RFC, answered by the initial RESPONSE) gets a new pair id; the
  server packets that answer it carry the same id.  Which request a packet answers is the shared rule
  of :mod:`manip.codecs.pairing` (erratum ``capture-pairing``), the one ``manip-conform verify`` and
  replay use: by position, answers in request order, the request-number word shown but never used to
  re-pair (a wrong echo is a violation verify reports).  A multi-packet reply keeps its pair until the empty
  terminator or an error, which is ``final``.  Asynchronous packets (0203-0205) quote the last request
  processed; they are not replies and carry no pair.
* **Meaning.**  Requests are decoded by their opcode's layout; a RESPONSE by the layout of the request
  it answers, when that request was seen (otherwise its payload is shown in hex); error strings are
  parsed; decode failures become a ``decode_error`` entry, never an exception.
* **Events.**  RFC, OPN, CLS (``refused`` before the OPN), LOS, EOF, ANS and FWD produce connection
  events with their texts.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from operator import attrgetter
from typing import Any, Final

from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.fastpath import FastLayout, plan
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import (
    decode_async,
    decode_error,
    decode_reply,
    decode_request,
    response_layout,
)
from manip.codecs.packet import Direction, Packet
from manip.codecs.pairing import Placement, ReplyPairing
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import ERROR_REPLY_OPS, ERROR_STRING_OPS, ChaosOp, ServerOp

SEEN_KEPT: Final = 2048
"""Packet numbers remembered per direction for spotting retransmissions (a window is at most 15)."""

_CONTROLLED: Final = frozenset(op.value for op in SPEC.chaos_opcodes.values() if op.controlled)
_TEXT_EVENTS: Final = {
    ChaosOp.CLS: "cls",
    ChaosOp.LOS: "los",
    ChaosOp.ANS: "ans",
    ChaosOp.FWD: "fwd",
}
RFC_NAME: Final = "rfc"
"""The ``op`` of an RFC and of the initial RESPONSE that answers it."""

# Plain ints for the per-packet tests (an enum member costs an attribute lookup on every packet).
_RFC: Final = int(ChaosOp.RFC)
_DAT: Final = int(ChaosOp.DAT)
_LAST_ERROR_OP: Final = int(ServerOp.ASYNCHRONOUS_WARNING)
_ASYNC_RESPONSE: Final = int(ServerOp.ASYNCHRONOUS_RESPONSE)
_RESPONSE: Final = int(ServerOp.RESPONSE)
_C2S_SEEN: Final = "c2s"


@dataclass(frozen=True, slots=True)
class _RequestPlan:
    """What the annotator needs of one request opcode, worked out once: its spec entry, its name and the
    fast decoder of its data layout (None: :func:`decode_request` decides, and raises what is wrong)."""

    op: RequestOpcode | None
    name: str | None
    pending_name: str
    fast: FastLayout | None
    reply_fast: FastLayout | None
    """The fast decoder of its RESPONSE's numbered layout (None for multi-packet replies)."""


def _request_plan(opcode: int) -> _RequestPlan:
    op = SPEC.requests.get(opcode)
    if op is None:
        return _RequestPlan(None, None, f"0{opcode:o}", None, None)
    reply = None if op.response.form == "multi" else plan(response_layout(op), numbered=True)
    return _RequestPlan(op, op.name, op.name, plan(op.request, numbered=False), reply)


_REQUEST_PLANS: Final = {opcode: _request_plan(opcode) for opcode in range(_DAT, 0o400)}


@dataclass(slots=True)
class Annotation:
    """What the annotator made of one packet (the JSON view, minus the Chaos header)."""

    conn: int
    kind: str
    retransmission: bool = False
    op: str | None = None
    request_number: int | None = None
    pair: int | None = None
    final: bool | None = None
    fields: dict[str, Any] | None = None
    text: str | None = None
    error: dict[str, Any] | None = None
    async_: dict[str, Any] | None = None
    payload_hex: str | None = None
    decode_error: dict[str, Any] | None = None
    events: list[dict[str, Any]] = field(default_factory=list)


@dataclass(slots=True)
class _Pending:
    pair: int
    op: RequestOpcode | None
    name: str
    reply_fast: FastLayout | None = None


_Seen = int | Placement[_Pending] | None
"""What ``_Conn.seen`` keeps of a packet number: a request's pair id, a server packet's placement."""


@dataclass(slots=True)
class _Conn:
    id: int
    link: int
    client: tuple[int, int]
    rfc_no: int | None = None
    opened: bool = False
    ended: bool = False
    pairing: ReplyPairing[_Pending] = field(default_factory=ReplyPairing)
    seen: dict[Direction, dict[int, _Seen]] = field(default_factory=lambda: {"c2s": {}, "s2c": {}})
    order: dict[Direction, deque[int]] = field(default_factory=lambda: {"c2s": deque(), "s2c": deque()})
    """The packet numbers of ``seen`` oldest first: dropping the oldest from a dict by iterating it
    would walk past every entry deleted before (the dict only compacts when it grows)."""


def decode_error_dict(exc: CodecError) -> dict[str, Any]:
    out: dict[str, Any] = {"message": exc.message}
    if exc.path:
        out["path"] = exc.path
    if exc.offset is not None:
        out["offset"] = exc.offset
    if exc.clause:
        out["clause"] = exc.clause
    return out


class Annotator:
    """Feed it every packet of a capture in order (:meth:`annotate`); see the module docstring."""

    def __init__(self) -> None:
        self._conns: dict[tuple[int, int, int], _Conn] = {}
        self._next_conn = 1
        self._next_pair = 1

    @property
    def connections(self) -> int:
        """Connections seen so far."""
        return self._next_conn - 1

    def annotate(self, link: int, direction: Direction, packet: Packet) -> Annotation:
        opcode = packet.opcode
        if direction == "c2s":
            key = (link, packet.src_host, packet.src_index)
        else:
            key = (link, packet.dest_host, packet.dest_index)
        conn = self._conns.get(key)
        if conn is None or (
            opcode == _RFC and direction == "c2s" and (conn.rfc_no != packet.packet_no or conn.ended)
        ):
            conn = _Conn(self._next_conn, link, (key[1], key[2]))
            self._next_conn += 1
            self._conns[key] = conn
        retransmission = False
        previous: _Seen = None
        if opcode >= _DAT or opcode in _CONTROLLED:
            seen = conn.seen[direction]
            number = packet.packet_no
            if number in seen:
                retransmission = True
                previous = seen[number]
            else:
                order = conn.order[direction]
                if len(seen) >= SEEN_KEPT:
                    del seen[order.popleft()]
                seen[number] = None
                order.append(number)
        if opcode >= _DAT:
            if direction == "c2s":
                ann = self._request(conn, packet, retransmission, previous)
            else:
                ann = self._server_packet(conn, packet, retransmission, previous)
        else:
            ann = self._control(conn, direction, packet, retransmission)
        ann.retransmission = retransmission
        return ann

    # ------------------------------------------------------------------------------ requests

    def _new_pair(self) -> int:
        pair = self._next_pair
        self._next_pair += 1
        return pair

    def _request(self, conn: _Conn, packet: Packet, retransmission: bool, previous: _Seen) -> Annotation:
        number = packet.packet_no
        req = _REQUEST_PLANS[packet.opcode]
        ann = Annotation(conn.id, "request", op=req.name, request_number=number)
        data = packet.data
        fast = req.fast.parse(data) if req.fast is not None else None
        if fast is not None:
            ann.fields = fast[1]
        else:
            try:
                ann.fields = dict(decode_request(packet.opcode, data).values)
            except CodecError as exc:
                ann.decode_error = decode_error_dict(exc)
                if data:
                    ann.payload_hex = data.hex()
        if retransmission:
            if isinstance(previous, int):
                ann.pair = previous
            return ann
        pair = ann.pair = self._next_pair
        self._next_pair = pair + 1
        conn.seen[_C2S_SEEN][number] = pair
        conn.pairing.request(_Pending(pair, req.op, req.pending_name, req.reply_fast), packet.opcode, data)
        return ann

    # ------------------------------------------------------------------------------ server packets

    def _server_packet(
        self, conn: _Conn, packet: Packet, retransmission: bool, previous: _Seen
    ) -> Annotation:
        opcode, data = packet.opcode, packet.data
        if retransmission:  # pairs like the first copy, and moves the pairing on no further
            place = previous if isinstance(previous, Placement) else None
        else:
            place = conn.pairing.server(opcode, data)
            conn.seen["s2c"][packet.packet_no] = place
        waiting = place.request if place is not None else None
        if waiting is not None and opcode == _RESPONSE and waiting.reply_fast is not None:
            # The common case first: a well-formed reply of a fixed numeric layout to a request seen.
            parsed = waiting.reply_fast.parse(data)
            if parsed is not None:
                return Annotation(
                    conn.id,
                    "reply",
                    op=waiting.name,
                    request_number=data[0] | data[1] << 8,
                    pair=waiting.pair,
                    final=True,
                    fields=parsed[1] or None,
                )
        if opcode > _LAST_ERROR_OP:
            ann = Annotation(conn.id, "data")
            if data:
                ann.payload_hex = data.hex()
            return ann
        number = int.from_bytes(data[:2], "little") if len(data) >= 2 else None
        pending = waiting
        if opcode == _ASYNC_RESPONSE:
            kind = "async"
        elif opcode in ERROR_STRING_OPS:
            kind = "error"
        else:
            kind = "reply"
        ann = Annotation(conn.id, kind, request_number=number)
        if pending is not None:
            ann.pair = pending.pair
            ann.op = pending.name
        try:
            if kind == "reply":
                self._reply(ann, pending, data)
            elif kind == "error":
                err = decode_error(opcode, data).error
                ann.error = {
                    "where": err.where,
                    "severity": err.severity,
                    "code": err.code,
                    "message": err.message,
                    "args": list(err.args),
                    "rendered": err.render(),
                    "problems": list(err.problems),
                }
                if opcode in ERROR_REPLY_OPS:
                    ann.final = True
            else:
                a = decode_async(data)
                ann.async_ = {
                    "condition": a.condition,
                    "condition_name": a.condition_name,
                    "word2": a.word2,
                    "word3": a.word3,
                }
        except CodecError as exc:
            ann.decode_error = decode_error_dict(exc)
            if len(data) > 2:
                ann.payload_hex = data[2:].hex()
            if kind != "async":
                ann.final = True
        if pending is not None and place is not None:
            ann.final = place.final  # the pairing rule decides where an answer ends, not the decoding
        return ann

    @staticmethod
    def _reply(ann: Annotation, pending: _Pending | None, data: bytes) -> None:
        op = pending.op if pending is not None else None
        reply = decode_reply(data, op)
        payload = reply.payload
        if op is None:
            if payload:
                ann.payload_hex = payload.hex()
            ann.final = pending is not None  # the initial RESPONSE answers the RFC
            return
        if op.response.form == "multi":
            ann.final = not payload
            if payload:
                ann.text = decode_lispm(payload)
            return
        ann.final = True
        if reply.values:
            ann.fields = dict(reply.values)

    # ------------------------------------------------------------------------------ control

    def _control(self, conn: _Conn, direction: Direction, packet: Packet, retransmission: bool) -> Annotation:
        opcode = packet.opcode
        ann = Annotation(conn.id, "control")
        if retransmission:
            return ann
        base = {"conn": conn.id, "link": conn.link, "direction": direction}
        if opcode == ChaosOp.RFC:
            text = packet.data.decode("latin-1")
            contact, _, args = text.partition(" ")
            ann.text = text
            ann.op = RFC_NAME
            if direction == "c2s":
                conn.rfc_no = packet.packet_no
                ann.pair = self._new_pair()
                conn.seen["c2s"][packet.packet_no] = ann.pair
                conn.pairing.rfc(_Pending(ann.pair, None, RFC_NAME))
            ann.events.append({**base, "event": "rfc", "contact": contact, "args": args})
        elif opcode == ChaosOp.OPN:
            conn.opened = True
            ann.events.append({**base, "event": "open"})
        elif opcode == ChaosOp.EOF:
            ann.events.append({**base, "event": "eof"})
        elif opcode in _TEXT_EVENTS:
            try:
                ann.text = decode_lispm(packet.data)
            except CodecError:
                ann.text = packet.data.decode("latin-1")
            event = _TEXT_EVENTS[ChaosOp(opcode)]
            if event == "cls" and not conn.opened and direction == "s2c":
                event = "refused"
            if event in ("cls", "los", "refused"):
                conn.ended = True
            ann.events.append({**base, "event": event, "reason": ann.text})
        return ann


def bad_frame(exc: DecodeError) -> Annotation:
    """The annotation of a frame that did not decode (it belongs to no connection: ``conn`` 0)."""
    return Annotation(0, "bad-frame", decode_error=decode_error_dict(exc))


def view_json(
    ann: Annotation, link: int, direction: Direction, seq: int, packet: Packet | None, nbytes: int
) -> dict[str, Any]:
    """The ``/manip/c2s|s2c`` message of one frame (``manip.Packet`` schema)."""
    out: dict[str, Any] = {"link": link, "conn": ann.conn, "direction": direction, "seq": seq}
    if packet is not None:
        out["opcode"] = packet.opcode
        out["opcode_name"] = SPEC.chaos_opcode_name(packet.opcode)
        out["src_host"] = packet.src_host
        out["src_index"] = packet.src_index
        out["dest_host"] = packet.dest_host
        out["dest_index"] = packet.dest_index
        out["packet_no"] = packet.packet_no
        out["ack_no"] = packet.ack_no
    out["nbytes"] = nbytes
    out["kind"] = ann.kind
    if ann.retransmission:
        out["retransmission"] = True
    if ann.op is not None:
        out["op"] = ann.op
    if ann.request_number is not None:
        out["request_number"] = ann.request_number
    if ann.pair is not None:
        out["pair"] = ann.pair
    if ann.final is not None:
        out["final"] = ann.final
    if ann.fields:
        out["fields"] = ann.fields
    if ann.text is not None:
        out["text"] = ann.text
    if ann.error is not None:
        out["error"] = ann.error
    if ann.async_ is not None:
        out["async"] = ann.async_
    if ann.payload_hex is not None:
        out["payload_hex"] = ann.payload_hex
    if ann.decode_error is not None:
        out["decode_error"] = ann.decode_error
    return out


# ---------------------------------------------------------------------------------------- view bytes

_JSON: Final = json.JSONEncoder(separators=(",", ":"), check_circular=False)
_encode = _JSON.encode
_HEADER: Final = (
    '{"link":%d,"conn":%d,"direction":"%s","seq":%d,"opcode":%d,"opcode_name":"%s","src_host":%d,'
    '"src_index":%d,"dest_host":%d,"dest_index":%d,"packet_no":%d,"ack_no":%d,"nbytes":%d,"kind":%s'
)
_NO_PACKET: Final = '{"link":%d,"conn":%d,"direction":"%s","seq":%d,"nbytes":%d,"kind":%s'
_OPCODE_NAMES: Final = SPEC.chaos_opcode_names
_FLOAT: Final = "%.9g"
"""How the view spells the floats of ``fields``: nine significant digits.  Every field float was a PDP-11
single on the wire (a 24-bit significand, no subnormals), and nine digits name each one exactly (parsing
them and rounding to 24 bits gives it back); ``repr`` would spell the double out to 17 digits, at three
times the cost, with digits that carry nothing.  A whole number keeps a point (``125.0``), as ``repr``."""
_float_lists: dict[int, str] = {}
"""``%.9g,%.9g,...`` per tuple length, so a tuple of floats is one ``%`` operation."""
_JUST_FLOATS: Final = {float}
_TAIL_KEYS: Final = (',"text":', ',"error":', ',"async":', ',"payload_hex":', ',"decode_error":')
_tail: Final = attrgetter("text", "error", "async_", "payload_hex", "decode_error")
"""The last, rarer entries of the view, in its order, and where the annotation keeps them."""
_quoted: dict[str, str] = {}
"""JSON of the short strings that recur (kinds, op and field names), made once each."""


def _quote(text: str) -> str:
    out = _quoted.get(text)
    if out is None:
        out = _encode(text)
        if len(_quoted) < 4096:  # op and field names come from the spec; a bound all the same
            _quoted[text] = out
    return out


def field_json(value: Any) -> str:
    """JSON of one decoded field value: ints and strings as JSON has them, floats as :data:`_FLOAT` (NaN
    and infinities as Python's json spells them), tuples and lists as arrays."""
    kind = type(value)
    if kind is tuple and set(map(type, value)) == _JUST_FLOATS:
        form = _float_lists.get(len(value))
        if form is None:
            form = _float_lists[len(value)] = ",".join([_FLOAT] * len(value))
        text: str = form % value
        if "n" not in text:  # no nan, no inf
            if text.count(".") != len(value):  # a whole number: keep it a float
                text = ",".join(map(_pointed, text.split(",")))
            return "[" + text + "]"
    if kind is tuple or kind is list:
        return "[" + ",".join(map(field_json, value)) + "]"
    if kind is float and value - value == 0.0:  # finite
        return _pointed(_FLOAT % value)
    return _encode(value)


def _pointed(number: str) -> str:
    """``125`` as ``125.0``, so a JSON reader reads back a float (and ``-0.0`` keeps its sign)."""
    return number if "." in number or "e" in number else number + ".0"


def view_bytes(
    ann: Annotation, link: int, direction: Direction, seq: int, packet: Packet | None, nbytes: int
) -> bytes:
    """The encoded ``/manip/c2s|s2c`` message of one frame: exactly the compact JSON of
    :func:`view_json` (same keys and order; Python's spelling, except the floats of ``fields``, which
    :func:`field_json` spells), written without building the dict.  The recorder calls it for every
    frame; a test holds it to :func:`view_json`."""
    quoted = _quoted
    kind = ann.kind
    qkind = quoted.get(kind) or _quote(kind)
    if packet is not None:
        opcode = packet.opcode
        out = _HEADER % (
            link,
            ann.conn,
            direction,
            seq,
            opcode,
            _OPCODE_NAMES[opcode],
            packet.src_host,
            packet.src_index,
            packet.dest_host,
            packet.dest_index,
            packet.packet_no,
            packet.ack_no,
            nbytes,
            qkind,
        )
    else:
        out = _NO_PACKET % (link, ann.conn, direction, seq, nbytes, qkind)
    if ann.retransmission:
        out += ',"retransmission":true'
    op = ann.op
    if op is not None:
        out += ',"op":' + (quoted.get(op) or _quote(op))
    if ann.request_number is not None:
        out += f',"request_number":{ann.request_number}'
    if ann.pair is not None:
        out += f',"pair":{ann.pair}'
    if ann.final is not None:
        out += ',"final":true' if ann.final else ',"final":false'
    fields = ann.fields
    if fields:
        sep = ',"fields":{'
        for name, value in fields.items():
            out += sep + (quoted.get(name) or _quote(name))
            if type(value) is int:
                out += f":{value}"
            else:
                out += ":" + field_json(value)
            sep = ","
        out += "}"
    if ann.text is not None or ann.error is not None or ann.async_ is not None or ann.payload_hex is not None:
        for key, value in zip(_TAIL_KEYS, _tail(ann), strict=True):
            if value is not None:
                out += key + _encode(value)
    elif ann.decode_error is not None:
        out += ',"decode_error":' + _encode(ann.decode_error)
    return (out + "}").encode()
