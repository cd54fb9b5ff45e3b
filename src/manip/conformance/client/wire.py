"""Judging what a client sent: its requests, its packet numbers, its acknowledgements and its window.

These checks run after every client case (the ``client-wire`` invariant,
:mod:`manip.conformance.suite.invariants`), whatever the case is about; cases about one of these rules
call the same functions and report under their own clauses.
"""

from __future__ import annotations

from collections.abc import Sequence

from manip.codecs.packet import Packet
from manip.conformance.client.server import WireRecord
from manip.conformance.judge.client_checks import check_client_request
from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation
from manip.ncp.packets import unpack_status
from manip.ncp.seq import seq_gt, seq_lt
from manip.spec.constants import ChaosOp, ServerOp

__all__ = [
    "ack_violations",
    "client_requests",
    "initial_response_violations",
    "judged_packets",
    "numbering_violations",
    "request_violations",
    "window_violations",
    "wire_packet",
]


def wire_packet(record: WireRecord) -> WirePacket:
    p = record.packet
    return WirePacket(record.dir, p.opcode, p.packet_no, p.ack_no, p.data, record.t)


def _controlled(packet: Packet) -> bool:
    return packet.opcode >= ChaosOp.DAT or packet.opcode in (ChaosOp.RFC, ChaosOp.OPN, ChaosOp.EOF)


def client_requests(records: Sequence[WireRecord]) -> list[WireRecord]:
    """The client's data packets, first copies only (a retransmission is the same request)."""
    seen: set[int] = set()
    out: list[WireRecord] = []
    for r in records:
        if r.dir == "c2s" and r.packet.opcode >= ChaosOp.DAT and r.packet.packet_no not in seen:
            seen.add(r.packet.packet_no)
            out.append(r)
    return out


def judged_packets(records: Sequence[WireRecord]) -> list[WirePacket]:
    """The data packets both ways as ``verify`` reads them from a recording: in order, the client's
    first copies only (so a rule of :mod:`manip.conformance.judge.checks` judges a live play and a
    recording alike)."""
    first = {id(r) for r in client_requests(records)}
    return [
        wire_packet(r)
        for r in records
        if r.packet.opcode >= ChaosOp.DAT and (r.dir == "s2c" or id(r) in first)
    ]


def request_violations(records: Sequence[WireRecord]) -> list[Violation]:
    """Every request a request opcode with the data its layout says (``check_client_request``)."""
    out: list[Violation] = []
    for r in client_requests(records):
        out += check_client_request(wire_packet(r))
    return out


def initial_response_violations(records: Sequence[WireRecord]) -> list[Violation]:
    """No request before the server's initial RESPONSE went out."""
    initial_at: float | None = None
    for r in records:
        if r.dir == "s2c" and r.packet.opcode == ServerOp.RESPONSE:
            initial_at = r.t
            break
    for r in client_requests(records):
        if initial_at is None or r.t < initial_at:
            return [
                Violation.at(
                    wire_packet(r),
                    "client.initial-response",
                    f"request #{r.packet.packet_no} sent before the server's initial RESPONSE",
                    expected="no request before the initial RESPONSE",
                )
            ]
    return []


def numbering_violations(records: Sequence[WireRecord]) -> list[Violation]:
    """The client's controlled packets numbered consecutively modulo 2^16."""
    last: int | None = None
    seen: set[int] = set()
    for r in records:
        p = r.packet
        if r.dir != "c2s" or not _controlled(p) or p.packet_no in seen:
            continue
        if last is not None and p.packet_no != (last + 1) & 0xFFFF:
            if seq_lt(p.packet_no, last):
                continue  # a retransmission of an earlier one
            return [
                Violation.at(
                    wire_packet(r),
                    "ncp.packet-numbers",
                    f"packet {p.packet_no} follows {last}: not consecutive",
                    expected=f"packet number {(last + 1) & 0xFFFF}",
                )
            ]
        seen.add(p.packet_no)
        last = p.packet_no
    return []


def ack_violations(records: Sequence[WireRecord], *, settle: float = 0.0) -> list[Violation]:
    """Every controlled packet the server sent, up to ``settle`` seconds before the client's last
    packet, is acknowledged by a later client packet (its ack field or an STS receipt)."""
    client = [r for r in records if r.dir == "c2s"]
    if not client:
        return []
    last_t = client[-1].t
    best: int | None = None
    for r in client:
        p = r.packet
        if p.opcode in (ChaosOp.RFC, ChaosOp.LOS, ChaosOp.CLS):
            continue
        acked = p.ack_no
        if p.opcode == ChaosOp.STS and len(p.data) >= 2:  # the receipt, which may run ahead of the ack
            receipt = int.from_bytes(p.data[:2], "little")
            acked = receipt if seq_gt(receipt, acked) else acked
        if best is None or seq_gt(acked, best):
            best = acked
    for r in records:
        p = r.packet
        if r.dir != "s2c" or not (p.opcode >= ChaosOp.DAT or p.opcode in (ChaosOp.OPN, ChaosOp.EOF)):
            continue
        if r.t > last_t - settle:
            break
        if best is None or seq_gt(p.packet_no, best):
            return [
                Violation.at(
                    wire_packet(r),
                    "ncp.acknowledge",
                    f"the server's packet {p.packet_no} was never acknowledged (highest ack seen: {best})",
                    expected="an ack field or STS covering every packet received",
                )
            ]
    return []


def window_violations(records: Sequence[WireRecord], window: int) -> list[Violation]:
    """The client never had more controlled packets unacknowledged than the window in force when it sent
    one: ``window`` until the server's OPN or an STS says otherwise, then what the latest of them says
    (read from every STS, whether or not it acknowledges anything new; a window shrunk mid-case binds
    the packets sent after it).  What the client may count as acknowledged is what the judging server
    had sent by then (the ack field of its OPN, STS, data and EOF packets).  Data packets and EOF count,
    as the Chaosnet NCP counts controlled packets; a retransmission (a number seen before) is judged
    when first sent."""
    acked: int | None = None
    offered = window
    seen: set[int] = set()
    for r in records:
        p = r.packet
        if r.dir == "s2c":
            if _carries_ack(p) and (acked is None or seq_gt(p.ack_no, acked)):
                acked = p.ack_no
            status = unpack_status(p.data) if p.opcode in (ChaosOp.OPN, ChaosOp.STS) else None
            if status is not None:
                offered = status[1]
            continue
        if not _counted(p) or acked is None or p.packet_no in seen:
            continue
        seen.add(p.packet_no)
        outstanding = (p.packet_no - acked) & 0xFFFF
        if 0 < outstanding <= 0x8000 and outstanding > offered:
            what = "EOF" if p.opcode == ChaosOp.EOF else "packet"
            return [
                Violation.at(
                    wire_packet(r),
                    "ncp.window",
                    f"{what} {p.packet_no} sent with {outstanding} unacknowledged; "
                    f"the server's window is {offered}",
                    expected=f"at most {offered} packets beyond the last acknowledged ({acked})",
                )
            ]
    return []


def _carries_ack(packet: Packet) -> bool:
    """A server packet whose ack field the client may read: OPN, STS, data and EOF."""
    return packet.opcode in (ChaosOp.OPN, ChaosOp.STS, ChaosOp.EOF) or packet.opcode >= ChaosOp.DAT


def _counted(packet: Packet) -> bool:
    """A client packet the window counts: data and EOF (RFC goes out before any window is known)."""
    return packet.opcode >= ChaosOp.DAT or packet.opcode == ChaosOp.EOF
