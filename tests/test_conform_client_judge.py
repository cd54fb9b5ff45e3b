"""The client judge's own rules, on hand-made wires and documents: the window as offered at each
moment, and every example of ``docs/client-harness.md`` read by the judge's parser."""

from __future__ import annotations

from manip.codecs.packet import Packet
from manip.conformance.client.server import WireRecord
from manip.conformance.client.wire import window_findings
from manip.ncp.packets import pack_status
from manip.spec.constants import ChaosOp


def _c2s(t: float, number: int) -> WireRecord:
    return WireRecord(t, "c2s", Packet(0o201, packet_no=number, ack_no=1))


def _sts(t: float, ack: int, window: int) -> WireRecord:
    return WireRecord(t, "s2c", Packet(ChaosOp.STS, ack_no=ack, data=pack_status(ack, window)))


OPN = WireRecord(0.0, "s2c", Packet(ChaosOp.OPN, packet_no=1, ack_no=1, data=pack_status(1, 4)))


def test_the_window_is_the_one_offered_when_the_packet_went_out() -> None:
    filled = [OPN, *(_c2s(0.1, n) for n in range(2, 6))]  # 4 unacknowledged: the window of 4, full
    assert window_findings(filled, 15) == []
    shrunk = [*filled, _sts(0.2, 3, 1), _c2s(0.3, 6)]  # 3 unacknowledged after the shrink to 1
    found = window_findings(shrunk, 15)
    assert [f.clause for f in found] == ["ncp.window"] and "window is 1" in found[0].message
    opened = [*filled, _sts(0.2, 5, 1), _c2s(0.3, 6)]  # all acknowledged: one more is allowed
    assert window_findings(opened, 15) == []


def test_past_the_offered_window_is_found_before_any_status() -> None:
    wire = [OPN, *(_c2s(0.1, n) for n in range(2, 7))]  # 5 unacknowledged, window 4
    assert [f.clause for f in window_findings(wire, 15)] == ["ncp.window"]
