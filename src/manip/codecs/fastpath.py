"""A fast decoder for fixed-size numeric layouts (the common replies: transforms, joint angles, words).

The construct definitions in :mod:`manip.codecs.messages` are the reference and produce the precise
errors; this plan only speeds up the well-formed case, and declines (returns None) on anything unusual,
which sends the caller down the construct path.  A test checks the two agree on random inputs.

Why it is exact: a PDP-11 F float and an IEEE single with the same 32 bits differ by a factor of 4
(F = 0.1f x 2^(e-128), IEEE = 1.f x 2^(e-127)) whenever the IEEE reading is a normal number, i.e. the
exponent is neither 0 nor 255.  So the floats are read by reordering each float's two words into IEEE
order, unpacking them as IEEE singles in C, and multiplying by 0.25 (exact).  Exponent 0 (zero, dirty
zero, reserved operand) and 255 show up as IEEE zeros, subnormals, infinities or NaNs and are checked
for before any value is returned.
"""

from __future__ import annotations

import math
import struct
from array import array
from bisect import bisect_left
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

from manip.spec import Layout

_FLT_MIN = 2.0**-126  # smallest normal IEEE single
_NEGATIVE_ZERO = 0x80000000  # the reserved operand with fraction 0 reads as IEEE -0.0


@dataclass(frozen=True)
class FastLayout:
    """Precomputed struct formats and slices for one fixed-size numeric layout."""

    size: int
    values: struct.Struct  # big-endian view of the word-swapped data: H/h words, f floats (x4)
    bits: struct.Struct  # the same with I for floats: the raw IEEE bit patterns
    float_get: Any  # itemgetter of the float positions in the unpacked tuple (None: no floats)
    fields: tuple[tuple[str, slice, bool, bool], ...]  # name, slice of the unpacked tuple, is float, single
    numbered: bool

    def parse(self, data: bytes) -> tuple[int | None, dict[str, Any]] | None:
        """Decode ``data`` (exactly ``size`` bytes), or None when the slow path must decide."""
        if len(data) != self.size:
            return None
        swapped = array("H", data)
        swapped.byteswap()  # each word now high byte first: floats read as IEEE singles, big-endian
        vals = self.values.unpack(swapped)
        if self.float_get is not None:
            fvals = self.float_get(vals)
            smallest = sorted(map(abs, fvals))
            if smallest[0] < _FLT_MIN and (
                bisect_left(smallest, _FLT_MIN) != fvals.count(0.0)  # subnormal: exponent 0, not zero
                or _NEGATIVE_ZERO in self.float_get(self.bits.unpack(swapped))  # reserved operand
            ):
                return None
            if not math.isfinite(sum(fvals)):  # exponent 255
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
    bit_codes = list(value_codes)
    fields: list[tuple[str, slice, bool, bool]] = []
    float_positions: list[int] = []
    for f in layout.fields:
        element, count = f.type.element, f.type.count
        if element not in ("float", "word", "int16") or count is None:
            return None
        start = len(value_codes)
        code = {"float": "f", "word": "H", "int16": "h"}[element]
        value_codes += [code] * count
        bit_codes += ["I" if element == "float" else "H"] * count
        if element == "float":
            float_positions += range(start, start + count)
        fields.append((f.name, slice(start, start + count), element == "float", count == 1))
    values = struct.Struct(">" + "".join(value_codes))
    getter: Any = None
    if len(float_positions) == 1:
        getter = _one(float_positions[0])  # a tuple even for one float, so the checks can count it
    elif float_positions:
        getter = itemgetter(*float_positions)
    return FastLayout(
        size=values.size,
        values=values,
        bits=struct.Struct(">" + "".join(bit_codes)),
        float_get=getter,
        fields=tuple(fields),
        numbered=numbered,
    )


def _one(index: int) -> Any:
    return lambda seq: (seq[index],)
