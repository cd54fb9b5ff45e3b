"""The built-in data extractors (the 1985 guide's "useful data extractor functions" in BKGND).

Each follows the contract in :mod:`manip.reference_client.request`: ``(request, payloads) -> value``,
raising on data that do not fit.  They are registered under the names in :data:`BUILTIN_EXTRACTORS`.
Layout-driven extractors read the reply with the spec layout of the request's opcode, so lengths are
checked exactly (clauses ``response.done-empty``, ``response.segment-number``, ``response.data-layout``).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Final

from manip.arm.transform import Transform
from manip.codecs.lisp import LispValue, read_alist
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import Value, decode_reply
from manip.reference_client.request import Request

_WORD = struct.Struct("<H")


def _single(request: Request[Any], payloads: Sequence[bytes]) -> bytes:
    if len(payloads) != 1:
        raise ValueError(f"expected one response packet, got {len(payloads)}")
    return payloads[0]


def extract_nothing(request: Request[Any], payloads: Sequence[bytes]) -> None:
    """Ignore the data (the 1985 guide's NIL extractor, as a named one)."""
    return None


def extract_done(request: Request[Any], payloads: Sequence[bytes]) -> None:
    """A "done": no data after the request number."""
    size = sum(len(p) for p in payloads)
    if size:
        raise ValueError(f"a done reply carries only the request number; {size} more bytes came")


def extract_segment(request: Request[Any], payloads: Sequence[bytes]) -> int:
    """The segment number of a motion reply: exactly one word."""
    data = _single(request, payloads)
    if len(data) != _WORD.size:
        raise ValueError(f"a motion reply carries one word (the segment number), got {len(data)} bytes")
    (segment,) = _WORD.unpack(data)
    return int(segment)


def extract_values(request: Request[Any], payloads: Sequence[bytes]) -> Mapping[str, Value]:
    """The reply read with the spec layout of the request's opcode, as field name -> value."""
    op = request.code.spec
    if op is None:
        raise ValueError(f"{request.code} has no spec layout; give the request an extractor")
    number = _WORD.pack((request.packet_number or 0) & 0xFFFF)
    data = _single(request, payloads)
    return decode_reply(number + data, op).values


def extract_value(request: Request[Any], payloads: Sequence[bytes]) -> Value:
    """The value of a reply layout with exactly one field."""
    values = extract_values(request, payloads)
    if len(values) != 1:
        raise ValueError(f"the reply layout has {len(values)} fields, not one: {sorted(values)}")
    (value,) = values.values()
    return value


def extract_floats(request: Request[Any], payloads: Sequence[bytes]) -> tuple[float, ...]:
    value = extract_value(request, payloads)
    if not isinstance(value, tuple) or not all(isinstance(v, float) for v in value):
        raise ValueError(f"the reply is not a vector of floats: {value!r}")
    return tuple(float(v) for v in value)


def extract_ints(request: Request[Any], payloads: Sequence[bytes]) -> tuple[int, ...]:
    value = extract_value(request, payloads)
    if not isinstance(value, tuple) or not all(isinstance(v, int) for v in value):
        raise ValueError(f"the reply is not a vector of integers: {value!r}")
    return tuple(int(v) for v in value)


def extract_word(request: Request[Any], payloads: Sequence[bytes]) -> int:
    value = extract_value(request, payloads)
    if not isinstance(value, int):
        raise ValueError(f"the reply is not one word: {value!r}")
    return value


def extract_transform(request: Request[Any], payloads: Sequence[bytes]) -> Transform:
    """12 floats, column major N O A P (clause ``here.transform``), checked to be a rotation."""
    return Transform.from_floats(extract_floats(request, payloads))


def extract_text(request: Request[Any], payloads: Sequence[bytes]) -> str:
    """The packets' bytes joined and read as Lisp Machine text."""
    return decode_lispm(b"".join(payloads))


def extract_alist(request: Request[Any], payloads: Sequence[bytes]) -> dict[str, LispValue]:
    """Describe-self: the text read as a Lisp alist, numbers octal (erratum ``octal-numbers``)."""
    return read_alist(extract_text(request, payloads))


def extract_words(request: Request[Any], payloads: Sequence[bytes]) -> tuple[int, ...]:
    """The data as unsigned 16-bit words, low byte first."""
    data = b"".join(payloads)
    if len(data) % 2:
        raise ValueError(f"{len(data)} bytes are not whole words")
    return tuple(w for (w,) in _WORD.iter_unpack(data))


def extract_raw(request: Request[Any], payloads: Sequence[bytes]) -> tuple[bytes, ...]:
    """The payloads untouched."""
    return tuple(payloads)


BUILTIN_EXTRACTORS: Final[Mapping[str, Callable[[Request[Any], Sequence[bytes]], Any]]] = {
    "nothing": extract_nothing,
    "done": extract_done,
    "segment": extract_segment,
    "values": extract_values,
    "value": extract_value,
    "floats": extract_floats,
    "ints": extract_ints,
    "word": extract_word,
    "transform": extract_transform,
    "text": extract_text,
    "alist": extract_alist,
    "words": extract_words,
    "raw": extract_raw,
}
