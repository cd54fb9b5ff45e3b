"""PDP-11 32-bit ("F", = VAX F_floating) floats: exact scalar, numpy bulk and construct codecs.

Layout (clause ``float.format``): word 0 holds the sign (bit 15), an excess-128 exponent (bits 14..7) and
the top 7 fraction bits; word 1 holds the low 16 fraction bits.  With a hidden bit the value is
``(-1)^s * (2^23 + f) / 2^24 * 2^(e - 128)``.  There are no subnormals, infinities or NaNs.  On the wire
each word is low byte first and word 0 comes first, so the four bytes read as one little-endian
``uint32`` ``u`` give ``w0 = u & 0xFFFF`` and ``w1 = u >> 16``; every function here speaks in that ``u``.

Every F value is exactly a Python float, so decoding is lossless.  Encoding rounds from float64's 53 bits
to 24 with integer arithmetic (never via float32, whose range lacks F's exponents 1, 2 and 255).

The two 1985 ends disagreed at the edges, so the behaviour there is a policy (errata ``float-rounding``
and ``float-decode``):

* ``rounding``: ``"half-even"`` (default; the Lisp Machine's ``ART-FPS-FLOAT`` and IEEE), ``"half-away"``
  (FP11 hardware: ties away from zero) or ``"truncate"`` (FP11 with the FPS T bit set).
* ``underflow``: ``"zero"`` (default; both ends flush to zero) or ``"error"``.
* ``dirty_zero`` (exponent 0, fraction non-zero): ``"zero"`` (default; FP11 and Lisp Machine read 0.0)
  or ``"error"``.
* ``reserved`` (sign 1, exponent 0: the FP11 undefined variable, the VAX reserved operand): ``"error"``
  (default) or ``"zero"`` (the Lisp Machine read it as 0.0).

Overflow is always an error (the FP11 gave 0 or trapped, the CADR saturated; neither is a value the
sender meant).  ``-0.0`` and flushed negatives encode as a clean zero, never as the reserved operand.
"""

from __future__ import annotations

import array
import functools
import math
import struct
import sys
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final, Literal, TypeAlias

from construct import Adapter, Int32ul, StreamError

from manip.codecs.errors import CodecError, DecodeError, EncodeError

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

# numpy (0.05-0.1 s to import) loads only when a bulk function runs: the scalar codecs, which decoding
# and the protocol use, never need it.  A value can only be a numpy scalar once numpy is loaded, so the
# scalar paths ask ``sys.modules`` rather than import it.

__all__ = [
    "DIRTY_ZERO_POLICIES",
    "F_MAX",
    "F_MIN_NORMAL",
    "RESERVED_POLICIES",
    "ROUNDINGS",
    "UNDERFLOW_POLICIES",
    "DirtyZero",
    "FFloat",
    "Float32F",
    "FloatLike",
    "Reserved",
    "Rounding",
    "Underflow",
    "f_to_u32",
    "f_to_words",
    "pack_f",
    "pack_f_array",
    "pack_f_few",
    "u32_to_f",
    "unpack_f",
    "unpack_f_array",
    "unpack_f_few",
    "words_to_f",
]

Rounding: TypeAlias = Literal["half-even", "half-away", "truncate"]
Underflow: TypeAlias = Literal["zero", "error"]
DirtyZero: TypeAlias = Literal["zero", "error"]
Reserved: TypeAlias = Literal["error", "zero"]
FloatLike: TypeAlias = "float | np.floating[Any]"
"""What the encoders accept: Python floats and numpy floating scalars (never ints or bools)."""

ROUNDINGS: Final[tuple[Rounding, ...]] = ("half-even", "half-away", "truncate")
UNDERFLOW_POLICIES: Final[tuple[Underflow, ...]] = ("zero", "error")
DIRTY_ZERO_POLICIES: Final[tuple[DirtyZero, ...]] = ("zero", "error")
RESERVED_POLICIES: Final[tuple[Reserved, ...]] = ("error", "zero")

F_MAX: Final = math.ldexp(0xFFFFFF, 127 - 24)
"""Largest F magnitude, (1 - 2^-24) * 2^127 = 1.7014117331926443e38 (bytes ``ff 7f ff ff``)."""
F_MIN_NORMAL: Final = math.ldexp(1.0, -128)
"""Smallest non-zero F magnitude, 2^-128 = 2.938735877055719e-39 (bytes ``80 00 00 00``)."""

_HIDDEN: Final = 1 << 23
_CARRY: Final = 1 << 24
_U32: Final = struct.Struct("<I")


# ------------------------------------------------------------------------------------------ policies


def _check(kind: str, value: object, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f"{kind} must be one of {', '.join(map(repr, allowed))}, not {value!r}")


def _check_encode(rounding: object, underflow: object) -> None:
    _check("rounding", rounding, ROUNDINGS)
    _check("underflow", underflow, UNDERFLOW_POLICIES)


def _check_decode(dirty_zero: object, reserved: object) -> None:
    _check("dirty_zero", dirty_zero, DIRTY_ZERO_POLICIES)
    _check("reserved", reserved, RESERVED_POLICIES)


# ------------------------------------------------------------------------------------------ scalar


def _not_a_float(x: object) -> EncodeError:
    return EncodeError(
        f"{type(x).__name__} {x!r} is not a float; a flonum must be passed as a float",
        clause="request-data.types",
    )


def _not_finite(x: object) -> EncodeError:
    return EncodeError(f"{x!r} has no PDP-11 representation", clause="float.not-finite")


def _round_general(x: object, rounding: str) -> tuple[int, int, int]:
    """(sign bit, q, exp) for a non-``float`` input, rounded once from all its bits; q == 0 for zero.

    numpy float16/32 widen to float exactly; a long double keeps its 64-bit mantissa so it is not
    rounded twice.  Anything that is not a real float is refused (never converted silently).
    """
    numpy = sys.modules.get("numpy")
    if numpy is None or not isinstance(x, numpy.floating):
        raise _not_a_float(x)
    if not numpy.isfinite(x):
        raise _not_finite(x)
    num, den = x.as_integer_ratio()  # den is a power of two
    if num == 0:
        return 0, 0, 0
    sign = 0x8000 if num < 0 else 0
    mant = abs(num)
    bits = mant.bit_length()
    exp = bits - den.bit_length() + 1  # 2^(exp-1) <= |x| < 2^exp
    drop = bits - 24
    if drop <= 0:
        _check("rounding", rounding, ROUNDINGS)
        return sign, mant << -drop, exp
    q = mant >> drop
    rest = mant & ((1 << drop) - 1)
    half = 1 << (drop - 1)
    if rounding == "half-even":
        q += rest > half or (rest == half and q & 1)
    elif rounding == "half-away":
        q += rest >= half
    elif rounding != "truncate":
        _check("rounding", rounding, ROUNDINGS)
    return sign, q, exp


def f_to_u32(x: FloatLike, *, rounding: Rounding = "half-even", underflow: Underflow = "zero") -> int:
    """Encode ``x`` as the little-endian ``uint32`` of its four wire bytes.

    Rounding happens once, from all the input's bits, and a carry out of the fraction bumps the exponent;
    only then are overflow (``float.range``) and underflow judged, so values just below 2^-128 that round
    up to it are kept, and values that round up past F_MAX are rejected.
    """
    if isinstance(x, float):  # the common case, np.float64 included: 53 bits, 29 of them dropped
        m, exp = math.frexp(x)  # x = m * 2^exp, 0.5 <= |m| < 1
        if not -1.0 < m < 1.0:  # frexp passes inf and nan through
            raise _not_finite(x)
        if m > 0.0:
            sign = 0
        elif m < 0.0:
            sign = 0x8000
            m = -m
        else:
            _check_encode(rounding, underflow)
            return 0
        mant = int(m * 9007199254740992.0)  # * 2^53: exact, 53 significant bits
        q = mant >> 29
        rest = mant & 0x1FFFFFFF
        if rounding == "half-even":
            q += rest > 0x10000000 or (rest == 0x10000000 and q & 1)
        elif rounding == "half-away":
            q += rest >= 0x10000000
        elif rounding != "truncate":
            _check("rounding", rounding, ROUNDINGS)
    else:
        sign, q, exp = _round_general(x, rounding)
        if q == 0:
            _check_encode(rounding, underflow)
            return 0
    if q == _CARRY:  # the fraction rounded up to 2^24: renormalise
        q = _HIDDEN
        exp += 1
    biased = exp + 128
    if biased > 255:
        raise EncodeError(f"{x!r} is beyond the PDP-11 float range (max {F_MAX!r})", clause="float.range")
    if biased < 1:
        _check("underflow", underflow, UNDERFLOW_POLICIES)
        if underflow == "error":
            raise EncodeError(
                f"{x!r} is below the smallest PDP-11 float ({F_MIN_NORMAL!r})", clause="float.range"
            )
        return 0
    return sign | biased << 7 | (q >> 16 & 0x7F) | (q & 0xFFFF) << 16


def _zero_pattern(u: int, dirty_zero: str, reserved: str) -> float:
    """Exponent 0: clean zero, dirty zero or the reserved operand, per policy."""
    _check_decode(dirty_zero, reserved)
    if u & 0x8000:
        if reserved == "error":
            raise DecodeError(
                f"reserved operand (sign 1, exponent 0): bytes {u.to_bytes(4, 'little').hex(' ')}",
                clause="float.reserved-operand",
            )
        return 0.0
    if u & 0xFFFF007F and dirty_zero == "error":
        raise DecodeError(
            f"dirty zero (exponent 0, fraction not 0): bytes {u.to_bytes(4, 'little').hex(' ')}",
            clause="float.dirty-zero",
        )
    return 0.0


def u32_to_f(u: int, *, dirty_zero: DirtyZero = "zero", reserved: Reserved = "error") -> float:
    """Decode the little-endian ``uint32`` of four wire bytes; the result is exact."""
    if type(u) is not int:
        u = _as_index(u)
    if u >> 32:  # also true for negatives
        raise DecodeError(f"{u!r} is not a 32-bit pattern", clause="float.format")
    e = (u >> 7) & 0xFF
    if e:
        v = math.ldexp(((u & 0x7F) << 16 | u >> 16) | _HIDDEN, e - 152)
        return -v if u & 0x8000 else v
    return _zero_pattern(u, dirty_zero, reserved)


def _as_index(u: object) -> int:
    if isinstance(u, int) and not isinstance(u, bool):
        return int(u)
    numpy = sys.modules.get("numpy")
    if numpy is not None and isinstance(u, numpy.integer):
        return int(u)
    raise DecodeError(f"{type(u).__name__} {u!r} is not a 32-bit pattern", clause="float.format")


# Scalar fast paths.  Both are exact and cover the common case only; anything else (other policies,
# non-float inputs, values near the ends of the range, bad offsets, the reserved operand) goes down the
# checked path above, which is the reference and raises the precise errors.
#
# Encoding: for |x| in [2^-128, _FAST_HIGH) the F pattern of x is the IEEE single of 4x with its words
# swapped.  4x is then a normal single (>= 2^-126) that rounds (to nearest, ties to even: half-even, in
# C) below 2^128, the two 24-bit roundings are the same, and F's exponent bias is IEEE's plus 2 (F is
# 0.1f x 2^(e-128), IEEE 1.f x 2^(E-127)).  Packing 4x twice as "<ff" puts the high word of the single
# (sign, exponent, top fraction: F's w0) at bytes 2-3 and its low word at bytes 4-5: bytes 2..6 are the
# wire bytes, one C call and one slice.
#
# Decoding: a float is w0 (sign, exponent, 7 fraction bits) and w1 (16 fraction bits), and its value is
# base[w0] + scale[w0] * w1 with base = +-(2^23 + top bits << 16) * 2^(e-152) and scale = +-2^(e-152).
# Both terms are exact and so is their sum (a 24-bit integer times a power of two), so two lookups in
# 65536-entry tables replace the bit work.  Exponent 0 reads as 0.0 (the default dirty-zero policy);
# the reserved operand's base is None, so the addition raises TypeError and the checked path reports it.

_FAST_HIGH: Final = math.ldexp(1.0, 126) - math.ldexp(1.0, 101)
"""Below this, 4x rounds to at most the largest single under 2^128 (the first tie above rounds up)."""
_PACK_TWICE: Final = struct.Struct("<ff").pack
_WORDS_FROM: Final = struct.Struct("<HH").unpack_from
_ZERO_BYTES: Final = bytes(4)


def _decode_tables() -> tuple[list[float | None], list[float]]:
    bases: list[float | None] = []
    scales: list[float] = []
    fractions = [float(top << 16 | _HIDDEN) for top in range(0x80)]  # exact: 24-bit integers
    for high in range(0x200):  # w0 >> 7: the sign bit, then the exponent; w0 & 0x7F is the top fraction
        exponent = high & 0xFF
        negative = high & 0x100
        if exponent == 0:  # clean or dirty zero reads 0.0; sign 1 is the reserved operand
            scales += [0.0] * 0x80
            bases += [None if negative else 0.0] * 0x80
            continue
        scale = math.ldexp(-1.0 if negative else 1.0, exponent - 152)
        scales += [scale] * 0x80
        bases += map(scale.__mul__, fractions)  # exact: times a power of two
    return bases, scales


_DECODE_BASE, _DECODE_SCALE = _decode_tables()


def pack_f(x: FloatLike, *, rounding: Rounding = "half-even", underflow: Underflow = "zero") -> bytes:
    """The four wire bytes of ``x``: ``[w0.lo, w0.hi, w1.lo, w1.hi]``."""
    if type(x) is float and rounding == "half-even":
        if F_MIN_NORMAL <= abs(x) < _FAST_HIGH:
            y = x * 4.0
            return _PACK_TWICE(y, y)[2:6]
        if x == 0.0 and underflow in UNDERFLOW_POLICIES:
            return _ZERO_BYTES
    return _U32.pack(f_to_u32(x, rounding=rounding, underflow=underflow))


def unpack_f(
    b: bytes | bytearray | memoryview,
    offset: int = 0,
    *,
    dirty_zero: DirtyZero = "zero",
    reserved: Reserved = "error",
) -> float:
    """Decode the float at ``b[offset:offset + 4]``; errors carry that byte offset."""
    if dirty_zero == "zero" and reserved == "error" and offset >= 0:
        try:
            w0, w1 = _WORDS_FROM(b, offset)
            return _DECODE_BASE[w0] + _DECODE_SCALE[w0] * w1  # type: ignore[no-any-return]
        except (struct.error, TypeError):
            pass  # too short, or the reserved operand: the checked path below says which
    if offset < 0 or len(b) - offset < 4:
        raise DecodeError(
            f"a float needs 4 bytes at offset {offset}, {max(0, len(b) - offset)} present",
            offset=offset,
            clause="float.format",
        )
    (u,) = _U32.unpack_from(b, offset)
    try:
        return u32_to_f(u, dirty_zero=dirty_zero, reserved=reserved)
    except CodecError as exc:
        raise exc.at("", offset) from None


def f_to_words(
    x: FloatLike, *, rounding: Rounding = "half-even", underflow: Underflow = "zero"
) -> tuple[int, int]:
    """``x`` as the two 16-bit words (w0, w1) the Cougar link sends, sign/exponent word first."""
    u = f_to_u32(x, rounding=rounding, underflow=underflow)
    return u & 0xFFFF, u >> 16


def words_to_f(w0: int, w1: int, *, dirty_zero: DirtyZero = "zero", reserved: Reserved = "error") -> float:
    """Decode a float from its two 16-bit words, w0 (sign/exponent) first."""
    if not (0 <= w0 <= 0xFFFF and 0 <= w1 <= 0xFFFF):
        raise DecodeError(f"words {w0!r}, {w1!r} are not both 16-bit", clause="float.format")
    return u32_to_f(w0 | w1 << 16, dirty_zero=dirty_zero, reserved=reserved)


# ------------------------------------------------------------------------------------------ numpy bulk
#
# Decoding swaps the words into the "VAX image" (sign bit 31, exponent 30..23, fraction 22..0), which has
# IEEE float32's shape; shifting that left by 29 lines the exponent and fraction up with float64's, and
# adding 894 to the exponent converts the bias (F: 1.f * 2^(e-129); float64: 1.f * 2^(E-1023)).  Encoding
# runs the same mapping backwards on the float64 bits, rounding with an integer add before the shift so a
# fraction carry moves into the exponent by itself.

_F64_TO_F_BIAS: Final = 894
_EXP_SHIFT_64: Final = 52
_DROP: Final = 29  # 52 - 23 fraction bits
_MIN_T: Final = (_F64_TO_F_BIAS + 1) << 23  # float64 exponent/fraction (>> 29) of 2^-128
_OVER_T: Final = (_F64_TO_F_BIAS + 256) << 23  # ... of 2^127, the first value past F_MAX


def _as_u32(buf: bytes | bytearray | memoryview | npt.NDArray[Any]) -> npt.NDArray[np.uint32]:
    """The wire ``uint32`` values of a byte buffer, a uint8 array, or a uint32 array taken as values."""
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    if isinstance(buf, np.ndarray):
        if buf.dtype.kind == "u" and buf.dtype.itemsize == 4:
            return buf.reshape(-1).astype(np.uint32, copy=False)
        if buf.dtype.kind != "u" or buf.dtype.itemsize != 1:
            raise TypeError(f"expected bytes, a uint8 array or a uint32 array, not {buf.dtype} values")
        raw: npt.NDArray[np.uint8] = np.ascontiguousarray(buf).reshape(-1)
    else:
        raw = np.frombuffer(buf, dtype=np.uint8)
    whole = raw.size - raw.size % 4
    if whole != raw.size:
        raise DecodeError(
            f"{raw.size} bytes is not a whole number of 4-byte floats", offset=whole, clause="float.format"
        )
    return raw.view("<u4").astype(np.uint32, copy=False)


def unpack_f_array(
    buf: bytes | bytearray | memoryview | npt.NDArray[Any],
    *,
    dirty_zero: DirtyZero = "zero",
    reserved: Reserved = "error",
) -> npt.NDArray[np.float64]:
    """Decode a run of wire floats to a 1-D float64 array, exactly, vectorised.

    ``buf`` is bytes-like, a uint8 array (raw bytes) or a uint32 array of wire values (``u`` as above).
    The first offending element raises the scalar error with ``path="[i]"`` and ``offset=4*i``.
    """
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    _check_decode(dirty_zero, reserved)
    if not isinstance(buf, np.ndarray) and dirty_zero == "zero" and len(buf) <= _SMALL_BYTES:
        small = _unpack_small(buf)
        if small is not None:
            return small
    u = _as_u32(buf)
    image = (u >> 16) | (u << 16)  # word swap (uint32 wraps): sign 31, exponent 30..23, fraction 22..0
    wide = image.astype(np.uint64)
    bits = wide & 0x7FFFFFFF
    bits <<= _DROP
    bits += _F64_TO_F_BIAS << _EXP_SHIFT_64
    wide >>= 31
    wide <<= 63
    bits |= wide
    zero = (image & 0x7F800000) == 0
    if zero.any():
        bad = np.zeros_like(zero)
        if reserved == "error":
            bad |= zero & (image >= 0x80000000)
        if dirty_zero == "error":
            bad |= zero & (image != 0) & (image < 0x80000000)
        if bad.any():
            i = int(bad.argmax())
            try:
                u32_to_f(int(u[i]), dirty_zero=dirty_zero, reserved=reserved)
            except CodecError as exc:
                raise exc.at(f"[{i}]", 4 * i) from None
            raise AssertionError("unreachable: bulk and scalar decoders disagree")  # pragma: no cover
        bits[zero] = 0
    return bits.view(np.float64)


# A few floats at a time (the simulated Cougar's memory, a reply's transform): numpy's fixed cost per
# call is many times the work, so these go through the scalar fast paths above and one array build.
# Whatever those decline (a reserved operand, a value near the range ends, another policy) takes the
# vectorised path below, which decides.

_SMALL_BYTES: Final = 256
_SMALL_WORDS: Final = [struct.Struct(f"<{n}H") for n in range(_SMALL_BYTES // 2 + 1)]


def _unpack_small(buf: bytes | bytearray | memoryview) -> npt.NDArray[np.float64] | None:
    """Default-dirty-zero decode of up to 64 floats, or None when the vectorised path must decide."""
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    size = len(buf)
    if size & 3:
        return None
    words = _SMALL_WORDS[size >> 1].unpack(buf)
    try:
        values = [
            _DECODE_BASE[w0] + _DECODE_SCALE[w0] * w1 for w0, w1 in zip(words[::2], words[1::2], strict=True)
        ]
    except TypeError:
        return None  # a reserved operand
    return np.array(values, dtype=np.float64)


def _pack_small(x: npt.NDArray[np.float64]) -> bytes | None:
    """Half-even encode of a few float64 values, or None when the vectorised path must decide."""
    out = []
    for v in x.tolist():
        if _FAST_HIGH > v >= F_MIN_NORMAL or -_FAST_HIGH < v <= -F_MIN_NORMAL:
            y = v * 4.0
            out.append(_PACK_TWICE(y, y)[2:6])
        elif v == 0.0:
            out.append(_ZERO_BYTES)
        else:
            return None
    return b"".join(out)


# A few plain floats in, Python floats out, no array (the simulated Cougar's memory, whose routines
# work in plain floats): one struct call for them all.  The encoding is the scalar fast path's (above)
# for every value at once: a big-endian single is its bytes 3 2 1 0 and the F words want 2 3 0 1, the
# same with each 16-bit word's bytes swapped, so one byteswap after the struct call.
# Whatever they decline (a reserved operand or dirty zero, a value not finite or beyond the F range, a
# non-float) goes to the vectorised path below, which decides and raises the precise errors.

_SINGLE_MIN: Final = math.ldexp(1.0, -126)
"""The least normal single: below it (but 0) a single has exponent 0."""
_RESERVED_ZERO: Final = b"\x00\x80\x00\x00"
"""The reserved operand with a zero fraction, which reads as the single -0.0 (the others as tiny ones)."""


@functools.cache
def _singles(count: int) -> struct.Struct:
    return struct.Struct(f">{count}f")


def unpack_f_few(raw: bytes | bytearray) -> list[float] | None:
    """The values of a few wire floats (default policies) as Python floats, or None when the vectorised
    decoder must decide: a word with exponent 0 but not a clean zero (a dirty zero or the reserved
    operand would read as a tiny single or -0.0) or exponent 255 (a single's infinity or NaN)."""
    if len(raw) & 3 or _RESERVED_ZERO in raw:  # (a match across two floats only costs the slow path)
        return None
    words = array.array("H", raw)
    words.byteswap()
    singles = _singles(len(raw) // 4).unpack(words.tobytes())
    magnitudes = list(map(abs, singles))
    if not math.isfinite(sum(magnitudes)) or min(filter(None, magnitudes), default=1.0) < _SINGLE_MIN:
        return None
    return [v * 0.25 for v in singles]


def pack_f_few(values: Sequence[float]) -> bytes | None:
    """Half-even wire floats of a few finite values within the F range (tiny ones flush to zero), or None
    (NaN, infinities, beyond F_MAX, not numbers): then the vectorised encoder decides."""
    try:
        magnitudes = list(map(abs, values))
        top = max(magnitudes, default=0.0)  # may pass a NaN over; their sum may not
        if not (top <= F_MAX and math.isfinite(sum(magnitudes))):
            return None
    except (TypeError, OverflowError):
        return None
    if top < _FAST_HIGH and min(filter(None, magnitudes), default=F_MIN_NORMAL) >= F_MIN_NORMAL:
        words = array.array("H", _singles(len(values)).pack(*[v * 4.0 + 0.0 for v in values]))
        words.byteswap()
        return words.tobytes()
    try:
        return b"".join([pack_f(v) for v in values])
    except EncodeError:
        return None  # not a float: the vectorised path converts it first


def _float64_values(
    values: Iterable[Any] | npt.NDArray[Any],
) -> tuple[npt.NDArray[np.float64] | list[Any], CodecError | None]:
    """The values up to the first non-float, flat, and the type error for that element (if any).

    The values come back as float64, or as a list when exactness needs the scalar path (long double).
    Arrays are judged by dtype; other iterables element by element, so a stray int is reported at its
    index exactly as the scalar encoder would, after any value error that comes before it.
    """
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    if isinstance(values, np.ndarray):
        flat = values.reshape(-1)
        if flat.dtype.kind != "f":
            error = _not_a_float(flat[0]).at("[0]", 0) if flat.size else None
            return np.zeros(0, np.float64), error
        if flat.dtype.itemsize > 8:
            return list(flat), None
        return flat.astype(np.float64, copy=False), None
    items = values if isinstance(values, (list, tuple)) else list(values)
    wide = False
    for i, v in enumerate(items):
        if type(v) is float:
            continue
        if not isinstance(v, (float, np.floating)):
            return _float64_values(items[:i])[0], _not_a_float(v).at(f"[{i}]", 4 * i)
        if not isinstance(v, float) and v.dtype.itemsize > 8:
            wide = True
    if wide:
        return list(items), None
    return np.array(items, dtype=np.float64).reshape(-1), None


def pack_f_array(
    values: Iterable[Any] | npt.NDArray[Any],
    *,
    rounding: Rounding = "half-even",
    underflow: Underflow = "zero",
) -> bytes:
    """Encode floats to consecutive wire floats, vectorised, with the scalar encoder's exact results.

    ``values``: a floating numpy array (any shape, taken flat) or an iterable of floats.  The first
    offending element raises the scalar error with ``path="[i]"`` and ``offset=4*i``.
    """
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    _check_encode(rounding, underflow)
    if (
        rounding == "half-even"
        and isinstance(values, np.ndarray)
        and values.dtype == np.float64
        and values.size <= _SMALL_BYTES // 4
    ):
        small = _pack_small(values.reshape(-1))
        if small is not None:
            return small
    x, type_error = _float64_values(values)
    if isinstance(x, list):
        out = bytearray()
        for i, v in enumerate(x):
            try:
                out += _U32.pack(f_to_u32(v, rounding=rounding, underflow=underflow))
            except CodecError as exc:
                raise exc.at(f"[{i}]", 4 * i) from None
        raw = bytes(out)
    else:
        raw = _pack_float64(x, rounding, underflow)
    if type_error is not None:
        raise type_error
    return raw


def _pack_float64(x: npt.NDArray[np.float64], rounding: str, underflow: str) -> bytes:
    import numpy as np  # noqa: PLC0415  # bulk only: see the imports

    b = np.ascontiguousarray(x).view(np.uint64)
    mag = b & 0x7FFFFFFFFFFFFFFF
    if rounding == "half-even":
        t = (mag >> _DROP) & 1
        t += (1 << (_DROP - 1)) - 1
        t += mag
    elif rounding == "half-away":
        t = mag + (1 << (_DROP - 1))
    else:
        t = mag.copy()
    t >>= _DROP  # now float64 exponent << 23 | rounded 23-bit fraction, carry included
    small = t < _MIN_T
    bad = t >= _OVER_T
    if underflow == "error":
        bad |= small & (mag != 0)
    if bad.any():
        i = int(bad.argmax())
        try:
            f_to_u32(float(x[i]), rounding=rounding, underflow=underflow)  # type: ignore[arg-type]
        except CodecError as exc:
            raise exc.at(f"[{i}]", 4 * i) from None
        raise AssertionError("unreachable: bulk and scalar encoders disagree")  # pragma: no cover
    t -= _F64_TO_F_BIAS << 23
    t |= (b >> 63) << 31
    t[small] = 0  # zeros and flushed values: clean zero, never a signed (reserved) one
    image = t.astype(np.uint32)
    u = (image >> 16) | (image << 16)
    return u.astype("<u4", copy=False).tobytes()


# ------------------------------------------------------------------------------------------ construct


def _construct_path(path: str) -> str:
    """construct's ``"(parsing) -> a -> b"`` as our dotted ``"a.b"`` (empty for compiled code's ``(???)``)."""
    parts = path.split(" -> ")
    return ".".join(parts[1:])


def _tell(stream: Any) -> int | None:
    try:
        return int(stream.tell())
    except Exception:  # a pipe or socket: no offset to report
        return None


def construct_parse(u: int, stream: Any, dirty_zero: str, reserved: str, path: str = "") -> float:
    """Decode for ``FFloat`` (interpreted): the error offset is where the 4 bytes began."""
    try:
        return u32_to_f(u, dirty_zero=dirty_zero, reserved=reserved)  # type: ignore[arg-type]
    except CodecError as exc:
        end = _tell(stream)
        raise exc.at(_construct_path(path), None if end is None else end - 4) from None


def construct_build(x: Any, stream: Any, rounding: str, underflow: str, path: str = "") -> int:
    """Encode for ``FFloat`` (interpreted): the error offset is where the bytes would go."""
    try:
        return f_to_u32(x, rounding=rounding, underflow=underflow)  # type: ignore[arg-type]
    except CodecError as exc:
        raise exc.at(_construct_path(path), _tell(stream)) from None


def construct_read(io: Any, dirty_zero: str, reserved: str) -> float:
    """Read and decode one float for compiled ``FFloat`` code (one call per field, nothing wrapped).

    A short read is construct's own ``StreamError``, as the interpreted ``Int32ul`` would raise.
    """
    data = io.read(4)
    if len(data) != 4:
        raise StreamError(f"stream read less than specified amount, expected 4, found {len(data)}", "(???)")
    return construct_parse(_U32.unpack(data)[0], io, dirty_zero, reserved)


def construct_write(x: Any, io: Any, rounding: str, underflow: str) -> Any:
    """Encode and write one float for compiled ``FFloat`` code; returns ``x`` as construct builders do."""
    io.write(_U32.pack(construct_build(x, io, rounding, underflow)))
    return x


class FFloat(Adapter):  # type: ignore[misc]  # construct is untyped
    """A PDP-11 float field for construct: ``Int32ul`` on the wire, an exact Python float in memory.

    Errors are raised as our ``DecodeError``/``EncodeError`` (with clause), not wrapped: construct passes
    exceptions that are not ``ConstructError`` through untouched, interpreted or compiled.  Interpreted,
    the error's ``path`` is the dotted field path (``"pose.values"``) and ``offset`` the stream position
    of the float; compiled code has no field names, so ``path`` is empty but ``offset`` is still set.
    ``_emitparse``/``_emitbuild`` let ``Struct.compile()`` inline the field (no per-field fallback).
    """

    def __init__(
        self,
        *,
        rounding: Rounding = "half-even",
        underflow: Underflow = "zero",
        dirty_zero: DirtyZero = "zero",
        reserved: Reserved = "error",
    ) -> None:
        super().__init__(Int32ul)
        _check_encode(rounding, underflow)
        _check_decode(dirty_zero, reserved)
        self.rounding: Rounding = rounding
        self.underflow: Underflow = underflow
        self.dirty_zero: DirtyZero = dirty_zero
        self.reserved: Reserved = reserved

    def __repr__(self) -> str:
        return (
            f"FFloat(rounding={self.rounding!r}, underflow={self.underflow!r}, "
            f"dirty_zero={self.dirty_zero!r}, reserved={self.reserved!r})"
        )

    def _parse(self, stream: Any, context: Any, path: str) -> float:
        u = self.subcon._parsereport(stream, context, path)
        return construct_parse(u, stream, self.dirty_zero, self.reserved, path)

    def _build(self, obj: Any, stream: Any, context: Any, path: str) -> Any:
        u = construct_build(obj, stream, self.rounding, self.underflow, path)
        self.subcon._build(u, stream, context, path)
        return obj

    def _decode(self, obj: int, context: Any, path: str) -> float:
        return u32_to_f(obj, dirty_zero=self.dirty_zero, reserved=self.reserved)

    def _encode(self, obj: Any, context: Any, path: str) -> int:
        return f_to_u32(obj, rounding=self.rounding, underflow=self.underflow)

    # Compiled code calls one helper per field that does the Int32ul read/write itself: going through
    # the subcon's emitted code would cost a nested ``reuse(..., lambda ...)`` per float (build 2x slower).

    def _emitparse(self, code: Any) -> str:
        code.append("from manip.codecs.pdp11float import construct_read")
        return f"construct_read(io, {self.dirty_zero!r}, {self.reserved!r})"

    def _emitbuild(self, code: Any) -> str:
        code.append("from manip.codecs.pdp11float import construct_write")
        return f"construct_write(obj, io, {self.rounding!r}, {self.underflow!r})"


Float32F: Final = FFloat()
"""The default field: half-even rounding, underflow to zero, dirty zero read as 0.0, reserved an error."""
