"""The likely cause of a wrong value, said beside the violation: what the bytes would mean if the sender
had swapped the two words of its floats, or the two bytes of each word, and whether a number is one off
or byte-swapped.

A reply whose floats come with their words swapped is as long as a right one; what fails is the value
(a reserved operand, a dirty zero, a joint angle of 1e-20).  Saying "the floats decode with their words
swapped: (10, -80, 80, 0, 10, 0)" points at the bug; "50 data bytes" does not.  Every function here is
pure and returns None when it has nothing better to say than the violation already does.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final

from manip.codecs.errors import CodecError
from manip.codecs.pdp11float import unpack_f
from manip.spec import RequestOpcode

__all__ = [
    "float_payload",
    "floats_diagnosis",
    "number_diagnosis",
    "swap_bytes",
    "swap_words",
]

PLAUSIBLE: Final = (1e-6, 1e7)
"""Magnitudes a float of the protocol takes (millimetres, degrees, ounces, direction cosines): a value
outside, other than zero, is more likely a misread than a measurement."""


def swap_words(data: bytes) -> bytes:
    """Each 4-byte float with its two words exchanged."""
    return b"".join(data[i + 2 : i + 4] + data[i : i + 2] for i in range(0, len(data) - len(data) % 4, 4))


def swap_bytes(data: bytes) -> bytes:
    """Each word with its two bytes exchanged."""
    return b"".join(data[i + 1 : i + 2] + data[i : i + 1] for i in range(0, len(data) - len(data) % 2, 2))


def _read(data: bytes) -> list[float] | None:
    """The floats of ``data`` (a multiple of 4 bytes), None when one is a reserved operand."""
    try:
        return [unpack_f(data, i) for i in range(0, len(data), 4)]
    except CodecError:
        return None


def _plausible(values: Sequence[float]) -> bool:
    return all(v == 0.0 or (math.isfinite(v) and PLAUSIBLE[0] <= abs(v) <= PLAUSIBLE[1]) for v in values)


def _show(values: Sequence[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


_SWAPS: Final[tuple[tuple[str, Callable[[bytes], bytes]], ...]] = (
    ("with the two words of each float swapped", swap_words),
    ("with the two bytes of each word swapped", swap_bytes),
    ("with both the words and their bytes swapped", lambda d: swap_bytes(swap_words(d))),
)


def floats_diagnosis(data: bytes, expected: Sequence[float] | None = None) -> str | None:
    """Say what the floats of ``data`` (PDP-11 memory order, a multiple of 4 bytes) would be with their
    words or bytes swapped, when that reads better than the bytes as sent: the values then match
    ``expected`` (when given), or they are all plausible where the bytes as sent are not."""
    if not data or len(data) % 4:
        return None
    as_sent = _read(data)
    for how, swap in _SWAPS:
        values = _read(swap(data))
        if values is None:
            continue
        if expected is not None:
            if len(values) == len(expected) and all(
                math.isclose(v, e, rel_tol=1e-6, abs_tol=1e-6) for v, e in zip(values, expected, strict=True)
            ):
                return f"the bytes read {_show(values)} {how}, the values expected: the sender swaps them"
            continue
        if (as_sent is None or not _plausible(as_sent)) and _plausible(values) and any(values):
            return f"likely cause: {how} the floats read {_show(values)}"
    return None


def float_payload(op: RequestOpcode, data: bytes) -> bytes:
    """The bytes of a reply's data (request number first) that hold floats, when its layout is floats
    alone (joints, a transform, forces...); empty otherwise."""
    fields = op.response.data.fields
    if not fields or any(f.type.element != "float" or f.type.count is None for f in fields):
        return b""
    size = sum(4 * (f.type.count or 0) for f in fields)
    return data[2 : 2 + size] if len(data) >= 2 + size else b""


def number_diagnosis(got: int, want: int, *, what: str = "number") -> str | None:
    """Why a 16-bit ``got`` may stand where ``want`` should: one off, or its two bytes swapped."""
    if got == want:
        return None
    if got == (want + 1) & 0xFFFF:
        return f"one more than the {what} expected: an off-by-one"
    if got == (want - 1) & 0xFFFF:
        return f"one less than the {what} expected: an off-by-one"
    if ((got & 0xFF) << 8) | (got >> 8) == want:
        return f"the {what} expected with its two bytes swapped (a word in the wrong byte order)"
    return None
