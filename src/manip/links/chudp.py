"""Chaos over UDP (CHUDP) as klh10 and simh speak it: one packet per datagram, a peer table by address.

One UDP socket reaches many neighbours, so the link keeps a table from Chaos address to UDP endpoint
and the driver names the neighbour (``next_hop``) for each packet.  Outgoing trailers carry our own
address as source and the neighbour's as destination, which is what klh10 learns peers from.

Incoming datagrams are decoded with the checksum checked; a bad one is counted and dropped, and so is
one whose trailer names our own address as its hardware source (clause ``chudp.trailer``: no other host
has it, and a peer learnt from it would be ourselves).  A sound
one holding an illegal packet (opcode, or more than 488 data bytes) is treated as good, so the NCP can
answer it with LOS, and counted under ``stats.illegal``.  A good one is accepted from a configured
endpoint or from a known address; from anyone else only if ``learn_peers`` is on (klh10's dynamic
peers), in which case its trailer source and UDP endpoint join the table.  Configured entries are never
replaced; a learnt entry follows its address to a new endpoint (a client that restarted on another
port).  A server's access rules come first (``admit``): a datagram from an address they do not allow is
dropped before it is decoded, and counted by them.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable, Mapping
from typing import Any, cast

from manip.codecs.chaos import IllegalPacketError
from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.framing import decode_chudp, encode_chudp
from manip.codecs.packet import Packet
from manip.ncp.defects import ChaosDefects
from manip.spec.notation import octal

from .base import Link, bad_reason
from .errors import LinkError

Endpoint = tuple[str, int]
Admit = Callable[[Endpoint], bool]
"""Asked about each datagram's sender before it is decoded: False drops it (the callable counts it)."""


def _endpoint(addr: Any) -> Endpoint:
    """(host, port) of a socket address; IPv6 addresses come with flow and scope fields."""
    return str(addr[0]), int(addr[1])


class ChudpLink(Link, asyncio.DatagramProtocol):
    """A CHUDP socket and its peer table."""

    kind = "chudp"
    point_to_point = False

    def __init__(
        self,
        *,
        my_addr: int,
        peers: Mapping[int, Endpoint] | None = None,
        learn_peers: bool = False,
        admit: Admit | None = None,
        name: str = "",
        defects: ChaosDefects | None = None,
    ) -> None:
        super().__init__(my_addr=my_addr, name=name, defects=defects)
        self.admit = admit
        self.peers: dict[int, Endpoint] = dict(peers or {})
        """Chaos address -> UDP endpoint of every neighbour, configured and learnt."""
        self.learn_peers = learn_peers
        self.peers_learned = 0
        self._configured = frozenset(self.peers)
        self._configured_endpoints = frozenset(self.peers.values())
        self._transport: asyncio.DatagramTransport | None = None
        self._closing_reason: str | None = None

    @property
    def local_address(self) -> Endpoint:
        """The bound (host, port)."""
        if self._transport is None:
            raise LinkError(f"{self.name} is not bound")
        return _endpoint(self._transport.get_extra_info("sockname"))

    def add_peer(self, address: int, endpoint: Endpoint) -> None:
        """Add or move a neighbour (``endpoint`` must be numeric, as datagrams report their source)."""
        self.peers[address] = endpoint

    # ---------------------------------------------------------------- asyncio.DatagramProtocol

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # Not every loop's datagram transport subclasses DatagramTransport (3.11's selector one).
        self._transport = cast(asyncio.DatagramTransport, transport)
        if self.name == self.kind:
            host, port = _endpoint(transport.get_extra_info("sockname"))
            self.name = f"chudp:[{host}]:{port}" if ":" in host else f"chudp:{host}:{port}"

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.stats.bytes_in += len(data)
        sender = _endpoint(addr)
        if self.admit is not None and not self.admit(sender):
            return
        illegal: IllegalPacketError | None = None
        try:
            packet = decode_chudp(data)
        except IllegalPacketError as exc:
            packet, illegal = exc.packet, exc
        except DecodeError as exc:
            self._bad(bad_reason(exc), f"{exc} (from {sender})", exc.clause)
            return
        trailer = packet.trailer
        if trailer is not None and trailer.source == self.my_addr:  # no other host has our address
            self._bad(
                "trailer",
                f"trailer source {octal(trailer.source)} is our own (from {sender})",
                "chudp.trailer",
            )
            return
        source = trailer.source if trailer is not None and trailer.source else packet.src_host
        known = self.peers.get(source)
        if known != sender and sender not in self._configured_endpoints:
            if not self._may_learn(source):
                self._bad("unknown_peer", f"address {octal(source)} from {sender}")
                return
            self.peers[source] = sender
            self.peers_learned += 1
        if illegal is not None:
            self._illegal(illegal, f" (from {sender})")
        self._deliver(packet)

    def error_received(self, exc: Exception) -> None:
        # An ICMP error for an earlier datagram (port unreachable): the NCP will retransmit or time out.
        self.stats.dropped["unreachable"] += 1

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        reason = self._closing_reason or (f"socket error: {exc}" if exc is not None else "closed")
        self._set_closed(reason)

    # ---------------------------------------------------------------- Link

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        transport = self._transport
        if transport is None or self._closing_reason is not None:
            return self._drop("closed", packet)
        hop = packet.dest_host if next_hop is None else next_hop
        endpoint = self.peers.get(hop)
        if endpoint is None:
            return self._drop("no_peer", packet)
        try:
            datagram = self._frame(encode_chudp, packet, hop)
        except EncodeError:
            return self._drop("encode", packet)
        transport.sendto(datagram, endpoint)
        stats = self.stats
        stats.frames_out += 1
        stats.bytes_out += len(datagram)
        return True

    def close(self) -> None:
        if self._closing_reason is None:
            self._closing_reason = "closed locally"
        if self._transport is None:
            self._set_closed(self._closing_reason)
        else:
            self._transport.close()

    # ---------------------------------------------------------------- internals

    def _may_learn(self, source: int) -> bool:
        return self.learn_peers and source & 0xFF != 0 and source not in self._configured


async def bind_chudp(
    host: str = "127.0.0.1",
    port: int = 0,
    *,
    my_addr: int,
    peers: Mapping[int, Endpoint] | None = None,
    learn_peers: bool = False,
    admit: Admit | None = None,
    defects: ChaosDefects | None = None,
) -> ChudpLink:
    """Bind a CHUDP socket at ``host:port`` (0: any free port); peer hosts are resolved here, once.

    ``admit`` is asked about every datagram's sender first (a server's access rules)."""
    loop = asyncio.get_running_loop()
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    resolved: dict[int, Endpoint] = {}
    for address, (peer_host, peer_port) in (peers or {}).items():
        try:
            infos = await loop.getaddrinfo(peer_host, peer_port, family=family, type=socket.SOCK_DGRAM)
        except OSError as exc:
            raise LinkError(f"cannot resolve CHUDP peer {peer_host}:{peer_port}: {exc}") from exc
        resolved[address] = _endpoint(infos[0][4])
    link = ChudpLink(my_addr=my_addr, peers=resolved, learn_peers=learn_peers, admit=admit, defects=defects)
    try:
        await loop.create_datagram_endpoint(lambda: link, local_addr=(host, port), family=family)
    except OSError as exc:
        raise LinkError(f"cannot bind CHUDP socket {host}:{port}: {exc}") from exc
    return link
