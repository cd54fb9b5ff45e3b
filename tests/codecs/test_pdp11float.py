"""PDP-11 F floats: golden vectors, an exact rational oracle, and agreement between the scalar, numpy and
construct codecs (clauses float.format, float.rounding, float.range, float.not-finite,
float.reserved-operand, float.dirty-zero, request-data.types)."""

from __future__ import annotations

import json
import math
from decimal import Decimal
from fractions import Fraction
from importlib import resources
from typing import Any

import numpy as np
import pytest
from construct import Array, Int16ul, StreamError, Struct
from hypothesis import example, given, settings
from hypothesis import strategies as st

from manip.codecs.errors import CodecError, DecodeError, EncodeError
from manip.codecs.pdp11float import (
    F_MAX,
    F_MIN_NORMAL,
    ROUNDINGS,
    FFloat,
    Float32F,
    f_to_u32,
    f_to_words,
    pack_f,
    pack_f_array,
    pack_f_few,
    u32_to_f,
    unpack_f,
    unpack_f_array,
    unpack_f_few,
    words_to_f,
)

VECTORS: dict[str, Any] = json.loads(resources.files("manip.vectors").joinpath("float.json").read_text())
ENCODE_POLICIES = ("rounding", "underflow")
DECODE_POLICIES = ("dirty_zero", "reserved")


def _same(a: float, b: float) -> bool:
    """Bit-for-bit float equality: 0.0 and -0.0 differ."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


def _fields(u: int) -> tuple[int, int, int]:
    """(sign, exponent, fraction) of a wire pattern, read from the bytes rather than the uint32."""
    b0, b1, b2, b3 = u.to_bytes(4, "little")
    w0, w1 = b0 | b1 << 8, b2 | b3 << 8
    return w0 >> 15, (w0 >> 7) & 0xFF, (w0 & 0x7F) << 16 | w1


def _is_reserved(u: int) -> bool:
    s, e, _ = _fields(u)
    return s == 1 and e == 0


# ------------------------------------------------------------------------------------------ oracles


def oracle_value(u: int) -> float:
    """Decode with rationals: (-1)^s * (2^23 + f) / 2^24 * 2^(e-128); exponent 0 is zero."""
    s, e, f = _fields(u)
    if e == 0:
        return 0.0
    v = Fraction(2**23 + f, 2**24) * Fraction(2) ** (e - 128)
    return float(-v if s else v)


def oracle_bytes(x: float | Fraction, rounding: str, underflow: str = "zero") -> bytes | str:
    """Encode with exact fractions, independent of the codec: the wire bytes, or the clause of the expected
    error."""
    if isinstance(x, float) and not math.isfinite(x):
        return "float.not-finite"
    if x == 0:
        return bytes(4)
    a = abs(Fraction(x))
    e = a.numerator.bit_length() - a.denominator.bit_length()
    while a >= Fraction(2) ** e:
        e += 1
    while a < Fraction(2) ** (e - 1):
        e -= 1
    scaled = a / Fraction(2) ** e * 2**24  # in [2^23, 2^24)
    q = math.floor(scaled)
    left = scaled - q
    if rounding == "half-away":
        q += left >= Fraction(1, 2)
    elif rounding == "half-even":
        q += left > Fraction(1, 2) or (left == Fraction(1, 2) and q % 2 == 1)
    if q == 2**24:
        q, e = 2**23, e + 1
    biased = e + 128
    if biased > 255:
        return "float.range"
    if biased < 1:
        return bytes(4) if underflow == "zero" else "float.range"
    frac = q - 2**23
    w0 = (0x8000 if x < 0 else 0) + biased * 128 + frac // 65536
    w1 = frac % 65536
    return bytes([w0 % 256, w0 // 256, w1 % 256, w1 // 256])


# ------------------------------------------------------------------------------------------ strategies

patterns = st.integers(0, 2**32 - 1)
exponent_zero = patterns.map(lambda u: u & 0xFFFF807F)  # clean, dirty and reserved zeros
edge_exponents = st.tuples(st.sampled_from([1, 2, 3, 127, 128, 129, 254, 255]), patterns).map(
    lambda t: (t[1] & 0xFFFF807F) | t[0] << 7
)
any_pattern = st.one_of(patterns, exponent_zero, edge_exponents)
valid_pattern = any_pattern.filter(lambda u: not _is_reserved(u))


@st.composite
def near_grid(draw: st.DrawFn) -> float:
    """Floats within an F unit of an F value, in 1/16 steps: ties, carries, both range ends."""
    e = draw(st.integers(1, 255))
    f = draw(st.integers(0, 2**23 - 1) | st.sampled_from([0, 1, 2**23 - 1]))
    k = draw(st.integers(-16, 16))
    v = math.ldexp((2**23 + f) * 16 + k, e - 152 - 4)
    return -v if draw(st.booleans()) else v


floats_any = st.one_of(
    st.floats(),
    st.floats(min_value=-2 * F_MAX, max_value=2 * F_MAX),
    st.floats(min_value=-4 * F_MIN_NORMAL, max_value=4 * F_MIN_NORMAL),
    near_grid(),
    st.sampled_from([F_MAX, -F_MAX, F_MIN_NORMAL, F_MIN_NORMAL / 2, 1 + 2**-24, -0.0, 1.7014118e38]),
)
roundings = st.sampled_from(ROUNDINGS)
underflows = st.sampled_from(["zero", "error"])
decode_policies = st.fixed_dictionaries(
    {"dirty_zero": st.sampled_from(["zero", "error"]), "reserved": st.sampled_from(["error", "zero"])}
)


def _outcome(fn: Any, *args: Any, **kwargs: Any) -> Any:
    """A result or a comparable summary of the error it raised."""
    try:
        return ("ok", fn(*args, **kwargs))
    except CodecError as exc:
        return (type(exc), exc.clause, exc.path, exc.offset, exc.message)


# ------------------------------------------------------------------------------------------ vectors


def _vector_cases() -> list[Any]:
    cases = []
    for v in VECTORS["vectors"]:
        policy = v.get("policy", {})
        if v["direction"] in ("both", "encode"):
            for rounding in v.get("rounding", ROUNDINGS):
                enc = {"rounding": rounding, **{k: policy[k] for k in policy if k in ENCODE_POLICIES}}
                cases.append(pytest.param("encode", v, enc, id=f"{v['name']}-encode-{rounding}"))
        if v["direction"] in ("both", "decode"):
            dec = {k: policy[k] for k in policy if k in DECODE_POLICIES}
            cases.append(pytest.param("decode", v, dec, id=f"{v['name']}-decode"))
    return cases


def test_vector_file_shape() -> None:
    assert VECTORS["format"] == "manip-vectors/1"
    assert VECTORS["subject"] == "pdp11-f-float"
    names = [v["name"] for v in VECTORS["vectors"]]
    assert len(names) == len(set(names))
    for v in VECTORS["vectors"]:
        assert v["direction"] in ("both", "encode", "decode")
        assert "hex" in v or ("error" in v and v["direction"] == "encode")
        assert "value_hex" in v or ("error" in v and v["direction"] == "decode")
        if isinstance(v.get("value"), float):  # a JSON number must name the same double as value_hex
            assert _same(v["value"], float.fromhex(v["value_hex"]))
        if "hex" in v:
            assert len(v["hex"]) == 8 and v["hex"] == v["hex"].lower()


@pytest.mark.parametrize(("op", "vector", "policy"), _vector_cases())
def test_golden_vector(op: str, vector: dict[str, Any], policy: dict[str, str]) -> None:
    clause = vector.get("error", {}).get("clause")
    if op == "encode":
        x = float.fromhex(vector["value_hex"])
        if clause:
            with pytest.raises(EncodeError) as info:
                pack_f(x, **policy)
            assert info.value.clause == clause
            with pytest.raises(EncodeError) as info:
                pack_f_array([x], **policy)
            assert (info.value.clause, info.value.offset) == (clause, 0)
            assert oracle_bytes(x, **policy) == clause
            return
        wire = bytes.fromhex(vector["hex"])
        assert pack_f(x, **policy) == wire
        assert pack_f_array(np.array([x, x]), **policy) == wire * 2
        w0, w1 = f_to_words(x, **policy)
        assert bytes([w0 & 0xFF, w0 >> 8, w1 & 0xFF, w1 >> 8]) == wire
        assert FFloat(**policy).build(x) == wire
        assert oracle_bytes(x, **policy) == wire
    else:
        wire = bytes.fromhex(vector["hex"])
        if clause:
            with pytest.raises(DecodeError) as info:
                unpack_f(wire, **policy)
            assert info.value.clause == clause
            with pytest.raises(DecodeError) as info:
                unpack_f_array(wire, **policy)
            assert info.value.clause == clause
            with pytest.raises(DecodeError) as info:
                FFloat(**policy).parse(wire)
            assert info.value.clause == clause
            return
        want = float.fromhex(vector["value_hex"])
        assert _same(unpack_f(wire, **policy), want)
        assert _same(float(unpack_f_array(wire, **policy)[0]), want)
        assert _same(words_to_f(wire[0] | wire[1] << 8, wire[2] | wire[3] << 8, **policy), want)
        assert _same(FFloat(**policy).parse(wire), want)


def test_vectors_cover_the_table() -> None:
    """Every row of the rounding table (and the non-finite errors) is present."""
    by_hex = {(v.get("hex"), v["direction"]) for v in VECTORS["vectors"]}
    for row in [
        "80400000",
        "80c00000",
        "00400000",
        "00410000",
        "40410000",
        "ff7fffff",
        "80000000",
        "00000000",
    ]:
        assert (row, "both") in by_hex
    for row in ["4941db0f", "4941da0f", "cc3ecdcc", "cc3ecccc", "80400100"]:
        assert (row, "encode") in by_hex
    clauses = {v.get("error", {}).get("clause") for v in VECTORS["vectors"]}
    assert {"float.range", "float.not-finite", "float.reserved-operand", "float.dirty-zero"} <= clauses


# ------------------------------------------------------------------------------------------ properties


@settings(max_examples=300)
@given(any_pattern, roundings)
def test_every_pattern_decodes_and_reencodes(u: int, rounding: str) -> None:
    if _is_reserved(u):
        with pytest.raises(DecodeError) as info:
            u32_to_f(u)
        assert info.value.clause == "float.reserved-operand"
        assert u32_to_f(u, reserved="zero") == 0.0
        return
    x = u32_to_f(u)
    assert _same(x, oracle_value(u))
    clean = 0 if _fields(u)[1] == 0 else u
    assert f_to_u32(x, rounding=rounding, underflow="error") == clean  # type: ignore[arg-type]


@given(valid_pattern)
def test_decode_encode_roundtrip_of_representable_values(u: int) -> None:
    x = u32_to_f(u)
    for rounding in ROUNDINGS:
        for v in (x, -x):
            assert _same(u32_to_f(f_to_u32(v, rounding=rounding)), v if v != 0 else 0.0)  # type: ignore[arg-type]


@settings(max_examples=400)
@given(floats_any, roundings, underflows)
def test_encode_matches_rational_oracle(x: float, rounding: str, underflow: str) -> None:
    want = oracle_bytes(x, rounding, underflow)
    got = _outcome(pack_f, x, rounding=rounding, underflow=underflow)
    if isinstance(want, str):
        assert got[0] is EncodeError and got[1] == want
    else:
        assert got == ("ok", want)


# The scalar fast paths (default policies) against the oracles: the switch to the checked path sits at
# 2^-128 and just below 2^126, so values straddling both are drawn on purpose.
_FAST_EDGES = [
    math.ldexp(1.0, 126) - math.ldexp(1.0, 101),
    math.ldexp(1.0, 126) - math.ldexp(1.0, 102),
    math.ldexp(1.0, 126),
    math.ldexp(1.0, -126),
    F_MIN_NORMAL,
    F_MIN_NORMAL * (1 - 2**-25),
    F_MIN_NORMAL * (1 - 2**-24),
]
fast_edges = st.tuples(st.sampled_from(_FAST_EDGES), st.integers(-3, 3), st.booleans()).map(
    lambda t: -math.nextafter(t[0], math.inf * t[1]) if t[2] else math.nextafter(t[0], math.inf * t[1])
)


@settings(max_examples=400)
@given(floats_any | fast_edges, underflows)
def test_half_even_encode_matches_the_oracle_either_side_of_the_fast_path(x: float, underflow: str) -> None:
    want = oracle_bytes(x, "half-even", underflow)
    got = _outcome(pack_f, x, underflow=underflow)
    assert got == ("ok", want) if isinstance(want, bytes) else got[:2] == (EncodeError, want)


@settings(max_examples=400)
@given(any_pattern, st.integers(0, 5))
def test_default_decode_matches_the_oracle_at_any_offset(u: int, offset: int) -> None:
    buf = bytes(range(offset)) + u.to_bytes(4, "little")
    if _is_reserved(u):
        with pytest.raises(DecodeError) as info:
            unpack_f(buf, offset)
        assert (info.value.clause, info.value.offset) == ("float.reserved-operand", offset)
    else:
        assert _same(unpack_f(buf, offset), oracle_value(u))
    with pytest.raises(DecodeError):
        unpack_f(buf[:-1], offset)  # one byte short
    with pytest.raises(DecodeError):
        unpack_f(buf, -4)  # never read from the end


@settings(max_examples=300)
@given(st.lists(any_pattern, max_size=20), st.sampled_from(["error", "zero"]))
def test_array_decode_of_few_and_many_floats_matches_the_oracle(us: list[int], reserved: str) -> None:
    """Up to 64 floats take the scalar tables, more the vectorised path: both against the oracle."""
    raw = b"".join(u.to_bytes(4, "little") for u in us)
    for copies in (1, 5):
        reserved_at = next((i for i, u in enumerate(us * copies) if _is_reserved(u)), None)
        if reserved_at is not None and reserved == "error":
            with pytest.raises(DecodeError) as info:
                unpack_f_array(raw * copies, reserved=reserved)  # type: ignore[arg-type]
            assert info.value.offset == 4 * reserved_at
            continue
        got = unpack_f_array(raw * copies, reserved=reserved).tolist()  # type: ignore[arg-type]
        assert all(_same(a, oracle_value(u)) for a, u in zip(got, us * copies, strict=True))


@settings(max_examples=300)
@given(st.lists(floats_any | fast_edges, max_size=20), underflows)
def test_array_encode_of_few_and_many_floats_matches_the_oracle(xs: list[float], underflow: str) -> None:
    for copies in (1, 5):
        wants = [oracle_bytes(x, "half-even", underflow) for x in xs * copies]
        bad = next((i for i, w in enumerate(wants) if isinstance(w, str)), None)
        array = np.array(xs * copies, dtype=np.float64)
        if bad is not None:
            with pytest.raises(EncodeError) as info:
                pack_f_array(array, underflow=underflow)  # type: ignore[arg-type]
            assert (info.value.clause, info.value.offset) == (wants[bad], 4 * bad)
            continue
        assert pack_f_array(array, underflow=underflow) == b"".join(wants)  # type: ignore[arg-type, misc]


@settings(max_examples=300)
@given(st.lists(floats_any | fast_edges, max_size=130), st.lists(any_pattern, max_size=130))
@example([], [0x0000_8000, 0x0000_4080])  # the reserved operand with a zero fraction reads as -0.0 in IEEE
@example([], [0x0001_0000, 0x0000_0001])  # dirty zeros
def test_the_few_float_codecs_match_the_oracle_or_decline(xs: list[float], us: list[int]) -> None:
    """pack_f_few / unpack_f_few (plain floats, default policies): the oracle's bytes and values, or None
    where the vectorised codecs must decide (an error, saturation, a reserved operand, a dirty zero)."""
    packed = pack_f_few(xs)
    wants = [oracle_bytes(x, "half-even", "zero") for x in xs]
    if packed is not None:
        assert packed == b"".join(wants)  # type: ignore[arg-type]
    else:
        assert any(isinstance(w, str) for w in wants)  # the vectorised encoder raises or saturates
    values = unpack_f_few(b"".join(u.to_bytes(4, "little") for u in us))
    if values is not None:
        assert not any(_is_reserved(u) for u in us)
        assert all(_same(a, oracle_value(u)) for a, u in zip(values, us, strict=True))


@settings(max_examples=200)
@given(st.floats(width=32) | st.floats(width=16), roundings, underflows)
def test_numpy_scalar_inputs_match_the_oracle(x: float, rounding: str, underflow: str) -> None:
    for typ in (np.float32, np.float16):
        with np.errstate(over="ignore"):
            narrow = typ(x)
        if float(narrow) == x or math.isnan(x):
            want = oracle_bytes(x, rounding, underflow)
            got = _outcome(pack_f, narrow, rounding=rounding, underflow=underflow)
            assert got == ("ok", want) if isinstance(want, bytes) else got[:2] == (EncodeError, want)


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="long double has no more bits than float64")
@settings(max_examples=100)
@given(st.integers(2**63, 2**64 - 1), st.integers(-260, 200), st.booleans(), roundings, underflows)
def test_long_double_inputs_match_the_oracle(
    mant: int, exp: int, negative: bool, rounding: str, underflow: str
) -> None:
    """A long double is rounded once from all its bits (where the platform has more than 53)."""
    x = np.longdouble(mant) * np.longdouble(2) ** exp
    exact = Fraction(*x.as_integer_ratio())
    assert exact == Fraction(mant) * Fraction(2) ** exp
    if negative:
        x, exact = -x, -exact
    want = oracle_bytes(exact, rounding, underflow)
    got = _outcome(pack_f, x, rounding=rounding, underflow=underflow)
    assert got == ("ok", want) if isinstance(want, bytes) else got[:2] == (EncodeError, want)


@settings(max_examples=60)
@given(st.lists(any_pattern, max_size=40), decode_policies)
def test_numpy_decode_agrees_with_scalar(us: list[int], policy: dict[str, Any]) -> None:
    raw = b"".join(u.to_bytes(4, "little") for u in us)

    def scalar() -> list[float]:
        return [unpack_f(raw, 4 * i, **policy) for i in range(len(us))]

    want = _outcome(scalar)
    got = _outcome(lambda: unpack_f_array(raw, **policy).tolist())
    if want[0] == "ok":
        assert got[0] == "ok"
        assert all(_same(a, b) for a, b in zip(got[1], want[1], strict=True))
    else:
        i = want[3] // 4
        assert got == (want[0], want[1], f"[{i}]", want[3], want[4])
        assert _outcome(unpack_f_array, np.array(us, dtype=np.uint32), **policy) == got


@settings(max_examples=60)
@given(st.lists(floats_any | st.integers(-3, 3), max_size=40), roundings, underflows)
def test_numpy_encode_agrees_with_scalar(xs: list[Any], rounding: str, underflow: str) -> None:
    def scalar() -> bytes:
        out = b""
        for i, x in enumerate(xs):
            try:
                out += pack_f(x, rounding=rounding, underflow=underflow)  # type: ignore[arg-type]
            except CodecError as exc:
                raise exc.at(f"[{i}]", 4 * i) from None
        return out

    want = _outcome(scalar)
    assert _outcome(pack_f_array, xs, rounding=rounding, underflow=underflow) == want
    if all(isinstance(x, float) for x in xs):
        arr = np.array(xs, dtype=np.float64).reshape(-1, 1)
        assert _outcome(pack_f_array, arr, rounding=rounding, underflow=underflow) == want


RECORD = Struct("n" / Int16ul, "v" / Array(12, Float32F))
RECORD_C = RECORD.compile()


def test_compiled_record_inlines_ffloat() -> None:
    assert "construct_read(" in RECORD_C.source and "construct_write(" in RECORD_C.source
    assert "linkedparsers[" not in RECORD_C.source and "linkedbuilders[" not in RECORD_C.source
    assert RECORD.sizeof() == 50


@settings(max_examples=60)
@given(st.lists(any_pattern, min_size=12, max_size=12), decode_policies)
def test_construct_decode_agrees_with_scalar(us: list[int], policy: dict[str, Any]) -> None:
    raw = b"\x07\x00" + b"".join(u.to_bytes(4, "little") for u in us)
    want = _outcome(lambda: [unpack_f(raw, 2 + 4 * i, **policy) for i in range(12)])
    rec = Struct("n" / Int16ul, "v" / Array(12, FFloat(**policy)))
    for codec, path in ((rec, "v"), (rec.compile(), "")):
        got = _outcome(lambda c=codec: list(c.parse(raw).v))
        if want[0] == "ok":
            assert got[0] == "ok" and all(_same(a, b) for a, b in zip(got[1], want[1], strict=True))
        else:
            assert got == (want[0], want[1], path, want[3], want[4])


@settings(max_examples=60)
@given(st.lists(floats_any, min_size=12, max_size=12), roundings, underflows)
def test_construct_encode_agrees_with_scalar(xs: list[float], rounding: str, underflow: str) -> None:
    want = _outcome(lambda: b"\x07\x00" + pack_f_array(xs, rounding=rounding, underflow=underflow))
    rec = Struct("n" / Int16ul, "v" / Array(12, FFloat(rounding=rounding, underflow=underflow)))  # type: ignore[arg-type]
    for codec, path in ((rec, "v"), (rec.compile(), "")):
        got = _outcome(codec.build, {"n": 7, "v": xs})
        if want[0] == "ok":
            assert got == want
        else:  # bulk offsets count from the first float; the record has a 2-byte word before it
            assert got == (want[0], want[1], path, want[3] + 2, want[4])


# ------------------------------------------------------------------------------------------ errors


@pytest.mark.parametrize(
    ("x", "clause"),
    [
        (math.nan, "float.not-finite"),
        (math.inf, "float.not-finite"),
        (-math.inf, "float.not-finite"),
        (1e39, "float.range"),
        (-1.7014118e38, "float.range"),
        (math.ldexp(2**25 - 1, 102), "float.range"),  # overflow only through the rounding carry
        (1, "request-data.types"),
        (True, "request-data.types"),
        (np.int64(3), "request-data.types"),
        ("1.0", "request-data.types"),
        (None, "request-data.types"),
        (Decimal("1.5"), "request-data.types"),
        (Fraction(1, 2), "request-data.types"),
        (np.float32("nan"), "float.not-finite"),
    ],
)
def test_encode_errors(x: Any, clause: str) -> None:
    for fn in (f_to_u32, pack_f, f_to_words):
        with pytest.raises(EncodeError) as info:
            fn(x)
        assert info.value.clause == clause
    with pytest.raises(EncodeError) as info:
        pack_f_array([1.0, x])
    assert (info.value.clause, info.value.path, info.value.offset) == (clause, "[1]", 4)


def test_overflow_carry_depends_on_rounding() -> None:
    x = math.ldexp(2**25 - 1, 102)  # exactly half an F unit above F_MAX
    assert pack_f(x, rounding="truncate") == bytes.fromhex("ff7fffff")
    for rounding in ("half-even", "half-away"):
        with pytest.raises(EncodeError, match="range"):
            pack_f(x, rounding=rounding)  # type: ignore[arg-type]


def test_underflow_policy_and_rounding_up_to_min() -> None:
    just_below = F_MIN_NORMAL * (1 - 2**-30)
    assert pack_f(just_below) == bytes.fromhex("80000000")  # rounds up into range: kept
    assert pack_f(just_below, rounding="truncate") == bytes(4)
    with pytest.raises(EncodeError) as info:
        pack_f(-just_below, rounding="truncate", underflow="error")
    assert info.value.clause == "float.range"
    assert pack_f(-1e-300) == bytes(4)
    assert pack_f(-5e-324) == bytes(4)  # a float64 subnormal
    with pytest.raises(EncodeError):
        pack_f_array(np.array([1.0, 0.0, -0.0, 1e-39]), underflow="error")


@pytest.mark.parametrize(
    ("hexbytes", "policy", "cls", "clause"),
    [
        ("00800000", {}, DecodeError, "float.reserved-operand"),
        ("7f803412", {}, DecodeError, "float.reserved-operand"),
        ("00000100", {"dirty_zero": "error"}, DecodeError, "float.dirty-zero"),
        ("01000000", {"dirty_zero": "error"}, DecodeError, "float.dirty-zero"),
    ],
)
def test_decode_errors(hexbytes: str, policy: dict[str, Any], cls: type, clause: str) -> None:
    wire = bytes.fromhex(hexbytes)
    with pytest.raises(cls) as info:
        unpack_f(b"\0\0" + wire, 2, **policy)
    assert (info.value.clause, info.value.offset) == (clause, 2)
    with pytest.raises(cls) as info:
        unpack_f_array(bytes.fromhex("80400000") + wire, **policy)
    assert (info.value.clause, info.value.path, info.value.offset) == (clause, "[1]", 4)
    u = int.from_bytes(wire, "little")
    with pytest.raises(cls):
        words_to_f(u & 0xFFFF, u >> 16, **policy)


def test_malformed_inputs() -> None:
    with pytest.raises(DecodeError) as info:
        unpack_f(b"\x80\x40\x00", 0)
    assert info.value.clause == "float.format"
    with pytest.raises(DecodeError) as info:
        unpack_f_array(b"\x80\x40\x00\x00\x01")
    assert (info.value.clause, info.value.offset) == ("float.format", 4)
    for bad in (-1, 2**32, 1.0, True):
        with pytest.raises(DecodeError):
            u32_to_f(bad)  # type: ignore[arg-type]
    with pytest.raises(DecodeError):
        words_to_f(0x10000, 0)
    with pytest.raises(TypeError):
        unpack_f_array(np.zeros(4, dtype=np.int16))
    with pytest.raises(EncodeError) as info:
        pack_f_array(np.arange(3))
    assert (info.value.clause, info.value.path) == ("request-data.types", "[0]")


@pytest.mark.parametrize(
    "call",
    [
        lambda: f_to_u32(1.0, rounding="nearest"),
        lambda: f_to_u32(0.0, underflow="flush"),
        lambda: u32_to_f(0, reserved="ignore"),
        lambda: pack_f_array([1.0], rounding="up"),
        lambda: unpack_f_array(b"", dirty_zero="warn"),
        lambda: FFloat(reserved="warn"),
    ],
)
def test_unknown_policy_is_rejected(call: Any) -> None:
    with pytest.raises(ValueError, match="must be one of"):
        call()


# ------------------------------------------------------------------------------------------ inputs


def test_input_kinds() -> None:
    one = bytes.fromhex("80400000")
    buf = one + bytes.fromhex("807f0000")
    for b in (buf, bytearray(buf), memoryview(buf), np.frombuffer(buf, dtype=np.uint8)):
        assert unpack_f_array(b).tolist() == [1.0, 2.0**126]
    assert unpack_f_array(np.frombuffer(buf, "<u4").astype(np.uint32)).tolist() == [1.0, 2.0**126]
    assert unpack_f_array(memoryview(b"\0" + buf)[1:]).tolist() == [1.0, 2.0**126]  # unaligned
    assert unpack_f_array(b"").shape == (0,)
    assert pack_f_array([]) == b""
    assert pack_f_array(x for x in [1.0]) == one
    assert pack_f(np.float32(1.0)) == pack_f(np.float64(1.0)) == pack_f(np.float16(1.0)) == one


def test_float32_input_is_exact_at_the_exponent_ends() -> None:
    """F exponents 1, 2 and 255 are float32 subnormals / top binade: no float32 shortcut may be used."""
    values = [F_MIN_NORMAL, 3 * F_MIN_NORMAL, 2.0**126, F_MAX, -F_MAX, 1.5 * 2**-127]
    want = b"".join(pack_f(v) for v in values)
    assert pack_f_array(np.array(values, dtype=np.float32)) == want
    assert unpack_f_array(want).tolist() == values


def test_long_double_rounds_once() -> None:
    ld = np.longdouble
    x = ld(1) + ld(2) ** -24 + ld(2) ** -60  # just above the tie (if long double has the bits)
    if np.finfo(ld).nmant < 63:
        pytest.skip("long double is float64 here")
    assert pack_f(x) == bytes.fromhex("80400100")
    assert pack_f_array(np.array([x], dtype=np.longdouble)) == bytes.fromhex("80400100")
    assert pack_f_array([1.0, x]) == bytes.fromhex("8040000080400100")


def test_words() -> None:
    assert f_to_words(1.0) == (0x4080, 0x0000)
    assert f_to_words(3.14159265) == (0x4149, 0x0FDB)
    assert f_to_words(0.1, rounding="truncate") == (0x3ECC, 0xCCCC)
    assert words_to_f(0o077777, 0o177777) == F_MAX
    assert words_to_f(0o000200, 0) == F_MIN_NORMAL


def test_construct_error_surface() -> None:
    """Errors come out of construct as our own classes, located; compiled code has no field path."""
    raw = b"\x07\x00" + bytes.fromhex("80400000") * 5 + bytes.fromhex("00800000") + bytes(24)
    with pytest.raises(DecodeError) as info:
        RECORD.parse(raw)
    assert (info.value.path, info.value.offset, info.value.clause) == ("v", 22, "float.reserved-operand")
    with pytest.raises(DecodeError) as info:
        RECORD_C.parse(raw)
    assert (info.value.path, info.value.offset) == ("", 22)
    with pytest.raises(EncodeError) as info:
        RECORD_C.build({"n": 1, "v": [1.0] * 11 + [1]})
    assert (info.value.offset, info.value.clause) == (46, "request-data.types")
    assert Float32F.build(-0.0) == bytes(4)
    for codec in (RECORD, RECORD_C):  # a short read stays construct's own StreamError
        with pytest.raises(StreamError):
            codec.parse(RECORD.build({"n": 1, "v": [1.0] * 12})[:-3])
    assert repr(Float32F).startswith("FFloat(rounding='half-even'")
