"""The recorder's and reader's fast paths agree with the slow ones they replace.

* the message appender writes the very bytes ``mcap``'s ``Writer.add_message`` writes;
* ``view_bytes`` is the compact JSON of ``view_json``, byte for byte, with the floats of ``fields`` in
  nine significant digits (and those digits give back every PDP-11 single exactly);
* the single-frame decoder gives what the framing's own decoders give, and fails where they fail;
* the annotator's fast request/reply decoding gives what ``decode_request`` / ``decode_reply`` give.
"""

from __future__ import annotations

import io
import json
import math
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

import manip.captures.recorder as recorder_module
from manip.captures import Annotation, Annotator, Recorder, iter_packets, read_capture
from manip.captures.appender import message_adder
from manip.captures.recorder import frame_decoder
from manip.captures.view import field_json, view_bytes, view_json
from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.framing import decode_chaosd, decode_tcp, encode_chaosd, encode_tcp
from manip.codecs.messages import (
    decode_reply,
    decode_request,
    encode_reply,
    encode_request,
    request_op,
    response_layout,
)
from manip.codecs.packet import Packet
from manip.codecs.pdp11float import pack_f, unpack_f, words_to_f
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from tests.support.paths import ROOT

CLIENT = (0o401, 0x1234)
SERVER = (0o440, 0x5678)
_JSON = json.JSONEncoder(separators=(",", ":"))


def compact(value: Any, in_fields: bool = False) -> str:
    """Compact JSON, written out plainly: Python's json, except the finite floats under ``fields``."""
    if isinstance(value, dict):
        items = (_JSON.encode(k) + ":" + compact(v, in_fields or k == "fields") for k, v in value.items())
        return "{" + ",".join(items) + "}"
    if isinstance(value, list | tuple):
        return "[" + ",".join(compact(v, in_fields) for v in value) + "]"
    if in_fields and type(value) is float and math.isfinite(value):
        text = f"{value:.9g}"
        return text if "." in text or "e" in text else text + ".0"
    return _JSON.encode(value)


def slow_view(
    ann: Annotation, link: int, direction: Any, seq: int, packet: Packet | None, nbytes: int
) -> bytes:
    return compact(view_json(ann, link, direction, seq, packet, nbytes)).encode()


@settings(max_examples=500, deadline=None)
@given(st.binary(min_size=4, max_size=4))
@example(pack_f(words_to_f(0x7FFF, 0xFFFF)))  # the largest single
@example(pack_f(words_to_f(0x0080, 0x0000)))  # the smallest
@example(pack_f(words_to_f(0x0080, 0x0001)))
def test_nine_digits_give_back_every_pdp11_single(wire: bytes) -> None:
    try:
        value = unpack_f(wire)
    except CodecError:  # a reserved operand: no number to spell
        return
    text = field_json(value)
    assert pack_f(float(text)) == pack_f(value)
    back = json.loads(text)
    assert type(back) is float and back == float(text)
    assert math.copysign(1.0, back) == math.copysign(1.0, value)
    assert len(text.lstrip("-").replace(".", "").split("e")[0].strip("0")) <= 9


# ------------------------------------------------------------------------------ appender

message = st.tuples(
    st.integers(0, 3),  # channel
    st.integers(-5, 50),  # time step (times may go backwards)
    st.binary(max_size=300),
    st.booleans(),  # as a pair with a second message
)


def write(messages: list[tuple[int, int, bytes, bool]], fast: bool, compression: CompressionType) -> bytes:
    out = io.BytesIO()
    writer = Writer(out, chunk_size=700, compression=compression)
    writer.start(profile="p", library="l")
    schema = writer.register_schema("s", "x", b"{}")
    channels = [writer.register_channel(f"/t{i}", "x", schema) for i in range(4)]
    add, add_pair, is_fast = message_adder(writer)
    assert is_fast, "mcap's Writer internals changed: update manip.captures.appender"
    t = 1_000
    for i, (c, step, data, pair) in enumerate(messages):
        t += step
        if not fast:
            writer.add_message(channels[c], t, data, t, i)
            if pair:
                writer.add_message(channels[(c + 1) % 4], t, data[::-1], t, i)
        elif pair:
            add_pair(channels[c], data, channels[(c + 1) % 4], data[::-1], t, i)
        else:
            add(channels[c], t, data, i)
        if i % 17 == 16:
            writer.flush()  # type: ignore[no-untyped-call]
    writer.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


@settings(max_examples=60, deadline=None)
@given(st.lists(message, max_size=60), st.sampled_from([CompressionType.NONE, CompressionType.ZSTD]))
def test_the_appender_writes_the_bytes_add_message_writes(
    messages: list[tuple[int, int, bytes, bool]], compression: CompressionType
) -> None:
    assert write(messages, True, compression) == write(messages, False, compression)


# ------------------------------------------------------------------------------ view bytes


def test_view_bytes_is_view_json_for_every_golden_packet() -> None:
    checked = 0
    for name in ("describe-self", "motion", "errors"):
        capture = read_capture(ROOT / "captures" / f"{name}.mcap")
        for p in [*capture.packets, *capture.bad_frames]:
            nbytes = len(p.packet.data) if p.packet is not None else len(p.frame)
            fast = view_bytes(p.annotation, p.link, p.direction, p.seq, p.packet, nbytes)
            assert fast == slow_view(p.annotation, p.link, p.direction, p.seq, p.packet, nbytes)
            checked += 1
    assert checked > 50


def test_the_recorded_view_is_what_the_slow_path_would_write(tmp_path: Path) -> None:
    """End to end: every view message in a recorded file equals view_json of the reader's annotation."""
    path = tmp_path / "v.mcap"
    with Recorder(path, command_line=["t"]) as rec:
        link = rec.open_link("tcp")
        number = 2
        for i in range(40):
            kind = ("here", "joint-angles", "set-joint-angles", "move")[i % 4]
            values = tuple(float(i * 7 + k) / 3 for k in range(12))
            if kind == "set-joint-angles":
                data, reply = encode_request(kind, joints=values[:6]), encode_reply(kind, number, segment=i)
            elif kind == "move":
                data, reply = encode_request(kind, transform=values), encode_reply(kind, number, segment=i)
            elif kind == "here":
                data, reply = encode_request(kind), encode_reply(kind, number, transform=values)
            else:
                data, reply = encode_request(kind), encode_reply(kind, number, joints=values[:6])
            request = Packet(request_op(kind).opcode, *SERVER, *CLIENT, number, number - 1, data)
            answer = Packet(ServerOp.RESPONSE, *CLIENT, *SERVER, number, number, reply)
            rec.frame(link, "c2s", encode_tcp(request), 10 + 2 * i)
            rec.frame(link, "s2c", encode_tcp(answer), 11 + 2 * i)
            number += 1
        rec.frame(link, "c2s", b"\x00\x03bad", 200)  # a bad frame
    views = {
        message.sequence: message.data
        for _, channel, message in make_reader(path.open("rb")).iter_messages()
        if channel.topic in ("/manip/c2s", "/manip/s2c")
    }
    packets = list(iter_packets(path))
    assert len(packets) == len(views) == 81
    for p in packets:
        nbytes = len(p.packet.data) if p.packet is not None else len(p.frame)
        assert views[p.seq] == slow_view(p.annotation, p.link, p.direction, p.seq, p.packet, nbytes)


floats = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [0.0, -0.0, 1e-7, 1e16, 1e22, -123.456, 0.1, math.nan, math.inf, -math.inf]
)
values = st.one_of(
    st.integers(-(2**40), 2**40),
    floats,
    st.tuples(floats, floats, floats),
    st.tuples(st.integers(-5, 70000), st.integers(-5, 70000)),
    st.tuples(floats, st.integers(0, 9)),
    st.tuples(),
    st.text(max_size=8),
    st.booleans(),
    st.lists(st.integers(0, 9), max_size=3),
)
texts = st.none() | st.text(max_size=12)


@settings(max_examples=200, deadline=None)
@given(
    kind=st.sampled_from(["request", "reply", "error", "async", "control", "data", "bad-frame"]),
    retransmission=st.booleans(),
    op=texts,
    request_number=st.none() | st.integers(0, 65535),
    pair=st.none() | st.integers(1, 10**6),
    final=st.none() | st.booleans(),
    fields=st.none() | st.dictionaries(st.text(min_size=1, max_size=6), values, max_size=4),
    text=texts,
    error=st.none() | st.dictionaries(st.sampled_from(["code", "args", "message"]), values, max_size=3),
    payload_hex=texts,
    with_packet=st.booleans(),
    header=st.tuples(*[st.integers(0, 0xFFFF)] * 6, st.integers(0, 255)),
)
def test_view_bytes_is_view_json_for_any_annotation(
    kind: str,
    retransmission: bool,
    op: str | None,
    request_number: int | None,
    pair: int | None,
    final: bool | None,
    fields: dict[str, Any] | None,
    text: str | None,
    error: dict[str, Any] | None,
    payload_hex: str | None,
    with_packet: bool,
    header: tuple[int, ...],
) -> None:
    ann = Annotation(
        3,
        kind,
        retransmission=retransmission,
        op=op,
        request_number=request_number,
        pair=pair,
        final=final,
        fields=fields,
        text=text,
        error=error,
        async_={"condition": 2, "condition_name": "x"} if kind == "async" else None,
        payload_hex=payload_hex,
        decode_error={"message": "bad \u00e9"} if kind == "bad-frame" else None,
    )
    dh, di, sh, si, pn, an, opcode = header
    packet = Packet(opcode, dh, di, sh, si, pn, an, b"xyz") if with_packet else None
    for direction in ("c2s", "s2c"):
        assert view_bytes(ann, 2, direction, 9, packet, 3) == slow_view(ann, 2, direction, 9, packet, 3)


# ------------------------------------------------------------------------------ single frames

packets = st.builds(
    Packet,
    opcode=st.sampled_from([1, 2, 3, 4, 5, 6, 0o200, 0o204, 0o215, 0o300]),
    dest_host=st.integers(0, 0xFFFF),
    dest_index=st.integers(0, 0xFFFF),
    src_host=st.integers(0, 0xFFFF),
    src_index=st.integers(0, 0xFFFF),
    packet_no=st.integers(0, 0xFFFF),
    ack_no=st.integers(0, 0xFFFF),
    data=st.binary(max_size=60),
)
damage = st.one_of(
    st.none(),
    st.tuples(st.just("flip"), st.integers(0, 10**6), st.integers(1, 255)),
    st.tuples(st.just("cut"), st.integers(1, 30)),
    st.tuples(st.just("extra"), st.binary(min_size=1, max_size=30)),
)


def damaged(frame: bytes, how: Any) -> bytes:
    if how is None:
        return frame
    if how[0] == "flip":
        at = how[1] % len(frame)
        return frame[:at] + bytes([frame[at] ^ how[2]]) + frame[at + 1 :]
    if how[0] == "cut":
        return frame[: max(0, len(frame) - how[1])]
    extra: bytes = how[1]
    return frame + extra


def outcome(decode: Any, frame: bytes) -> Packet | str:
    try:
        packet: Packet = decode(frame)
        return packet
    except DecodeError:
        return "error"


@settings(max_examples=300, deadline=None)
@given(packet=packets, how=damage, framing=st.sampled_from(["tcp", "chaosd"]))
def test_the_single_frame_decoder_agrees_with_the_framing(packet: Packet, how: Any, framing: str) -> None:
    encode, decode = (encode_tcp, decode_tcp) if framing == "tcp" else (encode_chaosd, decode_chaosd)
    frame = damaged(encode(packet, hw_dest=1, hw_src=2), how)
    fast = frame_decoder(framing)
    expected = outcome(decode, frame)
    assert outcome(fast, frame) == expected
    assert outcome(fast, frame) == expected  # and again: nothing is left behind by the first call
    if how is None:
        assert expected == packet


# ------------------------------------------------------------------------------ annotator


def request_ops() -> list[Any]:
    return sorted(SPEC.requests.values(), key=lambda op: op.opcode)


@settings(max_examples=300, deadline=None)
@given(
    op=st.sampled_from(request_ops()),
    request=st.binary(max_size=60),
    reply=st.binary(max_size=60),
    sizes=st.booleans(),
)
def test_fast_request_and_reply_decoding_agrees_with_the_codecs(
    op: Any, request: bytes, reply: bytes, sizes: bool
) -> None:
    if sizes and op.request.fixed_size is not None:  # often well formed: the fast path's case
        request = (request * 50)[: op.request.fixed_size]
    annotator = Annotator()
    req = annotator.annotate(1, "c2s", Packet(op.opcode, *SERVER, *CLIENT, 7, 0, request))
    try:
        expected: Any = dict(decode_request(op.opcode, request).values)
    except CodecError as exc:
        assert req.fields is None and req.decode_error is not None
        assert req.decode_error["message"] == exc.message
    else:
        assert req.fields == expected and req.decode_error is None
    reply_size = response_layout(op).fixed_size
    if sizes and reply_size is not None and op.response.form != "multi":
        reply = (reply * 50)[:reply_size]
    reply = struct.pack("<H", 7) + reply
    ans = annotator.annotate(1, "s2c", Packet(ServerOp.RESPONSE, *CLIENT, *SERVER, 8, 7, reply))
    assert ans.pair == req.pair and ans.op == op.name
    try:
        decoded = decode_reply(reply, op)
    except CodecError as exc:
        assert ans.decode_error is not None and ans.decode_error["message"] == exc.message
        return
    if op.response.form == "multi":  # a malformed request is answered by one packet
        assert ans.final == (not decoded.payload or req.decode_error is not None)
    else:
        assert ans.final is True
        assert ans.fields == (dict(decoded.values) or None)


@pytest.mark.parametrize("how", ["frame", "packet"])
def test_a_closed_recorder_refuses_frames_either_way(how: str) -> None:
    rec = Recorder(io.BytesIO(), command_line=["t"])
    link = rec.open_link("tcp")
    rec.close()
    packet = Packet(0o202, *SERVER, *CLIENT, 2, 1, b"")
    with pytest.raises(Exception, match="closed"):
        if how == "frame":
            rec.frame(link, "c2s", encode_tcp(packet), 1)
        else:
            rec.packet(link, "c2s", packet, t_ns=1)


# ------------------------------------------------------------------------------ batching


def _record_mixed(batch: int, monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int, int, bytes]]:
    """A session over two links through frame(), packet(), events and bad frames, recorded with the
    recorder's batch set to ``batch``; every message in file order."""
    monkeypatch.setattr(recorder_module, "BATCH", batch)
    out = io.BytesIO()
    rec = Recorder(out, command_line=["t"])
    tcp, chaosd = rec.open_link("tcp", t_ns=1), rec.open_link("chaosd", t_ns=2)
    t = 10
    for i in range(30):
        number = 2 + i
        request = Packet(request_op("joint-angles").opcode, *SERVER, *CLIENT, number, number - 1, b"")
        reply = encode_reply("joint-angles", number, joints=(float(i), 0.5, -1.0, 2.0, 3.0, 125.0))
        answer = Packet(ServerOp.RESPONSE, *CLIENT, *SERVER, number, number, reply)
        rec.frame(tcp, "c2s", encode_tcp(request), t)
        rec.packet(chaosd, "s2c", answer, t_ns=t + 1)
        rec.frame(tcp, "s2c", encode_tcp(answer), t + 2)
        if i % 7 == 3:
            rec.frame(tcp, "c2s", b"\x00\x03bad", t + 3)
            rec.event("note", t + 4, link=tcp)
        if i % 11 == 5:
            rec.close_link(chaosd, "test", t + 5)
            chaosd = rec.open_link("chaosd", t_ns=t + 6)
        if i == 17:
            rec.flush()
        t += 10
    assert rec.counts["/chaos/c2s"] == 30 + 4  # counts include frames still waiting
    assert rec.connections == 5  # one on the tcp link, one on each of the four chaosd links
    rec.close()
    reader = make_reader(io.BytesIO(out.getvalue()))
    return [  # the recording-started and -stopped events carry the clock's time
        (
            channel.topic,
            message.sequence,
            0 if b'"recording-' in message.data else message.log_time,
            message.data,
        )
        for _, channel, message in reader.iter_messages(log_time_order=False)
    ]


def test_batching_writes_what_frame_by_frame_recording_writes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    one_by_one = _record_mixed(1, monkeypatch)
    assert len(one_by_one) > 200
    for batch in (2, 7, 256):
        assert _record_mixed(batch, monkeypatch) == one_by_one


def test_a_flush_writes_the_frames_waiting_in_the_batch() -> None:
    out = io.BytesIO()
    rec = Recorder(out, command_line=["t"])
    link = rec.open_link("tcp")
    request = Packet(request_op("here").opcode, *SERVER, *CLIENT, 2, 1, b"")
    rec.frame(link, "c2s", encode_tcp(request), 5)
    before = len(out.getvalue())
    rec.flush()
    assert len(out.getvalue()) > before
    topics: dict[int, str] = {}
    written = []
    with pytest.raises(EndOfFile):  # the file is not finished: read up to its end
        for record in StreamReader(io.BytesIO(out.getvalue())).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, McapMessage):
                written.append(topics[record.channel_id])
    assert written.count("/chaos/c2s") == 1 and written.count("/manip/c2s") == 1
    rec.close()
