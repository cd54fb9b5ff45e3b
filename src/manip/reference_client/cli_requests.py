"""Requests typed at ``manip-client`` by opcode: ``raw OPCODE HEX`` and the wrist opcodes (0240-0253).

The spec's request layouts give the wrist commands their arguments, metavars and help, so nothing here
re-types the 1985 guide's tables.  Arguments are checked as the library checks them (the count each
field takes, word and int16 ranges, PDP-11 float range; for ``raw``, the data length and floats of a
known opcode) unless ``--no-check`` asks to send what was typed: then values are encoded by position
(words wrapped to 16 bits, values beyond the layout as words or floats as they are written), so a
server author can see what a server does with a malformed request.

Whatever comes back is shown decoded by the opcode's reply layout where the spec has one, and as hex
besides; a reply that does not decode is shown with what is wrong with it instead of failing.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import decode_reply, decode_request, encode_request
from manip.codecs.packet import MAX_DATA
from manip.codecs.pdp11float import pack_f
from manip.reference_client.request import Request, RequestCode, ResponseType
from manip.spec import SPEC, RequestOpcode
from manip.spec.notation import octal

__all__ = [
    "RAW_CHECKED",
    "RAW_UNCHECKED",
    "WRIST_OPCODES",
    "RawReply",
    "check_raw_data",
    "encode_arguments",
    "extract_raw",
    "parse_hex",
    "parse_opcode",
    "raw_code",
    "reply_record",
    "reply_text",
    "wrist_help",
    "wrist_metavar",
]

WRIST_OPCODES: Final = tuple(op for op in SPEC.requests.values() if 0o240 <= op.opcode <= 0o253)
RAW_CHECKED: Final = (0o200, 0o277)
"""The request opcodes of the Chaos manipulator protocol (E.1 and the Puma's extensions)."""
RAW_UNCHECKED: Final = (0o200, 0o377)
"""Every Chaos data opcode: with ``--no-check``, also the ones no request uses."""

_WORD_MAX: Final = 0xFFFF
_HEX_JUNK: Final = re.compile(r"[\s:,]|0x", re.IGNORECASE)
_WHOLE: Final = re.compile(r"[+-]?(0x[0-9a-fA-F]+|\d+)")
_ELEMENT_WORDS: Final = {"word": "word", "int16": "signed word", "float": "float", "small": "byte"}


# ------------------------------------------------------------------ reading what was typed


def parse_opcode(text: str, *, no_check: bool) -> int:
    """An opcode in octal (``0240`` or ``240``), within :data:`RAW_CHECKED` (:data:`RAW_UNCHECKED` with
    ``no_check``)."""
    if not text or set(text) - set("01234567"):
        raise ValueError(f"opcode {text!r} is not an octal number (0200-0277, as the 1985 guide writes them)")
    opcode = int(text, 8)
    low, high = RAW_UNCHECKED if no_check else RAW_CHECKED
    if not low <= opcode <= high:
        hint = "" if no_check else " (--no-check sends any data opcode, 0200-0377)"
        raise ValueError(f"opcode {octal(opcode)} is outside {octal(low)}-{octal(high)}{hint}")
    return opcode


def parse_hex(parts: Sequence[str]) -> bytes:
    """Data bytes in wire order from hex (``"3f 80"``, ``3f80``, ``0x3f,0x80``); nothing is no data."""
    digits = _HEX_JUNK.sub("", "".join(parts))
    try:
        data = bytes.fromhex(digits)
    except ValueError:
        raise ValueError(f"data {' '.join(parts)!r} is not hexadecimal bytes (two digits a byte)") from None
    if len(data) > MAX_DATA:  # not even --no-check can send it: no packet holds it
        raise ValueError(f"data is {len(data)} bytes; a Chaos packet holds at most {MAX_DATA}")
    return data


def check_raw_data(opcode: int, data: bytes) -> None:
    """Refuse data a spec opcode cannot carry (its length, a reserved-operand float); an opcode the spec
    does not define is left to the server (refusing it is its job)."""
    if opcode not in SPEC.requests:
        return
    try:
        decode_request(opcode, data)
    except CodecError as exc:
        op = SPEC.requests[opcode]
        raise ValueError(f"{octal(opcode)} {op.name}: {exc.message} (--no-check sends it anyway)") from None


def _integer(token: str) -> int:
    """A whole number as people write them here: ``0x1f`` hex, a leading 0 octal (``0100005``), else
    decimal; a sign is allowed."""
    sign, digits = (-1, token[1:]) if token.startswith("-") else (1, token.lstrip("+"))
    if digits[:2].lower() == "0x":
        return sign * int(digits[2:], 16)
    if len(digits) > 1 and digits.startswith("0"):
        return sign * int(digits, 8)
    return sign * int(digits, 10)


def _number(token: str, element: str) -> int | float:
    try:
        value = float(token) if element == "float" else _integer(token)
    except ValueError:
        kind = _ELEMENT_WORDS.get(element, element)
        raise ValueError(f"{token!r} is not a {kind}") from None
    if not math.isfinite(value):
        raise ValueError(f"{token!r} is not a finite number")
    return value


def _elements(op: RequestOpcode) -> list[tuple[str, str]]:
    """(argument name, element type) of each value the request takes, in order."""
    out: list[tuple[str, str]] = []
    for f in op.request.fields:
        count = f.type.count or 1
        name = f.name.upper()
        out += [(name if count == 1 else f"{name}{i + 1}", f.type.element) for i in range(count)]
    return out


def encode_arguments(op: RequestOpcode, tokens: Sequence[str], *, no_check: bool) -> bytes:
    """The data of ``op`` from the values typed; checked by the spec's layout unless ``no_check``."""
    if no_check:
        return _encode_unchecked(op, tokens)
    elements = _elements(op)
    if len(tokens) != len(elements):
        raise ValueError(
            f"{op.name} takes {len(elements)} value(s) ({wrist_metavar(op) or 'none'}), not {len(tokens)} "
            "(--no-check sends them anyway)"
        )
    values = iter(_number(token, element) for token, (_, element) in zip(tokens, elements, strict=True))
    fields: dict[str, Any] = {}
    for f in op.request.fields:
        count = f.type.count or 1
        taken = [next(values) for _ in range(count)]
        fields[f.name] = taken[0] if count == 1 else tuple(taken)
    try:
        return encode_request(op.opcode, **fields)
    except CodecError as exc:
        raise ValueError(f"{exc.message} (--no-check sends it anyway)") from None


def _encode_unchecked(op: RequestOpcode, tokens: Sequence[str]) -> bytes:
    elements = [element for _, element in _elements(op)]
    out = bytearray()
    for i, token in enumerate(tokens):
        # Beyond the layout a value is encoded as it is written: a whole number as a word.
        beyond = "word" if _WHOLE.fullmatch(token) else "float"
        element = elements[i] if i < len(elements) else beyond
        value = _number(token, element)
        if isinstance(value, float):
            try:
                out += pack_f(value)
            except CodecError as exc:
                raise ValueError(f"{token}: {exc.message} (no PDP-11 float has that value)") from None
        else:
            out += struct.pack("<H", value & _WORD_MAX)
    return bytes(out)


# ------------------------------------------------------------------ help from the spec


def wrist_metavar(op: RequestOpcode) -> str:
    names = []
    for f in op.request.fields:
        count = f.type.count or 1
        name = f.name.upper()
        names.append(name if count == 1 else f"{name}1 .. {name}{count}" if count > 3 else
                     " ".join(f"{name}{i + 1}" for i in range(count)))  # fmt: skip
    return " ".join(names)


def wrist_help(op: RequestOpcode) -> str:
    """The command's help: the spec's title, opcode, summary and section, and what each field is."""
    lines = [f"{op.title} ({octal(op.opcode)}): {op.summary}", ""]
    lines.append(f"\b\nSpec: {op.section}; hazard: {op.hazard}.")
    if op.request.fields:
        lines.append("Arguments:")
        for f in op.request.fields:
            count = f.type.count or 1
            kind = _ELEMENT_WORDS.get(f.type.element, f.type.element)
            lines.append(f"  {f.name.upper():<11} {count} {kind}{'s' if count > 1 else ''} ({f.type.name})")
    reply = op.response.data.fields if op.response.form == "data" else ()
    answer = {"done": "done", "segment": "a segment number", "multi": "text"}.get(op.response.form)
    lines.append(f"Reply: {answer or ', '.join(f'{f.name} ({f.type.name})' for f in reply)}.")
    lines.append("")
    lines.append("Numbers: floats as usual; words in decimal, 0x hex or 0-prefixed octal.")
    return "\n".join(lines)


# ------------------------------------------------------------------ the reply


@dataclass(frozen=True)
class RawReply:
    """What came back for a request sent by opcode."""

    opcode: int
    op: RequestOpcode | None
    request_number: int | None
    payloads: tuple[bytes, ...]
    values: Mapping[str, Any] | None = None
    """The reply decoded by the spec's layout (None: not a spec opcode, or it did not decode)."""
    problem: str | None = None
    """Why the reply did not decode by the spec's layout."""


def raw_code(opcode: int, data: bytes) -> tuple[RequestCode, ResponseType]:
    """A request code for ``opcode`` (its spec entry when there is one) and how many packets answer it."""
    op = SPEC.requests.get(opcode)
    multi = op is not None and op.response.form == "multi"
    name = op.name if op is not None else f"opcode-{octal(opcode)}"
    response = ResponseType.MULTI if multi else ResponseType.SINGLE
    return RequestCode(name, opcode, None, None, response, op), response


def extract_raw(request: Request[Any], payloads: Sequence[bytes]) -> RawReply:
    """The data extractor of a request sent by opcode: keeps the bytes and decodes what it can."""
    op = request.code.spec
    number = request.packet_number
    base = RawReply(request.opcode, op, number, tuple(payloads))
    if op is None:
        return base
    try:
        if op.response.form == "multi":
            return RawReply(**{**base.__dict__, "values": {"text": decode_lispm(b"".join(payloads))}})
        if len(payloads) != 1:
            raise ValueError(f"{len(payloads)} packets answered a single-packet request")
        reply = decode_reply(struct.pack("<H", (number or 0) & _WORD_MAX) + payloads[0], op)
    except (CodecError, ValueError) as exc:
        return RawReply(**{**base.__dict__, "problem": str(exc)})
    return RawReply(**{**base.__dict__, "values": dict(reply.values)})


def _shown(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple | list):
        return " ".join(_shown(v) for v in value)
    return str(value)


def reply_text(reply: RawReply) -> list[str]:
    name = reply.op.name if reply.op is not None else "not a spec opcode"
    data = b"".join(reply.payloads)
    what = "done" if not data and reply.values == {} else f"{len(data)} data bytes"
    lines = [f"{octal(reply.opcode)} {name}: reply to request {reply.request_number}, {what}"]
    for key, value in (reply.values or {}).items():
        lines.append(f"  {key}: {_shown(value)}")
    if reply.problem is not None:
        lines.append(f"  does not decode: {reply.problem}")
    if data:
        lines.append(f"  data: {data.hex(' ')}")
    return lines


def _json_value(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_json_value(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, int | float | str | bool) or value is None:
        return value
    return str(value)


def reply_record(reply: RawReply) -> dict[str, Any]:
    return {
        "opcode": octal(reply.opcode),
        "name": reply.op.name if reply.op is not None else None,
        "request_number": reply.request_number,
        "data": b"".join(reply.payloads).hex(),
        "values": _json_value(reply.values),
        "problem": reply.problem,
    }
