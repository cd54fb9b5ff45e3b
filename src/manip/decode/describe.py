"""Turn a packet into a labelled tree: the Chaos header, then what the data mean in the manip protocol.

Pure code with no I/O; :mod:`manip.decode.render` prints the tree as text, JSON or an annotated hex
dump.  Offsets of data fields count from the start of the Chaos data in natural byte order.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from manip.codecs.cougar import CougarMsg, Malformed, OutOfSync, StreamItem
from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import (
    AsyncResponse,
    ErrorReply,
    Reply,
    ServerMessage,
    decode_request,
    decode_server_packet,
    request_op,
    response_layout,
)
from manip.codecs.packet import Packet
from manip.spec import SPEC, Layout, RequestOpcode
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.notation import octal

ReadAs = Literal["auto", "request", "response"]
"""How to read a manip packet's data (``manip-decode --direction``): guessed, as a request, as a reply."""


@dataclass(slots=True)
class TreeNode:
    """One labelled item of a decoded packet."""

    label: str
    text: str = ""
    value: Any = None
    offset: int | None = None
    size: int | None = None
    children: list[TreeNode] = field(default_factory=list)

    def add(
        self,
        label: str,
        text: str = "",
        value: Any = None,
        offset: int | None = None,
        size: int | None = None,
    ) -> TreeNode:
        child = TreeNode(label, text, value, offset, size, [])
        self.children.append(child)
        return child

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"label": self.label}
        if self.text:
            out["text"] = self.text
        if self.value is not None:
            out["value"] = self.value
        if self.offset is not None:
            out["offset"] = self.offset
            out["size"] = self.size
        if self.children:
            out["children"] = [c.to_json() for c in self.children]
        return out


def describe_header(p: Packet) -> TreeNode:
    node = TreeNode("chaos header", offset=0, size=16)
    node.add("opcode", f"{octal(p.opcode)} {SPEC.chaos_opcode_name(p.opcode)}", p.opcode, 1, 1)
    node.add("fc", str(p.fc), p.fc, 2, 2)
    node.add("nbytes", str(p.nbytes), p.nbytes, 2, 2)
    node.add(
        "destination",
        f"host {octal(p.dest_host)} index {octal(p.dest_index)}",
        {"host": p.dest_host, "index": p.dest_index},
        4,
        4,
    )
    node.add(
        "source",
        f"host {octal(p.src_host)} index {octal(p.src_index)}",
        {"host": p.src_host, "index": p.src_index},
        8,
        4,
    )
    node.add("packet number", str(p.packet_no), p.packet_no, 12, 2)
    node.add("ack number", str(p.ack_no), p.ack_no, 14, 2)
    if p.trailer is not None:
        t = p.trailer
        node.add(
            "trailer",
            f"hw dest {octal(t.dest)} hw source {octal(t.source)} checksum {t.checksum:#06x}",
            {"dest": t.dest, "source": t.source, "checksum": t.checksum},
        )
    return node


# manip-decode --format json writes a packet a line, and the Chaos header is more than half of each line:
# built as a TreeNode tree and run through the JSON encoder it cost half the decoder's time.  header_json
# writes the same bytes straight from the packet (a test checks them against the tree for many packets);
# its strings are digits and opcode names, which need no escaping.

_ENCODE = json.JSONEncoder(separators=(",", ":")).encode
"""The compact encoder manip-decode writes JSON with."""


def header_json(p: Packet) -> str:
    """``describe_header(p).to_json()`` as compact JSON, without building either."""
    op, dh, di, sh, si = int(p.opcode), int(p.dest_host), int(p.dest_index), int(p.src_host), int(p.src_index)
    fc, nbytes, pn, an = int(p.fc), int(p.nbytes), int(p.packet_no), int(p.ack_no)
    out = (
        '{"label":"chaos header","offset":0,"size":16,"children":['
        f'{{"label":"opcode","text":"{octal(op)} {SPEC.chaos_opcode_name(op)}",'
        f'"value":{op},"offset":1,"size":1}},'
        f'{{"label":"fc","text":"{fc}","value":{fc},"offset":2,"size":2}},'
        f'{{"label":"nbytes","text":"{nbytes}","value":{nbytes},"offset":2,"size":2}},'
        f'{{"label":"destination","text":"host {octal(dh)} index {octal(di)}",'
        f'"value":{{"host":{dh},"index":{di}}},"offset":4,"size":4}},'
        f'{{"label":"source","text":"host {octal(sh)} index {octal(si)}",'
        f'"value":{{"host":{sh},"index":{si}}},"offset":8,"size":4}},'
        f'{{"label":"packet number","text":"{pn}","value":{pn},"offset":12,"size":2}},'
        f'{{"label":"ack number","text":"{an}","value":{an},"offset":14,"size":2}}'
    )
    t = p.trailer
    if t is not None:
        td, ts, tc = int(t.dest), int(t.source), int(t.checksum)
        out += (
            f',{{"label":"trailer","text":"hw dest {octal(td)} hw source {octal(ts)} checksum {tc:#06x}",'
            f'"value":{{"dest":{td},"source":{ts},"checksum":{tc}}}}}'
        )
    return out + "]}"


def packet_json(root: TreeNode, p: Packet) -> str:
    """The compact JSON of ``describe_packet(p, header=False)`` (``root``, maybe with nodes added since)
    as if it had been made with the header: the header from :func:`header_json`, the rest encoded."""
    if root.label != "packet" or not root.text or root.value is not None or root.offset is not None:
        return _ENCODE(TreeNode(root.label, root.text, root.value, root.offset, root.size,
                            [describe_header(p), *root.children]).to_json())  # fmt: skip
    parts = ['{"label":"packet","text":', _ENCODE(root.text), ',"children":[', header_json(p)]
    for child in root.children:
        parts.append(",")
        parts.append(_ENCODE(child.to_json()))
    parts.append("]}")
    return "".join(parts)


def _format_value(v: Any) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, tuple):
        return "(" + ", ".join(_format_value(x) for x in v) + ")"
    if isinstance(v, str):
        return repr(v)
    return str(v)


def _fields(node: TreeNode, layout: Layout, values: dict[str, Any] | Any, start: int) -> None:
    offset: int | None = start
    for f in layout.fields:
        size = f.type.fixed_size
        v = values.get(f.name)
        text = _format_value(v)
        if f.type.name == "transform" and isinstance(v, tuple):
            cols = ["N", "O", "A", "P"]
            text = "  ".join(
                f"{c}=({v[3 * i]:.6g}, {v[3 * i + 1]:.6g}, {v[3 * i + 2]:.6g})" for i, c in enumerate(cols)
            )
        node.add(f.name, text, list(v) if isinstance(v, tuple) else v, offset, size)
        offset = None if size is None or offset is None else offset + size


def describe_request(p: Packet) -> TreeNode:
    request = decode_request(p.opcode, p.data)
    op = request.op
    node = TreeNode(
        "manip request", f"{octal(op.opcode)} {op.name}: {op.title}", {"opcode": op.opcode, "name": op.name}
    )
    node.add("hazard", op.hazard, op.hazard)
    if op.extension:
        node.add("defined by", "manip (Puma extension opcode)")
    _fields(node, op.request, dict(request.values), 0)
    return node


def _describe_reply(reply: Reply, op: RequestOpcode | None) -> TreeNode:
    node = TreeNode(
        "manip response",
        f"0200 response to request {reply.request_number}",
        {"opcode": ServerOp.RESPONSE, "request_number": reply.request_number},
    )
    node.add("request number", str(reply.request_number), reply.request_number, 0, 2)
    if op is None:
        if reply.payload:
            node.add("data", reply.payload.hex(" "), reply.payload.hex(), 2, len(reply.payload))
            node.add("note", "pass --request-opcode to decode the data by the request's layout")
        else:
            node.add("data", "none (a done reply, or the end of a multi-packet reply)")
        return node
    node.text += f" ({op.name}, {op.response.form} reply)"
    if op.response.form == "multi" and reply.is_empty:
        node.add("end", "empty packet: end of the multi-packet reply")
    elif op.response.form == "multi":
        text = decode_lispm(reply.payload)
        node.add("text", repr(text), text, 2, len(reply.payload))
    else:
        _fields(node, response_layout(op), dict(reply.values), 2)
    return node


def _describe_error(err: ErrorReply) -> TreeNode:
    name = ServerOp(err.opcode).name.lower().replace("_", "-")
    e = err.error
    node = TreeNode(
        "manip error",
        f"{octal(err.opcode)} {name}: {e.render()}",
        {"opcode": err.opcode, "request_number": err.request_number},
    )
    node.add("request number", str(err.request_number), err.request_number, 0, 2)
    node.add("where", e.where, e.where)
    sev = SPEC.severities.get(e.severity)
    node.add("severity", f"{e.severity} ({sev.meaning if sev else 'unknown severity'})", e.severity)
    code = SPEC.error_codes.get(e.code)
    meaning = code.meaning if code else "a code of this server's own"
    node.add("code", f"{e.code} ({meaning})", e.code)
    node.add("message", repr(e.message), e.message)
    if e.args:
        node.add("arguments", ", ".join(str(a) for a in e.args), list(e.args))
    node.add("rendered", e.render(), e.render())
    for problem in e.problems:
        node.add("problem", problem, problem)
    return node


def _describe_async(a: AsyncResponse) -> TreeNode:
    """Either layout (erratum ``async-request-number``): the 1985 guide's has no request-number word,
    so its fields start two bytes earlier."""
    node = TreeNode(
        "manip asynchronous response",
        f"0203 {a.condition_name}" + (" (the 1985 guide's layout)" if a.request_number is None else ""),
        {"opcode": ServerOp.ASYNCHRONOUS_RESPONSE, "condition": a.condition, "layout": a.layout},
    )
    at = 0
    if a.request_number is not None:
        node.add("request number", str(a.request_number), a.request_number, 0, 2)
        at = 2
    node.add("condition", f"{a.condition} {a.condition_name}", a.condition, at, 2)
    if a.condition == 1:
        node.add(
            "action",
            {1: "1 stop trajectory", 2: "2 continue"}.get(a.word2, f"{a.word2} (undefined)"),
            a.word2,
            at + 2,
            2,
        )
        node.add("guard", str(a.word3), a.word3, at + 4, 2)
    else:
        node.add("reserved", str(a.word2), a.word2, at + 2, 2)
        node.add("segment" if a.condition == 2 else "word 3", str(a.word3), a.word3, at + 4, 2)
    return node


def describe_server_message(msg: ServerMessage, op: RequestOpcode | None = None) -> TreeNode:
    if isinstance(msg, Reply):
        return _describe_reply(msg, op)
    if isinstance(msg, ErrorReply):
        return _describe_error(msg)
    return _describe_async(msg)


def guess_direction(p: Packet) -> Literal["request", "response"]:
    """Requests and server packets share opcodes 0200-0205; the data usually tell them apart."""
    if p.opcode > 0o205 or not p.data:
        return "request"
    if p.opcode in (ServerOp.RESPONSE, ServerOp.ASYNCHRONOUS_RESPONSE):
        return "response"
    try:
        decode_server_packet(p.opcode, p.data)
    except CodecError:
        return "request"
    return "response"


def describe_control(p: Packet) -> TreeNode | None:
    """The meaning of the data of Chaos control packets."""
    match p.opcode:
        case ChaosOp.RFC:
            text = p.data.decode("ascii", "replace")
            contact, _, args = text.partition(" ")
            node = TreeNode("rfc", f"contact {contact!r}" + (f" args {args!r}" if args else ""))
            node.add("contact", contact, contact, 0, len(contact))
            if args:
                node.add("arguments", args, args, len(contact) + 1, len(args))
            return node
        case ChaosOp.OPN | ChaosOp.STS if len(p.data) >= 4:
            receipt, window = struct.unpack_from("<HH", p.data)
            node = TreeNode(SPEC.chaos_opcode_name(p.opcode).lower(), f"receipt {receipt} window {window}")
            node.add("receipt", str(receipt), receipt, 0, 2)
            node.add("window", str(window), window, 2, 2)
            return node
        case ChaosOp.CLS | ChaosOp.LOS | ChaosOp.ANS | ChaosOp.FWD:
            text = decode_lispm(p.data)
            node = TreeNode(SPEC.chaos_opcode_name(p.opcode).lower(), repr(text), text)
            if p.opcode == ChaosOp.FWD:
                node.add("new host", octal(p.ack_no), p.ack_no)
            return node
    return None


def describe_packet(
    p: Packet, *, direction: ReadAs = "auto", request: int | str | None = None, header: bool = True
) -> TreeNode:
    """The whole tree for one packet; decode problems become a ``decode error`` node (never raised).

    ``header=False`` leaves out the Chaos header node, for :func:`packet_json` to write it."""
    root = TreeNode("packet", f"{SPEC.chaos_opcode_name(p.opcode)} {octal(p.opcode)}, {p.nbytes} data bytes")
    if header:
        root.children.append(describe_header(p))
    control = describe_control(p)
    if control is not None:
        root.children.append(control)
        return root
    if not 0o200 <= p.opcode <= 0o277:
        if p.data:
            root.add("data", p.data.hex(" "), p.data.hex(), 0, len(p.data))
        return root
    side = guess_direction(p) if direction == "auto" else direction
    op = request_op(request) if request is not None else None
    try:
        if side == "request":
            node = describe_request(p)
        else:
            node = describe_server_message(decode_server_packet(p.opcode, p.data, op), op)
    except CodecError as exc:
        node = TreeNode(
            "decode error",
            str(exc),
            {"message": exc.message, "path": exc.path, "offset": exc.offset, "clause": exc.clause},
        )
    if direction == "auto":
        node.add("direction", f"{side} (guessed from opcode and length; --direction to choose)")
    root.children.append(node)
    return root


def describe_words(items: Sequence[StreamItem], direction: str) -> TreeNode:
    """A Cougar word stream, message by message."""
    root = TreeNode(f"cougar {direction} stream", f"{len(items)} item(s)")
    for item in items:
        if isinstance(item, CougarMsg):
            node = root.add(item.name, f"code {item.code}: {item.spec.remarks}", {"code": item.code})
            for name, v in item.values.items():
                node.add(name, _format_value(v), list(v) if isinstance(v, tuple) else v)
        elif isinstance(item, OutOfSync):
            root.add(
                "out of sync",
                f"unknown code {item.code}; buffer of {len(item.discarded)} word(s) dumped",
                {"code": item.code, "discarded": list(item.discarded)},
            )
        elif isinstance(item, Malformed):
            root.add("malformed", str(item.error), {"words": list(item.words)})
    return root


def describe_body(side: Literal["request", "response"], key: int | str, data: bytes) -> TreeNode:
    """A bare body, the data of one packet without its Chaos header (the form the golden vectors use).

    For a request ``key`` is its opcode (number or name).  For a response it is the request answered
    (a RESPONSE, 0200, decoded by that request's layout) or the name of another server opcode
    (``fatal-error``, ``non-fatal-error``, ``asynchronous-response``, ``asynchronous-error``,
    ``asynchronous-warning``).  Decode problems become a ``decode error`` node, as in a packet.
    """
    root = TreeNode("body", f"{side} body, {len(data)} bytes")
    try:
        if side == "request":
            op = request_op(key)
            node = describe_request(Packet(op.opcode, data=data))
        else:
            server = _SERVER_NAMES.get(key) if isinstance(key, str) else None
            if server is not None:
                node = describe_server_message(decode_server_packet(server, data))
            else:
                op = request_op(key)
                node = describe_server_message(decode_server_packet(ServerOp.RESPONSE, data, op), op)
    except CodecError as exc:
        node = TreeNode(
            "decode error",
            str(exc),
            {"message": exc.message, "path": exc.path, "offset": exc.offset, "clause": exc.clause},
        )
    root.children.append(node)
    return root


_SERVER_NAMES: dict[str, int] = {s.name: s.opcode for s in SPEC.server_opcodes.values() if s.opcode != 0o200}
"""Server opcodes by name, apart from RESPONSE (named by the request it answers)."""
