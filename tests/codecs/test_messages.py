"""Manip request and response bodies: round trips for every opcode, and the specific errors."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.messages import (
    copy_request_data,
    decode_async,
    decode_reply,
    decode_request,
    decode_server_packet,
    encode_async,
    encode_multi_text,
    encode_reply,
    encode_request,
    guard_hit,
    response_layout,
    segment_completed,
)
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import RequestOp, ServerOp
from tests.support.strategies import f_bytes, f_values, layout_values, request_and_values, requests


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.copysign(1, a) != math.copysign(1, b) and a == 0 == b)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


@given(request_and_values())
def test_every_request_round_trips(case: tuple[RequestOpcode, dict[str, Any]]) -> None:
    op, values = case
    data = encode_request(op.name, **values)
    assert len(data) == (op.request.fixed_size if op.request.fixed_size is not None else len(data))
    decoded = decode_request(op.opcode, data)
    assert decoded.op is op
    for name, value in values.items():
        assert _same(decoded.values[name], value), name


@given(
    requests.flatmap(lambda op: st.tuples(st.just(op), layout_values(response_layout(op)))),
    st.integers(0, 0xFFFF),
)
def test_every_reply_round_trips(case: tuple[RequestOpcode, dict[str, Any]], number: int) -> None:
    op, values = case
    data = encode_reply(op.name, number, **values)
    assert struct.unpack_from("<H", data)[0] == number  # response.echoes-request-number, low byte first
    reply = decode_reply(data, op.opcode)
    assert reply.request_number == number
    for name, value in values.items():
        assert _same(reply.values[name], value), name


@given(st.lists(f_values, min_size=12, max_size=12), st.integers(0, 0xFFFF))
def test_here_reply_bytes_match_an_independent_layout(transform: list[float], number: int) -> None:
    data = encode_reply("here", number, transform=tuple(transform))
    expected = struct.pack("<H", number) + b"".join(f_bytes(x) for x in transform)
    assert data == expected


def test_move_request_bytes() -> None:
    transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 100.0, -50.0, 0.5)
    data = encode_request("move", transform=transform)
    assert data == b"".join(f_bytes(x) for x in transform)
    assert data[:4] == bytes.fromhex("80400000")  # 1.0


def test_wrong_length_names_clause_and_offset() -> None:
    with pytest.raises(DecodeError) as err:
        decode_request(RequestOp.MOVE, b"\0" * 44)
    assert err.value.clause == "request.data-length"
    assert "48" in err.value.message and err.value.offset == 44
    with pytest.raises(DecodeError) as err:
        decode_request(RequestOp.HERE, b"\0\0")
    assert err.value.clause == "request.data-length"


def test_reserved_float_is_located() -> None:
    data = bytearray(encode_request("set-joint-angles", joints=(0.0, -90.0, 90.0, 0.0, 0.0, 0.0)))
    data[12:16] = bytes.fromhex("00800000")  # joint 4 becomes the reserved operand
    with pytest.raises(DecodeError) as err:
        decode_request(RequestOp.SET_JOINT_ANGLES, bytes(data))
    assert err.value.clause == "float.reserved-operand"
    assert err.value.offset == 12
    assert err.value.path == "set-joint-angles.joints[3]"


def test_unknown_request_opcode() -> None:
    with pytest.raises(DecodeError) as err:
        decode_request(0o237, b"")
    assert err.value.clause == "request.unknown-opcode"


def test_small_field_accepts_byte_or_word() -> None:
    assert decode_request(RequestOp.FREE_JOINT, b"\x03").values["joint"] == 3
    assert decode_request(RequestOp.FREE_JOINT, b"\x03\x00").values["joint"] == 3
    assert decode_request(RequestOp.SET_CONFIGURATION, b"\x01").values["configuration"] == 1


def test_types_follow_copy_manipulator_request_data() -> None:
    with pytest.raises(EncodeError) as err:
        encode_request("set-speed", factor=1)  # a fixnum where a flonum is required
    assert err.value.clause == "request-data.types"
    with pytest.raises(EncodeError):
        encode_request("hand", amount=1.0)
    with pytest.raises(EncodeError):
        encode_request("hand", amount=True)
    with pytest.raises(EncodeError, match="missing field"):
        encode_request("move")
    with pytest.raises(EncodeError, match="needs 12 values"):
        encode_request("move", transform=(1.0,) * 11)


def test_copy_request_data() -> None:
    assert copy_request_data([0o21, 5]) == bytes([0o21, 0, 5, 0])
    assert copy_request_data([1.0, [2, [-1]]]) == bytes.fromhex("80400000") + bytes([2, 0, 0xFF, 0xFF])
    for bad in ("x", None, True, 70000, {1: 2}):
        with pytest.raises(EncodeError) as err:
            copy_request_data([1, bad])
        assert err.value.clause == "request-data.types"
        assert err.value.path == "data[1]"


@given(
    st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=2000),
    st.integers(0, 0xFFFF),
)
def test_multi_packet_text(text: str, number: int) -> None:
    packets = encode_multi_text(number, text)
    assert all(len(p) <= 488 for p in packets)
    assert packets[-1] == struct.pack("<H", number)  # multi.terminated-by-empty
    replies = [decode_reply(p, "describe-self") for p in packets]
    assert {r.request_number for r in replies} == {number}  # multi.same-request-number
    assert replies[-1].is_empty and not any(r.is_empty for r in replies[:-1])
    assert "".join(str(r.values.get("text", "")) for r in replies) == text


def test_segment_and_done_replies() -> None:
    reply = decode_reply(encode_reply("move", 7, segment=3), RequestOp.MOVE)
    assert reply.segment == 3 and reply.request_number == 7
    done = decode_reply(struct.pack("<H", 9), RequestOp.CALIBRATE)
    assert done.is_empty
    with pytest.raises(DecodeError) as err:
        decode_reply(struct.pack("<HH", 9, 1), RequestOp.CALIBRATE)
    assert err.value.clause == "response.done-empty"
    with pytest.raises(DecodeError) as err:
        decode_reply(b"\x01", None)
    assert err.value.clause == "response.echoes-request-number"


@given(st.integers(0, 0xFFFF), st.integers(0, 15), st.booleans(), st.integers(0, 0xFFFF))
def test_async_responses(number: int, guard: int, stop: bool, segment: int) -> None:
    hit = decode_async(guard_hit(number, guard, stop=stop))
    assert (hit.request_number, hit.condition, hit.word2, hit.word3) == (number, 1, 1 if stop else 2, guard)
    assert hit.condition_name == "guard-hit"
    seg = decode_server_packet(ServerOp.ASYNCHRONOUS_RESPONSE, segment_completed(number, segment))
    assert seg == decode_async(struct.pack("<4H", number, 2, 0, segment))
    bare = encode_async(number, 2, 0, segment, async_has_request_number=False)
    assert decode_async(bare, async_has_request_number=False).word3 == segment
    guide = decode_async(bare)  # told apart by length: 6 bytes are the 1985 guide's layout
    assert (guide.request_number, guide.condition, guide.word3, guide.layout) == (None, 2, segment, "guide")
    assert decode_async(segment_completed(number, segment)).layout == "numbered"


@pytest.mark.parametrize("size", [0, 4, 5, 7, 9, 10])
def test_async_wrong_length(size: int) -> None:
    with pytest.raises(DecodeError) as err:
        decode_async(b"\0" * size)
    assert err.value.clause == "async.layout"
    assert "8 or 6 data bytes" in err.value.message


def test_async_layout_insisted_on() -> None:
    with pytest.raises(DecodeError):
        decode_async(b"\0" * 6, async_has_request_number=True)
    with pytest.raises(DecodeError):
        decode_async(b"\0" * 8, async_has_request_number=False)


def test_server_opcode_dispatch() -> None:
    with pytest.raises(DecodeError) as err:
        decode_server_packet(0o206, b"\0\0")
    assert err.value.clause == "response.server-opcodes"


def test_every_spec_request_has_a_reply_layout() -> None:
    for op in SPEC.requests.values():
        layout = response_layout(op)
        if op.response.form in ("done", "segment"):
            assert layout.fixed_size == (0 if op.response.form == "done" else 2)
