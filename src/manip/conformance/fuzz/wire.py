"""The fuzzer's links: raw sockets that send exactly the bytes they are given and hand over, decoded,
every packet the target sends, whichever link it comes on.

A stream wire (``tcp://``, ``unix://``: manip's TCP link framing) is one connection to the target; a
datagram wire (``chudp://``) one UDP socket.  Every packet that arrives goes to one :class:`Inbox`,
which gives it to the connection it names (:meth:`Inbox.register`) or keeps it by destination index
(the fuzzer gives every stray packet a source index of its own, so the answer names it).  Frames that
do not decode are kept (``Inbox.bad``): a target must not send them.

:func:`frame` lays a packet out for a link with the damage a :class:`~.steps.Stray` asks for, the
checksum recomputed after the damage (except when the checksum is the damage), so exactly one thing
is wrong with it.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Protocol, cast

from manip.codecs.chaos import chaos_checksum, packet_words
from manip.codecs.errors import DecodeError
from manip.codecs.framing import CHUDP_HEADER, FrameSyncError, TcpFrameDecoder, decode_chudp
from manip.codecs.packet import Packet
from manip.conformance.fuzz.steps import Damage
from manip.links.address import LinkAddress

__all__ = ["DatagramWire", "Inbox", "Receiver", "StreamWire", "Wire", "frame", "open_wire"]

_RESET: Final = struct.pack("ii", 1, 0)


class Receiver(Protocol):
    """A connection the inbox hands its packets to."""

    def on_packet(self, packet: Packet, now: float) -> None: ...


@dataclass
class Inbox:
    """Every packet from the target, on any wire: to its registered connection, else kept by index."""

    connections: dict[int, Receiver] = field(default_factory=dict)
    strays: defaultdict[int, list[tuple[Packet, float]]] = field(default_factory=lambda: defaultdict(list))
    bad: list[tuple[bytes, DecodeError]] = field(default_factory=list)
    on_stray: Callable[[Packet], None] | None = None

    def __post_init__(self) -> None:
        self.arrived = asyncio.Event()

    def register(self, index: int, connection: Receiver) -> None:
        self.connections[index] = connection

    def unregister(self, index: int) -> None:
        self.connections.pop(index, None)

    def deliver(self, packet: Packet, now: float) -> None:
        conn = self.connections.get(packet.dest_index)
        if conn is not None:
            conn.on_packet(packet, now)
        else:
            self.strays[packet.dest_index].append((packet, now))
            if self.on_stray is not None:
                self.on_stray(packet)
        self.arrived.set()

    def reject(self, raw: bytes, exc: DecodeError) -> None:
        if len(self.bad) < 100:
            self.bad.append((raw, exc))
        self.arrived.set()

    def clear_strays(self) -> None:
        self.strays.clear()
        self.bad.clear()


class Wire:
    """One link to the target (see the module docstring)."""

    datagram = False

    def __init__(self, address: LinkAddress, inbox: Inbox) -> None:
        self.address = address
        self.inbox = inbox
        self.ended: str | None = None
        self._loop = asyncio.get_running_loop()
        self.closed = self._loop.create_future()

    def send(self, data: bytes) -> None:
        raise NotImplementedError

    def close(self, *, reset: bool = False) -> None:
        raise NotImplementedError

    def _end(self, reason: str) -> None:
        if self.ended is None:
            self.ended = reason
        if not self.closed.done():
            self.closed.set_result(None)
        self.inbox.arrived.set()


class StreamWire(Wire, asyncio.Protocol):
    """A connection carrying manip's TCP link frames."""

    def __init__(self, address: LinkAddress, inbox: Inbox) -> None:
        super().__init__(address, inbox)
        self._transport: asyncio.Transport | None = None
        self._decoder = TcpFrameDecoder()
        self.closed_by_us = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.Transport", transport)

    def data_received(self, data: bytes) -> None:
        now = self._loop.time()
        try:
            items = self._decoder.feed(data)
        except FrameSyncError as exc:
            self.inbox.reject(data[:64], exc)
            items = list(exc.items)
            self.close()
        for item in items:
            if isinstance(item, Packet):
                self.inbox.deliver(item, now)
            else:
                self.inbox.reject(b"", item)

    def connection_lost(self, exc: Exception | None) -> None:
        if self.closed_by_us:
            self._end("closed by the fuzzer")
        elif exc is None:
            self._end("the target closed the link")
        else:
            self._end(f"the link failed: {exc}")

    def send(self, data: bytes) -> None:
        if self._transport is not None and self.ended is None and not self._transport.is_closing():
            self._transport.write(data)

    def close(self, *, reset: bool = False) -> None:
        if self._transport is None or self._transport.is_closing():
            return
        self.closed_by_us = self.ended is None
        if reset:
            sock = self._transport.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
            self._transport.abort()
        else:
            self._transport.close()


class DatagramWire(Wire, asyncio.DatagramProtocol):
    """A UDP socket speaking CHUDP to the target."""

    datagram = True

    def __init__(self, address: LinkAddress, inbox: Inbox) -> None:
        super().__init__(address, inbox)
        self._transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.DatagramTransport", transport)

    def datagram_received(self, data: bytes, addr: object) -> None:
        try:
            packet = decode_chudp(data)
        except DecodeError as exc:
            self.inbox.reject(data[:64], exc)
            return
        self.inbox.deliver(packet, self._loop.time())

    def error_received(self, exc: Exception) -> None:
        pass  # ICMP unreachable from a target that is gone: the liveness check says so

    def connection_lost(self, exc: Exception | None) -> None:
        self._end("closed")

    def send(self, data: bytes) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(data)

    def close(self, *, reset: bool = False) -> None:
        if self._transport is not None:
            self._transport.close()


async def open_wire(address: LinkAddress, inbox: Inbox, timeout: float) -> Wire:
    """A new wire to the target; OSError (refused, unreachable) or TimeoutError if it cannot be had."""
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(timeout):
        if address.scheme == "tcp":
            _, stream = await loop.create_connection(
                lambda: StreamWire(address, inbox), address.host, address.port
            )
            return stream
        if address.scheme == "unix":
            assert address.path is not None
            _, stream = await loop.create_unix_connection(lambda: StreamWire(address, inbox), address.path)
            return stream
        if address.scheme == "chudp":
            local = address.local or ("::1" if ":" in address.host else "127.0.0.1", 0)
            _, datagram = await loop.create_datagram_endpoint(
                lambda: DatagramWire(address, inbox),
                local_addr=local,
                remote_addr=(address.host, address.port),
            )
            return datagram
    raise ValueError(f"the fuzzer speaks tcp://, unix:// and chudp:// links, not {address.scheme}://")


def frame(packet: Packet, address: LinkAddress, *, datagram: bool, damage: Damage = "") -> bytes:
    """``packet`` laid out for the link (destination host 0: the target's, source host 0: ours), with
    ``damage`` done to it (see :data:`~.steps.Damage`)."""
    dest = packet.dest_host or address.peer_addr
    source = packet.src_host or address.my_addr
    packet = packet.with_(dest_host=dest, src_host=source)
    words = packet_words(packet)
    if damage == "header-byte":
        words[0] |= 1 + (packet.packet_no % 255)
    elif damage == "nbytes":
        nbytes = len(packet.data)
        wrong = nbytes + 2 if nbytes < 4 or packet.packet_no & 1 else nbytes - 2  # a different padded size
        words[1] = (words[1] & 0xF000) | wrong
    checksum = chaos_checksum([*words, dest, source])
    if damage == "checksum":
        checksum ^= 1 + (packet.packet_no % 0xFFFE)
    body = struct.pack(f">{len(words) + 3}H", *words, dest, source, checksum)
    if not datagram:
        return len(body).to_bytes(2, "big") + body
    head = CHUDP_HEADER
    if damage == "version":
        head = bytes([2 + packet.packet_no % 200]) + head[1:]
    elif damage == "function":
        head = head[:1] + bytes([2 + packet.packet_no % 200]) + head[2:]
    if damage == "short":
        body = body[: len(body) - 2 - 2 * (packet.packet_no % 4)]
    elif damage == "long":
        body += bytes(2 + 2 * (packet.packet_no % 4))
    return head + body
