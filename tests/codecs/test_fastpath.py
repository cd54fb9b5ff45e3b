"""The fast numeric decoder must agree with the construct reference, and decline whatever it cannot judge."""

from __future__ import annotations

import struct
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from manip.codecs.errors import CodecError
from manip.codecs.fastpath import plan
from manip.codecs.messages import _codec, response_layout
from manip.spec import SPEC, Layout

LAYOUTS = [op.request for op in SPEC.requests.values()] + [
    response_layout(op) for op in SPEC.requests.values()
]
PLANNED = [
    (layout, numbered) for layout in LAYOUTS for numbered in (False, True) if plan(layout, numbered=numbered)
]

# Float words biased towards the exponents the IEEE identity cannot handle (0, 1, 2, 254, 255).
special_w0 = st.sampled_from([0, 1, 2, 254, 255]).flatmap(
    lambda e: st.tuples(st.integers(0, 1), st.integers(0, 0x7F)).map(lambda sf: sf[0] << 15 | e << 7 | sf[1])
)
word = st.one_of(st.integers(0, 0xFFFF), special_w0, st.just(0), st.just(0x8000))


@st.composite
def payload(draw: st.DrawFn) -> tuple[Layout, bool, bytes]:
    layout, numbered = draw(st.sampled_from(PLANNED))
    fast = plan(layout, numbered=numbered)
    assert fast is not None
    words = draw(st.lists(word, min_size=fast.size // 2, max_size=fast.size // 2))
    return layout, numbered, struct.pack(f"<{len(words)}H", *words)


def _reference(layout: Layout, numbered: bool, data: bytes) -> dict[str, Any] | None:
    codec = _codec(layout)
    try:
        parsed = (codec.with_number if numbered else codec.struct).parse(data)
    except CodecError:
        return None
    out = {
        f.name: tuple(parsed[f.name]) if isinstance(parsed[f.name], list) else parsed[f.name]
        for f in layout.fields
    }
    if numbered:
        out["request_number"] = parsed["request_number"]
    return out


@settings(max_examples=500)
@given(payload())
def test_fast_path_agrees_with_construct(case: tuple[Layout, bool, bytes]) -> None:
    layout, numbered, data = case
    fast = plan(layout, numbered=numbered)
    assert fast is not None
    result = fast.parse(data)
    expected = _reference(layout, numbered, data)
    if expected is None:
        assert result is None  # the reference rejects it (reserved operand): the fast path must not accept
        return
    if result is None:
        return  # declined (e.g. dirty zero, exponent 255): the reference decides
    number, values = result
    if numbered:
        assert number == expected.pop("request_number")
    assert values == expected


def test_fast_path_declines_wrong_sizes() -> None:
    fast = plan(SPEC.request("here").response.data, numbered=True)
    assert fast is not None and fast.size == 50
    assert fast.parse(b"\0" * 48) is None
    assert plan(SPEC.request("free-joint").request, numbered=False) is None  # a `small` field
    assert plan(SPEC.request("examine-wrist").response.data, numbered=True) is None  # counted words


# Values for the encoder: exact types mixed with near misses (bools, ints for floats, floats for words),
# words just out of range, and floats at the ends of the IEEE identity (both F range ends, exponents 1
# and 254, subnormal singles, -0.0, infinities, NaN).
_EDGE_FLOATS = [0.0, -0.0, 1.0, -2.5, 2.0**-128, 2.0**-127, 2.0**-129, 2.0**125, 2.0**126, 1.7e38, 1e-300]
float_value = st.one_of(
    st.floats(),
    st.floats(min_value=-1e4, max_value=1e4),
    st.sampled_from(_EDGE_FLOATS),
    st.integers(-2, 2),
    st.booleans(),
)
word_value = st.one_of(st.integers(0, 0xFFFF), st.integers(-0x8001, 0x10000), st.booleans(), st.just(1.0))


@st.composite
def build_case(draw: st.DrawFn) -> tuple[Layout, bool, dict[str, Any], int]:
    layout, numbered = draw(st.sampled_from(PLANNED))
    values: dict[str, Any] = {}
    for f in layout.fields:
        element = float_value if f.type.element == "float" else word_value
        count = f.type.count
        assert count is not None
        if count == 1:
            values[f.name] = draw(element)
        else:
            size = draw(st.sampled_from([count, count, count, count - 1]))
            values[f.name] = draw(st.lists(element, min_size=size, max_size=size).map(tuple))
    if layout.fields and draw(st.integers(0, 9)) == 0:
        values.pop(layout.fields[0].name)
    number = draw(st.integers(0, 0xFFFF) | st.just(0x10000) | st.just(True))
    return layout, numbered, values, number


@settings(max_examples=500)
@given(build_case())
def test_fast_build_agrees_with_construct(case: tuple[Layout, bool, dict[str, Any], int]) -> None:
    layout, numbered, values, number = case
    fast = plan(layout, numbered=numbered)
    assert fast is not None
    built = fast.build(values, number if numbered else None)
    if built is None:
        return  # declined: the reference decides (and reports)
    codec = _codec(layout)
    obj = {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
    reference = (
        codec.with_number.build({"request_number": number, **obj}) if numbered else codec.struct.build(obj)
    )
    assert built == reference


def test_fast_build_takes_the_common_cases() -> None:
    here = plan(SPEC.request("here").response.data, numbered=True)
    assert here is not None
    transform = (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -150.5, 431.75, 20.25)
    built = here.build({"transform": transform}, 7)
    assert built is not None and here.parse(built) == (7, {"transform": transform})
    assert here.build({"transform": (-0.0, *transform[1:])}, 7) is None  # -0.0: the reference cleans it
    assert here.build({"transform": transform[:11]}, 7) is None
    assert here.build({"transform": transform, "extra": 1}, 7) is None
