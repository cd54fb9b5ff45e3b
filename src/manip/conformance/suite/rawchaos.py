"""A raw Chaos peer for conformance cases that test the target's NCP itself.

The NCP clauses (retransmission, window, LOS, duplicate RFC) cannot be tested through manip's own NCP:
it would retransmit, acknowledge and window for us.  :class:`RawPeer` instead opens the target's link
directly (``tcp://`` frames or ``chudp://`` datagrams, :mod:`manip.codecs.framing`), sends exactly the
packets a case forges and hands back what arrives, decoded, with the bytes as they came.  Nothing is
sent that the case did not ask for: no acknowledgement, no STS, no retransmission.

Theory of operation:

* :func:`RawPeer.open` connects (TCP) or binds a UDP socket (CHUDP); a reader task decodes every frame
  into a :class:`Received` (packet, bytes, time) and appends it to ``inbox``; frames that do not decode
  are kept in ``bad``.  Every packet both ways is also given to ``on_packet`` (cases record them).
* :meth:`RawPeer.receive` takes the first inbox packet a predicate accepts, waiting up to a timeout;
  :meth:`RawPeer.collect` takes every accepted packet for a given time (for "nothing else came").
* :meth:`RawPeer.handshake` drives the opening by hand: RFC with a chosen source index and packet
  number, wait for OPN (an RFC refused as busy is retried), and the connection (:class:`RawConnection`)
  is then OPEN on our side.  The STS answering the OPN is the case's to send (:meth:`RawConnection.sts`),
  with whatever window it wants; :meth:`RawConnection.data` sends data with a chosen number and ack.
* :meth:`RawPeer.close` sends CLS on every connection it opened (so the server frees its robot at once)
  and closes the link.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from manip.codecs.chaos import make_trailer, packet_words
from manip.codecs.errors import DecodeError
from manip.codecs.framing import (
    CHUDP_HEADER,
    MAX_BODY,
    decode_chudp,
    decode_tcp,
    encode_chudp,
    encode_tcp,
)
from manip.codecs.packet import Packet
from manip.conformance.judge.checks import Direction
from manip.conformance.suite.busy import BUSY_DELAY, BUSY_RETRIES, says_busy
from manip.links.address import LinkAddress, parse_address
from manip.links.errors import chaos_host, not_a_chaos_link
from manip.ncp.packets import pack_status, text, unpack_status
from manip.ncp.seq import seq_add
from manip.spec import SPEC
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

__all__ = [
    "Direction",
    "RawConnection",
    "RawError",
    "RawPeer",
    "Received",
    "RefusedError",
    "format_packet",
]

PacketHook = Callable[[Direction, Packet, bytes], None]
Match = Callable[[Packet], bool]

RFC_RETRY: Final = 1.0
"""Seconds between copies of an unanswered RFC during :meth:`RawPeer.handshake`."""
FOREIGN_HEAD: Final = 78
"""Bytes read after a first frame length no frame can have, to show what the peer is."""
FOREIGN_WAIT: Final = 0.5


class RawError(Exception):
    """The raw link could not be opened or used (the message says why)."""


class RefusedError(RawError):
    """The target answered our RFC with something other than OPN (CLS, ANS, FWD, LOS)."""

    def __init__(self, message: str, answer: Received) -> None:
        super().__init__(message)
        self.answer = answer


@dataclass(frozen=True)
class Received:
    """One packet from the target, with the frame bytes it came in and when (peer clock)."""

    packet: Packet
    raw: bytes
    time: float

    def __str__(self) -> str:
        return format_packet(self.packet)


def format_packet(p: Packet) -> str:
    """One line: opcode, addresses and indices (octal / hex), numbers, data length and a data preview."""
    source = f"{chaos_host(p.src_host)} index {octal(p.src_index)}"
    name = f"{SPEC.chaos_opcode_name(p.opcode)} {octal(p.opcode)}"
    what = f"{name} {source} -> {chaos_host(p.dest_host)} index {octal(p.dest_index)}"
    numbers = f"pkt#{p.packet_no} ack#{p.ack_no}"
    if p.opcode in (ChaosOp.OPN, ChaosOp.STS) and (status := unpack_status(p.data)) is not None:
        return f"{what} {numbers} receipt {status[0]} window {status[1]}"
    if p.opcode in (ChaosOp.LOS, ChaosOp.CLS, ChaosOp.RFC, ChaosOp.ANS) and p.data:
        return f"{what} {numbers} {text(p.data)!r}"
    return f"{what} {numbers} {len(p.data)} data bytes"


class _Transport:
    """The link below a raw peer: whole frames out, decoded frames in (subclasses per scheme)."""

    def __init__(self, address: LinkAddress) -> None:
        self.address = address
        self.deliver: Callable[[bytes, Packet | DecodeError], None] = lambda raw, item: None
        self.ended: str | None = None

    def encode(self, p: Packet) -> bytes:
        raise NotImplementedError

    def forge(self, p: Packet) -> bytes:
        """``p`` framed with no checks at all (an illegal opcode, more than 488 data bytes...)."""
        trailer = make_trailer(p, self.address.peer_addr, self.address.my_addr)
        words = [*packet_words(p), trailer.dest, trailer.source, trailer.checksum]
        return self.wrap(struct.pack(f">{len(words)}H", *words))

    def wrap(self, body: bytes) -> bytes:
        """The framing around a packet-plus-trailer body."""
        raise NotImplementedError

    def write(self, frame: bytes) -> None:
        raise NotImplementedError

    async def close(self) -> None:
        raise NotImplementedError


class _TcpTransport(_Transport):
    def __init__(
        self, address: LinkAddress, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        super().__init__(address)
        self._reader = reader
        self._writer = writer
        self._task = asyncio.get_running_loop().create_task(self._read())

    def encode(self, p: Packet) -> bytes:
        return encode_tcp(p, hw_dest=self.address.peer_addr, hw_src=self.address.my_addr)

    def wrap(self, body: bytes) -> bytes:
        return len(body).to_bytes(2, "big") + body

    def write(self, frame: bytes) -> None:
        if self.ended is None:
            self._writer.write(frame)

    async def _read(self) -> None:
        try:
            first = True
            while True:
                head = await self._reader.readexactly(2)
                length = int.from_bytes(head, "big")
                if first and length > MAX_BODY:
                    # no frame is that long (text is: b"HT" reads as 18516): say what the peer is
                    with contextlib.suppress(TimeoutError):
                        head += await asyncio.wait_for(self._reader.read(FOREIGN_HEAD), FOREIGN_WAIT)
                    self.ended = not_a_chaos_link(head)
                    return
                first = False
                body = await self._reader.readexactly(length)
                frame = head + body
                try:
                    self.deliver(frame, decode_tcp(frame))
                except DecodeError as exc:
                    self.deliver(frame, exc)
        except asyncio.IncompleteReadError:
            self.ended = "the target closed the TCP link"
        except OSError as exc:
            self.ended = f"TCP link error: {exc}"

    async def close(self) -> None:
        self.ended = self.ended or "closed by the case"
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError, OSError):
            await self._task
        self._writer.close()
        with contextlib.suppress(OSError):
            await self._writer.wait_closed()


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, owner: _ChudpTransport) -> None:
        self.owner = owner

    def datagram_received(self, data: bytes, addr: object) -> None:
        try:
            self.owner.deliver(data, decode_chudp(data))
        except DecodeError as exc:
            self.owner.deliver(data, exc)

    def error_received(self, exc: Exception) -> None:
        self.owner.errors += 1


class _ChudpTransport(_Transport):
    def __init__(self, address: LinkAddress) -> None:
        super().__init__(address)
        self.errors = 0
        self._udp: asyncio.DatagramTransport | None = None

    async def start(self) -> None:
        udp, _ = await asyncio.get_running_loop().create_datagram_endpoint(
            lambda: _UdpProtocol(self),
            local_addr=self.address.local,
            remote_addr=(self.address.host, self.address.port),
        )
        self._udp = udp

    def encode(self, p: Packet) -> bytes:
        return encode_chudp(p, hw_dest=self.address.peer_addr, hw_src=self.address.my_addr)

    def wrap(self, body: bytes) -> bytes:
        return CHUDP_HEADER + body

    def write(self, frame: bytes) -> None:
        if self._udp is not None and self.ended is None:
            self._udp.sendto(frame)

    async def close(self) -> None:
        self.ended = self.ended or "closed by the case"
        if self._udp is not None:
            self._udp.close()


@dataclass
class RawConnection:
    """A connection we opened by hand; numbers are ours to choose, defaults follow the usual rules."""

    peer: RawPeer
    index: int
    """Our (source) index."""
    rfc: Packet
    opn: Received
    next_packet_no: int = 0
    """The number our next controlled packet gets (RFC's + 1 at first)."""
    closed: bool = False

    @property
    def remote_index(self) -> int:
        return self.opn.packet.src_index

    @property
    def opn_no(self) -> int:
        return self.opn.packet.packet_no

    def mine(self, p: Packet) -> bool:
        """Whether ``p`` is for this connection from the target's side of it."""
        return p.dest_index == self.index and p.src_index == self.remote_index

    def packet(self, opcode: int, *, packet_no: int = 0, ack_no: int = 0, data: bytes = b"") -> Packet:
        return self.peer.packet(
            opcode,
            dest_index=self.remote_index,
            src_index=self.index,
            packet_no=packet_no,
            ack_no=ack_no,
            data=data,
        )

    def sts(self, *, ack: int, receipt: int | None = None, window: int = 5) -> Packet:
        """Send STS: ``ack`` in the header, (``receipt`` or ``ack``, ``window``) as data."""
        p = self.packet(
            ChaosOp.STS,
            packet_no=self.next_packet_no,
            ack_no=ack,
            data=pack_status(ack if receipt is None else receipt, window),
        )
        self.peer.send(p)
        return p

    def data(
        self, data: bytes, *, opcode: int = ChaosOp.DAT, ack: int, packet_no: int | None = None
    ) -> Packet:
        """Send a controlled data packet (next number unless ``packet_no``, which repeats an old one)."""
        number = self.next_packet_no if packet_no is None else packet_no
        if packet_no is None:
            self.next_packet_no = seq_add(number, 1)
        p = self.packet(opcode, packet_no=number, ack_no=ack, data=data)
        self.peer.send(p)
        return p

    def close(self, reason: str = "closed by the conformance case") -> None:
        """Send CLS (best effort, as Chaos closes are)."""
        if not self.closed:
            self.closed = True
            self.peer.send(self.packet(ChaosOp.CLS, data=reason.encode("latin-1")))


@dataclass
class RawPeer:
    """A raw Chaos peer on one link to the target; see the module docstring."""

    address: LinkAddress
    _transport: _Transport
    on_packet: PacketHook | None = None
    clock: Callable[[], float] | None = None
    """Times of what arrives (default: the event loop's clock, virtual in a simulated run)."""
    inbox: list[Received] = field(default_factory=list)
    bad: list[tuple[bytes, DecodeError]] = field(default_factory=list)
    sent: list[tuple[Packet, bytes]] = field(default_factory=list)
    connections: list[RawConnection] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._arrived = asyncio.Event()
        self._transport.deliver = self._deliver
        self._now: Callable[[], float] = self.clock or asyncio.get_running_loop().time

    @classmethod
    async def open(
        cls,
        address: str | LinkAddress,
        *,
        on_packet: PacketHook | None = None,
        clock: Callable[[], float] | None = None,
        timeout: float = 5.0,
    ) -> RawPeer:
        """Open the link to the target at ``address`` (tcp:// or chudp://); :class:`RawError` if not."""
        addr = parse_address(address) if isinstance(address, str) else address
        transport: _Transport
        try:
            async with asyncio.timeout(timeout):
                if addr.scheme == "tcp":
                    reader, writer = await asyncio.open_connection(addr.host, addr.port)
                    transport = _TcpTransport(addr, reader, writer)
                elif addr.scheme == "unix":
                    assert addr.path is not None
                    reader, writer = await asyncio.open_unix_connection(addr.path)
                    transport = _TcpTransport(addr, reader, writer)
                elif addr.scheme == "chudp":
                    udp = _ChudpTransport(addr)
                    await udp.start()
                    transport = udp
                else:
                    raise RawError(f"raw Chaos packets are not supported on {addr.scheme}:// links")
        except (OSError, TimeoutError) as exc:
            raise RawError(f"could not open {addr}: {type(exc).__name__}: {exc}") from exc
        return cls(addr, transport, on_packet, clock)

    # ------------------------------------------------------------------------------- sending

    def packet(
        self,
        opcode: int,
        *,
        dest_index: int = 0,
        src_index: int = 0,
        packet_no: int = 0,
        ack_no: int = 0,
        data: bytes = b"",
        dest_host: int | None = None,
    ) -> Packet:
        """A packet from us to the target host (``dest_host`` overrides the destination)."""
        return Packet(
            opcode,
            self.address.peer_addr if dest_host is None else dest_host,
            dest_index,
            self.address.my_addr,
            src_index,
            packet_no & 0xFFFF,
            ack_no & 0xFFFF,
            bytes(data),
        )

    def send(self, p: Packet) -> bytes:
        """Send ``p`` as it is; return the frame bytes written."""
        frame = self._transport.encode(p)
        self.send_frame(frame, p)
        return frame

    def send_forged(self, p: Packet) -> bytes:
        """Send ``p`` framed without any check (see :meth:`_Transport.forge`); return the frame."""
        frame = self._transport.forge(p)
        self.send_frame(frame, p)
        return frame

    def send_frame(self, frame: bytes, p: Packet) -> None:
        """Write ``frame`` (which may be forged beyond what :meth:`send` encodes); ``p`` is what it says."""
        self._transport.write(frame)
        self.sent.append((p, frame))
        if self.on_packet is not None:
            self.on_packet("c2s", p, frame)

    # ------------------------------------------------------------------------------- receiving

    @property
    def ended(self) -> str | None:
        """Why the link ended (TCP closed by the target), or None while it is up."""
        return self._transport.ended

    def _deliver(self, raw: bytes, item: Packet | DecodeError) -> None:
        if isinstance(item, DecodeError):
            self.bad.append((raw, item))
        else:
            self.inbox.append(Received(item, raw, self._now()))
            if self.on_packet is not None:
                self.on_packet("s2c", item, raw)
        self._arrived.set()

    def _take(self, match: Match) -> Received | None:
        for i, item in enumerate(self.inbox):
            if match(item.packet):
                return self.inbox.pop(i)
        return None

    async def receive(self, match: Match = lambda p: True, timeout: float = 2.0) -> Received | None:
        """The first packet ``match`` accepts (others stay in the inbox), or None after ``timeout``."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while True:
            found = self._take(match)
            if found is not None:
                return found
            remaining = deadline - loop.time()
            if remaining <= 0 or (self.ended is not None and not self._arrived.is_set()):
                return None
            self._arrived.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(remaining):
                    await self._arrived.wait()

    async def collect(self, duration: float, match: Match = lambda p: True) -> list[Received]:
        """Every packet ``match`` accepts within ``duration`` seconds (from the inbox first)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + duration
        out: list[Received] = []
        while True:
            item = await self.receive(match, max(0.0, deadline - loop.time()))
            if item is None:
                return out
            out.append(item)

    # ------------------------------------------------------------------------------- connections

    def rfc(self, index: int, packet_no: int, contact: str | None = None) -> Packet:
        """Send an RFC from our ``index`` with ``packet_no``; return it (to send again as a duplicate)."""
        name = self.address.contact if contact is None else contact
        p = self.packet(ChaosOp.RFC, src_index=index, packet_no=packet_no, data=name.encode("ascii"))
        self.send(p)
        return p

    async def handshake(
        self, index: int, packet_no: int, *, timeout: float = 5.0, retry_busy: bool = True
    ) -> RawConnection:
        """Open a connection by hand: RFC (copies every second while unanswered) until OPN.

        Raises :class:`RefusedError` on CLS/ANS/FWD/LOS (a CLS saying "busy" is retried first, the
        previous case's connection may still be closing) and :class:`RawError` on no answer."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        tries = 0
        while True:
            rfc = self.rfc(index, packet_no)
            answer = await self.receive(
                lambda p: p.dest_index == index and p.opcode != ChaosOp.SNS,
                min(RFC_RETRY, max(0.0, deadline - loop.time())),
            )
            if answer is None:
                if loop.time() >= deadline or self.ended is not None:
                    raise RawError(
                        f"no answer to RFC {self.address.contact!r} within {timeout:g} s"
                        + (f" ({self.ended})" if self.ended else "")
                    )
                continue
            p = answer.packet
            if p.opcode == ChaosOp.OPN:
                conn = RawConnection(self, index, rfc, answer, seq_add(packet_no, 1))
                self.connections.append(conn)
                return conn
            busy = p.opcode == ChaosOp.CLS and says_busy(text(p.data))
            if busy and retry_busy and tries < BUSY_RETRIES:
                tries += 1
                await asyncio.sleep(BUSY_DELAY)
                continue
            raise RefusedError(f"the RFC was answered by {format_packet(p)}", answer)

    async def close(self) -> None:
        """CLS on every open connection, then close the link."""
        for conn in self.connections:
            if self.ended is None:
                conn.close()
        if isinstance(self._transport, _TcpTransport) and self.ended is None:
            await asyncio.sleep(0)  # let the CLS frames reach the socket before it closes
        await self._transport.close()

    async def __aenter__(self) -> RawPeer:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
