"""The suite's raw Chaos peer: links to the target that send exactly the bytes they are given and hand
over, decoded, every frame the target sends, with the bytes it came in.

The NCP clauses (retransmission, window, LOS, duplicate RFC) cannot be tested through manip's own NCP:
it would retransmit, acknowledge and window for us.  Two users drive these links by hand instead: the
NCP cases (:class:`RawPeer`, which sends nothing a case did not ask for: no acknowledgement, no STS, no
retransmission) and the fuzzer (:mod:`manip.conformance.fuzz.session`, whose connection does the least a
peer must and nothing else).

Theory of operation:

* **Links.**  :func:`open_link` opens a :class:`RawLink` to the target: a :class:`RawStreamLink` (``tcp://``,
  ``unix://``: manip's TCP link framing, :mod:`manip.codecs.framing`; ``chaosd://``: usim's chaosd
  framing, through a daemon that routes by the trailer) or a :class:`RawDatagramLink` (``chudp://``).
  Every frame that arrives goes to the link's :class:`PacketSink`, decoded with its bytes (``deliver``)
  or refused (``reject``, with why); a stream whose framing is lost (a frame length no frame can have)
  is closed, and when that happens before any frame the link says what the peer is instead
  (:func:`~manip.links.errors.not_a_chaos_link`).  :meth:`RawLink.encode` frames a packet as the
  codecs do (they refuse what is illegal); :func:`frame` lays out any packet at all, with the damage a
  fuzz input asks for (:data:`Damage`) and the checksum recomputed after it (unless the checksum is the
  damage), so exactly one thing is wrong with it.
* **The NCP cases' peer.**  :meth:`RawPeer.open` opens one link and is its sink: every packet goes to
  ``inbox`` as a :class:`Received` (packet, bytes, time), frames that do not decode to ``bad``, and both
  ways to ``on_packet`` (cases record them).  :meth:`RawPeer.receive` takes the first inbox packet a
  predicate accepts, waiting up to a timeout; :meth:`RawPeer.collect` takes every accepted packet for a
  given time (for "nothing else came").
* :meth:`RawPeer.handshake` drives the opening by hand (:func:`rfc_until_open`, which the fuzzer's
  connection uses too): RFC with a chosen source index and packet number, wait for OPN (an RFC
  refused as busy is retried, :mod:`~manip.conformance.suite.busy`), and the connection
  (:class:`RawConnection`) is then OPEN on our side.  The STS answering the OPN is the case's to send
  (:meth:`RawConnection.sts`), with whatever window it wants; :meth:`RawConnection.data` sends data
  with a chosen number and ack.
* :meth:`RawPeer.close` sends CLS on every connection it opened (so the server frees its robot at once)
  and closes the link.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Final, Literal, Protocol, cast

from manip.codecs.chaos import chaos_checksum, packet_words
from manip.codecs.errors import DecodeError
from manip.codecs.framing import (
    CHUDP_HEADER,
    ChaosdFrameDecoder,
    FrameSyncError,
    StreamDecoder,
    TcpFrameDecoder,
    chaosd_frame,
    decode_chudp,
    encode_chaosd,
    encode_chudp,
    encode_tcp,
)
from manip.codecs.packet import Packet
from manip.conformance.judge.checks import Direction
from manip.conformance.suite.busy import BUSY_DELAY, BUSY_PATIENCE, says_busy
from manip.links.address import LinkAddress, parse_address
from manip.links.errors import chaos_host, not_a_chaos_link
from manip.ncp.packets import pack_status, text, unpack_status
from manip.ncp.seq import seq_add
from manip.spec import SPEC
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

__all__ = [
    "Damage",
    "Direction",
    "PacketSink",
    "RawConnection",
    "RawDatagramLink",
    "RawError",
    "RawLink",
    "RawPeer",
    "RawStreamLink",
    "Received",
    "RefusedError",
    "format_packet",
    "frame",
    "open_link",
    "rfc_until_open",
]

PacketHook = Callable[[Direction, Packet, bytes], None]
Match = Callable[[Packet], bool]
Damage = Literal["", "checksum", "nbytes", "header-byte", "version", "function", "short", "long"]
"""What :func:`frame` breaks below a packet: its checksum, its byte count, the unused header byte; on
CHUDP the datagram header's version or function byte, or its length (cut or padded)."""

RFC_RETRY: Final = 1.0
"""Seconds between copies of an unanswered RFC during :meth:`RawPeer.handshake`."""
FOREIGN_HEAD: Final = 80
"""Bytes of a peer's first data kept, to say what it is when its first frame length is no frame's."""
KEPT_BAD: Final = 100
MAX_RECEIVED: Final = 20_000
"""The most packets a :class:`RawPeer` takes from the target (a case needs a few dozen: the target's
NCP stops at the window, since the peer acknowledges nothing it is not told to); past it a flood is
counted (``RawPeer.dropped``), not kept."""
"""Frames that do not decode a :class:`RawPeer` keeps (the first ones)."""
_RESET: Final = struct.pack("ii", 1, 0)


class RawError(Exception):
    """The raw link could not be opened or used (the message says why)."""


class RefusedError(RawError):
    """The target answered our RFC with something other than OPN (CLS, ANS, FWD, LOS)."""

    def __init__(self, message: str, answer: Received) -> None:
        super().__init__(message)
        self.answer = answer


class PacketSink(Protocol):
    """Where a link puts what the target sends."""

    def deliver(self, packet: Packet, raw: bytes, now: float) -> None:
        """A frame that decoded, with its bytes and the event loop's time."""

    def reject(self, raw: bytes, exc: DecodeError) -> None:
        """A frame that did not decode (or the bytes after which a stream's framing was lost)."""

    def link_ended(self, link: RawLink) -> None:
        """The link closed (``link.ended`` says why)."""


class RawLink:
    """One link to the target (see the module docstring)."""

    datagram = False
    chaosd = False
    """The stream carries usim's chaosd framing (4-byte header, words low byte first), not manip's TCP
    link framing."""

    def __init__(self, address: LinkAddress, sink: PacketSink) -> None:
        self.address = address
        self.sink = sink
        self.ended: str | None = None
        """Why the link ended, or None while it is up."""
        self._loop = asyncio.get_running_loop()
        self.closed: asyncio.Future[None] = self._loop.create_future()

    def send(self, data: bytes) -> None:
        """Write ``data`` (a frame, part of one, or any bytes) as it is."""
        raise NotImplementedError

    def close(self, *, reset: bool = False) -> None:
        """Close the link (``reset``: a stream is reset, not closed in order)."""
        raise NotImplementedError

    def encode(self, p: Packet) -> bytes:
        """``p`` framed by the codecs, the trailer naming the target as the next hop and us as the last."""
        hop = {"hw_dest": self.address.peer_addr, "hw_src": self.address.my_addr}
        if self.datagram:
            return encode_chudp(p, **hop)
        return encode_chaosd(p, **hop) if self.chaosd else encode_tcp(p, **hop)

    def forge(self, p: Packet, *, damage: Damage = "") -> bytes:
        """``p`` framed with no checks at all (an illegal opcode, more than 488 data bytes...)."""
        hop = (self.address.peer_addr, self.address.my_addr)
        return frame(p, datagram=self.datagram, hop=hop, damage=damage, chaosd=self.chaosd)

    def _take(self, packet: Packet, raw: bytes, now: float) -> None:
        """Hand ``packet`` to the sink, unless it names our own address as its source: no other host has
        it, so its header is laid out wrong (``chaos.header.layout``), and a link refuses it."""
        if packet.src_host == self.address.my_addr:
            why = f"the source host {octal(packet.src_host)} is our own address"
            self.sink.reject(raw, DecodeError(why, "header.source", 8, "chaos.header.layout"))
            return
        self.sink.deliver(packet, raw, now)

    def _end(self, reason: str) -> None:
        if self.ended is None:
            self.ended = reason
        if not self.closed.done():
            self.closed.set_result(None)
        self.sink.link_ended(self)


class RawStreamLink(RawLink, asyncio.Protocol):
    """A connection carrying manip's TCP link frames (or, for ``chaosd://``, usim's chaosd frames)."""

    def __init__(self, address: LinkAddress, sink: PacketSink) -> None:
        super().__init__(address, sink)
        self._transport: asyncio.Transport | None = None
        self.chaosd = address.scheme == "chaosd"
        self._decoder: StreamDecoder = ChaosdFrameDecoder() if self.chaosd else TcpFrameDecoder()
        self._buffer = bytearray()
        """The bytes of the frames the decoder has not returned yet."""
        self._head = b""
        self._frames = 0
        self._closing: str | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.Transport", transport)

    def data_received(self, data: bytes) -> None:
        now = self._loop.time()
        if len(self._head) < FOREIGN_HEAD:
            self._head += data[: FOREIGN_HEAD - len(self._head)]
        self._buffer += data
        lost: FrameSyncError | None = None
        try:
            items = self._decoder.feed(data)
        except FrameSyncError as exc:
            items, lost = list(exc.items), exc
        for item in items:
            size = self._decoder.prefix + int.from_bytes(self._buffer[:2], "big")
            raw = bytes(self._buffer[:size])
            del self._buffer[:size]
            self._frames += 1
            if isinstance(item, Packet):
                self._take(item, raw, now)
            else:
                self.sink.reject(raw, item)
        if lost is not None:
            self.sink.reject(bytes(self._buffer[:64]), lost)
            foreign = self._frames == 0
            self._closing = not_a_chaos_link(self._head) if foreign else f"framing lost: {lost}"
            self.close()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._closing is not None:
            self._end(self._closing)
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
        if self._closing is None:
            self._closing = "closed by us"
        if reset:
            sock = self._transport.get_extra_info("socket")
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
            self._transport.abort()
        else:
            self._transport.close()


class RawDatagramLink(RawLink, asyncio.DatagramProtocol):
    """A UDP socket speaking CHUDP to the target."""

    datagram = True

    def __init__(self, address: LinkAddress, sink: PacketSink) -> None:
        super().__init__(address, sink)
        self._transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast("asyncio.DatagramTransport", transport)

    def datagram_received(self, data: bytes, addr: object) -> None:
        try:
            packet = decode_chudp(data)
        except DecodeError as exc:
            self.sink.reject(data, exc)
            return
        trailer = packet.trailer
        if trailer is not None and trailer.source == self.address.my_addr:  # no other host has our address
            why = f"the trailer's hardware source {octal(trailer.source)} is our own address"
            self.sink.reject(data, DecodeError(why, "trailer.source", len(data) - 4, "chudp.trailer"))
            return
        self._take(packet, data, self._loop.time())

    def error_received(self, exc: Exception) -> None:
        pass  # ICMP unreachable from a target that is gone: no answer says so

    def connection_lost(self, exc: Exception | None) -> None:
        self._end("closed")

    def send(self, data: bytes) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(data)

    def close(self, *, reset: bool = False) -> None:
        if self._transport is not None:
            self._transport.close()


async def open_link(address: LinkAddress, sink: PacketSink, timeout: float) -> RawLink:
    """A new link to the target; OSError (refused, unreachable) or TimeoutError if it cannot be had,
    :class:`RawError` for a scheme that carries no raw Chaos packets."""
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(timeout):
        if address.scheme == "tcp":
            _, stream = await loop.create_connection(
                lambda: RawStreamLink(address, sink), address.host, address.port
            )
            return stream
        if address.scheme in ("unix", "chaosd"):
            assert address.path is not None
            _, stream = await loop.create_unix_connection(lambda: RawStreamLink(address, sink), address.path)
            return stream
        if address.scheme == "chudp":
            local = address.local or ("::1" if ":" in address.host else "127.0.0.1", 0)
            _, datagram = await loop.create_datagram_endpoint(
                lambda: RawDatagramLink(address, sink),
                local_addr=local,
                remote_addr=(address.host, address.port),
            )
            return datagram
    raise RawError(f"raw Chaos packets are not supported on {address.scheme}:// links")


def frame(
    packet: Packet, *, datagram: bool, hop: tuple[int, int], damage: Damage = "", chaosd: bool = False
) -> bytes:
    """``packet`` laid out for a link as it is (no check), its trailer naming ``hop`` (next hop, last
    hop), with ``damage`` done to it (:data:`Damage`); a stream's frame in usim's chaosd framing with
    ``chaosd``, in manip's TCP link framing without."""
    dest, source = hop
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
    body = struct.pack(
        f"{'<' if chaosd and not datagram else '>'}{len(words) + 3}H", *words, dest, source, checksum
    )
    if chaosd and not datagram:
        return chaosd_frame(body)
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


async def rfc_until_open(
    send_rfc: Callable[[], object],
    answer: Callable[[float], Awaitable[Received | None]],
    *,
    contact: str,
    timeout: float,
    ended: Callable[[], str | None],
    retry_busy: bool = True,
) -> Received:
    """The opening of a connection by hand, for both users of the raw links: ``send_rfc`` (again every
    :data:`RFC_RETRY` seconds while unanswered) until ``answer`` (the target's next answer to it, or
    None after the seconds it is given) is OPN, which is returned.

    Raises :class:`RefusedError` on CLS, ANS, FWD or LOS (a CLS saying busy is retried first by the
    suite's one rule, :mod:`~manip.conformance.suite.busy`: the previous connection may still be
    closing) and :class:`RawError` when nothing answers within ``timeout`` or the link ``ended``."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    busy_until = loop.time() + BUSY_PATIENCE
    busy: Received | None = None
    while True:
        send_rfc()
        got = await answer(min(RFC_RETRY, max(0.0, deadline - loop.time())))
        if got is None:
            gone = ended()
            if loop.time() < deadline and gone is None:
                continue
            if busy is not None:
                reason = text(busy.packet.data)
                raise RefusedError(f"the RFC was refused as busy ({reason!r}) for {timeout:g} s", busy)
            raise RawError(
                f"no answer to RFC {contact!r} within {timeout:g} s" + (f" ({gone})" if gone else "")
            )
        p = got.packet
        if p.opcode == ChaosOp.OPN:
            return got
        if retry_busy and p.opcode == ChaosOp.CLS and says_busy(text(p.data)) and loop.time() < busy_until:
            busy = got
            await asyncio.sleep(BUSY_DELAY)
            continue
        raise RefusedError(f"the RFC was answered by {format_packet(p)}", got)


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
    on_packet: PacketHook | None = None
    clock: Callable[[], float] | None = None
    """Times of what arrives (default: the event loop's clock, virtual in a simulated run)."""
    inbox: list[Received] = field(default_factory=list)
    bad: list[tuple[bytes, DecodeError]] = field(default_factory=list)
    sent: list[tuple[Packet, bytes]] = field(default_factory=list)
    connections: list[RawConnection] = field(default_factory=list)
    received: int = 0
    dropped: int = 0
    """Packets past :data:`MAX_RECEIVED`: counted, neither kept nor passed to ``on_packet``."""
    _link: RawLink = field(init=False)

    def __post_init__(self) -> None:
        self._arrived = asyncio.Event()
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
        """Open the link to the target at ``address`` (tcp://, unix://, chudp://); else :class:`RawError`."""
        addr = parse_address(address) if isinstance(address, str) else address
        peer = cls(addr, on_packet, clock)
        try:
            peer._link = await open_link(addr, peer, timeout)
        except (OSError, TimeoutError) as exc:
            raise RawError(f"could not open {addr}: {type(exc).__name__}: {exc}") from exc
        return peer

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
        """Send ``p`` as the codecs frame it; return the frame bytes written."""
        raw = self._link.encode(p)
        self.send_frame(raw, p)
        return raw

    def send_forged(self, p: Packet) -> bytes:
        """Send ``p`` framed without any check (see :meth:`RawLink.forge`); return the frame."""
        raw = self._link.forge(p)
        self.send_frame(raw, p)
        return raw

    def send_frame(self, raw: bytes, p: Packet) -> None:
        """Write ``raw`` (which may be forged beyond what :meth:`send` encodes); ``p`` is what it says."""
        self._link.send(raw)
        self.sent.append((p, raw))
        if self.on_packet is not None:
            self.on_packet("c2s", p, raw)

    # ------------------------------------------------------------------------------- receiving

    @property
    def ended(self) -> str | None:
        """Why the link ended (TCP closed by the target), or None while it is up."""
        return self._link.ended

    def deliver(self, packet: Packet, raw: bytes, now: float) -> None:
        """The link's :class:`PacketSink`: into the inbox, timed by the peer's clock (at most
        :data:`MAX_RECEIVED` packets; the rest are counted)."""
        self.received += 1
        if self.received > MAX_RECEIVED:
            self.dropped += 1
            return
        self.inbox.append(Received(packet, raw, self._now()))
        if self.on_packet is not None:
            self.on_packet("s2c", packet, raw)
        self._arrived.set()

    def reject(self, raw: bytes, exc: DecodeError) -> None:
        if len(self.bad) < KEPT_BAD:
            self.bad.append((raw, exc))
        self._arrived.set()

    def link_ended(self, link: RawLink) -> None:
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
        """Open a connection by hand from our ``index``, the RFC numbered ``packet_no``
        (:func:`rfc_until_open`)."""
        contact = self.address.contact
        rfc = self.packet(ChaosOp.RFC, src_index=index, packet_no=packet_no, data=contact.encode("ascii"))
        answer = await rfc_until_open(
            lambda: self.send(rfc),
            lambda wait: self.receive(lambda p: p.dest_index == index and p.opcode != ChaosOp.SNS, wait),
            contact=contact,
            timeout=timeout,
            ended=lambda: self.ended,
            retry_busy=retry_busy,
        )
        conn = RawConnection(self, index, rfc, answer, seq_add(packet_no, 1))
        self.connections.append(conn)
        return conn

    async def close(self) -> None:
        """CLS on every open connection, then close the link."""
        for conn in self.connections:
            if self.ended is None:
                conn.close()
        self._link.close()  # a stream sends what it holds (the CLS frames) before it closes
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(RFC_RETRY):
                await asyncio.shield(self._link.closed)

    async def __aenter__(self) -> RawPeer:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
