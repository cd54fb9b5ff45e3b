"""A fast codec for fixed-size numeric layouts (the common replies: transforms, joint angles, words).

The construct definitions in :mod:`manip.codecs.messages` are the reference and produce the precise
errors; this plan only speeds up the well-formed case, and declines (returns None) on anything unusual,
which sends the caller down the construct path.  Tests check the two agree on random inputs, both ways.

Why it is exact: a PDP-11 F float and an IEEE single with the same 32 bits differ by a factor of 4
(F = 0.1f x 2^(e-128), IEEE = 1.f x 2^(e-127)) whenever the IEEE reading is a normal number, i.e. the
exponent is neither 0 nor 255.  So the floats are read by reordering each float's two words into IEEE
order (one byte swap of the whole buffer), unpacking them as IEEE singles in C, and multiplying by
0.25 (exact).  Exponents 0 (zero, dirty zero, reserved operand) and 255 are the only ones the identity
gets wrong; they are found from the high byte of each float's first word with one ``translate`` and
``count`` and, unless they are all clean zeros, the slow path decides.

Encoding runs the same identity backwards: each float is multiplied by 4 (exact), everything is packed
big-endian in C (IEEE singles round to nearest, ties to even: the default half-even policy), and the
bytes of each word are swapped back.  The same high-byte test then catches every float the identity
may have got wrong (a single that overflowed, went subnormal or came out as exponent 0, 1, 254 or 255,
and ``-0.0``, whose sign bit would make the reserved operand); only clean zeros pass it.
"""

from __future__ import annotations

import struct
from array import array
from collections.abc import Mapping
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

from manip.spec import Layout

# 1 for a w0 high byte whose exponent bits are all 0 or all 1 (ignoring the sign and the lowest bit).
_EDGE_EXPONENT = bytes(1 if b & 0x7F in (0, 0x7F) else 0 for b in range(256))
_SIGN_ONLY = 0x80  # sign 1, exponent 0 or 1: the reserved operand (or a tiny negative number)
_TIMES_4 = (4.0).__mul__
_FLOAT_TYPE = frozenset((float,))


@dataclass(frozen=True, slots=True)
class FastLayout:
    """Precomputed struct formats and slices for one fixed-size numeric layout."""

    size: int
    values: struct.Struct  # big-endian view of the word-swapped data: H/h words, f floats (x4)
    high_bytes: Any  # data -> bytes: each float's w0 high byte in the raw data
    float_get: Any  # itemgetter of the float positions in the unpacked tuple (None: no floats)
    fields: tuple[tuple[str, slice, bool, bool], ...]  # name, slice of the unpacked tuple, is float, single
    numbered: bool

    def build(self, values: Mapping[str, Any], number: int | None = None) -> bytes | None:
        """Encode ``values`` (with ``number`` first when numbered), or None when the slow path must.

        Only exact types are taken (``float`` for floats, ``int`` for words, no subclasses): anything
        else, a missing or extra field, a wrong count or a value out of range is for the reference to
        judge and report."""
        fields = self.fields
        if len(values) != len(fields):
            return None
        args: list[Any] = []
        if self.numbered:
            if type(number) is not int:
                return None
            args.append(number)
        try:
            for name, where, is_float, single in fields:
                v = values[name]
                if single:
                    if type(v) is not (float if is_float else int):
                        return None
                    args.append(v * 4.0 if is_float else v)
                elif len(v) != where.stop - where.start:
                    return None
                elif is_float:
                    if set(map(type, v)) != _FLOAT_TYPE:
                        return None
                    args += map(_TIMES_4, v)
                else:
                    if not all(type(x) is int for x in v):
                        return None
                    args += v
            packed = array("H", self.values.pack(*args))
        except (KeyError, TypeError, struct.error, OverflowError):
            return None  # a missing field, something without a length, a word out of range, an overflow
        packed.byteswap()
        data = packed.tobytes()
        if self.float_get is not None:
            high = self.high_bytes(data)
            flagged = high.translate(_EDGE_EXPONENT).count(1)
            if flagged and (flagged != self.float_get(args).count(0.0) or _SIGN_ONLY in high):
                return None
        return data

    def parse(self, data: bytes) -> tuple[int | None, dict[str, Any]] | None:
        """Decode ``data`` (exactly ``size`` bytes), or None when the slow path must decide."""
        if len(data) != self.size:
            return None
        swapped = array("H", data)
        swapped.byteswap()  # each word now high byte first: floats read as IEEE singles, big-endian
        vals = self.values.unpack(swapped)
        if self.float_get is not None:
            # The high byte of each float's sign/exponent word holds the sign and the top 7 exponent
            # bits: only 0 (exponent 0 or 1) or 0x7F (254 or 255) there can mean a float that the IEEE
            # reading gets wrong.  Such floats are accepted only if they are all clean zeros.
            high = self.high_bytes(data)
            flagged = high.translate(_EDGE_EXPONENT).count(1)
            if flagged and (flagged != self.float_get(vals).count(0.0) or _SIGN_ONLY in high):
                return None
        out: dict[str, Any] = {}
        for name, where, is_float, single in self.fields:
            chunk: Any = vals[where]
            if is_float:
                chunk = tuple([v * 0.25 for v in chunk])
            out[name] = chunk[0] if single else chunk
        return (vals[0] if self.numbered else None), out


def plan(layout: Layout, *, numbered: bool) -> FastLayout | None:
    """A fast plan for ``layout``, or None when it has variable or one-byte fields."""
    value_codes = ["H"] if numbered else []
    fields: list[tuple[str, slice, bool, bool]] = []
    float_positions: list[int] = []
    high: list[int] = []
    offset = 2 * len(value_codes)
    for f in layout.fields:
        element, count = f.type.element, f.type.count
        if element not in ("float", "word", "int16") or count is None:
            return None
        start = len(value_codes)
        code = {"float": "f", "word": "H", "int16": "h"}[element]
        value_codes += [code] * count
        if element == "float":
            float_positions += range(start, start + count)
            high += [offset + 4 * i + 1 for i in range(count)]
        offset += (4 if element == "float" else 2) * count
        fields.append((f.name, slice(start, start + count), element == "float", count == 1))
    values = struct.Struct(">" + "".join(value_codes))
    getter: Any = None
    high_bytes: Any = None
    if len(float_positions) == 1:
        getter = _one(float_positions[0])  # a tuple even for one float, so the check can count it
    elif float_positions:
        first, last = float_positions[0], float_positions[-1]
        contiguous = float_positions == list(range(first, last + 1))
        getter = itemgetter(slice(first, last + 1)) if contiguous else itemgetter(*float_positions)
    if high:
        contiguous = high == list(range(high[0], high[-1] + 1, 4))
        high_bytes = itemgetter(slice(high[0], high[-1] + 1, 4)) if contiguous else _bytes_at(high)
    return FastLayout(
        size=values.size,
        values=values,
        high_bytes=high_bytes,
        float_get=getter,
        fields=tuple(fields),
        numbered=numbered,
    )


def _bytes_at(positions: list[int]) -> Any:
    pick: Any = _one(positions[0])
    if len(positions) > 1:
        pick = itemgetter(*positions)
    return lambda data: bytes(pick(data))


def _one(index: int) -> Any:
    return lambda seq: (seq[index],)
