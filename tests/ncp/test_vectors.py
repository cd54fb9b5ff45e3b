"""The notes' CHUDP test vectors (chaosnet.md section 8) as Packets: the NCP must produce exactly them.

Hosts: toolkit 0401 with index 0x0A01, robot 0440 with index 0x5E02, windows 5, first packet numbers 1.
The byte framing of the same vectors is the codec layer's business; here only the header fields and data
matter.
"""

from __future__ import annotations

import struct

from manip.codecs.packet import Packet
from manip.ncp import ConnectionRequested, ConnState, DataReceived, Ncp, Opened
from manip.spec.constants import ChaosOp

CLIENT, SERVER = 0o401, 0o440
CLIENT_INDEX, SERVER_INDEX = 0x0A01, 0x5E02

RFC = Packet(ChaosOp.RFC, SERVER, 0, CLIENT, CLIENT_INDEX, 1, 0, b"PUMA")
OPN = Packet(ChaosOp.OPN, CLIENT, CLIENT_INDEX, SERVER, SERVER_INDEX, 1, 1, struct.pack("<HH", 1, 5))
STS = Packet(ChaosOp.STS, SERVER, SERVER_INDEX, CLIENT, CLIENT_INDEX, 2, 1, struct.pack("<HH", 1, 5))
DAT4 = Packet(ChaosOp.DAT, SERVER, SERVER_INDEX, CLIENT, CLIENT_INDEX, 2, 1, bytes([1, 2, 3, 4]))
DAT3 = Packet(ChaosOp.DAT, SERVER, SERVER_INDEX, CLIENT, CLIENT_INDEX, 3, 1, b"ABC")
ANS = Packet(ChaosOp.ANS, CLIENT, CLIENT_INDEX, SERVER, 0, 0, 0, b"OK")
LOS_FOR_DAT4 = Packet(ChaosOp.LOS, CLIENT, CLIENT_INDEX, SERVER, SERVER_INDEX, 2, 1)


def _client() -> Ncp:
    return Ncp(CLIENT, window=5, uniquizer=0x0A)


def _server() -> Ncp:
    """A server whose next index is 0x5E02: one connection (0x5D01) is made first to use slot 1."""
    server = Ncp(SERVER, window=5, uniquizer=0x5D)
    server.listen("PUMA")
    assert server.connect(0.0, 0o500, "OTHER") == 0x5D01
    server.packets_to_send()
    return server


def test_vector_1_rfc() -> None:
    client = _client()
    assert client.connect(0.0, SERVER, "PUMA") == CLIENT_INDEX
    assert client.packets_to_send() == [RFC]
    assert client.state(CLIENT_INDEX) is ConnState.RFC_SENT


def test_vector_2_opn() -> None:
    server = _server()
    server.receive(0.0, RFC)
    [event] = server.events()
    assert event == ConnectionRequested(SERVER_INDEX, CLIENT, CLIENT_INDEX, "PUMA", b"", RFC)
    server.accept(0.0, SERVER_INDEX)
    assert server.packets_to_send() == [OPN]
    assert server.state(SERVER_INDEX) is ConnState.OPEN
    assert not server.can_send(SERVER_INDEX), "transmit window is 0 until the STS"
    server.receive(0.0, STS)
    assert server.events() == [Opened(SERVER_INDEX, CLIENT, CLIENT_INDEX, 5)]
    assert server.window_space(SERVER_INDEX) == 5


def test_vector_3_sts_then_4_and_5_data() -> None:
    client = _client()
    client.connect(0.0, SERVER, "PUMA")
    client.packets_to_send()
    client.receive(0.0, OPN)
    assert client.packets_to_send() == [STS]
    assert client.events() == [Opened(CLIENT_INDEX, SERVER, SERVER_INDEX, 5)]
    assert client.send(0.0, CLIENT_INDEX, bytes([1, 2, 3, 4])) == 2
    assert client.send(0.0, CLIENT_INDEX, b"ABC") == 3
    assert client.packets_to_send() == [DAT4, DAT3]


def test_vectors_4_and_5_arrive_as_data_with_their_numbers() -> None:
    server = _server()
    server.receive(0.0, RFC)
    server.accept(0.0, SERVER_INDEX)
    server.receive(0.0, STS)
    server.events()
    server.receive(0.01, DAT4)
    server.receive(0.01, DAT3)
    events = server.events()
    assert events == [DataReceived(SERVER_INDEX, DAT4), DataReceived(SERVER_INDEX, DAT3)]
    assert [e.packet_no for e in events if isinstance(e, DataReceived)] == [2, 3]


def test_vector_6_ans() -> None:
    server = _server()
    server.receive(0.0, RFC)
    server.answer(0.0, SERVER_INDEX, b"OK")
    assert server.packets_to_send() == [ANS]
    assert server.state(SERVER_INDEX) is ConnState.CLOSED


def test_vector_7_los_reflects_the_offending_packet() -> None:
    stranger = Ncp(SERVER)
    stranger.receive(0.0, DAT4)
    [los] = stranger.packets_to_send()
    assert los.with_(data=b"") == LOS_FOR_DAT4
    assert los.data == b"Connection doesn't exist"
