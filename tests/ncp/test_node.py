"""The NCP's behaviour, one rule at a time, on a fake clock with packets carried by hand."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any, TypeVar

import pytest

from manip.codecs.packet import Packet
from manip.ncp import (
    Answered,
    Broken,
    Closed,
    ConnectionRequested,
    ConnState,
    DataReceived,
    EofReceived,
    Event,
    Forwarded,
    InvalidStateError,
    Lost,
    Ncp,
    Opened,
    UncontrolledReceived,
    UnknownConnectionError,
    WindowFullError,
)
from manip.spec.constants import ChaosOp

A, B = 0o401, 0o440

Filter = Callable[[Packet], bool]
T = TypeVar("T", bound=Event)


def _keep(_p: Packet) -> bool:
    return True


def shuttle(now: float, a: Ncp, b: Ncp, keep: Filter = _keep) -> list[Packet]:
    """Carry packets both ways at ``now`` until both NCPs are quiet; return every packet sent."""
    moved: list[Packet] = []
    while True:
        from_a, from_b = a.packets_to_send(), b.packets_to_send()
        if not from_a and not from_b:
            return moved
        moved += from_a + from_b
        for p in from_a:
            if keep(p):
                b.receive(now, p)
        for p in from_b:
            if keep(p):
                a.receive(now, p)


def open_pair(**options: Any) -> tuple[Ncp, Ncp, int, int]:
    """Two NCPs with an open connection between them (a called b), events drained."""
    a = Ncp(A, **options)
    b = Ncp(B, **options)
    b.listen("TEST")
    ca = a.connect(0.0, B, "TEST", "some args")
    b.receive(0.0, a.packets_to_send()[0])
    [req] = b.events()
    assert isinstance(req, ConnectionRequested)
    b.accept(0.0, req.conn_id)
    shuttle(0.0, a, b)
    assert isinstance(a.events()[0], Opened)
    assert isinstance(b.events()[0], Opened)
    return a, b, ca, req.conn_id


def of_type(events: list[Event], cls: type[T]) -> list[T]:
    return [e for e in events if isinstance(e, cls)]


def ops(packets: list[Packet]) -> list[int]:
    return [p.opcode for p in packets]


# ---------------------------------------------------------------------- opening


def test_indices_start_at_the_given_slot_and_uniquizer() -> None:
    a = Ncp(A, uniquizer=0x12, first_slot=0xFE)
    first, second, third = (a.connect(0.0, B, "TEST") for _ in range(3))
    assert (first, second, third) == (0x12FE, 0x13FF, 0x1401)  # the slot wraps past 255 to 1
    with pytest.raises(ValueError, match="first_slot"):
        Ncp(A, first_slot=0)
    with pytest.raises(ValueError, match="first_slot"):
        Ncp(A, first_slot=256)


def test_connect_and_accept_open_both_sides() -> None:
    a = Ncp(A, window=7)
    b = Ncp(B, window=9)
    b.listen("TEST")
    ca = a.connect(0.0, B, "TEST", b"x y")
    [rfc] = a.packets_to_send()
    assert (rfc.opcode, rfc.data, rfc.packet_no, rfc.dest_index) == (ChaosOp.RFC, b"TEST x y", 1, 0)
    b.receive(0.0, rfc)
    [req] = b.events()
    assert isinstance(req, ConnectionRequested)
    assert (req.contact, req.args, req.peer_host, req.peer_index) == ("TEST", b"x y", A, ca)
    assert b.state(req.conn_id) is ConnState.RFC_RECEIVED
    b.accept(0.0, req.conn_id)
    shuttle(0.0, a, b)
    assert a.events() == [Opened(ca, B, req.conn_id, 9)]
    assert b.events() == [Opened(req.conn_id, A, ca, 7)]
    assert a.state(ca) is b.state(req.conn_id) is ConnState.OPEN
    assert a.window_space(ca) == 9 and b.window_space(req.conn_id) == 7


def test_refusal_closes_the_caller() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    ca = a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    [req] = b.events()
    b.refuse(0.0, req.conn_id, "Go away")
    [cls] = b.packets_to_send()
    assert (cls.opcode, cls.src_index, cls.dest_index, cls.data) == (ChaosOp.CLS, 0, ca, b"Go away")
    a.receive(0.0, cls)
    assert a.events() == [Closed(ca, "Go away", by_peer=True)]
    assert a.state(ca) is ConnState.CLOSED and b.state(req.conn_id) is ConnState.CLOSED
    assert a.next_deadline() is None, "no more retransmission of the RFC"


def test_answer_and_forward() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    c1 = a.connect(0.0, B, "TEST")
    c2 = a.connect(0.0, B, "TEST", "again")
    shuttle(0.0, a, b)
    r1, r2 = of_type(b.events(), ConnectionRequested)
    b.answer(0.0, r1.conn_id, b"the answer")
    b.forward(0.0, r2.conn_id, 0o500, "ELSEWHERE")
    shuttle(0.0, a, b)
    answered, forwarded = a.events()
    assert isinstance(answered, Answered) and answered.conn_id == c1 and answered.data == b"the answer"
    assert isinstance(forwarded, Forwarded) and forwarded.conn_id == c2
    assert (forwarded.host, forwarded.contact) == (0o500, "ELSEWHERE")
    assert forwarded.packet.ack_no == 0o500, "FWD carries the new host in the ack field"


def test_rfc_without_listener_is_refused() -> None:
    a, b = Ncp(A), Ncp(B)
    ca = a.connect(0.0, B, "NOBODY")
    shuttle(0.0, a, b)
    [closed] = a.events()
    assert isinstance(closed, Closed) and closed.by_peer and closed.conn_id == ca
    assert b.connections() == []


def test_unlisten_refuses_later_rfcs() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    b.unlisten("TEST")
    a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    assert isinstance(a.events()[0], Closed)


def test_duplicate_rfc_while_pending_is_dropped() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    [rfc] = a.packets_to_send()
    b.receive(0.0, rfc)
    b.receive(0.1, rfc)
    a.timer(0.5)
    [again] = a.packets_to_send()
    assert again == rfc, "the RFC is retransmitted unchanged"
    b.receive(0.5, again)
    assert len(of_type(b.events(), ConnectionRequested)) == 1
    assert len(b.connections()) == 1
    assert b.packets_to_send() == []


def test_duplicate_rfc_on_open_connection_resends_the_unreceipted_opn() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    [rfc] = a.packets_to_send()
    b.receive(0.0, rfc)
    [req] = b.events()
    b.accept(0.0, req.conn_id)
    [opn] = b.packets_to_send()  # lost
    b.receive(0.2, rfc)
    assert b.packets_to_send() == [opn]
    a.receive(0.2, opn)
    shuttle(0.2, a, b)
    b.receive(0.3, rfc)  # the OPN is receipted now: nothing to resend
    assert b.packets_to_send() == []
    assert len(b.connections()) == 1


def test_half_open_server_waits_for_sts_and_probes_for_it() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    [req] = b.events()
    b.accept(0.0, req.conn_id)
    with pytest.raises(WindowFullError):
        b.send(0.0, req.conn_id, b"too early")
    shuttle(0.0, a, b, keep=lambda p: p.opcode != ChaosOp.STS)  # the client's STS is lost
    assert b.events() == [] and not b.can_send(req.conn_id)
    deadline = b.next_deadline()
    assert deadline is not None and deadline <= 0.5
    b.timer(0.5)
    probes = b.packets_to_send()
    assert ChaosOp.SNS in ops(probes)
    for p in probes:
        a.receive(0.5, p)
    shuttle(0.5, a, b)
    assert of_type(b.events(), Opened) and b.can_send(req.conn_id)


def test_duplicate_opn_is_answered_with_sts() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    b.accept(0.0, b.events()[0].conn_id)
    [opn] = b.packets_to_send()
    a.receive(0.0, opn)
    a.packets_to_send()
    a.receive(0.1, opn)
    assert ops(a.packets_to_send()) == [ChaosOp.STS]
    assert len(of_type(a.events(), Opened)) == 1


# ---------------------------------------------------------------------- LOS rules


def _stray(opcode: int, data: bytes = b"") -> Packet:
    return Packet(opcode, B, 0x0101, A, 0x0202, 7, 6, data)


@pytest.mark.parametrize(
    "opcode", [ChaosOp.OPN, ChaosOp.SNS, ChaosOp.STS, ChaosOp.EOF, ChaosOp.UNC, ChaosOp.DAT, 0o377]
)
def test_los_for_a_connection_that_does_not_exist(opcode: int) -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(opcode))
    [los] = b.packets_to_send()
    assert los == Packet(ChaosOp.LOS, A, 0x0202, B, 0x0101, 7, 6, b"Connection doesn't exist")


@pytest.mark.parametrize("opcode", [ChaosOp.LOS, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD])
def test_no_los_for_los_cls_ans_fwd_to_unknown_connections(opcode: int) -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(opcode, b"whatever"))
    assert b.packets_to_send() == []


@pytest.mark.parametrize("opcode", [ChaosOp.MNT, ChaosOp.RUT, ChaosOp.BRD])
def test_mnt_rut_brd_are_dropped(opcode: int) -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(opcode))
    assert b.packets_to_send() == []


def test_byte_count_over_488_draws_los() -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(ChaosOp.DAT, bytes(489)))
    [los] = b.packets_to_send()
    assert los.data == b"Illegal byte count 489 (at most 488)" and los.packet_no == 7


def test_488_bytes_is_fine() -> None:
    a, b, ca, _cb = open_pair()
    a.send(0.0, ca, bytes(488))
    shuttle(0.0, a, b)
    [got] = of_type(b.events(), DataReceived)
    assert got.data == bytes(488)


@pytest.mark.parametrize("opcode", [0, 0o17, 0o100, 0o176, 0o177])
def test_illegal_opcode_draws_los(opcode: int) -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(opcode))
    [los] = b.packets_to_send()
    assert los.opcode == ChaosOp.LOS and los.data == f"Illegal opcode {opcode:03o}".encode()
    # Reflected like every LOS: indices swapped, packet and ack numbers kept.
    assert (los.dest_host, los.dest_index, los.src_index) == (A, 0x0202, 0x0101)
    assert (los.packet_no, los.ack_no) == (7, 6)
    assert b.stats.los_sent == 1


def test_no_los_for_an_oversized_los_or_cls() -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(ChaosOp.LOS, bytes(500)))
    b.receive(0.0, _stray(ChaosOp.CLS, bytes(500)))
    assert b.packets_to_send() == []
    assert b.stats.los_sent == 0 and b.stats.dropped == 2


@pytest.mark.parametrize(
    ("opcode", "data", "says"),
    [(0o177, b"xy", b"Illegal opcode 177"), (ChaosOp.DAT, bytes(490), b"Illegal byte count 490")],
)
def test_illegal_packet_on_an_open_connection_draws_los_and_leaves_it_open(
    opcode: int, data: bytes, says: bytes
) -> None:
    a, b, ca, cb = open_pair()
    b.receive(0.0, Packet(opcode, B, cb, A, ca, 2, 1, data))
    [los] = b.packets_to_send()
    assert los.opcode == ChaosOp.LOS and los.data.startswith(says)
    assert (los.dest_index, los.src_index, los.packet_no, los.ack_no) == (ca, cb, 2, 1)
    assert b.state(cb) is ConnState.OPEN and b.events() == []
    a.receive(0.0, los)  # the sender of the illegal packet loses its connection, as AIM 628 says
    assert a.state(ca) is ConnState.LOST


def test_illegal_packet_for_another_host_is_dropped_not_answered() -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(0o177).with_(dest_host=0o777))
    b.receive(0.0, _stray(ChaosOp.DAT, bytes(490)).with_(dest_host=0o777))
    assert b.packets_to_send() == [] and b.stats.dropped == 2


def test_packets_for_other_hosts_are_dropped() -> None:
    b = Ncp(B)
    b.receive(0.0, _stray(ChaosOp.DAT).with_(dest_host=0o777))
    assert b.packets_to_send() == []
    assert b.stats.dropped == 1


def test_wrong_peer_index_counts_as_no_connection() -> None:
    _a, b, ca, cb = open_pair()
    b.receive(0.0, Packet(ChaosOp.DAT, B, cb, A, ca ^ 0x100, 2, 1, b"x"))
    [los] = b.packets_to_send()
    assert los.data == b"Connection doesn't exist"
    assert b.state(cb) is ConnState.OPEN and b.events() == []


def test_data_to_a_connection_still_calling_draws_los_closed() -> None:
    a = Ncp(A)
    ca = a.connect(0.0, B, "TEST")
    a.packets_to_send()
    a.receive(0.0, Packet(ChaosOp.DAT, A, ca, B, 0x0505, 2, 1, b"x"))
    [los] = a.packets_to_send()
    assert los.data == b"Connection is closed"
    assert a.state(ca) is ConnState.RFC_SENT


def test_packets_after_close_draw_los() -> None:
    a, b, ca, cb = open_pair()
    a.abort(0.0, ca, "bye")
    [cls] = a.packets_to_send()
    a.receive(0.0, Packet(ChaosOp.DAT, A, ca, B, cb, 2, 1, b"late"))
    [los] = a.packets_to_send()
    assert los.data == b"Connection doesn't exist"
    b.receive(0.0, cls)
    assert b.events() == [Closed(cb, "bye", by_peer=True)]


def test_los_from_peer_loses_the_connection() -> None:
    a, _b, ca, cb = open_pair()
    a.send(0.0, ca, b"data")
    [dat] = a.packets_to_send()
    a.receive(0.1, Packet(ChaosOp.LOS, A, ca, B, cb, dat.packet_no, dat.ack_no, b"Trouble"))
    [lost] = a.events()
    assert isinstance(lost, Lost) and lost.reason == "Trouble"
    assert a.state(ca) is ConnState.LOST
    assert a.next_deadline() is None
    with pytest.raises(InvalidStateError):
        a.send(0.2, ca, b"more")
    a.close(0.2, ca)  # harmless


def test_reused_slot_gets_a_new_index_and_stale_packets_do_not_match() -> None:
    a = Ncp(A)
    first = a.connect(0.0, B, "TEST")
    a.abort(0.0, first)
    others = [a.connect(0.0, B, "TEST") for _ in range(254)]
    reused = a.connect(0.0, B, "TEST")
    assert reused & 0xFF == first & 0xFF and reused != first
    assert first not in others
    a.packets_to_send()
    a.receive(0.0, Packet(ChaosOp.OPN, A, first, B, 0x0707, 1, 1, struct.pack("<HH", 1, 5)))
    assert ops(a.packets_to_send()) == [ChaosOp.LOS]
    assert a.state(reused) is ConnState.RFC_SENT


# ---------------------------------------------------------------------- data and windows


def test_window_limits_sending_and_acks_reopen_it() -> None:
    a, b, ca, _cb = open_pair(window=4)
    numbers = [a.send(0.0, ca, bytes([i])) for i in range(4)]
    assert numbers == [2, 3, 4, 5]
    assert not a.can_send(ca) and a.window_space(ca) == 0
    with pytest.raises(WindowFullError):
        a.send(0.0, ca, b"one too many")
    shuttle(0.0, a, b)
    got = of_type(b.events(), DataReceived)
    assert [e.data for e in got] == [bytes([i]) for i in range(4)]
    assert a.window_space(ca) == 4
    assert a.info(ca).unreceipted == 0


def test_out_of_order_packets_are_delivered_in_order_once() -> None:
    a, b, ca, _cb = open_pair()
    for i in range(5):
        a.send(0.0, ca, bytes([i]))
    packets = a.packets_to_send()
    for p in [packets[3], packets[1], packets[4], packets[1], packets[0], packets[2], packets[2]]:
        b.receive(0.0, p)
    got = of_type(b.events(), DataReceived)
    assert [e.data for e in got] == [bytes([i]) for i in range(5)]
    assert b.stats.duplicates_received == 2


def test_duplicate_data_is_answered_with_sts() -> None:
    a, b, ca, _cb = open_pair()
    a.send(0.0, ca, b"x")
    [dat] = a.packets_to_send()
    b.receive(0.0, dat)
    b.packets_to_send()
    b.receive(0.0, dat)
    [sts] = b.packets_to_send()
    assert sts.opcode == ChaosOp.STS and struct.unpack("<HH", sts.data) == (dat.packet_no, 15)
    assert sts.ack_no == dat.packet_no


def test_delayed_sts_acknowledges_a_lone_packet() -> None:
    a, b, ca, _cb = open_pair(ack_delay=0.1)
    a.send(0.0, ca, b"x")
    b.receive(0.0, a.packets_to_send()[0])
    assert b.packets_to_send() == []
    assert b.next_deadline() == pytest.approx(0.1)
    b.timer(0.1)
    [sts] = b.packets_to_send()
    a.receive(0.1, sts)
    assert a.info(ca).unreceipted == 0 and a.info(ca).outstanding == 0


def test_sts_after_a_third_of_the_window_is_read() -> None:
    a, b, ca, _cb = open_pair(window=6)
    for i in range(3):
        a.send(0.0, ca, bytes([i]))
    d0, d1, d2 = a.packets_to_send()
    b.receive(0.0, d0)
    b.receive(0.0, d1)
    assert b.packets_to_send() == [], "2 of 6 read: 3*2 is not more than 6"
    b.receive(0.0, d2)
    [sts] = b.packets_to_send()
    assert sts.ack_no == d2.packet_no


def test_reply_data_carries_the_ack() -> None:
    a, b, ca, cb = open_pair()
    n = a.send(0.0, ca, b"request")
    b.receive(0.0, a.packets_to_send()[0])
    b.send(0.0, cb, b"response")
    [reply] = b.packets_to_send()
    assert reply.ack_no == n
    a.receive(0.0, reply)
    assert a.info(ca).unreceipted == 0


def test_acks_beyond_what_was_sent_are_ignored() -> None:
    a, _b, ca, cb = open_pair()
    a.send(0.0, ca, b"x")
    a.packets_to_send()
    a.receive(0.0, Packet(ChaosOp.STS, A, ca, B, cb, 9, 1000, struct.pack("<HH", 1000, 15)))
    info = a.info(ca)
    assert info.outstanding == 1 and info.unreceipted == 1


def test_receipt_stops_retransmission_but_does_not_open_the_window() -> None:
    a, _b, ca, cb = open_pair(window=2)
    n1 = a.send(0.0, ca, b"1")
    a.send(0.0, ca, b"2")
    a.packets_to_send()
    a.receive(0.0, Packet(ChaosOp.STS, A, ca, B, cb, 9, 1, struct.pack("<HH", n1 + 1, 2)))
    info = a.info(ca)
    assert info.unreceipted == 0 and info.outstanding == 2 and not a.can_send(ca)
    a.timer(1.0)
    assert ChaosOp.DAT not in ops(a.packets_to_send())


def test_data_beyond_the_receive_window_is_dropped() -> None:
    _a, b, ca, cb = open_pair(window=3)
    last = b.info(cb).last_received
    b.receive(0.0, Packet(ChaosOp.DAT, B, cb, A, ca, (last + 5) & 0xFFFF, 1, b"far"))
    assert b.info(cb).buffered == 0 and b.events() == []


def test_retransmission_until_receipted() -> None:
    a, b, ca, _cb = open_pair()
    a.send(0.0, ca, b"x")
    [first] = a.packets_to_send()
    assert a.next_deadline() == pytest.approx(0.5)
    a.timer(0.5)
    [again] = a.packets_to_send()
    assert again == first
    b.receive(0.5, again)
    b.timer(1.0)
    for p in b.packets_to_send():
        a.receive(1.0, p)
    a.timer(1.5)
    assert ChaosOp.DAT not in ops(a.packets_to_send())


def test_uncontrolled_data_is_delivered_unsequenced() -> None:
    _a, b, ca, cb = open_pair()
    b.receive(0.0, Packet(ChaosOp.UNC, B, cb, A, ca, 0, 1, b"loose"))
    [unc] = b.events()
    assert isinstance(unc, UncontrolledReceived) and unc.packet.data == b"loose"


# ---------------------------------------------------------------------- reading by hand


def test_manual_read_holds_the_window_until_read_ack() -> None:
    a, b, ca, cb = open_pair(window=3, auto_read=False)
    nums = [a.send(0.0, ca, bytes([i])) for i in range(3)]
    shuttle(0.0, a, b)
    b.timer(0.1)
    shuttle(0.1, a, b)
    assert len(of_type(b.events(), DataReceived)) == 3
    info = a.info(ca)
    assert info.unreceipted == 0, "received in order: receipted"
    assert info.outstanding == 3 and not a.can_send(ca), "not read: not acknowledged"
    b.read_ack(0.2, cb, nums[0])
    assert b.packets_to_send() == [], "one of three read: not yet worth an STS"
    b.read_ack(0.2, cb, nums[2])
    shuttle(0.2, a, b)
    assert a.window_space(ca) == 3


def test_read_ack_beyond_delivery_is_an_error() -> None:
    _a, b, _ca, cb = open_pair(auto_read=False)
    with pytest.raises(InvalidStateError):
        b.read_ack(0.0, cb, b.info(cb).last_received + 1)


# ---------------------------------------------------------------------- closing


def test_graceful_close_sends_eof_then_cls() -> None:
    a, b, ca, cb = open_pair()
    for i in range(3):
        a.send(0.0, ca, bytes([i]))
    a.close(0.0, ca)
    with pytest.raises(InvalidStateError):
        a.send(0.0, ca, b"after close")
    moved = shuttle(0.0, a, b)
    sent_by_a = [p.opcode for p in moved if p.src_host == A]
    assert sent_by_a[:4] == [ChaosOp.DAT] * 3 + [ChaosOp.EOF]
    assert sent_by_a[-1] == ChaosOp.CLS
    got = b.events()
    assert [type(e) for e in got] == [DataReceived] * 3 + [EofReceived, Closed]
    assert got[-1] == Closed(cb, "", by_peer=True)
    assert a.events() == [Closed(ca, "", by_peer=False)]
    assert a.state(ca) is b.state(cb) is ConnState.CLOSED


def test_closing_after_the_peers_eof_sends_cls_alone() -> None:
    """Both ends close, the peer first: no EOF of ours to cross its CLS (and draw a LOS)."""
    a, b, ca, cb = open_pair()
    a.close(0.0, ca)
    [eof] = a.packets_to_send()
    b.receive(0.0, eof)
    assert [type(e) for e in b.events()] == [EofReceived]
    b.read_ack(0.0, cb, eof.packet_no)  # b's user takes the EOF (an STS acknowledges it) and closes
    b.close(0.0, cb)
    sent = b.packets_to_send()
    assert ops(sent) == [ChaosOp.STS, ChaosOp.CLS]
    assert b.events() == [Closed(cb, "", by_peer=False)] and b.state(cb) is ConnState.CLOSED
    for p in sent:
        a.receive(0.0, p)
    assert a.state(ca) is ConnState.CLOSED
    assert ChaosOp.LOS not in ops(a.packets_to_send())  # a's own CLS (if any) draws nothing


def test_closing_after_the_peers_eof_waits_for_our_data_to_be_acknowledged() -> None:
    a, b, ca, cb = open_pair()
    a.close(0.0, ca)
    b.receive(0.0, a.packets_to_send()[0])
    b.events()
    b.send(0.0, cb, b"last words")
    b.close(0.0, cb)
    assert ChaosOp.CLS not in ops(b.packets_to_send())  # "last words" is not acknowledged yet
    assert b.state(cb) is ConnState.OPEN
    b.timer(0.5)
    moved = shuttle(0.5, a, b)
    assert [type(e) for e in a.events()] == [DataReceived, Closed]  # the data came before the end
    assert ChaosOp.EOF not in [p.opcode for p in moved if p.src_host == B]
    assert b.state(cb) is ConnState.CLOSED


def test_close_with_a_full_window_waits_to_send_the_eof() -> None:
    a, b, ca, _cb = open_pair(window=2)
    a.send(0.0, ca, b"1")
    a.send(0.0, ca, b"2")
    a.close(0.0, ca)
    assert ChaosOp.EOF not in ops(a.packets_to_send())
    a.timer(0.5)
    shuttle(0.5, a, b)
    assert a.state(ca) is ConnState.CLOSED
    assert [type(e) for e in b.events()] == [DataReceived, DataReceived, EofReceived, Closed]


def test_abort_sends_cls_at_once_without_local_event() -> None:
    a, _b, ca, cb = open_pair()
    a.send(0.0, ca, b"unacked")
    a.packets_to_send()
    a.abort(0.0, ca, "Abandoned")
    [cls] = a.packets_to_send()
    assert (cls.opcode, cls.src_index, cls.dest_index, cls.data) == (ChaosOp.CLS, ca, cb, b"Abandoned")
    assert a.events() == [] and a.state(ca) is ConnState.CLOSED
    assert a.next_deadline() is None


def test_close_of_a_pending_rfc_refuses_it() -> None:
    a, b = Ncp(A), Ncp(B)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    [req] = b.events()
    b.close(0.0, req.conn_id)
    assert ops(b.packets_to_send()) == [ChaosOp.CLS]


# ---------------------------------------------------------------------- time


def run_clock(until: float, *nodes: Ncp, deliver: Filter = _keep) -> float:
    """Advance a fake clock through the nodes' deadlines up to ``until``, carrying packets at once."""
    now = 0.0
    while True:
        deadlines = [d for n in nodes if (d := n.next_deadline()) is not None]
        if not deadlines or min(deadlines) > until:
            return until
        now = max(now, min(deadlines))
        for n in nodes:
            n.timer(now)
        if len(nodes) == 2:
            shuttle(now, nodes[0], nodes[1], deliver)


def test_rfc_to_a_silent_host_times_out() -> None:
    a = Ncp(A, rfc_timeout=20.0)
    ca = a.connect(0.0, B, "TEST")
    a.packets_to_send()
    run_clock(19.9, a)
    assert len(a.packets_to_send()) == 39, "RFC retransmitted every 0.5 s"
    assert a.events() == []
    run_clock(20.0, a)
    assert a.events() == [Broken(ca, "Host not responding")]
    assert a.state(ca) is ConnState.INCOMPLETE


def test_unanswered_rfc_is_refused_after_the_timeout() -> None:
    a, b = Ncp(A), Ncp(B, rfc_timeout=10.0)
    b.listen("TEST")
    a.connect(0.0, B, "TEST")
    shuttle(0.0, a, b)
    [req] = b.events()
    run_clock(10.0, b)
    [cls] = b.packets_to_send()
    assert cls.data == b"Timeout"
    assert b.events() == [Closed(req.conn_id, "Timeout", by_peer=False)]


def test_silent_peer_is_detected_after_broken_after() -> None:
    a, b, ca, _cb = open_pair(broken_after=30.0)
    a.send(0.0, ca, b"into the void")
    silence_from_b: Filter = lambda p: p.src_host != B  # noqa: E731
    run_clock(29.9, a, b, deliver=silence_from_b)
    assert a.state(ca) is ConnState.OPEN and a.events() == []
    run_clock(30.0, a, b, deliver=silence_from_b)
    assert a.events() == [Broken(ca, "No packet from the peer for 30 s")]
    assert a.state(ca) is ConnState.INCOMPLETE
    assert a.next_deadline() is None


def test_silent_peer_of_an_idle_connection_is_probed_then_detected() -> None:
    a, b, ca, _cb = open_pair(broken_after=90.0)
    packets_from_a: list[Packet] = []

    def only_a(p: Packet) -> bool:
        if p.src_host == A:
            packets_from_a.append(p)
        return p.src_host == A

    run_clock(90.0, a, b, deliver=only_a)
    assert ChaosOp.SNS in ops(packets_from_a), "idle connections probe"
    assert of_type(a.events(), Broken)
    assert a.state(ca) is ConnState.INCOMPLETE


def test_idle_connection_with_a_live_peer_stays_open() -> None:
    a, b, ca, cb = open_pair(broken_after=90.0)
    run_clock(600.0, a, b)
    assert a.state(ca) is ConnState.OPEN and b.state(cb) is ConnState.OPEN
    assert a.events() == [] and b.events() == []


# ---------------------------------------------------------------------- user errors


def test_user_errors() -> None:
    a, _b, ca, _cb = open_pair()
    with pytest.raises(UnknownConnectionError):
        a.send(0.0, 0x7777, b"x")
    with pytest.raises(InvalidStateError):
        a.accept(0.0, ca)
    with pytest.raises(ValueError, match="data opcodes"):
        a.send(0.0, ca, b"x", opcode=ChaosOp.EOF)
    with pytest.raises(ValueError, match="more than 488"):
        a.send(0.0, ca, bytes(489))
    with pytest.raises(ValueError, match="contact"):
        a.connect(0.0, B, "TWO WORDS")
    with pytest.raises(ValueError, match="window"):
        Ncp(A, window=0)
    with pytest.raises(ValueError, match="address"):
        Ncp(0)


def test_sixteen_bit_data_opcodes_pass_through() -> None:
    a, b, ca, _cb = open_pair()
    a.send(0.0, ca, b"\x01\x00", opcode=ChaosOp.DWD)
    shuttle(0.0, a, b)
    [got] = of_type(b.events(), DataReceived)
    assert got.opcode == ChaosOp.DWD
