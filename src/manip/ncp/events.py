"""What the NCP tells its user.  Every event names the connection it belongs to (``conn_id``, the local
index).  Events are frozen dataclasses; the ones that come from a packet carry the whole packet, so a
layer above can see its packet number and ack field."""

from __future__ import annotations

from dataclasses import dataclass

from manip.codecs.packet import Packet


@dataclass(frozen=True, slots=True)
class Event:
    """Base class of all NCP events."""

    conn_id: int


@dataclass(frozen=True, slots=True)
class ConnectionRequested(Event):
    """An RFC for one of our contact names arrived.  Answer it with accept, refuse, answer or forward.

    ``rfc.packet_no`` is the RFC's packet number (manip's initial RESPONSE quotes it)."""

    peer_host: int
    peer_index: int
    contact: str
    args: bytes
    rfc: Packet


@dataclass(frozen=True, slots=True)
class Opened(Event):
    """The connection is established and the peer's receive window is known: data may be sent.

    The caller gets it when the OPN arrives; the accepting side when the first STS arrives."""

    peer_host: int
    peer_index: int
    window: int


@dataclass(frozen=True, slots=True)
class DataReceived(Event):
    """A data packet (opcode 0200-0377), delivered once and in packet-number order."""

    packet: Packet

    @property
    def opcode(self) -> int:
        return self.packet.opcode

    @property
    def data(self) -> bytes:
        return self.packet.data

    @property
    def packet_no(self) -> int:
        return self.packet.packet_no


@dataclass(frozen=True, slots=True)
class EofReceived(Event):
    """The peer's EOF, in sequence after its data.  The peer closes once it is acknowledged; without
    ``auto_read`` that means after ``read_ack`` of its packet number, as for data."""

    packet: Packet


@dataclass(frozen=True, slots=True)
class UncontrolledReceived(Event):
    """An UNC packet: not sequenced, not acknowledged, may be lost or duplicated."""

    packet: Packet


@dataclass(frozen=True, slots=True)
class Closed(Event):
    """The connection is closed.  ``by_peer``: the peer sent CLS (a refusal, if we were connecting);
    otherwise our own graceful close completed or an unanswered RFC timed out."""

    reason: str
    by_peer: bool


@dataclass(frozen=True, slots=True)
class Lost(Event):
    """The peer's NCP sent LOS: it does not know the connection (or something went badly wrong)."""

    reason: str
    packet: Packet


@dataclass(frozen=True, slots=True)
class Answered(Event):
    """Our RFC got a simple answer (ANS) instead of a connection."""

    data: bytes
    packet: Packet


@dataclass(frozen=True, slots=True)
class Forwarded(Event):
    """Our RFC was forwarded: try ``contact`` at ``host`` instead."""

    host: int
    contact: str
    packet: Packet


@dataclass(frozen=True, slots=True)
class Broken(Event):
    """The connection is INCOMPLETE: no answer to the RFC, or the peer fell silent for too long."""

    reason: str
