"""Manip request and response bodies, built from the spec's layouts.

Nothing about an individual opcode is written here: each request and response layout in
``manip/spec/data/manip.toml`` becomes a construct ``Struct`` (compiled for speed) when first used.  This
module adds what construct cannot say well: exact length checks with byte offsets, the ``small`` field
that may arrive as one byte or one word, and errors that name the clause they break.

Wire conventions (see the errata): words are little-endian, floats are PDP-11 F floats, and every packet
the server sends begins with a request-number word.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal

from construct import (
    Array,
    Construct,
    ConstructError,
    GreedyBytes,
    Int16sl,
    Int16ul,
    PrefixedArray,
    Struct,
    Terminated,
)

from manip.codecs.error_string import ErrorMessage, parse_error
from manip.codecs.errors import CodecError, DecodeError, EncodeError
from manip.codecs.fastpath import FastLayout, plan
from manip.codecs.lispm_text import decode_lispm, encode_lispm
from manip.codecs.pdp11float import Float32F, f_to_u32, u32_to_f
from manip.spec import SPEC, Field, FieldType, Layout, RequestOpcode
from manip.spec.constants import AsyncCondition, ServerOp

Value = float | int | str | tuple[float, ...] | tuple[int, ...]
"""A decoded field: a scalar for count 1, a tuple otherwise, str for text."""

REQUEST_NUMBER_BYTES: Final = 2
MAX_TEXT_PER_PACKET: Final = 488 - REQUEST_NUMBER_BYTES

_WORD = struct.Struct("<H")


# ----------------------------------------------------------------------------------------- layouts


def _element(ft: FieldType) -> Construct:
    match ft.element:
        case "float":
            base: Construct = Float32F
        case "word" | "small":
            base = Int16ul
        case "int16":
            base = Int16sl
        case "counted":
            return PrefixedArray(Int16ul, Int16ul)
        case "text":
            return GreedyBytes
    return base if ft.count == 1 else Array(ft.count, base)


@dataclass(frozen=True)
class _Codec:
    """The construct form of one layout, with and without a leading request number."""

    layout: Layout
    struct: Any
    with_number: Any
    fast: FastLayout | None
    fast_numbered: FastLayout | None

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.layout.fields)


_CODECS: dict[int, tuple[Layout, _Codec]] = {}


def _codec(layout: Layout) -> _Codec:
    """The codec of a layout, built once; keyed by identity (spec layouts live as long as the process)."""
    entry = _CODECS.get(id(layout))
    if entry is not None and entry[0] is layout:
        return entry[1]
    codec = _make_codec(layout)
    _CODECS[id(layout)] = (layout, codec)
    return codec


def _make_codec(layout: Layout) -> _Codec:
    fields = [f.name / _element(f.type) for f in layout.fields]
    plain = Struct(*fields, Terminated)
    numbered = Struct("request_number" / Int16ul, *fields, Terminated)
    return _Codec(
        layout,
        plain.compile(),
        numbered.compile(),
        plan(layout, numbered=False),
        plan(layout, numbered=True),
    )


def _has_small(layout: Layout) -> bool:
    return any(f.type.element == "small" for f in layout.fields)


def _check_length(layout: Layout, data: bytes, start: int, what: str, clause: str) -> bytes:
    """Check ``data[start:]`` against a layout's size; return data with a one-byte ``small`` widened."""
    body = len(data) - start
    size = layout.fixed_size
    if size is not None:
        if _has_small(layout) and body == size - 1:
            return data + b"\0"
        if body != size:
            raise DecodeError(
                f"{what} needs {size} data bytes after offset {start}, got {body}",
                path=what,
                offset=min(len(data), start + size),
                clause=clause,
            )
        return data
    # Variable layouts: counted words check their own count; text takes the rest.
    for f in layout.fields:
        if f.type.element == "counted":
            if body < 2:
                raise DecodeError(f"{what}.{f.name}: missing word count", what, start + body, clause)
            (n,) = _WORD.unpack_from(data, start)
            if body != 2 + 2 * n:
                raise DecodeError(
                    f"{what}.{f.name}: count says {n} words ({2 + 2 * n} bytes), {body} bytes present",
                    path=f"{what}.{f.name}",
                    offset=start,
                    clause=clause,
                )
    return data


def _float_fault(layout: Layout, data: bytes, start: int, what: str, exc: Exception) -> CodecError:
    """Locate the float that made a parse fail, for an error that points at its byte offset."""
    offset = start
    for f in layout.fields:
        ft = f.type
        if ft.element == "float" and ft.count is not None:
            for i in range(ft.count):
                (u,) = struct.unpack_from("<I", data, offset + 4 * i)
                try:
                    u32_to_f(u)
                except CodecError as inner:
                    index = f"[{i}]" if ft.count > 1 else ""
                    return DecodeError(inner.message, f"{what}.{f.name}{index}", offset + 4 * i, inner.clause)
        size = ft.fixed_size
        if size is None:
            break
        offset += size
    return DecodeError(f"{what}: {exc}", path=what, offset=start)


def _parse(
    layout: Layout, data: bytes, *, numbered: bool, what: str, clause: str
) -> tuple[int | None, dict[str, Value]]:
    codec = _codec(layout)
    fast = codec.fast_numbered if numbered else codec.fast
    if fast is not None:
        result = fast.parse(data)
        if result is not None:
            return result
    start = REQUEST_NUMBER_BYTES if numbered else 0
    if len(data) < start:
        raise DecodeError(
            f"{what}: no request-number word", what, len(data), "response.echoes-request-number"
        )
    data = _check_length(layout, data, start, what, clause)
    try:
        parsed = (codec.with_number if numbered else codec.struct).parse(data)
    except CodecError as exc:
        raise _float_fault(layout, data, start, what, exc) from exc
    except ConstructError as exc:
        raise _float_fault(layout, data, start, what, exc) from exc
    values: dict[str, Value] = {}
    for f in layout.fields:
        raw = parsed[f.name]
        if f.type.element == "text":
            values[f.name] = decode_lispm(bytes(raw))
        elif isinstance(raw, list):
            values[f.name] = tuple(raw)
        else:
            values[f.name] = raw
    return (parsed["request_number"] if numbered else None), values


def _build(layout: Layout, values: Mapping[str, Any], what: str, request_number: int | None = None) -> bytes:
    known = {f.name for f in layout.fields}
    extra = set(values) - known
    if extra:
        raise EncodeError(f"{what}: unknown field(s) {sorted(extra)}; expects {sorted(known)}", path=what)
    obj: dict[str, Any] = {}
    for f in layout.fields:
        if f.name not in values:
            raise EncodeError(f"{what}: missing field {f.name!r}", path=f"{what}.{f.name}")
        v = values[f.name]
        ft = f.type
        if ft.element == "text":
            v = encode_lispm(str(v))
        elif ft.count != 1:
            v = list(v)
            if ft.count is not None and len(v) != ft.count:
                raise EncodeError(
                    f"{what}.{f.name}: needs {ft.count} values, got {len(v)}", path=f"{what}.{f.name}"
                )
        obj[f.name] = v
        _check_types(ft, v, f"{what}.{f.name}")
    codec = _codec(layout)
    try:
        if request_number is None:
            return bytes(codec.struct.build(obj))
        return bytes(codec.with_number.build({"request_number": request_number, **obj}))
    except CodecError:
        raise
    except ConstructError as exc:
        raise EncodeError(f"{what}: {exc}", path=what) from exc


def _check_types(ft: FieldType, value: Any, path: str) -> None:
    """Apply the copy-manipulator-request-data rule: the right kind of number for each field."""
    items = value if isinstance(value, list) else [value]
    for i, item in enumerate(items):
        where = f"{path}[{i}]" if isinstance(value, list) else path
        if ft.element == "float":
            if isinstance(item, bool) or not isinstance(item, float):
                raise EncodeError(
                    f"{type(item).__name__} {item!r} where a float is required",
                    path=where,
                    clause="request-data.types",
                )
        elif ft.element in ("word", "int16", "small", "counted"):
            lo, hi = (-0x8000, 0x7FFF) if ft.element == "int16" else (0, 0xFFFF)
            if isinstance(item, bool) or not isinstance(item, int):
                raise EncodeError(
                    f"{type(item).__name__} {item!r} where an integer is required",
                    path=where,
                    clause="request-data.types",
                )
            if not lo <= item <= hi:
                raise EncodeError(f"{item} outside {lo}..{hi}", path=where, clause="request-data.types")


# ----------------------------------------------------------------------------------------- requests


@dataclass(frozen=True)
class DecodedRequest:
    """A decoded request: its opcode entry in the spec and its field values."""

    op: RequestOpcode
    values: Mapping[str, Value] = field(default_factory=dict)

    @property
    def opcode(self) -> int:
        return self.op.opcode


def request_op(key: int | str) -> RequestOpcode:
    """The spec entry (a :class:`~manip.spec.RequestOpcode`) for a request opcode given by number or by
    a name known only at run time (a user's); KeyError names the unknown key.  Code that names an
    opcode itself calls ``SPEC.request("here")``, where a misspelt name is a type error."""
    op = SPEC.requests.get(key) if isinstance(key, int) else SPEC.requests_by_name.get(key)
    if op is None:
        shown = f"0{key:o}" if isinstance(key, int) else repr(key)
        raise KeyError(f"no request opcode {shown} in the spec")
    return op


def encode_request(op: int | str, **values: Any) -> bytes:
    """Data bytes of a request packet (its Chaos opcode is ``request_op(op).opcode``)."""
    spec_op = request_op(op)
    fast = _codec(spec_op.request).fast
    if fast is not None:
        data = fast.build(values)
        if data is not None:
            return data
    return _build(spec_op.request, values, spec_op.name)


def decode_request(opcode: int, data: bytes) -> DecodedRequest:
    """Decode a request's data.  Unknown opcodes raise DecodeError (clause request.unknown-opcode)."""
    try:
        spec_op = SPEC.requests[opcode]
    except KeyError:
        raise DecodeError(
            f"opcode 0{opcode:o} is not a request opcode of the spec",
            path="opcode",
            offset=0,
            clause="request.unknown-opcode",
        ) from None
    _, values = _parse(spec_op.request, data, numbered=False, what=spec_op.name, clause="request.data-length")
    return DecodedRequest(spec_op, values)


def copy_request_data(items: object) -> bytes:
    """The 1985 guide's copy-manipulator-request-data: ints as 16-bit words, floats as F floats, lists
    flattened.

    Integers may be -32768..65535 (negatives are sent in two's complement); any other type is an error.
    """
    out = bytearray()

    def put(item: object, path: str) -> None:
        if isinstance(item, bool):
            raise EncodeError(
                f"bool {item!r} is neither a fixnum nor a flonum", path, clause="request-data.types"
            )
        if isinstance(item, int):
            if not -0x8000 <= item <= 0xFFFF:
                raise EncodeError(f"{item} does not fit in 16 bits", path, clause="request-data.types")
            out.extend(_WORD.pack(item & 0xFFFF))
        elif isinstance(item, float):
            try:
                out.extend(struct.pack("<I", f_to_u32(item)))
            except CodecError as exc:
                raise exc.at(path) from exc
        elif isinstance(item, (list, tuple)):
            for i, sub in enumerate(item):
                put(sub, f"{path}[{i}]")
        else:
            raise EncodeError(
                f"{type(item).__name__} {item!r} cannot be request data", path, clause="request-data.types"
            )

    put(items, "data")
    return bytes(out)


# ----------------------------------------------------------------------------------------- responses


@dataclass(frozen=True, slots=True)
class Reply:
    """A RESPONSE (0200) packet.  ``op`` is the request it answers, when the caller knows it."""

    request_number: int
    op: RequestOpcode | None
    values: Mapping[str, Value] = field(default_factory=dict)
    payload: bytes = b""
    """The data after the request number, undecoded (always set)."""

    @property
    def is_empty(self) -> bool:
        """True for a done reply and for the terminator of a multi-packet reply."""
        return not self.payload

    @property
    def segment(self) -> int:
        """The segment number of a motion reply."""
        seg = self.values.get("segment")
        if not isinstance(seg, int):
            raise ValueError("this reply carries no segment number")
        return seg


@dataclass(frozen=True)
class ErrorReply:
    """A fatal (0201), non-fatal (0202), asynchronous error (0204) or warning (0205) packet."""

    opcode: int
    request_number: int
    error: ErrorMessage

    @property
    def fatal(self) -> bool:
        return self.opcode == ServerOp.FATAL_ERROR


AsyncLayout = Literal["numbered", "guide"]
"""The two layouts of an asynchronous response (erratum ``async-request-number``): ``numbered``, manip's
8 bytes (request number, condition, two words), and ``guide``, the 1985 guide's 6 bytes (condition, two
words).  A reader tells them apart by length."""


@dataclass(frozen=True)
class AsyncResponse:
    """An asynchronous response (0203): a guard hit or a completed segment.

    ``request_number`` is None for the 1985 guide's own layout (6 data bytes: the condition code is the
    first word); manip's layout (8 bytes) puts the number of the last request processed first (erratum
    ``async-request-number``)."""

    request_number: int | None
    condition: int
    word2: int
    word3: int

    @property
    def condition_name(self) -> str:
        entry = SPEC.async_codes.get(self.condition)
        return entry.name if entry else f"unknown-{self.condition}"

    @property
    def layout(self) -> AsyncLayout:
        """``numbered`` (manip's 8 bytes) or ``guide`` (the 1985 guide's 6 bytes)."""
        return "guide" if self.request_number is None else "numbered"


ServerMessage = Reply | ErrorReply | AsyncResponse

_SEGMENT = Layout((Field("segment", SPEC.field_types["word"]),))
_EMPTY = Layout(())
_REPLY_CLAUSE: Final[Mapping[str, str]] = {
    "done": "response.done-empty",
    "segment": "response.segment-number",
    "data": "response.data-layout",
    "multi": "response.data-layout",
}


def response_layout(op: RequestOpcode) -> Layout:
    """The data layout after the request number of a (non-terminator) RESPONSE to ``op``."""
    match op.response.form:
        case "done":
            return _EMPTY
        case "segment":
            return _SEGMENT
        case _:
            return op.response.data


def encode_reply(op: int | str, request_number: int, **values: Any) -> bytes:
    """Data of a RESPONSE packet answering ``op`` (for a multi reply: one text chunk)."""
    spec_op = request_op(op)
    layout = response_layout(spec_op)
    fast = _codec(layout).fast_numbered
    if fast is not None:  # (never a multi reply: text has no fast plan)
        data = fast.build(values, request_number)
        if data is not None:
            return data
    if spec_op.response.form == "multi" and not any(values.values()):
        raise EncodeError(
            f"{spec_op.name}.reply: an empty chunk would end the reply; use encode_terminator",
            path=f"{spec_op.name}.reply",
            clause="multi.terminated-by-empty",
        )
    return _build(layout, values, f"{spec_op.name}.reply", request_number)


def encode_terminator(request_number: int) -> bytes:
    """The empty RESPONSE that ends a multi-packet reply (request number only)."""
    return _WORD.pack(request_number)


def encode_multi_text(request_number: int, text: str) -> list[bytes]:
    """A multi-packet text reply: chunks of at most 486 text bytes, then the terminator."""
    raw = encode_lispm(text)
    number = _WORD.pack(request_number)
    chunks = [number + raw[i : i + MAX_TEXT_PER_PACKET] for i in range(0, len(raw), MAX_TEXT_PER_PACKET)]
    return [*chunks, encode_terminator(request_number)]


class _ReplyBuilder:
    """A plain class with :class:`Reply`'s slots: filling one and reassigning ``__class__`` skips the
    frozen dataclass's ``__init__`` (see :func:`~manip.codecs.packet.make_packet`, the same trick)."""

    __slots__ = Reply.__slots__
    request_number: int
    op: RequestOpcode
    values: dict[str, Value]
    payload: bytes


_new_reply = object.__new__
_REPLY_PLANS: dict[int | str, tuple[RequestOpcode, FastLayout | None]] = {}
"""Per request opcode (by number and by name): its spec entry and the fast plan of its reply, if any."""


def _reply_plan(op: int | str | RequestOpcode) -> tuple[RequestOpcode, FastLayout | None]:
    """The plan for ``op``, remembered when ``op`` is a number or a name (a spec entry is used as is)."""
    if isinstance(op, RequestOpcode):
        return op, _codec(response_layout(op)).fast_numbered
    spec_op = request_op(op)
    entry = _REPLY_PLANS[op] = (spec_op, _codec(response_layout(spec_op)).fast_numbered)
    return entry


def decode_reply(data: bytes, op: int | str | RequestOpcode | None = None) -> Reply:
    """Decode a RESPONSE packet's data; with ``op`` the payload is decoded by that request's layout."""
    if op is not None:
        plan = None if isinstance(op, RequestOpcode) else _REPLY_PLANS.get(op)
        spec_op, fast = plan or _reply_plan(op)
        if fast is not None:
            parsed = fast.parse(data)
            if parsed is not None:  # a numbered plan: the number is an int
                reply = _new_reply(_ReplyBuilder)
                reply.request_number, reply.values = parsed  # type: ignore[assignment]
                reply.op = spec_op
                reply.payload = data[REQUEST_NUMBER_BYTES:] if type(data) is bytes else bytes(data[2:])
                reply.__class__ = Reply  # type: ignore[assignment]
                return reply  # type: ignore[return-value]
    if len(data) < REQUEST_NUMBER_BYTES:
        raise DecodeError(
            f"response has {len(data)} data bytes; the request number needs 2",
            path="request_number",
            offset=len(data),
            clause="response.echoes-request-number",
        )
    (number,) = _WORD.unpack_from(data, 0)
    payload = bytes(data[REQUEST_NUMBER_BYTES:])
    if op is None:
        return Reply(number, None, {}, payload)
    spec_op = op if isinstance(op, RequestOpcode) else request_op(op)
    kind = spec_op.response.form
    if kind == "multi" and not payload:
        return Reply(number, spec_op, {}, payload)
    _, values = _parse(
        response_layout(spec_op),
        data,
        numbered=True,
        what=f"{spec_op.name}.reply",
        clause=_REPLY_CLAUSE[kind],
    )
    return Reply(number, spec_op, values, payload)


def encode_error(opcode: int, request_number: int, error: ErrorMessage) -> bytes:
    """Data of an error packet (0201, 0202, 0204 or 0205)."""
    if opcode not in (
        ServerOp.FATAL_ERROR,
        ServerOp.NON_FATAL_ERROR,
        ServerOp.ASYNCHRONOUS_ERROR,
        ServerOp.ASYNCHRONOUS_WARNING,
    ):
        raise EncodeError(f"opcode 0{opcode:o} does not carry an error string", path="opcode")
    return _WORD.pack(request_number) + error.encode()


def decode_error(opcode: int, data: bytes, *, align_args: bool | None = None) -> ErrorReply:
    if len(data) < REQUEST_NUMBER_BYTES:
        raise DecodeError(
            "error packet without a request number",
            "request_number",
            len(data),
            "response.echoes-request-number",
        )
    (number,) = _WORD.unpack_from(data, 0)
    try:
        error = parse_error(data[REQUEST_NUMBER_BYTES:], align_args=align_args, body="string")
    except CodecError as exc:
        raise exc.at("error", REQUEST_NUMBER_BYTES) from exc
    return ErrorReply(opcode, number, error)


_ASYNC = struct.Struct("<4H")
_ASYNC_NO_NUMBER = struct.Struct("<3H")
ASYNC_SIZES: Final[Mapping[AsyncLayout, int]] = {"numbered": _ASYNC.size, "guide": _ASYNC_NO_NUMBER.size}


def encode_async(
    request_number: int, condition: int, word2: int, word3: int, *, async_has_request_number: bool = True
) -> bytes:
    """Data of an asynchronous response (0203): manip's numbered layout, or without the request number
    the 1985 guide's own (erratum ``async-request-number``)."""
    for name, v in (
        ("request_number", request_number),
        ("condition", condition),
        ("word2", word2),
        ("word3", word3),
    ):
        if not 0 <= v <= 0xFFFF:
            raise EncodeError(f"{v} does not fit in a word", path=name, clause="async.layout")
    if async_has_request_number:
        return _ASYNC.pack(request_number, condition, word2, word3)
    return _ASYNC_NO_NUMBER.pack(condition, word2, word3)


def decode_async(data: bytes, *, async_has_request_number: bool | None = None) -> AsyncResponse:
    """An asynchronous response's data in either layout, told apart by length (8 bytes: numbered, 6: the
    1985 guide's); ``async_has_request_number`` insists on one of them."""
    sizes = {True: _ASYNC.size, False: _ASYNC_NO_NUMBER.size}
    allowed = (
        sizes
        if async_has_request_number is None
        else {async_has_request_number: sizes[async_has_request_number]}
    )
    numbered = next((k for k, size in allowed.items() if size == len(data)), None)
    if numbered is None:
        wanted = " or ".join(str(size) for size in sorted(allowed.values(), reverse=True))
        raise DecodeError(
            f"asynchronous response needs {wanted} data bytes, got {len(data)}",
            path="async",
            offset=min(len(data), _ASYNC_NO_NUMBER.size),
            clause="async.layout",
        )
    if numbered:
        number, condition, w2, w3 = _ASYNC.unpack(data)
        return AsyncResponse(number, condition, w2, w3)
    condition, w2, w3 = _ASYNC_NO_NUMBER.unpack(data)
    return AsyncResponse(None, condition, w2, w3)


def guard_hit(request_number: int, guard: int, *, stop: bool) -> bytes:
    return encode_async(request_number, AsyncCondition.GUARD_HIT, 1 if stop else 2, guard)


def segment_completed(request_number: int, segment: int) -> bytes:
    return encode_async(request_number, AsyncCondition.SEGMENT_COMPLETED, 0, segment)


def decode_server_packet(
    opcode: int, data: bytes, op: int | str | RequestOpcode | None = None, *, align_args: bool | None = None
) -> ServerMessage:
    """Decode any packet a server sends, by its Chaos opcode."""
    match opcode:
        case ServerOp.RESPONSE:
            return decode_reply(data, op)
        case ServerOp.ASYNCHRONOUS_RESPONSE:
            return decode_async(data)
        case (
            ServerOp.FATAL_ERROR
            | ServerOp.NON_FATAL_ERROR
            | ServerOp.ASYNCHRONOUS_ERROR
            | ServerOp.ASYNCHRONOUS_WARNING
        ):
            return decode_error(opcode, data, align_args=align_args)
    raise DecodeError(
        f"opcode 0{opcode:o} is not a server opcode (0200-0205)",
        path="opcode",
        offset=0,
        clause="response.server-opcodes",
    )
