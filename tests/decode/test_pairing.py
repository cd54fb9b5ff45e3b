"""The decoder's stream pairing keeps a bound on what it remembers: a stream of requests nobody answers,
or of connections without end, is read in bounded memory, and the answers that do come still pair."""

from __future__ import annotations

import pytest

from manip.codecs.packet import Packet
from manip.decode import pairing
from manip.decode.pairing import StreamPairing
from manip.spec.constants import ChaosOp

SERVER, CLIENT = 0o440, 0o401


def _open(stream: StreamPairing, index: int) -> None:
    """An RFC from the client's ``index`` and the server's OPN from its index 0x2001."""
    stream.place(Packet(ChaosOp.RFC, SERVER, 0, CLIENT, index, 1, 0, b"PUMA"))
    stream.place(Packet(ChaosOp.OPN, CLIENT, index, SERVER, 0x2001, 1, 1, b""))


def _here(index: int, number: int) -> Packet:
    return Packet(0o201, SERVER, 0x2001, CLIENT, index, number, 0, b"")


def _done(index: int, number: int) -> Packet:
    return Packet(0o200, CLIENT, index, SERVER, 0x2001, 1, 0, number.to_bytes(2, "little"))


def test_unanswered_requests_are_let_go_beyond_the_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pairing, "MAX_PENDING", 8)
    stream = StreamPairing()
    _open(stream, 0x1001)
    for number in range(2, 1002):
        assert stream.place(_here(0x1001, number)).side == "request"
    (state,) = stream._connections.values()
    assert len(state.outstanding()) == 8 and state.forgotten == 1000 + 1 - 8  # the RFC's entry too
    answer = stream.place(_done(0x1001, 994))  # the oldest still kept
    assert (answer.side, answer.request_opcode, answer.request_no) == ("response", 0o201, 994)


def test_connections_beyond_the_bound_forget_the_least_recently_seen(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pairing, "MAX_CONNECTIONS", 4)
    stream = StreamPairing()
    for index in range(0x1001, 0x1101):
        _open(stream, index)
        stream.place(_here(index, 2))
    assert len(stream._connections) == 4
    stream.place(_done(0x1100, 1))  # the initial RESPONSE answers the RFC
    last = stream.place(_done(0x1100, 2))  # the newest connection is still paired
    assert (last.request_opcode, last.request_no) == (0o201, 2)
