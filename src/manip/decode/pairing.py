"""Which way each packet of a frame stream went, and which request each answer is to: what lets
``manip-decode --link tcp|chaosd`` decode a reply by its request's layout without ``--request-opcode``,
as ``--pcap``, ``--mcap`` and the Wireshark dissector do.

The server is the side an RFC is sent to; once one was seen, a packet from the server's host is a server
packet and any other a request.  Before any RFC (a stream cut mid-connection) the direction is guessed from
opcode and length (:func:`~manip.decode.describe.guess_direction`).  Answers are paired with requests by
the one pairing rule (:class:`~manip.codecs.pairing.ReplyPairing`, by position on each connection); in a
stream cut mid-connection, where positions are not known, an answer goes with the request whose packet
number its first word carries, if that request is in the stream.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

from manip.codecs.packet import Packet
from manip.codecs.pairing import ReplyPairing
from manip.decode.describe import ReadAs, guess_direction
from manip.spec.constants import ChaosOp

__all__ = ["MAX_CONNECTIONS", "MAX_PENDING", "Paired", "StreamPairing"]

MAX_PENDING: Final = 4096
"""Unanswered requests kept per connection: a stream of requests nobody answers is read in bounded
memory (a Chaos window is far smaller, so a live exchange never comes near it)."""
MAX_CONNECTIONS: Final = 4096
"""Connections whose pairing is kept; the one seen least recently is let go first."""

Endpoint = tuple[int, int]
"""A Chaos host address and connection index."""


@dataclass(frozen=True, slots=True)
class Paired:
    """What the stream says of one packet: its side, and for an answer, its request."""

    side: ReadAs
    """``request``, ``response``, or ``auto`` (not known: the decoder guesses)."""
    request_opcode: int | None = None
    """The opcode of the request an answer is paired with."""
    request_no: int | None = None
    """That request's Chaos packet number."""


@dataclass
class StreamPairing:
    """The pairing state of one stream of frames, fed every packet in order (:meth:`place`)."""

    servers: set[int] = field(default_factory=set)
    """Hosts an RFC was sent to."""
    _connections: dict[frozenset[Endpoint], ReplyPairing[tuple[int, int]]] = field(default_factory=dict)
    _numbered: dict[int, int] = field(default_factory=dict)
    """Mid-connection: request packet number -> opcode, of the requests guessed so far."""

    def _pairing(self, packet: Packet) -> ReplyPairing[tuple[int, int]]:
        key = frozenset({(packet.src_host, packet.src_index), (packet.dest_host, packet.dest_index)})
        connections = self._connections
        if packet.opcode == ChaosOp.OPN:  # the server's OPN names its own index: the RFC's entry moves
            rfc_key = frozenset({(packet.src_host, 0), (packet.dest_host, packet.dest_index)})
            if rfc_key in connections and key not in connections:
                connections[key] = connections.pop(rfc_key)
        pairing = connections.pop(key, None)  # re-inserted last: the dict's order is the last seen
        if pairing is None:
            pairing = ReplyPairing(MAX_PENDING)
            if len(connections) >= MAX_CONNECTIONS:
                del connections[next(iter(connections))]
        connections[key] = pairing
        return pairing

    def place(self, packet: Packet) -> Paired:
        """Feed one packet; returns its side and, for an answer, the request it answers."""
        if packet.opcode == ChaosOp.RFC:
            self.servers.add(packet.dest_host)
            self._pairing(packet).rfc((0, packet.packet_no))
            return Paired("auto")
        if not 0o200 <= packet.opcode <= 0o277:
            if packet.opcode == ChaosOp.OPN:
                self._pairing(packet)
            return Paired("auto")
        if not self.servers or packet.src_host == packet.dest_host:
            return self._guessed(packet)
        pairing = self._pairing(packet)
        if packet.src_host not in self.servers:
            pairing.request((packet.opcode, packet.packet_no), packet.opcode, packet.data)
            return Paired("request")
        placement = pairing.server(packet.opcode, packet.data)
        if placement.role == "answer" and placement.request is not None and placement.request[0]:
            return Paired("response", *placement.request)
        return Paired("response")

    def _guessed(self, packet: Packet) -> Paired:
        """No RFC seen (or one host both ways): the side by opcode and length, an answer by its number
        (at most one request per 16-bit packet number is kept)."""
        if guess_direction(packet) == "request":
            self._numbered[packet.packet_no] = packet.opcode
            return Paired("auto")
        number = int.from_bytes(packet.data[:2], "little") if len(packet.data) >= 2 else None
        if number is not None and number in self._numbered:
            return Paired("auto", self._numbered[number], number)
        return Paired("auto")
