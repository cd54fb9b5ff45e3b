"""Cougar word codecs and COMINT's streaming semantics (the 1985 guide, B.7, Table 1)."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.codecs.cougar import (
    CougarMsg,
    Malformed,
    OutOfSync,
    WordStream,
    decode,
    encode,
    lookup,
)
from manip.codecs.errors import DecodeError, EncodeError
from manip.spec import SPEC, CougarMessage
from tests.support.strategies import cougar_values

commands = st.sampled_from(sorted(SPEC.cougar_commands.values(), key=lambda m: m.code))
responses = st.sampled_from(sorted(SPEC.cougar_responses.values(), key=lambda m: m.code))


def _msgs(table: st.SearchStrategy[CougarMessage]) -> st.SearchStrategy[tuple[CougarMessage, dict[str, Any]]]:
    return table.flatmap(lambda m: st.tuples(st.just(m), cougar_values(m)))


def _eq(a: Any, b: Any) -> bool:
    if isinstance(a, tuple):
        return all(_eq(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return a == b or (a == 0 and b == 0 and math.copysign(1, a) != math.copysign(1, b))
    return bool(a == b)


@given(_msgs(commands))
def test_commands_round_trip(case: tuple[CougarMessage, dict[str, Any]]) -> None:
    msg, values = case
    words = encode("command", msg.name, **values)
    assert words[0] == msg.code
    if msg.data_words is not None:
        assert len(words) == 1 + msg.data_words  # cougar.command.layout
    out = decode("command", words)
    assert all(_eq(out.values[k], v) for k, v in values.items())


@given(_msgs(responses))
def test_responses_round_trip(case: tuple[CougarMessage, dict[str, Any]]) -> None:
    msg, values = case
    out = decode("response", encode("response", msg.name, **values))
    assert all(_eq(out.values[k], v) for k, v in values.items())


def test_table_1_examples() -> None:
    assert encode("command", "NOP") == [0]
    assert encode("command", "DPST", address=0o1000, value=7) == [11, 0o1000, 7]
    assert encode("command", "VERS", version=3) == [13, 3]
    # GUARDS: bit 15 = stop the move, index in the low 4 bits, then dvec (6 floats) and tol.
    words = encode("command", "GUARDS", type_index=0x8000 | 5, dvec=(0.0, 0.0, 1.0, 0.0, 0.0, 0.0), tol=10.0)
    assert len(words) == 16 and words[1] == 0x8005
    assert words[6:8] == [0x4080, 0x0000]  # 1.0 as two words, sign/exponent word first
    reply = decode("response", [4, 3, 10, 20, 30])  # EXMN data: count then words
    assert reply.values["words"] == (10, 20, 30)
    raw = decode("response", [9, *[(-5) & 0xFFFF] * 8])
    assert raw.values["gauges"] == (-5,) * 8


@given(
    st.lists(_msgs(commands), max_size=8),
    st.lists(st.integers(0, 400), max_size=10),
)
def test_chunking_never_changes_the_result(
    msgs: list[tuple[CougarMessage, dict[str, Any]]], cuts: list[int]
) -> None:
    words = [w for m, v in msgs for w in encode("command", m.name, **v)]
    whole = WordStream("command").feed(words)
    stream = WordStream("command")
    pieces: list[CougarMsg | OutOfSync | Malformed] = []
    start = 0
    for cut in sorted(c % (len(words) + 1) for c in cuts):
        pieces += stream.feed(words[start:cut])
        start = max(start, cut)
    pieces += stream.feed(words[start:])
    assert [p.words for p in pieces if isinstance(p, CougarMsg)] == [
        p.words for p in whole if isinstance(p, CougarMsg)
    ]
    assert len(whole) == len(msgs) and stream.pending == ()


def test_partial_command_waits() -> None:
    stream = WordStream("command")
    words = encode("command", "NFV", offset=(1.0, 2.0, 3.0))
    assert stream.feed(words[:-1]) == []  # cougar.comint.partial-waits
    assert stream.pending == tuple(words[:-1])
    (msg,) = stream.feed(words[-1:])
    assert isinstance(msg, CougarMsg) and msg.values["offset"] == (1.0, 2.0, 3.0)


@given(
    st.lists(_msgs(commands), min_size=1, max_size=4),
    st.integers(20, 0xFFFF),
    st.lists(st.integers(0, 0xFFFF), max_size=20),
)
def test_out_of_sync_recovers_at_the_next_command(
    msgs: list[tuple[CougarMessage, dict[str, Any]]], bad: int, junk: list[int]
) -> None:
    stream = WordStream("command")
    items = stream.feed([bad, *junk])
    assert len(items) == 1 and isinstance(items[0], OutOfSync)
    assert items[0].code == bad and items[0].discarded == (bad, *junk)  # cougar.comint.unknown-code
    assert stream.pending == ()
    good = [w for m, v in msgs for w in encode("command", m.name, **v)]
    assert [p.name for p in stream.feed(good) if isinstance(p, CougarMsg)] == [m.name for m, _ in msgs]


def test_reserved_float_in_a_stream_is_reported_and_consumed() -> None:
    stream = WordStream("response")
    words = encode("response", "FORCES", forces=(1.0,) * 6)
    words[3:5] = [0x8000, 0]
    items = stream.feed([*words, 8, 2])
    assert isinstance(items[0], Malformed) and items[0].error.clause == "float.reserved-operand"
    assert isinstance(items[1], CougarMsg) and items[1].values["version"] == 2


def test_errors() -> None:
    with pytest.raises(DecodeError) as err:
        decode("command", [99])
    assert err.value.clause == "cougar.comint.unknown-code"
    with pytest.raises(DecodeError) as err:
        decode("command", [4, 0, 0])
    assert err.value.clause == "cougar.comint.partial-waits"
    with pytest.raises(DecodeError) as err:
        decode("command", [13, 1, 2])
    assert err.value.clause == "cougar.command.layout"
    with pytest.raises(EncodeError):
        encode("command", "SEN", theta_sensed=(1.0,) * 5)
    with pytest.raises(EncodeError):
        encode("command", "WGOV", offsets=(40000,) * 8)
    with pytest.raises(KeyError):
        lookup("command", "NOPE")
    with pytest.raises(ValueError):
        WordStream("command").feed([70000])
