"""Chaos packet codec and link framings: golden vectors, round trips, streams, and every refusal."""

from __future__ import annotations

import json
import struct
from importlib import resources
from itertools import pairwise
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.codecs import framing as fw
from manip.codecs.chaos import (
    HEADER,
    PACKET,
    IllegalPacketError,
    chaos_checksum,
    compiled_packet,
    decode_raw,
    encode_raw,
    is_legal_opcode,
    packet_words,
    parse_header,
)
from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.framing import (
    FRAMINGS,
    ChaosdFrameDecoder,
    FrameSyncError,
    StreamDecoder,
    TcpFrameDecoder,
    decode_chaosd,
    decode_chudp,
    decode_stream,
    decode_tcp,
    encode_chaosd,
    encode_chudp,
    encode_tcp,
)
from manip.codecs.packet import MAX_DATA, Packet, Trailer, make_packet, make_trailer_value
from manip.spec.constants import ChaosOp

# ------------------------------------------------------------------------------------ vectors


def _load() -> list[dict[str, Any]]:
    doc = json.loads(resources.files("manip.vectors").joinpath("chaos.json").read_text())
    assert doc["format"] == "manip-vectors/1"
    assert doc["subject"] == "chaos-framing"
    return list(doc["vectors"])


VECTORS = _load()
GOOD = [v for v in VECTORS if "packet" in v]
BAD = [v for v in VECTORS if "error" in v]


def _packet(spec: dict[str, Any]) -> tuple[Packet, Trailer | None]:
    t = spec["trailer"]
    trailer = None if t is None else Trailer(t["dest"], t["source"], t["checksum"])
    p = Packet(
        opcode=spec["opcode"],
        dest_host=spec["dest_host"],
        dest_index=spec["dest_index"],
        src_host=spec["src_host"],
        src_index=spec["src_index"],
        packet_no=spec["packet_no"],
        ack_no=spec["ack_no"],
        data=bytes.fromhex(spec["data_hex"]),
        fc=spec["fc"],
    )
    return p, trailer


def _decode_one(framing: str, b: bytes) -> Packet:
    match framing:
        case "chudp":
            return decode_chudp(b)
        case "tcp":
            return decode_tcp(b)
        case "chaosd":
            return decode_chaosd(b, verify=True)
        case _:
            return decode_raw(b)


def _encode_one(framing: str, p: Packet, trailer: Trailer | None) -> bytes:
    hw: dict[str, int] = {} if trailer is None else {"hw_dest": trailer.dest, "hw_src": trailer.source}
    match framing:
        case "chudp":
            return encode_chudp(p, **hw)
        case "tcp":
            return encode_tcp(p, **hw)
        case "chaosd":
            return encode_chaosd(p, **hw)
        case _:
            return encode_raw(p)


def test_vector_file_covers_every_framing_and_notes_vector() -> None:
    assert {v["framing"] for v in GOOD} == set(FRAMINGS)
    assert sum(v["framing"] == "chudp" for v in GOOD) == 7
    assert len({v["name"] for v in VECTORS}) == len(VECTORS)


@pytest.mark.parametrize("vec", GOOD, ids=lambda v: v["name"])
def test_golden_decode(vec: dict[str, Any]) -> None:
    expected, trailer = _packet(vec["packet"])
    got = _decode_one(vec["framing"], bytes.fromhex(vec["hex"]))
    assert got == expected
    assert got.trailer == trailer
    assert FRAMINGS[vec["framing"]].decode(bytes.fromhex(vec["hex"])) == [expected]


@pytest.mark.parametrize("vec", GOOD, ids=lambda v: v["name"])
def test_golden_encode(vec: dict[str, Any]) -> None:
    p, trailer = _packet(vec["packet"])
    assert _encode_one(vec["framing"], p, trailer).hex() == vec["hex"]
    # The vectors use a direct link (trailer = packet addresses), which is also the registry's default.
    assert FRAMINGS[vec["framing"]].encode(p).hex() == vec["hex"]


@pytest.mark.parametrize("vec", BAD, ids=lambda v: v["name"])
def test_error_vectors(vec: dict[str, Any]) -> None:
    with pytest.raises(DecodeError) as info:
        FRAMINGS[vec["framing"]].decode(bytes.fromhex(vec["hex"]))
    want = vec["error"]
    assert info.value.clause == want["clause"], str(info.value)
    assert info.value.offset == want["offset"], str(info.value)
    assert info.value.path == want["path"], str(info.value)


def test_checksum_error_message_shows_expected_and_found() -> None:
    bad = next(v for v in BAD if v["name"] == "chudp-bad-checksum")
    with pytest.raises(DecodeError, match=r"0x5a1b.*0x5a1a"):
        decode_chudp(bytes.fromhex(bad["hex"]))
    p = decode_chudp(bytes.fromhex(bad["hex"]), verify=False)
    assert p.data == b"PUMA"
    assert p.trailer == Trailer(0o440, 0o401, 0x5A1B)


# ------------------------------------------------------------------------------------ strategies

legal_opcodes = st.one_of(st.integers(0o1, 0o16), st.integers(0o200, 0o377))
words = st.integers(0, 0xFFFF)


any_data = st.binary(max_size=MAX_DATA)


def packet_strategy(
    opcodes: st.SearchStrategy[int], data: st.SearchStrategy[bytes] = any_data
) -> st.SearchStrategy[Packet]:
    return st.builds(
        Packet,
        opcode=opcodes,
        dest_host=words,
        dest_index=words,
        src_host=words,
        src_index=words,
        packet_no=words,
        ack_no=words,
        data=data,
        fc=st.integers(0, 15),
    )


packets = packet_strategy(legal_opcodes)


# ------------------------------------------------------------------------------------ round trips


@given(packets)
def test_raw_round_trip(p: Packet) -> None:
    b = encode_raw(p)
    assert len(b) == 16 + len(p.data) + len(p.data) % 2
    assert decode_raw(b) == p


@given(packets)
def test_construct_definition_agrees_with_fast_codec(p: Packet) -> None:
    b = encode_raw(p)
    obj = {
        "header": {
            "op": {"opcode": p.opcode, "unused": 0},
            "count": {"fc": p.fc, "nbytes": p.nbytes},
            "dest_host": p.dest_host,
            "dest_index": p.dest_index,
            "src_host": p.src_host,
            "src_index": p.src_index,
            "packet_no": p.packet_no,
            "ack_no": p.ack_no,
        },
        "data": p.data,
        "pad": None,
    }
    assert PACKET.build(obj) == b
    assert compiled_packet().build(obj) == b
    for parsed in (PACKET.parse(b), compiled_packet().parse(b)):
        assert parsed.header.op.opcode == p.opcode
        assert parsed.header.count.fc == p.fc
        assert parsed.header.count.nbytes == p.nbytes
        assert parsed.header.ack_no == p.ack_no
        assert parsed.data == p.data
    assert parse_header(b).dest_index == p.dest_index


def test_construct_header_shape() -> None:
    assert HEADER.sizeof() == 16
    with pytest.raises(DecodeError) as info:
        parse_header(b"\0" * 15)
    assert info.value.clause == "chaos.header.layout"


@given(packets, words, words)
def test_chudp_round_trip(p: Packet, hw_dest: int, hw_src: int) -> None:
    b = encode_chudp(p, hw_dest=hw_dest, hw_src=hw_src)
    assert len(b) == 4 + 16 + len(p.data) + len(p.data) % 2 + 6
    got = decode_chudp(b)
    assert got == p
    assert got.trailer is not None
    assert (got.trailer.dest, got.trailer.source) == (hw_dest, hw_src)
    # Each packet word goes out most significant byte first.
    assert struct.unpack(f">{len(packet_words(p))}H", b[4:-6]) == tuple(packet_words(p))


@given(packets)
def test_tcp_round_trip(p: Packet) -> None:
    b = encode_tcp(p)
    assert b[2:] == encode_chudp(p)[4:]
    assert int.from_bytes(b[:2], "big") == len(b) - 2
    assert decode_tcp(b) == p


@given(packets)
def test_chaosd_round_trip(p: Packet) -> None:
    b = encode_chaosd(p)
    assert (b[0] << 8 | b[1], b[2], b[3]) == (len(b) - 4, 1, 0)
    got = decode_chaosd(b, verify=True)
    assert got == p
    assert got.trailer == decode_chudp(encode_chudp(p)).trailer


@given(packets)
def test_registry_round_trip(p: Packet) -> None:
    for framing in FRAMINGS.values():
        assert framing.decode(framing.encode(p)) == [p], framing.name


def test_raw_pad_byte_optional_but_nothing_after_it() -> None:
    p = Packet(0o200, 1, 2, 3, 4, 5, 6, b"ABC")
    b = encode_raw(p)
    assert b.endswith(b"C\0")
    assert decode_raw(b[:-1]) == p
    with pytest.raises(DecodeError) as info:
        decode_raw(b + b"\0")
    assert (info.value.clause, info.value.path) == ("chaos.header.nbytes", "header.nbytes")


# ------------------------------------------------------------------------------------ streams

DECODERS: dict[str, type[StreamDecoder]] = {"tcp": TcpFrameDecoder, "chaosd": ChaosdFrameDecoder}


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    edges = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    return [data[a:b] for a, b in pairwise(edges)]


@settings(max_examples=60)
@given(
    st.sampled_from(sorted(DECODERS)),
    st.lists(packets, min_size=1, max_size=4),
    st.lists(st.integers(0, 10_000), max_size=12),
)
def test_stream_any_chunking(name: str, ps: list[Packet], cuts: list[int]) -> None:
    stream = b"".join(FRAMINGS[name].encode(p) for p in ps)
    decoder = DECODERS[name]()
    got: list[Packet | DecodeError] = []
    for chunk in _chunks(stream, cuts):
        got += decoder.feed(chunk)
    decoder.finish()
    assert got == ps
    assert decoder.pending == 0
    assert decoder.offset == len(stream)
    assert FRAMINGS[name].decode(stream) == ps


@settings(max_examples=40)
@given(st.sampled_from(sorted(DECODERS)), st.lists(st.integers(0, 200), max_size=6))
def test_stream_reports_bad_frame_in_place_and_continues(name: str, cuts: list[int]) -> None:
    a = Packet(0o200, 0o440, 1, 0o401, 2, 10, 3, b"first")
    b = Packet(0o200, 0o440, 1, 0o401, 2, 11, 3, b"second")
    c = Packet(0o200, 0o440, 1, 0o401, 2, 12, 3, b"third")
    fa, fb, fc = (FRAMINGS[name].encode(p) for p in (a, b, c))
    fb = fb[:-1] + bytes([fb[-1] ^ 0x01])  # corrupt b's checksum
    decoder = DECODERS[name](verify=True)
    items: list[Packet | DecodeError] = []
    for chunk in _chunks(fa + fb + fc, cuts):
        items += decoder.feed(chunk)
    decoder.finish()
    assert items[0] == a and items[2] == c
    err = items[1]
    assert isinstance(err, DecodeError)
    assert err.clause == "chudp.checksum"
    assert err.offset == len(fa) + len(fb) - 2  # the checksum word, counted from the stream start


def test_stream_nbytes_mismatch_is_reported_and_skipped() -> None:
    a = Packet(0o200, 0o440, 1, 0o401, 2, 10, 3, b"abcd")
    frame = bytearray(encode_tcp(a))
    frame[5] = 2  # nbytes 4 -> 2 (word 1 low byte, MSB-first); fix the checksum by hand
    body = bytes(frame[2:-2])
    frame[-2:] = chaos_checksum(struct.unpack(f">{len(body) // 2}H", body)).to_bytes(2, "big")
    items = TcpFrameDecoder().feed(bytes(frame) + encode_tcp(a))
    assert isinstance(items[0], DecodeError) and items[0].clause == "chaos.header.nbytes"
    assert items[0].offset == 2 + 2
    assert items[1] == a


@pytest.mark.parametrize(
    ("name", "bad"),
    [("tcp", b"\x00\x15"), ("tcp", b"\x00\x00"), ("tcp", b"\x02\x00"), ("chaosd", b"\x00\x1a\x00\x00")],
)
def test_stream_framing_error_raises_and_keeps_earlier_packets(name: str, bad: bytes) -> None:
    good = Packet(0o5, 1, 2, 3, 4, 0, 0, b"OK")
    frame = FRAMINGS[name].encode(good)
    decoder = DECODERS[name]()
    with pytest.raises(FrameSyncError) as info:
        decoder.feed(frame + frame + bad + frame)
    err = info.value
    assert err.items == (good, good)
    assert err.offset is not None and err.offset >= 2 * len(frame)
    assert err.clause == DECODERS[name].clause
    assert decoder.failed is err
    with pytest.raises(FrameSyncError):
        decoder.feed(frame)


def test_stream_finish_inside_frame() -> None:
    frame = encode_tcp(Packet(0o1, data=b"PUMA"))
    decoder = TcpFrameDecoder()
    assert decoder.feed(frame + frame[:5]) == [Packet(0o1, data=b"PUMA")]
    assert decoder.pending == 5
    with pytest.raises(DecodeError) as info:
        decoder.finish()
    assert (info.value.clause, info.value.offset) == ("link.tcp.framing", len(frame))


def test_single_frame_decoders_want_exactly_one_frame() -> None:
    frame = encode_tcp(Packet(0o1, data=b"PUMA"))
    with pytest.raises(DecodeError, match="one frame"):
        decode_tcp(frame + frame)
    with pytest.raises(DecodeError) as info:
        decode_chaosd(b"\x00\x1a\x01")
    assert info.value.clause == "link.chaosd.framing"


def test_chaosd_checksum_verified_only_on_request() -> None:
    frame = bytearray(encode_chaosd(Packet(0o1, 0o440, 0, 0o401, 0x0A01, 1, 0, b"PUMA")))
    frame[-2:] = frame[-1:-3:-1]  # checksum bytes swapped, as usim writes them on a little-endian host
    assert decode_chaosd(bytes(frame)).data == b"PUMA"
    with pytest.raises(DecodeError) as info:
        decode_chaosd(bytes(frame), verify=True)
    assert info.value.clause == "chudp.checksum"


# ------------------------------------------------------------------------------------ refusals


@pytest.mark.parametrize("opcode", range(256))
def test_opcode_legality(opcode: int) -> None:
    b = encode_raw(Packet(opcode, data=b"x"))  # encoding an illegal opcode is allowed, on purpose
    assert is_legal_opcode(opcode) == (1 <= opcode <= 0o16 or opcode >= 0o200)
    if is_legal_opcode(opcode):
        assert decode_raw(b).opcode == opcode
    else:
        with pytest.raises(DecodeError) as info:
            decode_raw(b)
        assert (info.value.clause, info.value.path, info.value.offset) == (
            "chaos.opcode.legal",
            "header.opcode",
            1,
        )


def test_raw_refusals() -> None:
    good = encode_raw(Packet(0o1, data=b"PUMA"))
    cases = {
        "chaos.header.layout": good[:15],
        "chaos.header.unused-byte-zero": b"\x07" + good[1:],
        "chaos.data.max-488": good[:2] + (489).to_bytes(2, "little") + good[4:] + bytes(489),
        "chaos.header.nbytes": good[:-1],
    }
    for clause, b in cases.items():
        with pytest.raises(DecodeError) as info:
            decode_raw(b)
        assert info.value.clause == clause


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("opcode", 256),
        ("opcode", -1),
        ("fc", 16),
        ("dest_host", 0x10000),
        ("dest_index", -1),
        ("src_host", 0x10000),
        ("src_index", 0x10000),
        ("packet_no", 0x10000),
        ("ack_no", 0x10000),
    ],
)
def test_encode_refuses_out_of_range_fields(field: str, value: int) -> None:
    p = Packet(0o1).with_(**{field: value})
    for encode in (encode_raw, encode_chudp, encode_tcp, encode_chaosd):
        with pytest.raises(EncodeError) as info:
            encode(p)
        assert info.value.path == field
        assert field in str(info.value)


def test_encode_refuses_too_much_data_and_bad_trailer() -> None:
    assert len(encode_raw(Packet(0o200, data=bytes(MAX_DATA)))) == 16 + MAX_DATA
    for encode in (encode_raw, encode_chudp, encode_tcp, encode_chaosd):
        with pytest.raises(EncodeError) as info:
            encode(Packet(0o200, data=bytes(MAX_DATA + 1)))
        assert info.value.clause == "chaos.data.max-488"
    with pytest.raises(EncodeError) as info:
        encode_chudp(Packet(0o1), hw_dest=0x10000)
    assert info.value.path == "trailer.dest"


@given(packets, st.data())
def test_chudp_single_bit_flip_detected(p: Packet, data: st.DataObject) -> None:
    b = bytearray(encode_chudp(p))
    bit = data.draw(st.integers(8 * 4, 8 * len(b) - 1), label="bit")
    b[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(DecodeError) as info:
        decode_chudp(bytes(b))
    assert info.value.clause == "chudp.checksum"


# ------------------------------------------------------------------------------------ checksum


def _simple_checksum(words: list[int]) -> int:
    """Ones'-complement sum as arithmetic modulo 0xFFFF, written independently of the codec."""
    total = sum(words)
    folded = 0 if total == 0 else (total - 1) % 0xFFFF + 1  # 0xFFFF, not 0, for a non-zero sum
    return 0xFFFF - folded


@given(st.lists(words, max_size=300))
def test_checksum_matches_simple_sum(ws: list[int]) -> None:
    assert chaos_checksum(ws) == _simple_checksum(ws)


def test_checksum_worked_example() -> None:
    # Notes section 8, vector 1: the words sum to 0xA5E5 without carries, so the checksum is 0x5A1A.
    ws = [0x0100, 0x0004, 0x0120, 0x0000, 0x0101, 0x0A01, 0x0001, 0x0000, 0x5550, 0x414D, 0x0120, 0x0101]
    assert chaos_checksum(ws) == 0x5A1A == _simple_checksum(ws)
    assert chaos_checksum([0xFFFF, 0x0001]) == _simple_checksum([0xFFFF, 0x0001]) == 0xFFFE


# ------------------------------------------------------------------------------------ fast paths
#
# fw._fast_body and fw._decode_body are the per-packet fast paths; _body_checked and
# _decode_body_checked are the reference.  The fast paths must give the same bytes, packets, trailers and
# errors, and must hand anything unusual to the reference.

any_opcodes = st.integers(0, 0xFF)
fast_packets = packet_strategy(any_opcodes)
hops = st.one_of(st.none(), words)
orders = st.sampled_from([">", "<"])


@given(fast_packets, hops, hops, orders)
def test_fast_encode_equals_reference(p: Packet, hw_dest: int | None, hw_src: int | None, order: str) -> None:
    want = fw._body_checked(p, order, hw_dest, hw_src)  # type: ignore[arg-type]
    assert fw._fast_body(p, order, hw_dest, hw_src, False) == want  # type: ignore[arg-type]
    assert fw._body(p, order, hw_dest, hw_src) == want  # type: ignore[arg-type]
    if order == ">":
        tcp = fw._fast_body(p, ">", hw_dest, hw_src, True)
        assert tcp == len(want).to_bytes(2, "big") + want
        assert encode_tcp(p, hw_dest=hw_dest, hw_src=hw_src) == tcp


class _Index:
    """Not an int, but usable as one by struct: the reference refuses it, so the fast path must too."""

    def __init__(self, value: int) -> None:
        self.value = value

    def __index__(self) -> int:
        return self.value


FIELDS = ("opcode", "fc", "dest_host", "dest_index", "src_host", "src_index", "packet_no", "ack_no")


@given(
    fast_packets,
    st.sampled_from(FIELDS),
    st.one_of(
        st.integers(-(2**20), -1),
        st.integers(0x10000, 2**20),
        st.floats(0, 10),
        st.none(),
        st.builds(_Index, st.integers(0, 0xF)),
    ),
)
def test_fast_encode_hands_bad_fields_to_the_reference(p: Packet, name: str, value: object) -> None:
    bad = p.with_(**{name: value})
    assert fw._fast_body(bad, ">", None, None, True) is None
    for encode in (encode_chudp, encode_tcp, encode_chaosd):
        with pytest.raises(EncodeError) as fast:
            encode(bad)
        with pytest.raises(EncodeError) as ref:
            fw._body_checked(bad, ">", None, None)
        assert (fast.value.path, str(fast.value)) == (ref.value.path, str(ref.value))


@given(
    fast_packets, st.sampled_from(["hw_dest", "hw_src"]), st.one_of(st.integers(0x10000, 2**20), st.none())
)
def test_fast_encode_bad_hop_and_oversize(p: Packet, which: str, value: int | None) -> None:
    if value is not None:
        with pytest.raises(EncodeError) as info:
            encode_tcp(p, **{which: value})
        assert info.value.path == {"hw_dest": "trailer.dest", "hw_src": "trailer.source"}[which]
    big = p.with_(data=bytes(MAX_DATA + 1))
    assert fw._fast_body(big, "<", None, None, False) is None
    with pytest.raises(EncodeError):
        encode_chaosd(big)


@given(fast_packets)
def test_fast_encode_leaves_a_bytearray_alone(p: Packet) -> None:
    """Data that is not ``bytes`` goes the checked way, and an odd-length bytearray is not padded in place."""
    raw = bytearray(p.data)
    q = p.with_(data=raw)
    assert fw._fast_body(q, ">", None, None, True) is None
    assert encode_tcp(q) == encode_tcp(p)
    assert raw == p.data


def _fields(exc: DecodeError) -> tuple[str, str, int | None, str | None]:
    return exc.message, exc.path, exc.offset, exc.clause


def _same_decode(body: bytes, base: int, order: str, verify: bool) -> None:
    """Decode ``body`` both ways (inside a larger buffer, to exercise the offsets): same packet or error."""
    buf = b"\xaa" * 3 + body + b"\x55"
    try:
        want = fw._decode_body_checked(body, base, order, verify=verify)  # type: ignore[arg-type]
    except DecodeError as exc:
        with pytest.raises(DecodeError) as info:
            fw._decode_body(buf, 3, 3 + len(body), base, order, verify=verify)  # type: ignore[arg-type]
        got = info.value
        assert _fields(got) == _fields(exc)
        assert type(got) is type(exc)
        if isinstance(exc, IllegalPacketError):
            assert isinstance(got, IllegalPacketError)
            assert got.packet == exc.packet and got.packet.trailer == exc.packet.trailer
        return
    got_p = fw._decode_body(buf, 3, 3 + len(body), base, order, verify=verify)  # type: ignore[arg-type]
    assert got_p == want
    assert got_p.trailer == want.trailer
    assert type(got_p.data) is bytes


@given(fast_packets, hops, hops, orders, st.booleans())
def test_fast_decode_equals_reference_on_good_frames(
    p: Packet, hw_dest: int | None, hw_src: int | None, order: str, verify: bool
) -> None:
    _same_decode(fw._body_checked(p, order, hw_dest, hw_src), 7, order, verify)  # type: ignore[arg-type]


@given(fast_packets, orders, st.booleans(), st.data())
def test_fast_decode_equals_reference_on_damaged_frames(
    p: Packet, order: str, verify: bool, data: st.DataObject
) -> None:
    body = bytearray(fw._body_checked(p, order, None, None))  # type: ignore[arg-type]
    for _ in range(data.draw(st.integers(1, 3), label="flips")):
        at = data.draw(st.integers(0, len(body) - 1), label="byte")
        body[at] = data.draw(st.integers(0, 255), label="value")
    _same_decode(bytes(body), 0, order, verify)


@given(
    st.integers(11, 255).flatmap(lambda n: st.binary(min_size=2 * n, max_size=2 * n)), orders, st.booleans()
)
def test_fast_decode_equals_reference_on_random_bodies(body: bytes, order: str, verify: bool) -> None:
    _same_decode(body, 2, order, verify)


@given(st.binary(max_size=600).filter(lambda b: len(b) % 2 == 0), orders)
def test_block_checksum_identity(b: bytes, order: str) -> None:
    """The fast paths' checksum: the bytes read as one integer fold like the sum of their words."""
    ws = list(struct.unpack(f"{order}{len(b) // 2}H", b))
    assert fw._ones_sum(int.from_bytes(b, "big" if order == ">" else "little")) == 0xFFFF - _simple_checksum(
        ws
    ) or not any(ws)
    assert ~fw._ones_sum(sum(ws)) & 0xFFFF == _simple_checksum(ws)


@given(st.lists(packets, max_size=5), st.sampled_from([bytes, bytearray, memoryview]))
def test_stream_decoder_takes_any_buffer(ps: list[Packet], kind: type) -> None:
    stream = b"".join(encode_tcp(p) for p in ps)
    d = TcpFrameDecoder()
    got = d.feed(kind(stream[:5])) + d.feed(kind(stream[5:]))
    assert got == [fw._decode_body_checked(encode_tcp(p)[2:], 0, ">", verify=True) for p in ps]
    assert d.pending == 0 and d.offset == len(stream)


@given(fast_packets, st.one_of(st.none(), st.builds(Trailer, words, words, words)))
def test_make_packet_builds_a_real_packet(p: Packet, trailer: Trailer | None) -> None:
    fields = (p.opcode, p.dest_host, p.dest_index, p.src_host, p.src_index, p.packet_no, p.ack_no, p.data)
    made = make_packet(*fields, p.fc, trailer)
    assert type(made) is Packet and made == p and hash(made) == hash(p)
    assert made.trailer == trailer and repr(made) == repr(p.with_(trailer=trailer))
    with pytest.raises(AttributeError):
        made.opcode = 1  # type: ignore[misc]
    t = make_trailer_value(1, 2, 3)
    assert type(t) is Trailer and t == Trailer(1, 2, 3) and hash(t) == hash(Trailer(1, 2, 3))


# ------------------------------------------------------------------------------------ illegal but sound
#
# A frame whose framing, checksum and lengths check out but whose packet has an illegal opcode or more
# than 488 data bytes: strict decoding raises the error it always did, as an IllegalPacketError holding
# the packet; strict=False returns the packet.  Anything garbled is refused in both modes.

SOUND_ILLEGAL_VECTORS = {"chudp-opcode-0", "chudp-opcode-017", "chudp-opcode-0177", "raw-opcode-0177"}
"""The error vectors that are illegal but sound; every other error vector is garbled."""


def _decode_lenient(framing: str, b: bytes) -> Packet:
    match framing:
        case "chudp":
            return decode_chudp(b, strict=False)
        case "tcp":
            return decode_tcp(b, strict=False)
        case "chaosd":
            return decode_chaosd(b, verify=True, strict=False)
        case _:
            return decode_raw(b, strict=False)


@pytest.mark.parametrize("vec", BAD, ids=lambda v: v["name"])
def test_error_vectors_strict_and_lenient(vec: dict[str, Any]) -> None:
    raw = bytes.fromhex(vec["hex"])
    want = vec["error"]
    with pytest.raises(DecodeError) as info:
        _decode_one(vec["framing"], raw)
    strict = info.value
    assert (strict.clause, strict.offset, strict.path) == (want["clause"], want["offset"], want["path"])
    if vec["name"] in SOUND_ILLEGAL_VECTORS:
        assert isinstance(strict, IllegalPacketError)
        got = _decode_lenient(vec["framing"], raw)
        assert got == strict.packet and not is_legal_opcode(got.opcode)
        assert got.opcode == (raw[4] if vec["framing"] == "chudp" else raw[1])
        assert got.data == b"PUMA"
    else:
        assert not isinstance(strict, IllegalPacketError)
        with pytest.raises(DecodeError) as lenient:
            _decode_lenient(vec["framing"], raw)
        assert not isinstance(lenient.value, IllegalPacketError)
        assert _fields(lenient.value) == _fields(strict)


def _forge_body(p: Packet, order: str, hw_dest: int = 0o440, hw_src: int = 0o401) -> bytes:
    """Header, padded data and trailer with a correct checksum, whatever the opcode or data length."""
    ws = [*packet_words(p), hw_dest, hw_src]
    ws.append(chaos_checksum(ws))
    return struct.pack(f"{order}{len(ws)}H", *ws)


def _forge(framing: str, p: Packet) -> bytes:
    if framing == "chudp":
        return fw.CHUDP_HEADER + _forge_body(p, ">")
    if framing == "tcp":
        body = _forge_body(p, ">")
        return len(body).to_bytes(2, "big") + body
    if framing == "chaosd":
        body = _forge_body(p, "<")
        return bytes((len(body) >> 8, len(body) & 0xFF, 1, 0)) + body
    return encode_raw(p) if len(p.data) <= MAX_DATA else struct.pack("<8H", *packet_words(p)[:8]) + p.data


def _is_illegal(p: Packet) -> bool:
    return not is_legal_opcode(p.opcode) or len(p.data) > MAX_DATA


any_packets = packet_strategy(
    any_opcodes, st.one_of(st.binary(max_size=MAX_DATA), st.binary(min_size=MAX_DATA + 1, max_size=700))
)


@given(any_packets, st.sampled_from(["chudp", "tcp", "chaosd", "raw"]))
def test_sound_frames_decode_leniently_whatever_the_opcode_or_count(p: Packet, framing: str) -> None:
    if framing in ("tcp", "chaosd") and len(p.data) > MAX_DATA:
        p = p.with_(data=p.data[:MAX_DATA])  # a stream frame cannot hold more (its length is framing)
    frame = _forge(framing, p)
    got = _decode_lenient(framing, frame)
    assert got == p
    if _is_illegal(p):
        with pytest.raises(IllegalPacketError) as info:
            _decode_one(framing, frame)
        assert info.value.packet == got and info.value.packet.trailer == got.trailer
        # The opcode is reported first, as strict decoding always has.
        legal = is_legal_opcode(p.opcode)
        assert info.value.clause == ("chaos.data.max-488" if legal else "chaos.opcode.legal")
    else:
        assert _decode_one(framing, frame) == got


def _frame_words(framing: str, ws: list[int], *, checksum_delta: int = 0) -> bytes:
    """Frame header and data words ``ws`` with trailer 0440/0401 and a checksum (off by the delta)."""
    ws = [*ws, 0o440, 0o401]
    ws.append((chaos_checksum(ws) + checksum_delta) & 0xFFFF)
    body = struct.pack(f"{'<' if framing == 'chaosd' else '>'}{len(ws)}H", *ws)
    if framing == "chudp":
        return fw.CHUDP_HEADER + body
    if framing == "tcp":
        return len(body).to_bytes(2, "big") + body
    return bytes((len(body) >> 8, len(body) & 0xFF, 1, 0)) + body


@pytest.mark.parametrize("framing", ["chudp", "tcp", "chaosd"])
def test_illegal_and_garbled_is_garbled(framing: str) -> None:
    """An illegal opcode does not make a frame deliverable when anything else about it is wrong."""
    ws = packet_words(Packet(0o177, 0o440, 0, 0o401, 0x0A01, 1, 0, b"PUMA"))
    unused = [ws[0] | 1, *ws[1:]]
    short = [ws[0], 6, *ws[2:]]  # nbytes 6, 4 data bytes
    cases = [
        (_frame_words(framing, unused), "chaos.header.unused-byte-zero"),
        (_frame_words(framing, short), "chaos.opcode.legal"),  # strict order: the opcode is named
    ]
    if framing != "chaosd":  # chaosd checksums are not verified by default
        cases.append((_frame_words(framing, ws, checksum_delta=1), "chudp.checksum"))
    assert isinstance(_decode_lenient(framing, _frame_words(framing, ws)), Packet)  # the control
    for frame, clause in cases:
        for decode in (_decode_one, _decode_lenient):
            with pytest.raises(DecodeError) as info:
                decode(framing, frame)
            assert not isinstance(info.value, IllegalPacketError)
            assert info.value.clause == clause, str(info.value)


def test_oversize_count_without_the_data_is_garbled() -> None:
    """nbytes 490 in a datagram with 4 data bytes: the count is refused, in both modes, not answered."""
    p = Packet(ChaosOp.DAT, 0o440, 0x5E02, 0o401, 0x0A01, 2, 1, b"abcd")
    ws = list(packet_words(p))
    ws[1] = 490
    ws += [0o440, 0o401]
    ws.append(chaos_checksum(ws))
    datagram = fw.CHUDP_HEADER + struct.pack(f">{len(ws)}H", *ws)
    for strict in (True, False):
        with pytest.raises(DecodeError) as info:
            decode_chudp(datagram, strict=strict)
        assert not isinstance(info.value, IllegalPacketError)
        assert info.value.clause == "chaos.data.max-488"


def test_oversize_fits_only_in_a_datagram() -> None:
    p = Packet(ChaosOp.DAT, 0o440, 0x5E02, 0o401, 0x0A01, 2, 1, bytes(range(256)) + bytes(234))
    datagram = _forge("chudp", p)
    assert len(datagram) == 4 + 16 + 490 + 6
    got = decode_chudp(datagram, strict=False)
    assert got == p and got.trailer == Trailer(0o440, 0o401, struct.unpack(">H", datagram[-2:])[0])
    with pytest.raises(IllegalPacketError, match="at most 488") as info:
        decode_chudp(datagram)
    assert (info.value.path, info.value.offset) == ("header.nbytes", 6)
    # The same packet cannot be framed for TCP: its length is beyond what the framing allows.
    with pytest.raises(FrameSyncError):
        decode_tcp(_forge("tcp", p), strict=False)
    with pytest.raises(EncodeError):
        encode_chudp(p)


def test_stream_items_carry_illegal_packets() -> None:
    good = Packet(ChaosOp.DAT, 0o440, 0x5E02, 0o401, 0x0A01, 2, 1, b"ok")
    illegal = good.with_(opcode=0o20, packet_no=3)
    stream = encode_tcp(good) + _forge("tcp", illegal) + encode_tcp(good.with_(packet_no=4))
    d = TcpFrameDecoder()
    items = d.feed(stream[:7]) + d.feed(stream[7:])
    assert [type(item) for item in items] == [Packet, IllegalPacketError, Packet]
    assert isinstance(items[1], IllegalPacketError) and items[1].packet == illegal
    assert items[1].offset == len(encode_tcp(good)) + 2 + 0  # word 0, high byte first
    assert decode_stream(TcpFrameDecoder(), stream, strict=False)[1] == illegal
    with pytest.raises(IllegalPacketError):
        decode_stream(TcpFrameDecoder(), stream)
    with pytest.raises(IllegalPacketError):
        FRAMINGS["tcp"].decode(stream)  # the registry (manip-decode) stays strict


def test_illegal_packet_error_moves_with_its_packet() -> None:
    p = Packet(0o177, 0o440, 0, 0o401, 0x0A01, 1, 0, b"x")
    with pytest.raises(IllegalPacketError) as info:
        decode_raw(encode_raw(p))
    moved = info.value.at("frame", 10)
    assert isinstance(moved, IllegalPacketError) and moved.packet == p
    assert (moved.path, moved.offset, moved.clause) == ("frame.header.opcode", 11, "chaos.opcode.legal")
