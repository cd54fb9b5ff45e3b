"""Links over a byte stream (TCP, unix socket): one connection is one point-to-point Chaos link.

The framing codec finds the packets; this module only moves bytes.  A frame that decodes badly is
counted and skipped (its length says where the next starts); a bad length means the frame boundaries
are lost, so the stream is closed and counted under ``framing``.  A sound frame with an illegal opcode is
delivered for the NCP to answer (``stats.illegal``); a stream frame cannot hold more than 488 data bytes.
``waiting_since`` says how long a frame has been awaited, for a server's guard to close links that stall.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Final, TypeVar, cast

from manip.codecs.chaos import IllegalPacketError
from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.framing import MAX_BODY, MIN_BODY, FrameSyncError, StreamDecoder, StreamItem
from manip.codecs.packet import Packet
from manip.ncp.defects import ChaosDefects

from .base import Encoder, Link, bad_reason
from .errors import LinkError, not_a_chaos_link

S = TypeVar("S", bound="StreamLink")


HEAD_KEPT: Final = 80
"""Bytes kept of what the peer sent first: when it is not the link framing at all (an HTTP server at the
address), the reason the link closes shows them (:func:`~manip.links.errors.not_a_chaos_link`)."""
UNBOUNDED_BODY: Final = MIN_BODY + 0x1000
"""The longest frame body a stream link takes without the 488-byte bound: 4095 data bytes and a pad."""
WRITE_BUFFER_LIMIT: Final = 256 * 1024
"""Above this many unsent bytes a link drops packets (``dropped['congested']``) instead of queueing
more: a peer that stopped reading must not make us buffer without end, and the NCP retransmits."""


def stream_max_body(defects: ChaosDefects | None) -> int:
    """The longest frame body a stream link with ``defects`` takes: 488 data bytes, or with no bound on
    the data (a defect) what the 12-bit nbytes can count."""
    return MAX_BODY if defects is None or defects.bounds_data else UNBOUNDED_BODY


class StreamLink(Link, asyncio.Protocol):
    """An asyncio protocol that is a link: frames out with ``encode``, frames in with ``decoder``."""

    learns_peer: bool = True
    """Take ``peer_addr`` from the trailer source of the first good frame when it is not known."""

    def __init__(
        self,
        encode: Encoder,
        decoder: StreamDecoder,
        *,
        my_addr: int,
        peer_addr: int | None = None,
        name: str = "",
        defects: ChaosDefects | None = None,
    ) -> None:
        super().__init__(my_addr=my_addr, peer_addr=peer_addr, name=name, defects=defects)
        self._encode = encode
        self._decoder = decoder
        self._transport: asyncio.Transport | None = None
        self._closing_reason: str | None = None
        self._loop = asyncio.get_running_loop()
        self.waiting_since: float | None = None
        """Loop time since which a frame is awaited: from the connection until the first frame, then
        from the first byte of each frame until it is complete; None while nothing is held back (a
        server's :class:`~manip.links.guard.LinkGuard` closes a link on which it grows old)."""
        self._head = b""

    # ---------------------------------------------------------------- asyncio.Protocol

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.Transport, transport)
        self.waiting_since = self._loop.time()
        if self._closing_reason is not None:  # closed before the connection was made
            transport.close()

    def data_received(self, data: bytes) -> None:
        if self._closing_reason is not None:
            return  # closing (framing lost, or closed by us): what follows is not read
        self.stats.bytes_in += len(data)
        if len(self._head) < HEAD_KEPT:
            self._head += data[: HEAD_KEPT - len(self._head)]
        try:
            items = self._decoder.feed(data)
        except FrameSyncError as exc:
            foreign = not exc.items and not self.stats.frames_in and not self.stats.bad_total
            self._take(exc.items)
            self._bad("framing", exc, exc.clause)
            if foreign:  # not one frame before the framing broke: the peer does not speak it at all
                self.abort(f"{not_a_chaos_link(self._head)} (framing lost: {exc})")
            else:
                self.abort(f"framing lost: {exc}")
            return
        if items:
            self.waiting_since = self._loop.time() if self._decoder.pending else None
        elif self.waiting_since is None and self._decoder.pending:
            self.waiting_since = self._loop.time()
        self._take(items)

    def eof_received(self) -> bool | None:
        if self._closing_reason is None:
            self._closing_reason = "end of stream from the peer"
        return None  # let the transport close

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None
        reason = self._closing_reason
        if reason is None:
            reason = f"connection lost: {exc}" if exc is not None else "closed by the peer"
        self._set_closed(reason)

    # ---------------------------------------------------------------- Link

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        transport = self._transport
        # A transport closing after a socket error logs a warning for every write (a peer that resets
        # while we send would fill the log): such packets are dropped and counted instead.
        if transport is None or self._closing_reason is not None or transport.is_closing():
            return self._drop("closed", packet)
        if transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
            return self._drop("congested", packet)
        hop = next_hop if next_hop is not None else self.peer_addr
        try:
            frame = self._frame(self._encode, packet, hop)
        except EncodeError:
            return self._drop("encode", packet)
        transport.write(frame)
        stats = self.stats
        stats.frames_out += 1
        stats.bytes_out += len(frame)
        return True

    def close(self) -> None:
        self._shut("closed locally", abort=False)

    def abort(self, reason: str = "aborted locally") -> None:
        """Drop the connection at once, discarding unsent output."""
        self._shut(reason, abort=True)

    # ---------------------------------------------------------------- extras

    def pause_reading(self) -> None:
        """Stop reading from the socket (tests use it to make a peer fall silent)."""
        if self._transport is not None:
            self._transport.pause_reading()

    def resume_reading(self) -> None:
        if self._transport is not None:
            self._transport.resume_reading()

    @property
    def transport(self) -> asyncio.Transport | None:
        return self._transport

    # ---------------------------------------------------------------- internals

    def _take(self, items: list[StreamItem] | tuple[StreamItem, ...]) -> None:
        for item in items:
            if isinstance(item, DecodeError):
                if not isinstance(item, IllegalPacketError):
                    self._bad(bad_reason(item), item, item.clause)
                    continue
                item = self._illegal(item)
            if self.peer_addr is None:
                trailer = item.trailer
                if self.learns_peer and trailer is not None and trailer.source:
                    self.peer_addr = trailer.source
            self._deliver(item)

    def _shut(self, reason: str, *, abort: bool) -> None:
        if self._closing_reason is None:
            self._closing_reason = reason
        transport = self._transport
        if transport is None:
            self._set_closed(self._closing_reason)
        elif abort:
            transport.abort()
        else:
            transport.close()


async def dial(link: S, connect: Callable[[], Awaitable[object]], where: str, timeout: float | None) -> S:
    """Make ``link``'s connection with ``connect`` (``loop.create_connection`` and its kin) within
    ``timeout``; :class:`LinkError` naming ``where`` if it cannot be made (the link is closed then)."""
    try:
        async with asyncio.timeout(timeout):
            await connect()
    except (OSError, TimeoutError) as exc:
        link.close()
        what = "timed out" if isinstance(exc, TimeoutError) else str(exc)
        raise LinkError(f"cannot reach {where}: {what}") from exc
    return link
